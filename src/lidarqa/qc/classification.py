"""Classification against a reference: a multi-class confusion matrix, with κ.

The delivery's points are matched to a reference classification given as another point
cloud (or catalog): *the same points* (``tolerance=0``: the reference point at the same
position, to 1 mm) or the *nearest* reference point within ``tolerance`` metres.
Unmatched delivery points are counted apart. Rows of the matrix are reference classes,
columns delivery classes; producer's accuracy is per reference class (recall), user's
accuracy per delivery class (precision), and Cohen's κ is computed from the whole matrix.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from .conformance import FAIL, PASS, Check

__all__ = ["ConfusionMatrix", "confusion_matrix", "match_reference", "reference_confusion",
           "ReferenceTask"]


@dataclass(frozen=True)
class ConfusionMatrix:
    """Counts ``matrix[i, j]``: reference class ``codes[i]``, delivery class ``codes[j]``."""

    codes: tuple[int, ...]
    matrix: np.ndarray
    n_unmatched: int = 0

    def __add__(self, o: ConfusionMatrix) -> ConfusionMatrix:
        codes = tuple(sorted(set(self.codes) | set(o.codes)))
        m = np.zeros((len(codes), len(codes)), dtype=np.int64)
        for src in (self, o):
            idx = [codes.index(c) for c in src.codes]
            m[np.ix_(idx, idx)] += src.matrix
        return ConfusionMatrix(codes, m, self.n_unmatched + o.n_unmatched)

    @property
    def n(self) -> int:
        """Number of points compared."""
        return int(self.matrix.sum())

    @property
    def overall(self) -> float:
        """Overall accuracy (share of points on the diagonal)."""
        return float(np.trace(self.matrix) / self.n) if self.n else float("nan")

    @property
    def producers(self) -> np.ndarray:
        """Producer's accuracy per reference class (row): diagonal / row sum."""
        rows = self.matrix.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(rows > 0, np.diag(self.matrix) / rows, np.nan)

    @property
    def users(self) -> np.ndarray:
        """User's accuracy per delivery class (column): diagonal / column sum."""
        cols = self.matrix.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(cols > 0, np.diag(self.matrix) / cols, np.nan)

    @property
    def kappa(self) -> float:
        """Cohen's κ of the matrix."""
        n = self.n
        if n == 0:
            return float("nan")
        po = np.trace(self.matrix) / n
        pe = float(np.sum(self.matrix.sum(axis=0) * self.matrix.sum(axis=1))) / (n * n)
        return float((po - pe) / (1 - pe)) if pe < 1 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the matrix and its accuracies."""
        return {"codes": list(self.codes), "matrix": self.matrix.tolist(), "n": self.n,
                "n_unmatched": self.n_unmatched, "overall_accuracy": self.overall,
                "kappa_coefficient": self.kappa,
                "producers_accuracy": {str(c): _f(v) for c, v in zip(self.codes, self.producers,
                                                                     strict=True)},
                "users_accuracy": {str(c): _f(v) for c, v in zip(self.codes, self.users,
                                                                 strict=True)}}


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def confusion_matrix(reference: np.ndarray, delivered: np.ndarray) -> ConfusionMatrix:
    """Confusion matrix of two class arrays of the same length (matched points)."""
    r = np.asarray(reference, dtype=np.int64)
    d = np.asarray(delivered, dtype=np.int64)
    codes = tuple(int(c) for c in np.union1d(np.unique(r), np.unique(d)))
    if not codes:
        return ConfusionMatrix((), np.zeros((0, 0), dtype=np.int64))
    ri = np.searchsorted(codes, r)
    di = np.searchsorted(codes, d)
    k = len(codes)
    m = np.bincount(ri * k + di, minlength=k * k).reshape(k, k)
    return ConfusionMatrix(codes, m.astype(np.int64))


def match_reference(points: np.ndarray, ref_points: np.ndarray, *, tolerance: float
                    ) -> np.ndarray:
    """Index of each point's reference point (-1: none within `tolerance`, 1 mm if 0)."""
    from scipy.spatial import cKDTree

    if len(ref_points) == 0 or len(points) == 0:
        return np.full(len(points), -1, dtype=np.int64)
    tol = max(float(tolerance), 1e-3)
    d, i = cKDTree(ref_points).query(points, k=1, distance_upper_bound=tol)
    i = np.where(np.isfinite(d), i, -1)
    return i.astype(np.int64)


@dataclass(frozen=True)
class ReferenceTask:
    """Per tile: read the tile and the reference points over it, match, count."""

    reference_paths: tuple[str, ...]
    reference_bounds: tuple[tuple[float, ...], ...]
    tolerance: float

    def __call__(self, tile: Any) -> ConfusionMatrix:
        """The confusion matrix of one tile against its reference."""
        from ..io.las import read_las

        cloud = read_las(tile.path)
        x0, y0, x1, y1 = tile.bounds2d
        pad = max(self.tolerance, 1e-3)
        refs, rcls = [], []
        for p, (a, b, c, d) in zip(self.reference_paths, self.reference_bounds, strict=True):
            if a > x1 + pad or c < x0 - pad or b > y1 + pad or d < y0 - pad:
                continue
            rc = read_las(p)
            m = ((rc.xyz[:, 0] >= x0 - pad) & (rc.xyz[:, 0] <= x1 + pad)
                 & (rc.xyz[:, 1] >= y0 - pad) & (rc.xyz[:, 1] <= y1 + pad))
            refs.append(rc.xyz[m])
            rcls.append(np.asarray(rc.classification)[m])
        ref = np.concatenate(refs) if refs else np.empty((0, 3))
        rc_ = np.concatenate(rcls) if rcls else np.empty(0, dtype=np.int64)
        idx = match_reference(cloud.xyz, ref, tolerance=self.tolerance)
        ok = idx >= 0
        cm = confusion_matrix(rc_[idx[ok]], np.asarray(cloud.classification)[ok])
        return ConfusionMatrix(cm.codes, cm.matrix, int(np.count_nonzero(~ok)))


def reference_confusion(catalog: Any, reference: Any, *, tolerance: float, allowed: Any,
                        engine: Any = None, progress: bool = False
                        ) -> tuple[dict[str, Any], dict[str, Check]]:
    """Block confusion matrix (a ``block`` entry of ``qc``) and a per-tile check."""
    from ..tiling import open_catalog, run_tiles

    ref = open_catalog(reference, skip_bad=False)
    task = ReferenceTask(tuple(t.path for t in ref.tiles),
                         tuple(tuple(float(v) for v in t.bounds2d) for t in ref.tiles),
                         float(tolerance))
    outcomes = run_tiles(catalog, task, engine=engine, progress=progress,
                         description="Classification")
    total = ConfusionMatrix((), np.zeros((0, 0), dtype=np.int64))
    per_tile: dict[str, Check] = {}
    for oc in outcomes:
        path = catalog.tiles[oc.chunk.index].path
        if not oc.ok:
            per_tile[path] = Check(FAIL, None, None, f"classification not compared: {oc.error}")
            continue
        cm = cast(ConfusionMatrix, oc.result)  # ok: the task's result
        total = total + cm
        per_tile[path] = Check(PASS, _f(cm.overall), None,
                               f"overall accuracy {100 * cm.overall:.1f} %, κ {cm.kappa:.3f} "
                               f"against the reference ({cm.n:,} matched, {cm.n_unmatched:,} "
                               "unmatched; information)" if cm.n else
                               "no point matched the reference")
    d = total.to_dict()
    d.update({"status": PASS, "value": _f(total.kappa), "limit": None,
              "message": (f"κ {total.kappa:.3f}, overall accuracy {100 * total.overall:.1f} % "
                          f"over {total.n:,} matched points (information)") if total.n else
              "no point matched the reference"})
    return d, per_tile
