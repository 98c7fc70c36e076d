"""Point-based progressive TIN densification (Axelsson 2000), ALGORITHMS.md §1.1.

Seeds are the lowest points of a coarse grid; a Delaunay TIN is built from them
and densified iteratively with points close to a facet (distance) that make
small angles with its vertices (iteration angle), with mirroring at steep
edges, terrain-angle screening and a minimum edge length.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import InvalidPointsError
from ._tin import TIN, Criteria, lowest_per_cell, mirror_point, screen_seeds, test_points, virtual_hull
from ._prefilter import low_outliers

__all__ = ["PTD", "PTDResult", "ptd_filter", "mirror_point"]


@dataclass(frozen=True)
class PTDResult:
    """Outcome of point-based PTD.

    Attributes
    ----------
    ground_mask : ndarray of bool, shape (N,)
    seed_idx : ndarray of int, seed points after terrain-angle screening
    tin_vertices : ndarray of int, indices of the real TIN vertices (final ground set G)
    tin_triangles : ndarray of int, shape (K, 3), triangles over `tin_vertices` positions
        (virtual-vertex triangles removed)
    n_iter : int
    added_per_iter : tuple of int
    mirrored_accepts : int
    stop_reason : str
        ``"no_gain"``, ``"min_gain_frac"`` or ``"max_iter"``.
    n_low_outliers : int
        Points removed by the low-outlier pre-filter.
    """

    ground_mask: np.ndarray
    seed_idx: np.ndarray
    tin_vertices: np.ndarray
    tin_triangles: np.ndarray
    n_iter: int
    added_per_iter: tuple[int, ...]
    mirrored_accepts: int
    stop_reason: str
    n_low_outliers: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_points": int(self.ground_mask.size),
            "n_ground": int(self.ground_mask.sum()),
            "n_seeds": int(self.seed_idx.size),
            "n_tin_vertices": int(self.tin_vertices.size),
            "n_iter": self.n_iter,
            "added_per_iter": list(self.added_per_iter),
            "mirrored_accepts": self.mirrored_accepts,
            "stop_reason": self.stop_reason,
            "n_low_outliers": self.n_low_outliers,
        }


@dataclass(frozen=True)
class PTD:
    """Progressive TIN densification ground filter (Axelsson 2000).

    Parameters
    ----------
    cell_size : float, default 60.0
        Seed grid cell (m), about the largest building footprint.
    max_terrain_angle : float, default 88.0
        Steepest allowed facet (degrees), for seed screening and new sub-facets.
    iter_angle : float, default 6.0
        Largest vertex angle beta (degrees) of an accepted point.
    iter_distance : float, default 0.5
        Largest distance (m) from an accepted point to its facet.
    min_edge_length : float, default 1.0
        Triangles whose three horizontal edges are all shorter (m) are frozen.
    mirror : bool, default True
        Also test the point mirrored through its nearest real vertex.
    max_iter : int, default 100
    edge_mode : {"freeze", "reduce"}, default "freeze"
    min_gain_frac : float, default 0.0
        Stop early when an iteration adds fewer than this fraction of |G|.
    low_outlier_distance : float, default 1.0
        Points more than this (m) below every neighbour within `low_outlier_radius`
        are low outliers: never seeds, never ground. 0 disables the pre-filter.
    low_outlier_radius : float, default 5.0
        Neighbourhood radius (m) of the low-outlier test.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.mgrid[0:20, 0:20].reshape(2, -1).T.astype(float)
    >>> pts = np.column_stack([g, np.zeros(len(g))])
    >>> bool(PTD(cell_size=10).ground_mask(pts).all())
    True
    """

    cell_size: float = 60.0
    max_terrain_angle: float = 88.0
    iter_angle: float = 6.0
    iter_distance: float = 0.5
    min_edge_length: float = 1.0
    mirror: bool = True
    max_iter: int = 100
    edge_mode: str = "freeze"
    min_gain_frac: float = 0.0
    low_outlier_distance: float = 1.0
    low_outlier_radius: float = 5.0

    def __post_init__(self) -> None:
        check_positive(self.cell_size, "cell_size")
        check_range(self.max_terrain_angle, "max_terrain_angle", 0.0, 90.0, lo_open=True)
        check_range(self.iter_angle, "iter_angle", 0.0, 90.0, lo_open=True, hi_open=True)
        check_positive(self.iter_distance, "iter_distance")
        check_positive(self.min_edge_length, "min_edge_length", allow_zero=True)
        check_choice(self.edge_mode, ("freeze", "reduce"), "edge_mode")
        check_positive(self.min_gain_frac, "min_gain_frac", allow_zero=True)
        check_positive(self.low_outlier_distance, "low_outlier_distance", allow_zero=True)
        check_positive(self.low_outlier_radius, "low_outlier_radius")
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            from ..errors import OptionError

            raise OptionError(f"max_iter must be an integer >= 1, got {self.max_iter!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def criteria(self) -> Criteria:
        return Criteria(
            iter_angle=math.radians(self.iter_angle),
            iter_distance=float(self.iter_distance),
            max_terrain_angle=math.radians(self.max_terrain_angle),
            min_edge_length=float(self.min_edge_length),
            mirror=bool(self.mirror),
            edge_mode=self.edge_mode,
        )

    def run(self, points: Any, *, candidates: Any = None) -> PTDResult:
        """Run the filter and return the full :class:`PTDResult`.

        Parameters
        ----------
        points : ndarray of shape (N, 3)
            x, y, z in metres; finite.
        candidates : ndarray of bool, shape (N,), optional
            Points allowed to be ground (e.g. last returns, not noise). Others are
            ignored by the filter and never ground. Default: all.
        """
        pts = as_points(points)
        n = pts.shape[0]
        cand = np.ones(n, dtype=bool) if candidates is None else _as_mask(candidates, n)
        return _ptd(pts, cand, self)

    def ground_mask(self, points: Any, *, candidates: Any = None) -> np.ndarray:
        """Boolean ground mask ``(N,)`` of `points` (see :meth:`run`)."""
        return self.run(points, candidates=candidates).ground_mask


def ptd_filter(points: Any, *, candidates: Any = None, **params: Any) -> PTDResult:
    """Functional form: ``PTD(**params).run(points, candidates=candidates)``."""
    return PTD(**params).run(points, candidates=candidates)


def _as_mask(mask: Any, n: int) -> np.ndarray:
    m = np.asarray(mask)
    if m.shape != (n,):
        raise InvalidPointsError(f"candidates must have shape ({n},), got {m.shape}")
    return m.astype(bool)


def _empty_result(n: int, n_out: int = 0) -> PTDResult:
    e = np.zeros(0, dtype=np.int64)
    return PTDResult(np.zeros(n, dtype=bool), e, e, np.zeros((0, 3), dtype=np.int64), 0, (), 0,
                     "no_candidates", n_out)


def prepare(points: np.ndarray, cand: np.ndarray, low_d: float, low_r: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Shift to a local origin and drop low outliers from the candidates."""
    xyz = points - points.min(axis=0) if points.shape[0] else points.copy()
    n_out = 0
    if low_d > 0 and cand.sum() > 3:
        ci = np.flatnonzero(cand)
        out = low_outliers(xyz[ci], distance=low_d, radius=low_r)
        if out.any():
            cand = cand.copy()
            cand[ci[out]] = False
            n_out = int(out.sum())
    return xyz, cand, n_out


def _ptd(points: np.ndarray, cand: np.ndarray, par: PTD) -> PTDResult:
    n = points.shape[0]
    if n == 0 or not cand.any():
        return _empty_result(n)
    xyz, cand, n_out = prepare(points, cand, par.low_outlier_distance, par.low_outlier_radius)
    if not cand.any():
        return _empty_result(n, n_out)
    crit = par.criteria()
    ci = np.flatnonzero(cand)
    lo = xyz[ci].min(axis=0)
    hi = xyz[ci].max(axis=0)
    seeds = lowest_per_cell(xyz, ci, par.cell_size, lo)
    virtual = virtual_hull(xyz, seeds, par.cell_size, lo, hi)
    seeds = screen_seeds(xyz, seeds, virtual, crit.max_terrain_angle)
    ground = np.zeros(n, dtype=bool)
    in_tin = np.zeros(n, dtype=bool)
    ground[seeds] = True
    in_tin[seeds] = True
    open_ = cand & ~ground  # candidates still undecided
    added: list[int] = []
    n_mirror = 0
    stop = "no_gain"
    n_iter = 0
    tin = None
    for k in range(1, int(par.max_iter) + 1):
        n_iter = k
        g_idx = np.flatnonzero(in_tin)
        tin = TIN(xyz, g_idx, virtual)
        oi = np.flatnonzero(open_)
        if oi.size == 0:
            added.append(0)
            break
        res = test_points(tin, xyz[oi], crit)
        # XY duplicates of vertices: ground or not, never inserted, decided once
        dup_ok = oi[res.duplicate_ok]
        ground[dup_ok] = True
        open_[oi[res.duplicate]] = False
        # one point per triangle: smallest score, then beta, then index
        pi = np.flatnonzero(res.passed)
        if pi.size == 0:
            added.append(0)
            break
        tri = res.tri[pi]
        order = np.lexsort((oi[pi], res.beta[pi], res.score[pi], tri))
        t_sorted = tri[order]
        first = np.ones(order.size, dtype=bool)
        first[1:] = t_sorted[1:] != t_sorted[:-1]
        keep = pi[order[first]]
        new = oi[keep]
        n_mirror += int(res.mirrored[keep].sum())
        ground[new] = True
        in_tin[new] = True
        open_[new] = False
        added.append(int(new.size))
        if par.min_gain_frac > 0 and new.size / max(1, int(in_tin.sum())) < par.min_gain_frac:
            stop = "min_gain_frac"
            break
        if k == par.max_iter:
            stop = "max_iter"
    g_idx = np.flatnonzero(in_tin)
    tin = TIN(xyz, g_idx, virtual)
    tris = tin.simplices[(tin.simplices < tin.n_real).all(axis=1)]
    return PTDResult(
        ground_mask=ground,
        seed_idx=seeds,
        tin_vertices=g_idx,
        tin_triangles=tris,
        n_iter=n_iter,
        added_per_iter=tuple(added),
        mirrored_accepts=n_mirror,
        stop_reason=stop,
        n_low_outliers=n_out,
    )
