"""Relative accuracy of flight strips (swaths): overlap differences, repeatability, offsets.

Absolute accuracy (check points) says how far the cloud is from the ground
truth; relative accuracy says whether the cloud agrees with itself. Three
measures, all computed from **local planes fitted per grid cell in each strip
separately** (not from nearest neighbours, which mix point noise and
interpolation error into the figure):

* **Interswath (swath-overlap) differences**: in every cell covered by two
  strips and *smooth* in both (plane residual RMS ≤ `max_roughness`, slope ≤
  `max_slope`), dz = height of strip B's plane − height of strip A's plane at
  the cell centre. Per pair: RMSDz, mean, median, max |dz|, 95th percentile
  of |dz| and the area compared, with pass/fail against a quality level.
* **Intraswath (smooth-surface) repeatability**: within one strip, the spread
  of the points about their cell's plane on smooth cells: the residual RMSE
  and the max − min difference in cells of about two point spacings (the
  USGS practice; median, 95th percentile, maximum).
* **Strip offsets**: the 3-D shift (dx, dy, dz), optionally with three small
  rotations, of each strip relative to another, by weighted least squares on
  the matched cell planes: every cell where both strips fit a good plane
  (any slope up to `offset_max_slope`, normals within `max_normal_angle`)
  gives one observation  dz = dz_t − b·dx_t − c·dy_t  (b, c: the plane's
  slopes), so tilted roof faces of several orientations fix dx and dy and
  flat ground fixes dz. σ per parameter from the a-posteriori variance
  factor. With more than two strips the offsets of all strips are adjusted
  together as a network, with one **reference strip held fixed** (the strip
  covering the most cells unless chosen). The spread of the adjusted strip
  heights is the measured strip-adjustment noise E4 (σ_strip of the height
  error propagation in :mod:`lidarqa.accuracy.heights`).

Quality levels (:data:`QUALITY_LEVELS`) are the relative vertical accuracy
requirements of the USGS Lidar Base Specification (2023 revision, table
"Relative vertical accuracy requirements"), which ASPRS Positional Accuracy
Standards for Digital Geospatial Data, Edition 2 (2023) repeats for lidar
(table "Lidar data relative vertical accuracy", by vertical accuracy class):

=====  ===============================  ==================  =================
level  smooth-surface repeatability     swath-overlap RMSDz  swath-overlap max
=====  ===============================  ==================  =================
QL0    ≤ 0.03 m (max difference)        ≤ 0.04 m             ≤ ±0.08 m
QL1    ≤ 0.06 m                         ≤ 0.08 m             ≤ ±0.16 m
QL2    ≤ 0.06 m                         ≤ 0.08 m             ≤ ±0.16 m
QL3    ≤ 0.12 m                         ≤ 0.16 m             ≤ ±0.32 m
=====  ===============================  ==================  =================

All sums behind the per-cell planes are additive (:func:`cell_sums` on a
:class:`Grid` from :func:`grid_for`; the residual extremes of
:func:`residual_extremes` combine with :func:`merge_extremes`), so a tile
catalog can accumulate them per chunk and solve once.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import DegenerateGeometryError, InvalidPointsError, OptionError
from . import _swaths_kernels as K
from ._swaths_kernels import (
    Grid,
    cell_sums,
    grid_for,
    merge_extremes,
    ranges_from_extremes,
    residual_extremes,
)

__all__ = [
    "QUALITY_LEVELS",
    "DEFAULT_QUALITY_LEVEL",
    "PairDifference",
    "StripRepeatability",
    "StripOffset",
    "DzGrid",
    "SwathReport",
    "assess_swaths",
    "last_return_mask",
    "surface_class_mask",
    "SURFACE_CLASSES",
    "auto_cell_size",
    "select_surface",
    "assess_options",
    "strip_planes",
    "range_plan",
    "swaths_from_planes",
    # the per-region half, for chunked runs: sums and residual extremes per grid cell
    "Grid",
    "grid_for",
    "cell_sums",
    "residual_extremes",
    "merge_extremes",
    "ranges_from_extremes",
]

#: Relative vertical accuracy (m): (intraswath max difference, interswath RMSDz,
#: interswath max |dz|), USGS Lidar Base Specification 2023 rev. / ASPRS Ed. 2 (2023). The one
#: table of these limits: ``lidarqa qc``'s profiles read it too. QL0 is half of QL1 as in the
#: LBS table; not re-checked against the 2024 rev. A text.
QUALITY_LEVELS: dict[str, tuple[float, float, float]] = {
    "QL0": (0.03, 0.04, 0.08),
    "QL1": (0.06, 0.08, 0.16),
    "QL2": (0.06, 0.08, 0.16),
    "QL3": (0.12, 0.16, 0.32),
}
#: Default level: QL1 (≥ 8 pts/m², the density class of IGN LiDAR HD and most current ALS).
DEFAULT_QUALITY_LEVEL = "QL1"

CELL_TARGET_POINTS = 16  # auto cell size: about this many points per strip and cell
MIN_OFFSET_OBS = 10
CLUSTER_SIZE = 10.0  # m: blocks of cells for the cluster-robust σ of pair offsets


@dataclass(frozen=True)
class PairDifference:
    """Swath-overlap differences of strip B minus strip A on smooth cells (m, m²)."""

    strip_a: int
    strip_b: int
    overlap_area: float  # cells where both strips fit a plane
    area: float  # cells compared (smooth in both)
    n_cells: int
    rmsdz: float
    mean: float
    median: float
    std: float
    max_abs: float
    p95_abs: float
    passes_rmsdz: bool
    passes_max: bool

    @property
    def passed(self) -> bool:
        """True when both the RMSDz and the maximum |dz| meet the quality level."""
        return bool(self.passes_rmsdz and self.passes_max)

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["passed"] = self.passed
        return d


@dataclass(frozen=True)
class StripRepeatability:
    """Smooth-surface repeatability within one strip (m, m²)."""

    strip: int
    n_cells: int
    area: float
    rmse: float  # pooled residual RMS about the cell planes
    median_range: float  # max − min residual per range cell: median over range cells
    p95_range: float
    max_range: float
    passed: bool  # median_range within the level's smooth-surface threshold
    assessed: bool = True  # False: too little smooth surface (< min_overlap_cells cells)
    range_cell: float = float("nan")  # side (m) of the cells the max − min is taken over
    n_range_cells: int = 0

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class StripOffset:
    """Offset of strip B relative to strip A: B's coordinates − A's (m; rotations in degrees)."""

    strip_a: int
    strip_b: int
    dx: float
    dy: float
    dz: float
    sigma_dx: float
    sigma_dy: float
    sigma_dz: float
    rotations: tuple[float, float, float] | None  # about x, y, z (degrees), if estimated
    sigma_rotations: tuple[float, float, float] | None
    n_obs: int
    sigma0: float  # a-posteriori σ of unit weight (≈ 1 if the weights are right)
    method: str  # "pair" (this pair alone) or "network" (whole block)
    # σ (dx, dy, dz) from the spread of the residuals between 10 m blocks (cluster-robust);
    # larger than the formal σ when neighbouring cells share errors (roof faces that are not
    # planar, local strip deformation). Pairs only.
    sigma_robust: tuple[float, float, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class DzGrid:
    """A raster of dz (strip B − strip A, m) on the analysis grid; NaN where not compared."""

    strip_a: int
    strip_b: int
    x0: float  # west edge
    y1: float  # north edge
    cell_size: float
    dz: np.ndarray = field(repr=False)  # (rows, cols) float32, row 0 = north


@dataclass(frozen=True)
class SwathReport:
    """Everything :func:`assess_swaths` measured."""

    quality_level: str
    thresholds: dict[str, float]
    cell_size: float
    strips: tuple[int, ...]
    pairs: tuple[PairDifference, ...]
    repeatability: tuple[StripRepeatability, ...]
    pair_offsets: tuple[StripOffset, ...]
    network_offsets: tuple[StripOffset, ...]  # each strip relative to the reference strip
    reference_strip: int | None
    e4: float  # measured strip noise: std of the adjusted strip heights (m)
    grids: tuple[DzGrid, ...] = field(repr=False, default=())
    flags: tuple[str, ...] = ()
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """True when every pair and every assessed repeatability surface passes."""
        return all(p.passed for p in self.pairs) and all(
            r.passed for r in self.repeatability if r.assessed
        )

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "quality_level": self.quality_level,
            "thresholds": dict(self.thresholds),
            "cell_size": self.cell_size,
            "strips": list(self.strips),
            "passed": self.passed,
            "pairs": [p.to_dict() for p in self.pairs],
            "repeatability": [r.to_dict() for r in self.repeatability],
            "pair_offsets": [o.to_dict() for o in self.pair_offsets],
            "network_offsets": [o.to_dict() for o in self.network_offsets],
            "reference_strip": self.reference_strip,
            "e4": self.e4,
            "flags": list(self.flags),
            "parameters": dict(self.parameters),
        }


def last_return_mask(fields: dict[str, np.ndarray], n: int) -> np.ndarray:
    """Last and single returns (return_number == number_of_returns); all points if unknown."""
    rn, nr = fields.get("return_number"), fields.get("number_of_returns")
    if rn is None or nr is None:
        return np.ones(n, dtype=bool)
    rn, nr = np.asarray(rn), np.asarray(nr)
    keep = (rn == nr) | (nr == 0)
    return keep


#: Classes compared by default: ground and buildings (hard surfaces). Unclassified points
#: hold vehicles and other objects that move between passes, vegetation is not smooth.
SURFACE_CLASSES = (2, 6)
#: Never compared: noise (7, 18) and IGN's artefact/virtual/other classes.
EXCLUDED_CLASSES = (7, 18, 64, 65, 66, 67)


def surface_class_mask(classification: np.ndarray | None, n: int) -> np.ndarray:
    """Points of :data:`SURFACE_CLASSES`; if there are none (unclassified data), all but noise."""
    if classification is None:
        return np.ones(n, dtype=bool)
    cls = np.asarray(classification)
    keep = np.isin(cls, SURFACE_CLASSES)
    return keep if keep.any() else ~np.isin(cls, EXCLUDED_CLASSES)


def select_surface(
    cloud: Any, *, classes: Any = None, all_returns: bool = False, where: str = "the cloud"
) -> np.ndarray:
    """The points compared between strips: last/single returns of the surface classes.

    `classes` given: those classes; else :func:`surface_class_mask` (ground and
    buildings; every class but noise when the cloud has no classification).
    `all_returns` keeps every return.
    """
    n = len(cloud)
    keep = np.ones(n, dtype=bool) if all_returns else last_return_mask(cloud.fields, n)
    cls = cloud.classification
    if cls is not None:
        keep &= np.isin(cls, classes) if classes else surface_class_mask(cls, n)
    elif classes:
        raise InvalidPointsError(f"{where} has no classification; cannot select --classes")
    return keep


def auto_cell_size(
    points: np.ndarray, strip: np.ndarray, *, target: int = CELL_TARGET_POINTS
) -> float:
    """A cell size (m, multiple of 0.25) holding about `target` points of one strip.

    The density of each strip is its point count over the area of the 5 m cells
    it occupies; the median over strips is used.
    """
    return cell_size_from_occupancy(strip_occupancy(points, strip), target=target)


DENSITY_CELL = 5.0  # m: cells over which auto_cell_size measures each strip's density


def strip_occupancy(points: np.ndarray, strip: np.ndarray) -> dict[int, tuple[int, np.ndarray]]:
    """Per strip: its point count and the keys of the 5 m cells it occupies.

    Keys are on one lattice for any input (multiples of 5 m), so the parts of
    several chunks combine: counts add, keys unite.
    """
    out = {}
    for s in np.unique(strip).tolist():
        xy = points[strip == s, :2]
        ix = np.floor(xy[:, 0] / DENSITY_CELL).astype(np.int64)
        iy = np.floor(xy[:, 1] / DENSITY_CELL).astype(np.int64)
        out[int(s)] = (len(xy), np.unique(ix * (1 << 32) + iy))
    return out


def cell_size_from_occupancy(
    occupancy: dict[int, tuple[int, np.ndarray]], *, target: int = CELL_TARGET_POINTS
) -> float:
    """:func:`auto_cell_size` from :func:`strip_occupancy` (of the whole data)."""
    dens = [n / (len(keys) * DENSITY_CELL**2) for n, keys in occupancy.values() if n >= 3]
    if not dens:
        return 1.0
    size = np.sqrt(target / float(np.median(dens)))
    return float(max(0.5, np.ceil(size * 4.0) / 4.0))


@dataclass
class _Strip:
    id: int
    planes: K.CellPlanes
    sigma: float = np.nan


def assess_swaths(
    points: np.ndarray,
    strip: np.ndarray,
    *,
    cell_size: float | None = None,
    min_points: int = 8,
    max_roughness: float = 0.05,
    max_slope: float = 10.0,
    offset_max_slope: float = 60.0,
    max_normal_angle: float = 10.0,
    quality_level: str = DEFAULT_QUALITY_LEVEL,
    estimate_offsets: bool = True,
    rotations: bool = False,
    reference_strip: int | None = None,
    min_overlap_cells: int = 10,
    range_cell: float | None = None,
    return_grids: bool = True,
) -> SwathReport:
    """Relative accuracy of overlapping flight strips.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z (m). Pass only the points to compare: typically last/single
        returns (:func:`last_return_mask`), without noise classes.
    strip : ndarray of shape (N,), int
        Flight strip of each point (``point_source_id``, or one id per file).
    cell_size : float, optional
        Grid cell size (m); default: :func:`auto_cell_size` (≈ 16 points of
        one strip per cell).
    min_points : int, default 8
        Points of one strip a cell needs for its plane.
    max_roughness : float, default 0.05
        Smooth-surface test: a cell's plane residual RMS must not exceed this (m).
    max_slope : float, default 10.0
        Smooth-surface test for the dz statistics: plane slope (degrees). On
        slopes a horizontal offset leaks into dz.
    offset_max_slope : float, default 60.0
        Steepest plane used for the offsets (degrees).
    max_normal_angle : float, default 10.0
        Planes of the two strips in a cell match only if their normals differ by
        at most this (degrees).
    quality_level : {"QL0", "QL1", "QL2", "QL3"}, default "QL1"
        Thresholds of :data:`QUALITY_LEVELS` for pass/fail.
    estimate_offsets : bool, default True
        Estimate strip offsets (pairwise, and as a network for > 2 strips).
    rotations : bool, default False
        Also estimate three small rotations per strip (about the block centre).
    reference_strip : int, optional
        The strip held fixed in the network (default: the one with most cells).
    min_overlap_cells : int, default 10
        Pairs sharing fewer planar cells are not reported as overlapping.
    range_cell : float, optional
        Side (m) of the cells over which the smooth-surface max − min is taken.
        Default: about twice the strip's nominal point spacing, the USGS practice
        (each plane cell split into k × k sub-cells, k = round(√n̄ / 2) for n̄
        points per smooth cell: ~4 points per range cell). Residuals are always
        about the plane cell's plane; range cells need at least 3 points.
    return_grids : bool, default True
        Keep a dz raster per pair (:class:`DzGrid`).

    Returns
    -------
    SwathReport

    Raises
    ------
    InvalidPointsError
        Bad `points`/`strip` shapes, or fewer than two strips.
    DegenerateGeometryError
        No pair of strips overlaps, or no overlap has a smooth surface.
    """
    points = as_points(points, min_points=3)
    strip = np.asarray(strip)
    if strip.shape != (len(points),):
        raise InvalidPointsError(f"strip must have shape ({len(points)},), got {strip.shape}")
    if strip.dtype.kind not in "iu":
        raise InvalidPointsError(f"strip ids must be integers, got dtype {strip.dtype}")
    assess_options(
        quality_level=quality_level,
        max_roughness=max_roughness,
        max_slope=max_slope,
        offset_max_slope=offset_max_slope,
        max_normal_angle=max_normal_angle,
        min_points=min_points,
    )
    ids = np.unique(strip)
    if len(ids) < 2:
        raise InvalidPointsError(
            f"one flight strip only ({', '.join(map(str, ids))}): relative accuracy needs at "
            "least two overlapping strips"
        )
    if cell_size is None:
        cell_size = auto_cell_size(points, strip, target=max(CELL_TARGET_POINTS, 2 * min_points))
    assess_options(cell_size=cell_size, range_cell=range_cell)

    grid = K.grid_for(points[:, :2], cell_size)
    z0 = float(np.median(points[:, 2]))
    order = np.argsort(strip, kind="stable")
    bounds = np.searchsorted(strip[order], ids)
    bounds = np.append(bounds, len(order))
    per_strip_points = []
    planes = []
    for i in range(len(ids)):
        sel = np.sort(order[bounds[i] : bounds[i + 1]])  # original order within a strip
        pts = points[sel]
        per_strip_points.append(pts)
        keys, sums = K.cell_sums(pts, grid, z0)
        planes.append(strip_planes(keys, sums, z0, cell_size=cell_size, min_points=min_points))

    def extremes(i: int, selected: np.ndarray, split: int) -> tuple:
        return K.residual_extremes(per_strip_points[i], grid, planes[i], selected, split=split)

    return swaths_from_planes(
        grid,
        z0,
        ids,
        planes,
        extremes,
        min_points=min_points,
        max_roughness=max_roughness,
        max_slope=max_slope,
        offset_max_slope=offset_max_slope,
        max_normal_angle=max_normal_angle,
        quality_level=quality_level,
        estimate_offsets=estimate_offsets,
        rotations=rotations,
        reference_strip=reference_strip,
        min_overlap_cells=min_overlap_cells,
        range_cell=range_cell,
        return_grids=return_grids,
    )


def assess_options(
    *,
    quality_level: str = DEFAULT_QUALITY_LEVEL,
    max_roughness: float = 0.05,
    max_slope: float = 10.0,
    offset_max_slope: float = 60.0,
    max_normal_angle: float = 10.0,
    min_points: int = 8,
    cell_size: float | None = None,
    range_cell: float | None = None,
    **other: Any,
) -> None:
    """Check the options of :func:`assess_swaths` (raises on a bad value)."""
    check_choice(quality_level, tuple(QUALITY_LEVELS), "quality_level")
    check_positive(max_roughness, "max_roughness")
    check_range(max_slope, "max_slope", 0.0, 90.0)
    check_range(offset_max_slope, "offset_max_slope", 0.0, 90.0)
    check_range(max_normal_angle, "max_normal_angle", 0.0, 90.0)
    if min_points < 4:
        raise InvalidPointsError(f"min_points must be >= 4, got {min_points}")
    if cell_size is not None:
        check_positive(cell_size, "cell_size")
    if range_cell is not None:
        check_positive(range_cell, "range_cell")
    known = {"estimate_offsets", "rotations", "reference_strip", "min_overlap_cells",
             "return_grids"}
    unknown = sorted(set(other) - known)
    if unknown:
        raise OptionError(f"unknown option(s): {', '.join(unknown)}")


def strip_planes(
    keys: np.ndarray, sums: np.ndarray, z0: float, *, cell_size: float, min_points: int
) -> K.CellPlanes:
    """One strip's cell planes from its (merged) cell sums."""
    return K.fit_cell_planes(keys, sums, z0, min_points=min_points, min_spread=0.15 * cell_size)


def range_plan(
    planes: K.CellPlanes,
    *,
    cell_size: float,
    max_roughness: float,
    max_slope: float,
    range_cell: float | None,
) -> tuple[np.ndarray, int]:
    """The smooth cells of one strip and the split of each into range cells.

    Returns ``(smooth, split)``; ``split`` is 0 when the strip has no smooth cell.
    """
    tan_smooth = np.tan(np.radians(max_slope))
    with np.errstate(invalid="ignore"):
        smooth = (
            planes.ok
            & (planes.rms <= max_roughness)
            & (planes.b**2 + planes.c**2 <= tan_smooth**2)
        )
    if not smooth.any():
        return smooth, 0
    if range_cell is None:
        split = max(1, round(float(np.sqrt(np.mean(planes.n[smooth]))) / 2.0))
    else:
        split = range_split(cell_size, range_cell)
    return smooth, split


MAX_RANGE_SPLIT = 64  # range cells per cell side at most (a cell holds ~16 points)


def range_split(cell_size: float, range_cell: float) -> int:
    """Range cells per cell side for an explicit `range_cell` (m)."""
    check_positive(range_cell, "range_cell")
    ratio = float(cell_size) / float(range_cell)
    if not ratio <= MAX_RANGE_SPLIT + 0.5:
        raise OptionError(
            f"range_cell {range_cell:g} m is too small for cells of {cell_size:g} m (at least "
            f"{cell_size / MAX_RANGE_SPLIT:g} m)"
        )
    return max(1, round(ratio))


def swaths_from_planes(
    grid: K.Grid,
    z0: float,
    ids: np.ndarray,
    planes: list[K.CellPlanes],
    extremes: Any,
    *,
    min_points: int = 8,
    max_roughness: float = 0.05,
    max_slope: float = 10.0,
    offset_max_slope: float = 60.0,
    max_normal_angle: float = 10.0,
    quality_level: str = DEFAULT_QUALITY_LEVEL,
    estimate_offsets: bool = True,
    rotations: bool = False,
    reference_strip: int | None = None,
    min_overlap_cells: int = 10,
    range_cell: float | None = None,
    return_grids: bool = True,
) -> SwathReport:
    """The :class:`SwathReport` of strips whose cell planes are known.

    What :func:`assess_swaths` does after fitting the planes, for callers that
    fit them another way (a tile catalog adds the cell sums of its chunks).
    ``extremes(i, selected, split)`` gives the residual extremes of strip ``i``
    (:func:`residual_extremes`) for its
    ``selected`` cells split ``split × split``. `z0` is the height of the
    rotation centre (with `rotations`).
    """
    cell_size = grid.cell_size
    thr_rep, thr_rms, thr_max = QUALITY_LEVELS[quality_level]
    strips = [_Strip(int(s), p) for s, p in zip(ids, planes, strict=True)]

    tan_smooth = np.tan(np.radians(max_slope))
    tan_off = np.tan(np.radians(offset_max_slope))
    cos_normal = np.cos(np.radians(max_normal_angle))

    def good(p: K.CellPlanes) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return p.ok & (p.rms <= max_roughness)

    def slope2(p: K.CellPlanes) -> np.ndarray:
        return p.b**2 + p.c**2

    flags: list[str] = []
    # ---- intraswath repeatability
    repeat: list[StripRepeatability] = []
    for i, st in enumerate(strips):
        p = st.planes
        smooth, split = range_plan(
            p,
            cell_size=cell_size,
            max_roughness=max_roughness,
            max_slope=max_slope,
            range_cell=range_cell,
        )
        off_ok = good(p) & (slope2(p) <= tan_off**2)
        st.sigma = float(np.sqrt(np.median(p.rms[off_ok] ** 2))) if off_ok.any() else np.nan
        n_c = int(smooth.sum())
        if n_c == 0:
            repeat.append(
                StripRepeatability(st.id, 0, 0.0, np.nan, np.nan, np.nan, np.nan, False, False)
            )
            flags.append(f"strip {st.id}: no smooth surface, repeatability not assessed")
            continue
        _, ranges = K.ranges_from_extremes(extremes(i, smooth, split), min_points=3)
        if len(ranges) == 0:  # no range cell with 3 points: fall back to whole cells
            split = 1
            _, ranges = K.ranges_from_extremes(extremes(i, smooth, 1), min_points=1)
        dof = np.maximum(p.n[smooth] - 3, 1)
        rmse = float(np.sqrt(np.sum(p.rms[smooth] ** 2 * dof) / np.sum(dof)))
        med = float(np.median(ranges))
        repeat.append(
            StripRepeatability(
                st.id,
                n_c,
                n_c * cell_size**2,
                rmse,
                med,
                float(np.percentile(ranges, 95)),
                float(ranges.max()),
                bool(med <= thr_rep),
                n_c >= min_overlap_cells,
                float(cell_size / split),
                len(ranges),
            )
        )
        if n_c < min_overlap_cells:
            flags.append(f"strip {st.id}: only {n_c} smooth cells, repeatability not assessed")

    # ---- pairs
    pairs: list[PairDifference] = []
    grids: list[DzGrid] = []
    obs: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
    centre = np.array(
        [grid.x0 + 0.5 * grid.nx * cell_size, grid.y0 + 0.5 * grid.ny * cell_size, z0]
    )
    for i in range(len(strips)):
        for j in range(i + 1, len(strips)):
            A, B = strips[i].planes, strips[j].planes
            common, ia, ib = np.intersect1d(A.keys, B.keys, assume_unique=True, return_indices=True)
            both = A.ok[ia] & B.ok[ib]
            if int(both.sum()) < min_overlap_cells:
                continue
            ia, ib, common = ia[both], ib[both], common[both]
            with np.errstate(invalid="ignore"):
                ga, gb = good(A)[ia], good(B)[ib]
                sa, sb = slope2(A)[ia], slope2(B)[ib]
            smooth = ga & gb & (sa <= tan_smooth**2) & (sb <= tan_smooth**2)
            dz_all = B.a[ib] - A.a[ia]
            dz = dz_all[smooth]
            sid = (strips[i].id, strips[j].id)
            if len(dz) == 0:
                flags.append(f"no smooth surface in the overlap of strips {sid[0]} and {sid[1]}")
                nan = np.nan
                pairs.append(
                    PairDifference(
                        *sid,
                        len(common) * cell_size**2,
                        0.0,
                        0,
                        nan,
                        nan,
                        nan,
                        nan,
                        nan,
                        nan,
                        False,
                        False,
                    )
                )
            else:
                ad = np.abs(dz)
                rmsdz = float(np.sqrt(np.mean(dz**2)))
                pairs.append(
                    PairDifference(
                        *sid,
                        overlap_area=len(common) * cell_size**2,
                        area=len(dz) * cell_size**2,
                        n_cells=len(dz),
                        rmsdz=rmsdz,
                        mean=float(dz.mean()),
                        median=float(np.median(dz)),
                        std=float(dz.std(ddof=1)) if len(dz) > 1 else np.nan,
                        max_abs=float(ad.max()),
                        p95_abs=float(np.percentile(ad, 95)),
                        passes_rmsdz=bool(rmsdz <= thr_rms),
                        passes_max=bool(ad.max() <= thr_max),
                    )
                )
                if return_grids:  # cropped to the pair's overlap (rows: north first)
                    iy, ix = np.divmod(common, grid.nx)
                    r0, r1, c0, c1 = iy.min(), iy.max(), ix.min(), ix.max()
                    img = np.full((r1 - r0 + 1, c1 - c0 + 1), np.nan, dtype=np.float32)
                    img[r1 - iy[smooth], ix[smooth] - c0] = dz
                    grids.append(
                        DzGrid(
                            *sid,
                            grid.x0 + c0 * cell_size,
                            grid.y0 + (r1 + 1) * cell_size,
                            cell_size,
                            img,
                        )
                    )
            if estimate_offsets:
                with np.errstate(invalid="ignore"):
                    nb = np.column_stack([-A.b[ia], -A.c[ia], np.ones(len(ia))])
                    nb2 = np.column_stack([-B.b[ib], -B.c[ib], np.ones(len(ib))])
                    cosang = np.sum(nb * nb2, axis=1) / (
                        np.linalg.norm(nb, axis=1) * np.linalg.norm(nb2, axis=1)
                    )
                    use = ga & gb & (sa <= tan_off**2) & (sb <= tan_off**2) & (cosang >= cos_normal)
                if use.sum() >= MIN_OFFSET_OBS:
                    bb = 0.5 * (A.b[ia] + B.b[ib])[use]
                    cc = 0.5 * (A.c[ia] + B.c[ib])[use]
                    xy = grid.centres(common[use])
                    d = np.column_stack([xy, 0.5 * (A.a[ia] + B.a[ib])[use]]) - centre
                    cols = [-bb, -cc, np.ones_like(bb)]
                    if rotations:
                        cols += [
                            d[:, 1] + cc * d[:, 2],
                            -d[:, 0] - bb * d[:, 2],
                            bb * d[:, 1] - cc * d[:, 0],
                        ]
                    g = np.column_stack(cols)
                    sa2, sb2 = strips[i].sigma ** 2, strips[j].sigma ** 2
                    qa, qb = A.q[ia][use], B.q[ib][use]
                    var = sa2 * qa[:, 0, 0] + sb2 * qb[:, 0, 0]
                    # Errors in variables: the slopes in g are estimates too. Their
                    # covariance (and their covariance with dz) is removed from the
                    # normal equations (corrected score), else offsets shrink by
                    # var(slope) / (slope² + var(slope)): a few % on 1 m cells.
                    u = g.shape[1]
                    cg = np.zeros((len(g), u, u))
                    cg[:, :2, :2] = 0.25 * (sa2 * qa[:, 1:, 1:] + sb2 * qb[:, 1:, 1:])
                    cgl = np.zeros((len(g), u))
                    cgl[:, :2] = -0.5 * (sb2 * qb[:, 0, 1:] - sa2 * qa[:, 0, 1:])
                    flat = ((sa <= tan_smooth**2) & (sb <= tan_smooth**2))[use]
                    block = np.floor(xy / CLUSTER_SIZE).astype(np.int64)
                    cluster = np.unique(block, axis=0, return_inverse=True)[1].ravel()
                    obs[(i, j)] = (g, dz_all[use], 1.0 / var, flat, cg, cgl, cluster)
    if not pairs:
        raise DegenerateGeometryError(
            f"no two of the strips {', '.join(map(str, ids))} overlap (fewer than "
            f"{min_overlap_cells} shared {cell_size:g} m cells with {min_points}+ points each)"
        )
    if all(p.n_cells == 0 for p in pairs):
        raise DegenerateGeometryError(
            "no smooth surface in any strip overlap (every shared cell has plane residuals above "
            f"{max_roughness:g} m or a slope above {max_slope:g}°)"
        )

    pair_offsets: list[StripOffset] = []
    network: list[StripOffset] = []
    ref = None
    e4 = np.nan
    if estimate_offsets:
        kept = {}
        for (i, j), (g, obs_dz, w, flat, cg, cgl, cluster) in obs.items():
            keep = _robust_keep(g, obs_dz, w)
            g, obs_dz, w, flat, cg, cgl = (
                g[keep],
                obs_dz[keep],
                w[keep],
                flat[keep],
                cg[keep],
                cgl[keep],
            )
            w = _variance_components(g, obs_dz, w, flat)
            kept[(i, j)] = _normals(g, obs_dz, w, cg, cgl)
            sol = _solve(kept[(i, j)])
            if sol is not None:
                x, cov, s0 = sol
                off = _offset(strips[i].id, strips[j].id, x, cov, len(g), s0, rotations, "pair")
                robust = _cluster_sigma(g, obs_dz, w, x, kept[(i, j)][0], cluster[keep])
                pair_offsets.append(replace(off, sigma_robust=robust))
        if kept:
            counts = np.array([len(s.planes.keys) for s in strips])
            if reference_strip is None:
                ref_i = int(np.argmax(counts))  # ties: first (smallest id)
            else:
                if reference_strip not in [s.id for s in strips]:
                    raise InvalidPointsError(
                        f"reference_strip {reference_strip} is not one of the strips "
                        f"{', '.join(str(s.id) for s in strips)}"
                    )
                ref_i = [s.id for s in strips].index(reference_strip)
            ref = strips[ref_i].id
            network, e4, net_flags = _network(strips, kept, ref_i, rotations)
            flags.extend(net_flags)
        else:
            flags.append("too few matched planes to estimate strip offsets")

    params = dict(
        cell_size=cell_size,
        min_points=min_points,
        max_roughness=max_roughness,
        max_slope=max_slope,
        offset_max_slope=offset_max_slope,
        max_normal_angle=max_normal_angle,
        quality_level=quality_level,
        rotations=rotations,
        min_overlap_cells=min_overlap_cells,
        range_cell=range_cell,
    )
    return SwathReport(
        quality_level=quality_level,
        thresholds={"repeatability": thr_rep, "rmsdz": thr_rms, "max_abs": thr_max},
        cell_size=float(cell_size),
        strips=tuple(s.id for s in strips),
        pairs=tuple(pairs),
        repeatability=tuple(repeat),
        pair_offsets=tuple(pair_offsets),
        network_offsets=tuple(network),
        reference_strip=ref,
        e4=float(e4),
        grids=tuple(grids),
        flags=tuple(flags),
        parameters=params,
    )


def _robust_keep(g: np.ndarray, obs_dz: np.ndarray, w: np.ndarray, k: float = 4.0) -> np.ndarray:
    """Iteratively drop observations whose standardised residual exceeds k robust σ."""
    keep = np.ones(len(obs_dz), dtype=bool)
    for _ in range(5):
        if keep.sum() <= g.shape[1]:
            break
        sw = np.sqrt(w[keep])
        x, *_ = np.linalg.lstsq(g[keep] * sw[:, None], obs_dz[keep] * sw, rcond=None)
        r = (obs_dz - g @ x) * np.sqrt(w)
        scale = 1.4826 * np.median(np.abs(r[keep]))
        if not np.isfinite(scale) or scale == 0:
            break
        new = np.abs(r) <= k * scale
        if np.array_equal(new, keep):
            break
        keep = new
    return keep


def _variance_components(
    g: np.ndarray, obs_dz: np.ndarray, w: np.ndarray, group: np.ndarray
) -> np.ndarray:
    """Rescale the weights of flat and tilted cells by their own variance factors.

    Cells on tilted faces carry more than point noise (a crease or a slightly
    curved face inside the cell is sampled differently by each strip), so one
    variance factor for all cells would inflate the σ of dz (fixed mostly by
    flat cells). Two groups, their factors estimated from the residuals with
    redundancy numbers, two passes.
    """
    w = w.copy()
    for _ in range(2):
        sw = np.sqrt(w)
        a = g * sw[:, None]
        try:
            q, _ = np.linalg.qr(a)
        except np.linalg.LinAlgError:
            return w
        x, *_ = np.linalg.lstsq(a, obs_dz * sw, rcond=None)
        r2 = w * (obs_dz - g @ x) ** 2
        redundancy = 1.0 - np.sum(q * q, axis=1)
        for m in (group, ~group):
            red = float(redundancy[m].sum())
            if m.sum() > g.shape[1] and red > 0:
                w[m] /= float(r2[m].sum()) / red
    return w


def _normals(
    g: np.ndarray, obs_dz: np.ndarray, w: np.ndarray, cg: np.ndarray, cgl: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Bias-corrected normal equations of one pair: (N, n, Σ w l², number of observations)."""
    gw = g * w[:, None]
    n_mat = gw.T @ g - np.einsum("m,mij->ij", w, cg)
    rhs = gw.T @ obs_dz - np.einsum("m,mi->i", w, cgl)
    return n_mat, rhs, float(np.sum(w * obs_dz * obs_dz)), len(obs_dz)


def _solve(
    normals: tuple[np.ndarray, np.ndarray, float, int],
) -> tuple[np.ndarray, np.ndarray, float] | None:
    n_mat, rhs, ll, m = normals
    u = len(rhs)
    if m <= u or np.linalg.cond(n_mat) > 1e12:
        return None
    inv = np.linalg.inv(n_mat)
    x = inv @ rhs
    s0 = float(np.sqrt(max(ll - x @ rhs, 0.0) / (m - u)))
    return x, inv * s0**2, s0


def _cluster_sigma(
    g: np.ndarray,
    obs_dz: np.ndarray,
    w: np.ndarray,
    x: np.ndarray,
    n_mat: np.ndarray,
    cluster: np.ndarray,
) -> tuple[float, float, float] | None:
    """Cluster-robust (sandwich) σ of dx, dy, dz: residual scores summed per block."""
    cluster = np.unique(cluster, return_inverse=True)[1].ravel()
    n_cl = int(cluster.max()) + 1 if len(cluster) else 0
    if n_cl < 5:
        return None
    score = g * (w * (obs_dz - g @ x))[:, None]
    per = np.zeros((n_cl, g.shape[1]))
    np.add.at(per, cluster, score)
    bread = np.linalg.inv(n_mat)
    cov = bread @ (per.T @ per) @ bread * n_cl / (n_cl - 1)
    sd = np.sqrt(np.maximum(np.diag(cov)[:3], 0.0))
    return (float(sd[0]), float(sd[1]), float(sd[2]))


def _offset(
    a: int, b: int, x: np.ndarray, cov: np.ndarray, n: int, s0: float, rot: bool, method: str
) -> StripOffset:
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    def deg3(v: np.ndarray) -> tuple[float, float, float]:
        d = np.degrees(v[3:6])
        return float(d[0]), float(d[1]), float(d[2])

    r = deg3(x) if rot else None
    sr = deg3(sd) if rot else None
    return StripOffset(
        a,
        b,
        float(x[0]),
        float(x[1]),
        float(x[2]),
        float(sd[0]),
        float(sd[1]),
        float(sd[2]),
        r,
        sr,
        int(n),
        float(s0),
        method,
    )


def _network(
    strips: list[_Strip],
    kept: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, float, int]],
    ref_i: int,
    rot: bool,
) -> tuple[list[StripOffset], float, list[str]]:
    """Adjust all strips' offsets at once; strip `ref_i` is held fixed (datum)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    flags: list[str] = []
    s = len(strips)
    edges = np.array(list(kept), dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(s, s))
    _, label = connected_components(graph, directed=False)
    conn = label == label[ref_i]
    for k_off in np.flatnonzero(~conn):
        flags.append(
            f"strip {strips[k_off].id} is not connected to reference strip "
            f"{strips[ref_i].id}: no network offset"
        )
    unknown = [k for k in range(s) if conn[k] and k != ref_i]
    pos = {k: n for n, k in enumerate(unknown)}
    u = 6 if rot else 3
    dim = u * len(unknown)
    n_mat = np.zeros((dim, dim))
    rhs = np.zeros(dim)
    ll, m = 0.0, 0
    for (i, j), (nn, nl, pair_ll, pair_m) in kept.items():
        if not (conn[i] and conn[j]):
            continue
        ll += pair_ll
        m += pair_m
        for k, sign in ((j, 1.0), (i, -1.0)):
            if k == ref_i:
                continue
            a = slice(pos[k] * u, pos[k] * u + u)
            rhs[a] += sign * nl
            for k2, sign2 in ((j, 1.0), (i, -1.0)):
                if k2 == ref_i:
                    continue
                b = slice(pos[k2] * u, pos[k2] * u + u)
                n_mat[a, b] += sign * sign2 * nn
    out: list[StripOffset] = []
    if dim == 0 or m <= dim or np.linalg.cond(n_mat) > 1e12:
        flags.append("the strip network is not solvable (too few matched planes)")
        return out, np.nan, flags
    inv = np.linalg.inv(n_mat)
    x = inv @ rhs
    s0 = float(np.sqrt(max(float(ll - x @ rhs), 0.0) / (m - dim)))
    cov = inv * s0**2
    tz = [0.0]
    xk: np.ndarray
    ck: np.ndarray
    for k in range(s):
        if not conn[k]:
            continue
        if k == ref_i:
            xk, ck = np.zeros(u), np.zeros((u, u))
        else:
            a = slice(pos[k] * u, pos[k] * u + u)
            xk, ck = x[a], cov[a, a]
            tz.append(float(xk[2]))
        out.append(_offset(strips[ref_i].id, strips[k].id, xk, ck, m, s0, rot, "network"))
    e4 = float(np.std(tz, ddof=1)) if len(tz) >= 2 else np.nan
    return out, e4, flags
