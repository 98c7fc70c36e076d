"""ISPRS filter-test error measures (Sithole & Vosselman 2004), :ref:`alg-isprs`.

Type I (ground rejected), type II (object accepted as ground), total error and
Cohen's kappa, from two boolean label arrays or from the four counts of the
2×2 cross table; and :func:`terrain_scores`, the terrain model of the predicted
ground against that of the reference (for references whose ground is partial).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidPointsError

__all__ = [
    "FilterErrors",
    "filter_errors",
    "filter_errors_from_counts",
    "filter_errors_from_file",
    "TerrainScores",
    "terrain_scores",
    "THINNED_RATIO",
]


@dataclass(frozen=True)
class FilterErrors:
    """The 2×2 cross table of a ground filter against a reference, and its error measures.

    Attributes
    ----------
    a, b, c, d : int
        Counts: reference ground predicted ground (a) / object (b); reference
        object predicted ground (c) / object (d).
    type_i : float
        b / (a + b), fraction of reference ground rejected (nan without reference ground).
    type_ii : float
        c / (c + d), fraction of reference objects accepted as ground (nan without objects).
    total : float
        (b + c) / n.
    kappa : float
        Cohen's kappa (nan when the chance agreement is 1).
    p_o, p_e : float
        Observed and chance agreement.
    """

    a: int
    b: int
    c: int
    d: int
    type_i: float
    type_ii: float
    total: float
    kappa: float
    p_o: float
    p_e: float

    @property
    def n(self) -> int:
        """Number of evaluated points."""
        return self.a + self.b + self.c + self.d

    @property
    def confusion(self) -> np.ndarray:
        """The 2×2 table ``[[a, b], [c, d]]`` (rows: reference ground, object)."""
        return np.array([[self.a, self.b], [self.c, self.d]], dtype=np.int64)

    @property
    def type_i_pct(self) -> float:
        """Type I error (ground rejected) in percent."""
        return 100.0 * self.type_i

    @property
    def type_ii_pct(self) -> float:
        """Type II error (non-ground accepted) in percent."""
        return 100.0 * self.type_ii

    @property
    def total_pct(self) -> float:
        """Total error in percent."""
        return 100.0 * self.total

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dictionary: fractions, percentages, ``n_evaluated`` and ``confusion``."""
        return {
            "type_i": self.type_i,
            "type_ii": self.type_ii,
            "total": self.total,
            "kappa": self.kappa,
            "type_i_pct": self.type_i_pct,
            "type_ii_pct": self.type_ii_pct,
            "total_pct": self.total_pct,
            "p_o": self.p_o,
            "p_e": self.p_e,
            "n_evaluated": self.n,
            "confusion": {
                "ref_ground_pred_ground": self.a,
                "ref_ground_pred_object": self.b,
                "ref_object_pred_ground": self.c,
                "ref_object_pred_object": self.d,
            },
        }


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


def filter_errors_from_counts(a: int, b: int, c: int, d: int) -> FilterErrors:
    """Error measures from the four cross-table counts.

    Parameters
    ----------
    a, b, c, d : int
        Reference ground → predicted ground (a) / object (b); reference object →
        predicted ground (c) / object (d). Non-negative.

    Returns
    -------
    FilterErrors

    Raises
    ------
    InvalidPointsError
        If a count is negative or all counts are zero.

    Examples
    --------
    >>> e = filter_errors_from_counts(40, 10, 5, 45)
    >>> round(e.type_i, 2), round(e.type_ii, 2), round(e.total, 2), round(e.kappa, 2)
    (0.2, 0.1, 0.15, 0.7)
    """
    counts = [int(v) for v in (a, b, c, d)]
    if min(counts) < 0:
        raise InvalidPointsError(f"counts must be >= 0, got {counts}")
    a, b, c, d = counts
    n = a + b + c + d
    if n == 0:
        raise InvalidPointsError("cannot compute filter errors of zero points")
    e, f, g, h = a + b, c + d, a + c, b + d
    p_o = (a + d) / n
    p_e = (e * g + f * h) / (n * n)
    kappa = (p_o - p_e) / (1.0 - p_e) if p_e < 1.0 else math.nan
    return FilterErrors(
        a=a,
        b=b,
        c=c,
        d=d,
        type_i=_ratio(b, e),
        type_ii=_ratio(c, f),
        total=(b + c) / n,
        kappa=kappa,
        p_o=p_o,
        p_e=p_e,
    )


def filter_errors(ref_ground: Any, pred_ground: Any, *, mask: Any = None) -> FilterErrors:
    """ISPRS type I / type II / total error and Cohen's kappa of a ground filter.

    Parameters
    ----------
    ref_ground : array_like of bool, shape (N,)
        Reference labels, True = ground.
    pred_ground : array_like of bool, shape (N,)
        Filter output, True = ground.
    mask : array_like of bool, shape (N,), optional
        Only points where `mask` is True are evaluated (e.g. to ignore some classes).

    Returns
    -------
    FilterErrors

    Raises
    ------
    InvalidPointsError
        If the arrays differ in length or no point is evaluated.

    Examples
    --------
    >>> e = filter_errors([True, True, False, False], [True, False, False, False])
    >>> e.type_i, e.type_ii, e.total
    (0.5, 0.0, 0.25)
    """
    ref = np.asarray(ref_ground)
    pred = np.asarray(pred_ground)
    if ref.ndim != 1 or pred.ndim != 1 or ref.shape != pred.shape:
        raise InvalidPointsError(
            "ref_ground and pred_ground must be 1-D of the same length, "
            f"got {ref.shape} and {pred.shape}"
        )
    ref = ref.astype(bool)
    pred = pred.astype(bool)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != ref.shape:
            raise InvalidPointsError(f"mask must have shape {ref.shape}, got {m.shape}")
        m = m.astype(bool)
        ref, pred = ref[m], pred[m]
    a = int(np.count_nonzero(ref & pred))
    b = int(np.count_nonzero(ref & ~pred))
    c = int(np.count_nonzero(~ref & pred))
    d = int(np.count_nonzero(~ref & ~pred))
    return filter_errors_from_counts(a, b, c, d)


def filter_errors_from_file(
    reference: Any,
    pred_ground: Any,
    *,
    ground_class: int = 2,
    ignore_classes: Any = None,
) -> FilterErrors:
    """Filter errors against the classification of a reference cloud or file.

    Parameters
    ----------
    reference : str, path or PointCloud
        Reference point cloud, same points in the same order as `pred_ground`.
    pred_ground : array_like of bool, shape (N,)
        Filter output, True = ground.
    ground_class : int, default 2
        Reference class that means ground; every other class is an object.
    ignore_classes : sequence of int, optional
        Reference classes left out of the evaluation.

    Returns
    -------
    FilterErrors
    """
    from ..io import PointCloud, read

    cloud = reference if isinstance(reference, PointCloud) else read(reference)
    cls = cloud.classification
    if cls is None:
        raise InvalidPointsError("the reference cloud has no classification field")
    cls = np.asarray(cls)
    mask = None
    if ignore_classes:
        mask = ~np.isin(cls, np.asarray(list(ignore_classes)))
    return filter_errors(cls == ground_class, pred_ground, mask=mask)


#: reference non-ground points within `near_limit` of the reference surface per
#: reference ground point above which the reference ground "looks thinned"
#: (see :func:`terrain_scores`)
THINNED_RATIO = 0.25

#: largest grid (cells) :func:`terrain_scores` evaluates; beyond it, a larger cell is needed
MAX_CELLS = 200_000_000
_BLOCK_CELLS = 1 << 21

THINNED_NOTE = (
    "the reference ground looks thinned; per-point type I/II errors punish finding more "
    "ground — judge by the terrain model"
)


@dataclass(frozen=True)
class TerrainScores:
    """The terrain model of a ground filter against that of a reference (:func:`terrain_scores`).

    Attributes
    ----------
    rmse : float
        RMSE (m) of predicted minus reference terrain over the scored grid cells.
    bias : float
        Mean (m) of predicted minus reference terrain over the scored cells.
    cells_off : float
        Share of scored cells where the two terrains differ by more than `off_limit`.
    objects_taken : float
        Share of scored predicted ground points more than `above_limit` above the
        reference terrain.
    ground_lost : float
        Share of scored reference ground points more than `above_limit` from the
        predicted terrain (above or below).
    on_surface_ratio : float
        Reference non-ground points within `near_limit` of the reference terrain per
        reference ground point.
    thinned : bool
        ``on_surface_ratio > thinned_ratio``: the reference ground looks thinned.
    n_cells, n_pred_scored, n_ref_scored, n_pred_ground, n_ref_ground : int
        Scored cells; scored and total predicted / reference ground points.
    cell, off_limit, above_limit, near_limit, thinned_ratio : float
        The settings (m; `thinned_ratio` dimensionless).
    reason : str
        Why nothing could be scored (empty when scores were computed).
    """

    rmse: float
    bias: float
    cells_off: float
    objects_taken: float
    ground_lost: float
    on_surface_ratio: float
    thinned: bool
    n_cells: int
    n_pred_scored: int
    n_ref_scored: int
    n_pred_ground: int
    n_ref_ground: int
    cell: float
    off_limit: float
    above_limit: float
    near_limit: float
    thinned_ratio: float
    reason: str = ""

    @property
    def note(self) -> str:
        """The sentence to show when the reference looks thinned (else empty)."""
        return THINNED_NOTE if self.thinned else ""

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dictionary (lengths in m, shares as fractions; NaN as None)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "rmse_m": num(self.rmse),
            "bias_m": num(self.bias),
            "cells_off": num(self.cells_off),
            "objects_taken": num(self.objects_taken),
            "ground_lost": num(self.ground_lost),
            "reference_on_surface_ratio": num(self.on_surface_ratio),
            "reference_thinned": self.thinned,
            "n_cells": self.n_cells,
            "n_pred_scored": self.n_pred_scored,
            "n_ref_scored": self.n_ref_scored,
            "n_pred_ground": self.n_pred_ground,
            "n_ref_ground": self.n_ref_ground,
            "cell_m": self.cell,
            "off_limit_m": self.off_limit,
            "above_limit_m": self.above_limit,
            "near_limit_m": self.near_limit,
            "thinned_ratio_limit": self.thinned_ratio,
            "reason": self.reason,
            "note": self.note,
        }


class _Surface:
    """The Delaunay TIN of some points and its height anywhere (NaN outside its convex hull).

    The TIN is startinpy's (the one the ground filter grows), built by inserting
    the vertices in a canonical spatial order (cells, then x, y, z), so that of
    several vertices on one XY spot (closer than its 1 mm snap tolerance) the same
    one is kept and co-circular vertices are triangulated alike whatever the input
    order. Queries are answered in spatial order too (short walks). Coordinates are
    expected to be shifted near the origin.
    """

    def __init__(self, vertices: np.ndarray) -> None:
        import startinpy

        from .._arrays import spatial_order

        self._order = spatial_order
        self.dt = None
        if vertices.shape[0] < 3:
            return
        v = vertices[np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))]
        self.lo = v[:, :2].min(axis=0)
        span = v[:, :2].max(axis=0) - self.lo
        # cells of a few vertices each: the insertion walks stay short at any density
        self.step = max(2.0 * math.sqrt(max(float(span[0] * span[1]), 1e-6) / len(v)), 1e-3)
        dt = startinpy.DT()
        dt.insert(np.ascontiguousarray(v[spatial_order(v[:, :2], self.lo, self.step)]))
        if dt.number_of_triangles() > 0:  # else collinear vertices: no surface
            self.dt = dt

    def heights(self, xy: np.ndarray) -> np.ndarray:
        out = np.full(xy.shape[0], np.nan)
        if self.dt is None or xy.shape[0] == 0:
            return out
        order = self._order(xy, self.lo, self.step)
        z = self.dt.interpolate({"method": "TIN"}, np.ascontiguousarray(xy[order]))
        out[order] = np.asarray(z, dtype=np.float64)
        return out


def _share(flags: np.ndarray) -> float:
    return float(np.count_nonzero(flags)) / flags.size if flags.size else math.nan


def terrain_scores(
    points: Any,
    predicted_ground: Any,
    reference_ground: Any,
    *,
    mask: Any = None,
    cell: float = 1.0,
    off_limit: float = 0.5,
    above_limit: float = 0.3,
    near_limit: float = 0.15,
    thinned_ratio: float = THINNED_RATIO,
) -> TerrainScores:
    """Score the terrain model of a ground filter against the reference's.

    See :ref:`alg-terrain-scores`.

    Two Delaunay TINs are built, one of the predicted ground points and one of the
    reference ground points, and compared where both exist: at the centres of a
    `cell` m grid aligned on multiples of `cell` (so a tiling of the area gives the
    same cells) that lie inside both TINs, i.e. inside the intersection of the
    convex hulls of the two ground sets. No other clipping is done: a cell inside
    both hulls is scored even when it is far from any ground point. Heights are
    vertical (z) differences, predicted minus reference.

    - ``rmse``, ``bias``: RMSE and mean of the difference over the scored cells;
    - ``cells_off``: share of scored cells off by more than `off_limit`;
    - ``objects_taken``: share of predicted ground points (inside the reference
      TIN) more than `above_limit` above the reference terrain;
    - ``ground_lost``: share of reference ground points (inside the predicted
      TIN) more than `above_limit` above or below the predicted terrain;
    - ``on_surface_ratio``: reference non-ground points within `near_limit` of
      the reference terrain per reference ground point. A complete reference
      leaves few non-ground points on its own ground surface; above
      `thinned_ratio` the reference ground looks thinned (vendors often keep a
      subset of the ground as class 2) and per-point type I/II errors punish a
      filter for finding more ground: judge it by the terrain model then.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Coordinates (m).
    predicted_ground, reference_ground : array_like of bool, shape (N,)
        Filter output and reference labels, True = ground.
    mask : array_like of bool, shape (N,), optional
        Only points where `mask` is True take part (e.g. to leave out classes).
    cell : float, default 1.0
        Grid cell (m).
    off_limit : float, default 0.5
        Terrain difference (m) from which a cell counts as off.
    above_limit : float, default 0.3
        Height (m) above (or, for ground lost, from) a terrain from which a point
        counts as taken or lost.
    near_limit : float, default 0.15
        Distance (m, vertical) to the reference terrain within which a reference
        non-ground point counts as lying on it.
    thinned_ratio : float, default :data:`THINNED_RATIO` (0.25)
        `on_surface_ratio` above which the reference looks thinned.

    Returns
    -------
    TerrainScores
        With NaN scores and a `reason` when either ground set has fewer than 3
        points or the TINs share no cell.

    Raises
    ------
    InvalidPointsError
        If the arrays do not match.
    OptionError
        If a setting is not positive.

    Examples
    --------
    >>> g = np.mgrid[0:20, 0:20].reshape(2, -1).T.astype(float)
    >>> pts = np.column_stack([g, np.zeros(len(g))])
    >>> ref = np.ones(len(pts), dtype=bool)
    >>> s = terrain_scores(pts, ref, ref)
    >>> s.rmse, s.cells_off, s.objects_taken, s.ground_lost
    (0.0, 0.0, 0.0, 0.0)
    """
    from .._validate import as_mask, as_points, check_positive

    p = as_points(points)
    n = p.shape[0]
    pred = as_mask(predicted_ground, n, "predicted_ground")
    ref = as_mask(reference_ground, n, "reference_ground")
    ev = np.ones(n, dtype=bool) if mask is None else as_mask(mask, n, "mask")
    cell = check_positive(cell, "cell")
    off_limit = check_positive(off_limit, "off_limit", allow_zero=True)
    above_limit = check_positive(above_limit, "above_limit", allow_zero=True)
    near_limit = check_positive(near_limit, "near_limit", allow_zero=True)
    thinned_ratio = check_positive(thinned_ratio, "thinned_ratio", allow_zero=True)
    # near the origin (startinpy's snapping and the interpolation at UTM magnitudes);
    # the grid below stays aligned on absolute multiples of `cell`
    shift = np.floor(p[:, :2].min(axis=0) / cell) * cell if n else np.zeros(2)
    p = p - np.append(shift, 0.0)
    pg = p[pred & ev]
    rg = p[ref & ev]
    settings: dict[str, Any] = {
        "cell": cell,
        "off_limit": off_limit,
        "above_limit": above_limit,
        "near_limit": near_limit,
        "thinned_ratio": thinned_ratio,
    }
    nan = math.nan

    def empty(reason: str, ratio: float = nan) -> TerrainScores:
        return TerrainScores(
            nan, nan, nan, nan, nan, ratio, bool(ratio > thinned_ratio), 0, 0, 0,
            len(pg), len(rg), reason=reason, **settings,
        )  # fmt: skip

    if len(rg) < 3:
        return empty("fewer than 3 reference ground points")
    # the reference surface and the points lying on it
    other = p[~ref & ev]
    ref_tin = _Surface(rg)
    h_other = other[:, 2] - ref_tin.heights(other[:, :2])
    ratio = float(np.count_nonzero(np.abs(h_other) <= near_limit)) / len(rg)
    if len(pg) < 3:
        return empty("fewer than 3 predicted ground points", ratio)
    # grid cells over the intersection of the two bounding boxes, aligned on `cell`
    lo = np.maximum(pg[:, :2].min(axis=0), rg[:, :2].min(axis=0))
    hi = np.minimum(pg[:, :2].max(axis=0), rg[:, :2].max(axis=0))
    i0 = np.floor(lo / cell).astype(np.int64)
    i1 = np.floor(hi / cell).astype(np.int64)
    if (i1 < i0).any():
        return empty("the predicted and reference ground do not overlap", ratio)
    nx, ny = (i1 - i0 + 1).tolist()
    if nx * ny > MAX_CELLS:
        return empty(
            f"the common extent holds {nx * ny:,} cells of {cell:g} m (more than "
            f"{MAX_CELLS:,}): score with a larger cell",
            ratio,
        )
    pred_tin = _Surface(pg)
    iy = np.arange(i0[1], i1[1] + 1)
    cy = (iy + 0.5) * cell
    # the grid in blocks of whole columns (bounded memory), summed in a fixed order
    step = max(1, _BLOCK_CELLS // ny)
    n_cells = n_off = 0
    sum_d = sum_d2 = 0.0
    for x0 in range(int(i0[0]), int(i1[0]) + 1, step):
        cx = (np.arange(x0, min(x0 + step, int(i1[0]) + 1)) + 0.5) * cell
        centres = np.column_stack([np.repeat(cx, ny), np.tile(cy, cx.size)])
        d = pred_tin.heights(centres) - ref_tin.heights(centres)
        d = d[np.isfinite(d)]
        n_cells += d.size
        n_off += int(np.count_nonzero(np.abs(d) > off_limit))
        sum_d += float(d.sum())
        sum_d2 += float((d * d).sum())
    if n_cells == 0:
        return empty("the predicted and reference ground TINs share no grid cell", ratio)
    h_pred = pg[:, 2] - ref_tin.heights(pg[:, :2])
    h_pred = h_pred[np.isfinite(h_pred)]
    h_ref = rg[:, 2] - pred_tin.heights(rg[:, :2])
    h_ref = h_ref[np.isfinite(h_ref)]
    return TerrainScores(
        rmse=math.sqrt(sum_d2 / n_cells),
        bias=sum_d / n_cells,
        cells_off=n_off / n_cells,
        objects_taken=_share(h_pred > above_limit),
        ground_lost=_share(np.abs(h_ref) > above_limit),
        on_surface_ratio=ratio,
        thinned=bool(ratio > thinned_ratio),
        n_cells=int(n_cells),
        n_pred_scored=int(h_pred.size),
        n_ref_scored=int(h_ref.size),
        n_pred_ground=len(pg),
        n_ref_ground=len(rg),
        **settings,
    )
