"""Score detected edges and corners against a scene's exact truth.

The criteria are those of the geometry issue: a true edge is *found* when some
detected segment lies within `max_rms` (RMS of the perpendicular distances of
the true edge's two endpoints to the detected line) and covers at least
`min_overlap` of the true edge's length; a true corner is found when a detected
corner lies within `max_distance`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..io.vector import PointSet, Segments

__all__ = ["EdgeScore", "CornerScore", "score_edges", "score_corners"]


class _Counts:
    """Counts shared by the score results (``true_index`` and ``matched`` arrays)."""

    true_index: np.ndarray
    matched: np.ndarray
    n_found: int

    @property
    def n_true(self) -> int:
        return int(len(self.true_index))

    @property
    def n_matched(self) -> int:
        return int((self.matched >= 0).sum())

    @property
    def recall(self) -> float:
        """Share of scored true items that were found (NaN when none were scored)."""
        return self.n_matched / self.n_true if self.n_true else float("nan")

    def _counts(self) -> dict[str, Any]:
        return {
            "n_true": self.n_true,
            "n_found": int(self.n_found),
            "n_matched": self.n_matched,
            "recall": float(self.recall),
        }


@dataclass(frozen=True, eq=False)
class EdgeScore(_Counts):
    """Result of :func:`score_edges`.

    Attributes
    ----------
    true_index : ndarray of shape (m,)
        Indices (rows of the truth) of the true edges that were scored.
    matched : ndarray of shape (m,)
        Row of the detected segment matched to each scored true edge, -1 if none.
    rms : ndarray of shape (m,)
        RMS endpoint distance (m) to the matched segment (NaN if none).
    overlap : ndarray of shape (m,)
        Covered fraction of the true length by the matched segment (NaN if none).
    n_found : int
        Number of detected segments.
    """

    true_index: np.ndarray
    matched: np.ndarray
    rms: np.ndarray
    overlap: np.ndarray
    n_found: int

    def found_of_kind(self, truth: Segments, kind: str) -> tuple[int, int]:
        """``(matched, scored)`` counts of the true edges of one `kind` (e.g. "eave")."""
        kinds = np.asarray(truth.attributes["kind"])[self.true_index]
        return int((self.matched[kinds == kind] >= 0).sum()), int((kinds == kind).sum())

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        ok = self.matched >= 0
        return {
            **self._counts(),
            "rms_mean": float(np.mean(self.rms[ok])) if ok.any() else None,
            "rms_max": float(np.max(self.rms[ok])) if ok.any() else None,
            "overlap_mean": float(np.mean(self.overlap[ok])) if ok.any() else None,
        }


@dataclass(frozen=True, eq=False)
class CornerScore(_Counts):
    """Result of :func:`score_corners` (same layout as :class:`EdgeScore`)."""

    true_index: np.ndarray
    matched: np.ndarray
    distance: np.ndarray
    n_found: int

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        ok = self.matched >= 0
        return {
            **self._counts(),
            "distance_mean": float(np.mean(self.distance[ok])) if ok.any() else None,
            "distance_max": float(np.max(self.distance[ok])) if ok.any() else None,
        }


def _select(attributes: dict, n: int, kinds: Sequence[str] | None) -> np.ndarray:
    keep = np.ones(n, dtype=bool)
    if kinds is not None:
        keep &= np.isin(np.asarray(attributes["kind"]).astype(str), np.asarray(list(kinds), str))
    return keep


def score_edges(
    found: Segments,
    truth: Segments,
    *,
    max_rms: float = 0.03,
    min_overlap: float = 0.7,
    min_length: float = 2.0,
    kinds: Sequence[str] | None = None,
) -> EdgeScore:
    """Match true edges to detected segments.

    Parameters
    ----------
    found : Segments
        Detected segments.
    truth : Segments
        True edges, e.g. ``scene.edges``.
    max_rms : float, default 0.03
        Largest RMS (m) of the perpendicular distances of the true endpoints to
        the detected (infinite) line.
    min_overlap : float, default 0.7
        Smallest share of the true length covered by the detected segment
        projected onto the true edge.
    min_length : float, default 2.0
        Only true edges at least this long (m) are scored.
    kinds : sequence of str, optional
        Only true edges of these kinds (e.g. ``("ridge", "eave", "verge", "wall")``).

    Returns
    -------
    EdgeScore
        For each scored true edge the best (smallest RMS) qualifying detected
        segment; a detected segment may match several collinear true edges.
    """
    keep = _select(truth.attributes, len(truth), kinds) & (truth.lengths >= min_length)
    idx = np.flatnonzero(keep)
    m = len(idx)
    matched = np.full(m, -1, dtype=np.int64)
    rms_out = np.full(m, np.nan)
    ov_out = np.full(m, np.nan)
    if m and len(found):
        s = truth.start[idx]  # (m, 3)
        e = truth.end[idx]
        length = np.linalg.norm(e - s, axis=1)
        v = (e - s) / length[:, None]
        a = found.start  # (k, 3)
        d = found.end - a
        dl = np.linalg.norm(d, axis=1)
        u = np.divide(d, dl[:, None], out=np.zeros_like(d), where=dl[:, None] > 0)

        def perp(p: np.ndarray) -> np.ndarray:  # (m, k) distance of p_i to line k
            w = p[:, None, :] - a[None, :, :]
            along = np.einsum("ikj,kj->ik", w, u)
            return np.linalg.norm(w - along[..., None] * u[None], axis=2)

        rms = np.sqrt(0.5 * (perp(s) ** 2 + perp(e) ** 2))
        ta = np.einsum("ikj,ij->ik", a[None] - s[:, None], v)
        tb = np.einsum("ikj,ij->ik", found.end[None] - s[:, None], v)
        lo = np.maximum(np.minimum(ta, tb), 0.0)
        hi = np.minimum(np.maximum(ta, tb), length[:, None])
        overlap = np.clip(hi - lo, 0.0, None) / length[:, None]
        ok = (rms <= max_rms) & (overlap >= min_overlap) & (dl[None] > 0)
        cost = np.where(ok, rms, np.inf)
        best = np.argmin(cost, axis=1) if cost.shape[1] else np.zeros(m, int)
        has = np.isfinite(cost[np.arange(m), best])
        matched[has] = best[has]
        rms_out[has] = rms[np.arange(m), best][has]
        ov_out[has] = overlap[np.arange(m), best][has]
    return EdgeScore(true_index=idx, matched=matched, rms=rms_out, overlap=ov_out,
                     n_found=len(found))


def score_corners(
    found: PointSet,
    truth: PointSet,
    *,
    max_distance: float = 0.03,
    kinds: Sequence[str] | None = None,
) -> CornerScore:
    """Match true corners to the nearest detected corner within `max_distance` (m, 3D).

    Parameters
    ----------
    found : PointSet
        Detected corners.
    truth : PointSet
        True corners, e.g. ``scene.corners``.
    max_distance : float, default 0.03
    kinds : sequence of str, optional
        Only true corners of these kinds (``"ridge"``, ``"eave"``, ``"foot"``, ``"car"``).

    Returns
    -------
    CornerScore
    """
    keep = _select(truth.attributes, len(truth), kinds)
    idx = np.flatnonzero(keep)
    m = len(idx)
    matched = np.full(m, -1, dtype=np.int64)
    dist = np.full(m, np.nan)
    if m and len(found):
        from scipy.spatial import cKDTree

        dd, jj = cKDTree(found.xyz).query(truth.xyz[idx], k=1)
        ok = dd <= max_distance
        matched[ok] = jj[ok]
        dist[ok] = dd[ok]
    return CornerScore(true_index=idx, matched=matched, distance=dist, n_found=len(found))
