"""Segment-based progressive TIN densification (Lin & Zhang 2014/2015), :ref:`alg-segment-ptd`.

The cloud is segmented into planar surfaces (surface growing, :ref:`alg-segmentation`), object
segments (façades, vegetation) are removed by orientation and scatterness
(:ref:`alg-features`), and the PTD framework (:ref:`alg-ptd`) then decides per *segment*: segments
holding a seed point are ground, and an undecided segment becomes ground when
enough of its points pass the point-wise PTD tests against the current TIN.
Lower parts of objects are rejected with their segment; terrain patches that
cross break lines (curbs) are kept whole.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit, prange

from .._arrays import colmax, colmin
from .._gridkernels import centred_moments, grid_keys
from .._progress import ProgressCallback, report, stage
from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import DegenerateGeometryWarning, InvalidPointsError, OptionError
from ._gap import gap_mask
from ._perched import perched_mask
from ._tin import TIN, build_tin, tree_workers, virtual_hull
from .features import (
    _segment_planes,
    detect_object_segments,
    segment_features,
    vegetation_segments,
)
from .ptd import DensifyState, TINParameters, densify, final_pass, initial_seeds, prepare

__all__ = [
    "SegmentPTD",
    "SegmentPTDResult",
    "segment_ptd",
    "default_grow_radius",
    "thin_lowest",
    "surface_lowest",
]

#: largest `filter_density` (points/m²): a 1 mm cell
MAX_FILTER_DENSITY = 1e6


@dataclass(frozen=True)
class SegmentPTDResult:
    """Outcome of segment-based PTD.

    Attributes
    ----------
    ground_mask : ndarray of bool, shape (N,)
    labels : ndarray of int, shape (N,)
        Segment labels used (-1 = unsegmented or not a candidate).
    object_segments : ndarray of bool, shape (S,)
        Segments flagged as objects (façade / vegetation).
    ground_segments : ndarray of bool, shape (S,)
        Segments accepted as ground.
    n_seed_points : int
        Points of the seed segments (all labelled ground at once).
    accepted_per_iter : tuple of int
        Segments accepted in each sweep.
    n_point_ptd : int
        Unsegmented points added by the point-wise pass.
    grow_radius : float
        Surface-growing radius used (m), nan when labels were given.
    """

    ground_mask: np.ndarray
    labels: np.ndarray
    object_segments: np.ndarray
    ground_segments: np.ndarray
    n_seed_points: int
    accepted_per_iter: tuple[int, ...]
    n_point_ptd: int
    grow_radius: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "n_points": int(self.ground_mask.size),
            "n_ground": int(self.ground_mask.sum()),
            "n_segments": int(self.object_segments.size),
            "n_object_segments": int(self.object_segments.sum()),
            "n_ground_segments": int(self.ground_segments.sum()),
            "n_unsegmented": int((self.labels < 0).sum()),
            "n_seed_points": self.n_seed_points,
            "accepted_per_iter": list(self.accepted_per_iter),
            "n_point_ptd": self.n_point_ptd,
            "grow_radius": self.grow_radius,
        }


def default_grow_radius(points: np.ndarray, *, factor: float = 2.5, floor: float = 0.3) -> float:
    """Surface-growing radius from the point density: `factor` × mean point spacing (m).

    The spacing is 1/sqrt(density); the density is the median point count of the
    occupied cells of an XY grid whose cell holds about 50 points on average,
    divided by the cell area (robust to scan-line patterns and to empty areas).
    Never below `floor`.
    """
    points = as_points(points)
    n = points.shape[0]
    if n < 2:
        return floor
    lo = colmin(points[:, :2])
    span = colmax(points[:, :2]) - lo
    area = float(max(span[0], 1e-9) * max(span[1], 1e-9))
    if area <= 1e-12:
        return floor
    cell = math.sqrt(50.0 * area / n)
    ij = np.floor((points[:, :2] - lo) / cell).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    counts = np.bincount(key)
    counts = counts[counts > 0]
    density = float(np.median(counts)) / (cell * cell)
    if not np.isfinite(density) or density <= 0:
        return floor
    return max(floor, factor / math.sqrt(density))


@dataclass(frozen=True)
class SegmentPTD(TINParameters):
    """Segment-based PTD ground filter.

    Parameters
    ----------
    cell_size, max_terrain_angle, iter_angle, iter_distance, min_edge_length, mirror,
    mirror_max_distance, max_iter, edge_mode, seed_support, seed_radius, seed_dz
        As in :class:`lidarqa.ground.ptd.PTD` (m, degrees).
    accept_ratio : float, default 0.5
        A segment is ground (all its points) when at least this fraction of its
        points pass the point-wise PTD tests.
    reject_ratio : float, default 0.5
        A segment with a smaller fraction of passing points is entirely non-ground;
        between `reject_ratio` and `accept_ratio` its points keep their point-wise result.
    seed_segments : bool, default True
        Every segment holding a seed point is ground as a whole (:ref:`alg-segment-ptd`);
        False: seed segments are judged by the vote like the others.
    min_tested : int, default 3
        Segments with fewer tested points (inside the TIN) stay undecided.
    unsegmented : {"point_ptd", "drop"}, default "point_ptd"
        Unsegmented points: densify them point-wise against the segment TIN (ALS),
        or never ground (the MLS paper).
    orientation_thr : float, default 45.0
        Degrees; steeper segments are façades (objects).
    scatter_thr : float, default 0.2
        Segments with larger mean scatterness are vegetation (objects).
    k_feat : int, default 10
        Neighbourhood of the scatterness feature.
    min_facade_points : int, default 0
    grow_radius : float or None, default None
        Surface-growing radius (m); None = `grow_radius_factor` × mean point spacing
        (see :func:`default_grow_radius`).
    grow_radius_factor : float, default 2.5
    max_segment_density : float, default 8.0
        Denser clouds (points/m², from :func:`default_grow_radius`'s estimate) are
        segmented on a voxel subsample of about this density (voxel edge
        1/sqrt(density) m, the point nearest each voxel centre); every other point
        takes the label of its voxel's sample point.
        0 = always segment every point.
    grow_dist : float, default 0.3
        Surface-growing plane distance (m).
    seed_dist : float, default 0.2
        Surface-growing seed plane distance (m).
    k_seed : int, default 20
    min_segment_size : int, default 10
    final_distance : float, default 0.0
        After densification, undecided non-object points within this distance (m)
        of the TIN become ground; 0 disables.
    min_gain_frac : float, default 1e-3
        A densification stops once an iteration adds fewer than this fraction of the
        TIN's vertices (saves many near-empty iterations on large clouds).
    seed_support, seed_radius, seed_dz, seed_support_ratio
        Seed support test, as in :class:`lidarqa.ground.PTD`.
    raised_step : float, default 0.0
        Raised-segment test (m; 0 disables). A segment about to be accepted is
        rejected for good when at least `raised_ratio` of its border points (points
        whose nearest already-accepted ground point of another segment lies within
        `raised_radius` m in XY) are more than `raised_step` m above that point and
        steeper than `raised_angle` degrees from it: roofs and bridges whose low
        edge touches the terrain. Curbs (a few decimetres) are not steps. When it
        rejects a segment, the unsegmented points (judged in the last sweep against
        a TIN that held it) are judged again against the ground that remains.
    raised_angle : float, default 45.0
    raised_ratio : float, default 0.5
    raised_radius : float, default 3.0
    connect_min_size : int, default 0
        Connection pass after the densification (0 disables): a rejected non-object
        segment of at least this many points becomes ground when at least
        `connect_ratio` of its border points are within ``connect_distance +
        dxy·tan(connect_angle)`` m (vertically) of their nearest ground point of
        another segment, and it is not raised (see `raised_step`). Repeated while
        segments are added (at most 10 rounds). Reaches terrain patches the TIN
        spanned over (between buildings) that join the ground smoothly.
    connect_distance : float, default 0.5
    connect_angle : float, default 20.0
    connect_ratio : float, default 0.5
    below_pass : bool, default False
        Final pass: undecided candidates outside object segments that lie more than
        `below_distance` m below the facet of the final ground TIN (thinned like the
        densification TIN; facets with a virtual vertex excluded) become ground.
        Objects stand on the terrain, so a point under the ground surface is terrain
        the densification could not reach (pits, concave slopes), or low noise.
    below_distance : float, default 0.0
    perched_step : float, default 0.0
        Perched-surface test, the last step (m; 0 disables): accepted ground whose
        surroundings drop by more than `perched_step` m, steeper than
        `perched_angle` degrees, on opposite sides within `perched_radius` m is
        rejected: roofs reached from a hillside, bridge decks, wall tops. Terrain
        drops on one side only (terrace edges, cuts) or at a slope's grade
        (embankments), and stays ground. The test sees only the part of a surface
        with drops on both sides; where the raised test is on (`raised_step` > 0),
        an accepted segment it cuts into is then judged whole by it (with
        `perched_step` and `perched_angle` as the step and the angle) against the
        ground that remains, and rejected when at least `raised_ratio` of its border points
        (10 or more) are raised: a flat roof built into a slope, whose uphill
        edge meets the terrain, goes whole once its perched part and the
        point-wise ground on it are gone.
    perched_angle : float, default 45.0
    perched_radius : float, default 8.0
    gap_step : float, default 0.0
        Gap test, after the perched test (m; 0 disables; the clearance under a deck):
        a bridge deck stands on piers, so between its edge and the lower ground beyond
        it the cloud holds no return at an intermediate height, while an embankment's
        side is a slope that carries returns. A drop of more than `gap_step` m to
        accepted ground (a surface, not an outlier) within 12 m at a grade steeper
        than 30° is clean when its corridor (1.5 m either side) holds no candidate in
        the middle of the drop; accepted points whose drops are (nearly all) clean
        and that have such an edge facing the other way within 12 m at their level
        are rejected. Catches what the perched test cannot reach in sparse clouds
        (2 m between points): a narrow deck over a valley; not a deck level with
        ground that continues beside it. See :mod:`lidarqa.ground._gap`.
    filter_density : float, default 0.0
        Dense clouds (points/m²; 0 = off, the automatic parameters set it for dense
        airborne clouds): the filter runs on the lowest candidate of each XY cell of
        1/sqrt(`filter_density`) m (cells on absolute coordinates, so tiles and chunks
        see the same cells), and every other candidate joins the ground when the
        candidate joins the ground when the lowest point of its cell is ground and it
        lies within `join_distance` m (vertically) of the least-squares plane through
        the lowest ground points of its cell and the eight cells around it. Terrain is
        the lower envelope of the cloud, so the lowest points carry the decision; the
        plane test then takes the ground points the thinning set aside, and leaves low
        vegetation, cars and the feet of walls that stand higher.
    join_distance : float, default 0.15
        See `filter_density` (m).
    join_below : bool, default False
        With `filter_density`: a cell whose lowest point is not ground but lies more
        than `join_distance` m below the plane of its ground neighbours (at least
        three of the nine cells) is tested against that plane too, so the surface
        above a return from below the ground joins. For ground-based scans, where a
        return below the ground is a multipath echo (a wet road, glass); from the
        air the lowest return is the best ground evidence, and this stays off.
    surface_support : int, default 8
        With `filter_density`: the point filtered in each cell is its lowest candidate
        that starts a surface, i.e. with at least `surface_support` other candidates of
        its cell, and a quarter of the cell's candidates in all, in the 5 cm above it;
        a cell without one keeps its lowest candidate. A return alone under a dense
        surface (a multipath echo under a road, a stray return under a roof) is then
        not the cell's terrain evidence. Only dense cells hold such a surface (at
        4 points/m², 9 returns within 5 cm in a 0.5 m cell: mobile and terrestrial
        scans, dense airborne roofs); the terrain pass (`terrain_density`) keeps the
        lowest candidate. 0 = always the lowest candidate.
    terrain_density : float, default 0.0
        Terrain first (points/m²; 0 = off; only with `filter_density`): the filter
        first runs, thinned the same way, at this lower density, where a cell is
        large enough to hold a ground return even under a closed canopy; its ground
        is the terrain model. The run at `filter_density` starts its densification
        from that ground (the terrain's ground points among its own cells are its seed
        points, in place of its seed cells), its ground is then kept only up to
        `terrain_distance` m above the TIN of the terrain, and the terrain's own
        ground points are added. Under forest the lowest point of a
        small cell is often a branch or the understorey, and the small cells let the
        densification climb onto it; the large cells see the ground. In the open the
        small cells keep their detail (curbs, narrow paths). The automatic
        parameters of dense airborne clouds set 0.5 (1.4 m cells).
    terrain_distance : float, default 0.3
        See `terrain_density` (m).
    terrain_band : float or None, default 1.0
        With `terrain_density`: the run at `filter_density` filters only the lowest
        points at most this many metres above the terrain model (None = all of them).
        Higher ones could not stay ground (`terrain_distance`); the band keeps the low
        parts of objects with their surroundings up to 1 m so the segment test still
        sees a shrub or a car as an object. Under forest this leaves out the canopy
        cells: a third of the cells and half of the run's time on the BC forest tiles.
    terrain_grow_radius : float or None, default None
        Surface-growing radius of the terrain pass (m); None = `grow_radius` scaled
        by the cell ratio sqrt(`filter_density` / `terrain_density`) when that is
        given, else estimated on the terrain pass's own cells as `grow_radius` is on
        the fine ones. A catalog gives both radii, estimated once on the whole
        catalog, so every chunk grows the surfaces one in-memory run would.
    facade_distance : float, default 0.0
        Façade segments on trial (m; 0 = off, Lin & Zhang's rule: every point of a
        façade segment is an object). Points of segments flagged as façades by
        `orientation_thr` alone (not scattered) stay out of the densification, and at
        the end, after the below pass, those within `facade_distance` m (vertically)
        of the final ground surface become ground, and so do the points below that
        surface of a façade segment it passes through (one with a point within the
        distance): the below pass, for a bank whose foot the terrain's TIN spans over
        (a concave slope under houses built into it). Below the surface alone is not
        enough: a wall at the edge of a data gap lies under the long facets that
        bridge the gap, without touching them. At airborne spacings surface
        growing also links the two levels of a steep bank or retaining wall into one
        near-vertical segment; this keeps its terrain without letting a wall's points
        steer the TIN. The ALS preset, and so the automatic parameters of sparse
        airborne clouds, set it to their iteration distance (0.7 m).
    roof_ratio : float, default 0.0
        Final roof check (0 = off; needs `raised_step`), run against the final
        ground surface after the below and façade passes, when the ground around
        every segment is known. (1) The raised test again, for accepted segments
        with at least 10 border points. (2) Gable pairs: two adjacent segments
        sloping 10–60° whose aspects differ by more than 135° and that meet in a
        convex ridge (each centroid more than 0.3 m below the other's plane) are
        rejected together when at least `roof_ratio` of their pooled border
        points are raised. Houses built into a slope touch the terrain on the
        uphill side, so their border is raised on one side only; a ridge between
        two opposite roof planes is what tells them from a terrace. Natural
        ridges (dykes, hill crests) meet the terrain at grade and have no raised
        border. The ALS preset sets 0.15.
    """

    cell_size: float = 60.0
    max_terrain_angle: float = 88.0
    iter_angle: float = 6.0
    iter_distance: float = 0.5
    min_edge_length: float = 1.0
    mirror: bool = True
    mirror_max_distance: float = float("inf")
    max_iter: int = 100
    edge_mode: str = "freeze"
    accept_ratio: float = 0.5
    reject_ratio: float = 0.5
    seed_segments: bool = True
    min_tested: int = 3
    unsegmented: str = "point_ptd"
    orientation_thr: float = 45.0
    scatter_thr: float = 0.2
    k_feat: int = 10
    min_facade_points: int = 0
    grow_radius: float | None = None
    grow_radius_factor: float = 2.5
    max_segment_density: float = 8.0
    grow_dist: float = 0.3
    seed_dist: float = 0.2
    k_seed: int = 20
    min_segment_size: int = 10
    final_distance: float = 0.0
    min_gain_frac: float = 1e-3
    seed_support: int = 3
    seed_radius: float = 5.0
    seed_dz: float = 1.0
    seed_support_ratio: float = 0.25
    raised_step: float = 0.0
    raised_angle: float = 45.0
    raised_ratio: float = 0.5
    raised_radius: float = 3.0
    connect_min_size: int = 0
    connect_distance: float = 0.5
    connect_angle: float = 20.0
    connect_ratio: float = 0.5
    below_pass: bool = False
    below_distance: float = 0.0
    perched_step: float = 0.0
    perched_angle: float = 45.0
    perched_radius: float = 8.0
    gap_step: float = 0.0
    filter_density: float = 0.0
    join_distance: float = 0.15
    join_below: bool = False
    surface_support: int = 8
    terrain_density: float = 0.0
    terrain_distance: float = 0.3
    terrain_band: float | None = 1.0
    terrain_grow_radius: float | None = None
    facade_distance: float = 0.0
    roof_ratio: float = 0.0

    def __post_init__(self) -> None:
        self._check_tin_parameters()
        check_choice(self.unsegmented, ("point_ptd", "drop"), "unsegmented")
        check_range(self.accept_ratio, "accept_ratio", 0.0, 1.0)
        check_range(self.reject_ratio, "reject_ratio", 0.0, 1.0)
        if self.reject_ratio > self.accept_ratio:
            raise OptionError(
                f"reject_ratio ({self.reject_ratio}) must be <= accept_ratio ({self.accept_ratio})"
            )
        check_range(self.orientation_thr, "orientation_thr", 0.0, 90.0)
        check_positive(self.scatter_thr, "scatter_thr")
        check_positive(self.grow_dist, "grow_dist")
        check_positive(self.seed_dist, "seed_dist")
        check_positive(self.final_distance, "final_distance", allow_zero=True)
        check_positive(self.min_gain_frac, "min_gain_frac", allow_zero=True)
        check_positive(self.grow_radius_factor, "grow_radius_factor")
        check_positive(self.max_segment_density, "max_segment_density", allow_zero=True)
        check_positive(self.raised_step, "raised_step", allow_zero=True)
        check_range(self.raised_angle, "raised_angle", 0.0, 90.0, hi_open=True)
        check_range(self.raised_ratio, "raised_ratio", 0.0, 1.0)
        check_positive(self.raised_radius, "raised_radius")
        check_positive(self.connect_distance, "connect_distance", allow_zero=True)
        check_range(self.connect_angle, "connect_angle", 0.0, 90.0, hi_open=True)
        check_range(self.connect_ratio, "connect_ratio", 0.0, 1.0)
        check_positive(self.below_distance, "below_distance", allow_zero=True)
        check_positive(self.perched_step, "perched_step", allow_zero=True)
        check_range(self.perched_angle, "perched_angle", 0.0, 90.0, hi_open=True)
        check_positive(self.perched_radius, "perched_radius")
        check_positive(self.gap_step, "gap_step", allow_zero=True)
        check_range(self.filter_density, "filter_density", 0.0, MAX_FILTER_DENSITY)
        check_positive(self.join_distance, "join_distance", allow_zero=True)
        check_range(self.terrain_density, "terrain_density", 0.0, MAX_FILTER_DENSITY)
        check_positive(self.terrain_distance, "terrain_distance", allow_zero=True)
        if self.terrain_band is not None:
            check_positive(self.terrain_band, "terrain_band", allow_zero=True)
        if self.terrain_grow_radius is not None:
            check_positive(self.terrain_grow_radius, "terrain_grow_radius")
        check_positive(self.facade_distance, "facade_distance", allow_zero=True)
        check_range(self.roof_ratio, "roof_ratio", 0.0, 1.0)
        for name in ("connect_min_size", "surface_support"):
            v = getattr(self, name)
            if int(v) != v or v < 0:
                raise OptionError(f"{name} must be an integer >= 0, got {v!r}")
        if self.grow_radius is not None:
            check_positive(self.grow_radius, "grow_radius")
        for name in ("max_iter", "min_tested", "k_feat", "k_seed", "min_segment_size"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise OptionError(f"{name} must be an integer >= 1, got {v!r}")

    def segment(self, points: Any, *, candidates: Any = None) -> tuple[np.ndarray, float]:
        """Surface-growing labels of the candidate points (others -1) and the radius used."""
        labels, radius, _ = self._segment(points, candidates=candidates)
        return labels, radius

    def _segment(
        self, points: Any, *, candidates: Any = None, progress: ProgressCallback | None = None
    ) -> tuple[np.ndarray, float, Any]:
        from ..geometry.segmentation import surface_growing

        pts = as_points(points)
        n = pts.shape[0]
        cand = np.ones(n, dtype=bool) if candidates is None else np.asarray(candidates, dtype=bool)
        labels = np.full(n, -1, dtype=np.int64)
        ci = np.flatnonzero(cand)
        if ci.size < 3:
            return labels, math.nan, None
        sub = pts[ci] - colmin(pts[ci])
        r0 = default_grow_radius(sub, factor=self.grow_radius_factor, floor=0.0)
        density = (self.grow_radius_factor / r0) ** 2 if r0 > 0 else 0.0
        sample = np.arange(ci.size)
        voxel_of = None
        if self.max_segment_density > 0 and density > self.max_segment_density:
            sample, voxel_of = _voxel_sample(sub, 1.0 / math.sqrt(self.max_segment_density))
        radius = (
            self.grow_radius
            if self.grow_radius is not None
            else max(0.3, r0)  # from the full density, also when segmenting a sample
        )
        lab_s = surface_growing(
            sub[sample],
            k_seed=int(self.k_seed),
            seed_dist=float(self.seed_dist),
            grow_radius=float(radius),
            grow_dist=float(self.grow_dist),
            min_segment_size=int(self.min_segment_size),
            refine_boundaries=False,
            progress=progress,
        )
        if voxel_of is None:
            labels[ci] = lab_s
            return labels, float(radius), None
        labels[ci] = lab_s[voxel_of]  # every point takes the label of its voxel's sample point
        return labels, float(radius), ci[sample]

    def run(
        self,
        points: Any,
        *,
        labels: Any = None,
        candidates: Any = None,
        object_segments: Any = None,
        progress: ProgressCallback | None = None,
    ) -> SegmentPTDResult:
        """Run the filter.

        Parameters
        ----------
        points : ndarray of shape (N, 3)
            x, y, z in metres; finite.
        labels : ndarray of int, shape (N,), optional
            Segment labels (-1 = unsegmented). Default: surface growing of the candidates.
        candidates : ndarray of bool, shape (N,), optional
            Points allowed to be ground (others are ignored and never ground).
        object_segments : ndarray of bool, shape (S,), optional
            Object flag per segment; default: orientation / scatterness rule (:ref:`alg-features`).
        progress : callable, optional
            Called with the estimated fraction of the work done (0..1).
        """
        pts = as_points(points)
        n = pts.shape[0]
        cand = np.ones(n, dtype=bool) if candidates is None else _mask(candidates, n, "candidates")
        if self.filter_density > 0 and labels is None and object_segments is None:
            return self._run_thinned(pts, cand, progress)
        return self._run_points(pts, cand, labels, object_segments, progress)

    def _run_points(
        self,
        pts: np.ndarray,
        cand: np.ndarray,
        labels: Any,
        object_segments: Any,
        progress: ProgressCallback | None,
        seeds: np.ndarray | None = None,
    ) -> SegmentPTDResult:
        """The filter on every point given (no thinning); `seeds` replace the seed cells."""
        n = pts.shape[0]
        radius = math.nan
        feature_idx = None
        if labels is None:
            lab, radius, feature_idx = self._segment(
                pts, candidates=cand, progress=stage(progress, 0.0, 0.4)
            )
        else:
            lab = np.asarray(labels)
            if lab.shape != (n,):
                raise InvalidPointsError(f"labels must have shape ({n},), got {lab.shape}")
            lab = lab.astype(np.int64).copy()
        lab[~cand] = -1
        result = _segment_ptd(
            pts, lab, cand, object_segments, self, radius, feature_idx, stage(progress, 0.4, 1.0),
            seeds,
        )
        report(progress, 1.0)
        return result

    def _run_thinned(
        self, pts: np.ndarray, cand: np.ndarray, progress: ProgressCallback | None
    ) -> SegmentPTDResult:
        """`filter_density`: filter the lowest point per cell, then join the others."""
        n = pts.shape[0]
        ci = np.flatnonzero(cand)
        inner = replace(self, filter_density=0.0, terrain_density=0.0)
        if ci.size == 0:
            return inner.run(pts, candidates=cand, progress=progress)
        terrain = None
        fine = (0.0, 0.97)
        if 0 < self.terrain_density < self.filter_density:
            # a given growing radius is the fine cells'; the coarse cells are wider
            gr = self.terrain_grow_radius
            if gr is None and self.grow_radius is not None:
                gr = self.grow_radius * math.sqrt(self.filter_density / self.terrain_density)
            # the terrain pass keeps each cell's lowest candidate: its terrain model is the
            # median point per cell (_on_terrain), which a low return does not pull down
            coarse = replace(
                self, filter_density=self.terrain_density, terrain_density=0.0, grow_radius=gr,
                terrain_grow_radius=None, surface_support=0,
            )
            terrain = coarse.run(pts, candidates=cand, progress=stage(progress, 0.0, 0.3))
            fine = (0.3, 0.97)
        p = pts[ci]
        win, inv, cells = thin_lowest(p, 1.0 / math.sqrt(self.filter_density))
        if self.surface_support > 0:
            win = surface_lowest(p, inv, win, int(self.surface_support))
        wp = np.ascontiguousarray(p[win])
        # terrain first: the fine run starts from the terrain's ground (its cells hold
        # no seed cell's worth of ground under a canopy), not from its own seed cells,
        # and filters only the lowest points within `terrain_band` of the terrain model
        height = None
        run = np.arange(wp.shape[0])
        seeds = None
        if terrain is not None:
            height = _terrain_model(pts, terrain.ground_mask, 1.0 / math.sqrt(self.terrain_density))
            if height is not None and self.terrain_band is not None:
                run = np.flatnonzero(~(height(ci[win]) > self.terrain_band))
                if self.grow_radius is None:  # the radius of every lowest point's spacing
                    r0 = default_grow_radius(wp - colmin(wp), factor=self.grow_radius_factor,
                                             floor=0.0)
                    inner = replace(inner, grow_radius=max(0.3, r0))
            seeds = np.flatnonzero(terrain.ground_mask[ci[win[run]]])
        res = inner._run_points(
            np.ascontiguousarray(wp[run]), np.ones(run.size, dtype=bool), None, None,
            stage(progress, *fine), seeds,
        )
        wg = np.zeros(wp.shape[0], dtype=bool)
        wg[run] = res.ground_mask
        wlab = np.full(wp.shape[0], -1, dtype=np.int64)
        wlab[run] = res.labels
        planes = _cell_planes(cells, wp, wg, float(self.join_distance), bool(self.join_below))
        ok = _join(p, inv, wp, planes, float(self.join_distance))
        ok[win[wg]] = True  # a ground lowest point stays ground whatever its plane says
        ground = np.zeros(n, dtype=bool)
        ground[ci[ok]] = True
        if terrain is not None:
            ground = _on_terrain(ground, terrain.ground_mask, self.terrain_distance, height)
        lab = np.full(n, -1, dtype=np.int64)
        lab[ci] = wlab[inv]
        report(progress, 1.0)
        return SegmentPTDResult(
            ground,
            lab,
            res.object_segments,
            res.ground_segments,
            res.n_seed_points,
            res.accepted_per_iter,
            res.n_point_ptd,
            res.grow_radius,
        )

    def ground_mask(self, points: Any, *, labels: Any = None, candidates: Any = None) -> np.ndarray:
        """Boolean ground mask ``(N,)`` of `points` (see :meth:`run`)."""
        return self.run(points, labels=labels, candidates=candidates).ground_mask


def segment_ptd(
    points: Any,
    labels: Any,
    object_mask_by_segment: Any = None,
    *,
    candidates: Any = None,
    **params: Any,
) -> np.ndarray:
    """Ground mask from points, segment labels and object flags (:ref:`alg-segment-ptd`)."""
    return (
        SegmentPTD(**params)
        .run(points, labels=labels, candidates=candidates, object_segments=object_mask_by_segment)
        .ground_mask
    )


def _argmin_per_group(
    key: np.ndarray, value: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each distinct `key`, the index of the smallest `value` (ties by x, y, z, then index).

    Returns ``(winner_index_sorted_by_key, inverse)`` where ``inverse[i]`` is the
    group number of point i (groups numbered in ascending key order). One stable
    integer sort and a linear numba scan; independent of the input order.
    """
    value = np.ascontiguousarray(value, dtype=np.float64)
    n_keys = int(key.max()) + 1 if key.size else 0
    if 0 < n_keys <= 4 * key.size + 1024 and key.min() >= 0:  # small range: one pass, no sort
        return _group_argmin_dense(
            np.ascontiguousarray(key, dtype=np.int64), value,
            np.ascontiguousarray(p, dtype=np.float64), n_keys,
        )
    order = np.argsort(key, kind="stable")
    return _group_argmin_scan(
        key[order], order, np.ascontiguousarray(value, dtype=np.float64),
        np.ascontiguousarray(p, dtype=np.float64),
    )


@njit(cache=True, nogil=True)
def _group_argmin_dense(key, value, p, n_keys):  # pragma: no cover - numba
    # same winners as the sorted scan: smallest value, then x, y, z; full ties keep
    # the smallest index (points are visited in index order)
    n = key.size
    best = np.full(n_keys, -1, np.int64)
    for i in range(n):
        k = key[i]
        b = best[k]
        if b < 0:
            best[k] = i
            continue
        vi, vb = value[i], value[b]
        if vi < vb or (
            vi == vb
            and (
                p[i, 0] < p[b, 0]
                or (p[i, 0] == p[b, 0] and (
                    p[i, 1] < p[b, 1] or (p[i, 1] == p[b, 1] and p[i, 2] < p[b, 2])
                ))
            )
        ):
            best[k] = i
    rank = np.full(n_keys, -1, np.int64)
    winners = np.empty(n_keys, np.int64)
    g = 0
    for k in range(n_keys):
        if best[k] >= 0:
            rank[k] = g
            winners[g] = best[k]
            g += 1
    inv = np.empty(n, np.int64)
    for i in range(n):
        inv[i] = rank[key[i]]
    return winners[:g], inv


@njit(cache=True, nogil=True)
def _group_argmin_scan(sorted_key, order, value, p):  # pragma: no cover - numba
    n = sorted_key.size
    winners = np.empty(n, np.int64)
    inv = np.empty(n, np.int64)
    g = -1
    best = -1
    for s in range(n):
        i = order[s]
        if s == 0 or sorted_key[s] != sorted_key[s - 1]:
            if best >= 0:
                winners[g] = best
            g += 1
            best = i
        else:
            vi, vb = value[i], value[best]
            if vi < vb or (
                vi == vb
                and (
                    p[i, 0] < p[best, 0]
                    or (p[i, 0] == p[best, 0] and (
                        p[i, 1] < p[best, 1]
                        or (p[i, 1] == p[best, 1] and p[i, 2] < p[best, 2])
                    ))
                )
            ):
                best = i
        inv[i] = g
    if best >= 0:
        winners[g] = best
    return winners[: g + 1], inv


def _voxel_sample(p: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """The point nearest each occupied voxel's centre, and each point's voxel number."""
    f = p / voxel
    q = np.floor(f)
    d2 = ((f - q - 0.5) ** 2).sum(axis=1)
    return _argmin_per_group(_cell_keys(q, p), d2, p)


def _cell_keys(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """One integer key >= 0 per distinct row of cell coordinates `q` (floats from np.floor).

    Keys are row-major cell numbers in the cells' bounding box when that box has fewer
    than 2**62 cells, else (cells far finer than the points' extent, e.g. a 1e-300 m
    cell) the rank of each distinct cell, or of each distinct position in `p` when the
    cell coordinates overflowed: no integer overflow, whatever the cell size.
    """
    lo = colmin(q)
    span = colmax(q) - lo + 1.0
    if np.isfinite(span).all() and float(np.prod(span)) < 2.0**62:
        qi = (q - lo).astype(np.int64)
        key = qi[:, 0].copy()
        for d in range(1, q.shape[1]):
            key = key * int(span[d]) + qi[:, d]
        return key
    rows = q if np.isfinite(q).all() else p[:, : q.shape[1]]
    return np.unique(rows, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)


def thin_lowest(points: Any, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lowest point of each occupied XY cell of `cell` m (cells on absolute coordinates).

    Returns ``(winners, inverse, cells)``: the index of each cell's lowest point (ties
    by x, y, z), cells in lexicographic (column, row) order; the cell number of every
    point; and the ``(column, row)`` of each cell as floats. Independent of the
    input order.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e.copy(), np.zeros((0, 2))
    # floor(min / cell) = min(floor(x / cell)): division and floor are monotonic
    lo = np.floor(colmin(p[:, :2]) / cell)
    span = np.floor(colmax(p[:, :2]) / cell) - lo + 1.0
    if np.isfinite(span).all() and float(np.prod(span)) < 2.0**62:
        key = grid_keys(p[:, 0], p[:, 1], float(cell), lo[0], lo[1], int(span[1]))
    else:
        key = _cell_keys(np.floor(p[:, :2] / cell), p)
    win, inv = _argmin_per_group(key, np.ascontiguousarray(p[:, 2]), p)
    return win, inv, np.ascontiguousarray(np.floor(p[win, :2] / cell))


@njit(cache=True, nogil=True)
def _find_cell(cells, cx, cy):  # pragma: no cover - numba
    """Row of (cx, cy) in `cells` sorted lexicographically, -1 if absent."""
    lo, hi = 0, cells.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if cells[mid, 0] < cx or (cells[mid, 0] == cx and cells[mid, 1] < cy):
            lo = mid + 1
        else:
            hi = mid
    if lo < cells.shape[0] and cells[lo, 0] == cx and cells[lo, 1] == cy:
        return lo
    return -1


def _cell_lut(cells: np.ndarray) -> tuple[np.ndarray, float, float, int]:
    """Row of each cell in a raster over the cells' bounding box (-1 = empty), for O(1) lookups.

    Returns ``(lut, x0, y0, ny)``; `lut` is empty when the box holds far more cells than
    there are (scattered cells: the lookups then search the sorted rows).
    """
    m = cells.shape[0]
    if m == 0:
        return np.zeros(0, dtype=np.int64), 0.0, 0.0, 0
    lo = colmin(cells)
    span = colmax(cells) - lo + 1.0
    if not float(span[0]) * float(span[1]) <= 4 * m + 1_000_000:
        return np.zeros(0, dtype=np.int64), 0.0, 0.0, 0
    ny = int(span[1])
    lut = np.full(int(span[0]) * ny, -1, dtype=np.int64)
    ij = (cells - lo).astype(np.int64)
    lut[ij[:, 0] * ny + ij[:, 1]] = np.arange(m)
    return lut, float(lo[0]), float(lo[1]), ny


@njit(cache=True, nogil=True)
def _cell_row(cells, lut, x0, y0, ny, cx, cy):  # pragma: no cover - numba
    """Row of cell (cx, cy): from the raster `lut` when there is one, else by bisection."""
    if lut.size == 0:
        return _find_cell(cells, cx, cy)
    i = cx - x0
    j = cy - y0
    if i < 0 or j < 0 or j >= ny:
        return -1
    k = int(i) * ny + int(j)
    if k >= lut.size:
        return -1
    return lut[k]


def _cell_planes(cells, wp, wg, tol, below):
    """Per cell: (a, b, c, has) of z = a + b·dx + c·dy about its lowest point (see the kernel)."""
    lut, x0, y0, ny = _cell_lut(cells)
    return _cell_planes_kernel(cells, lut, x0, y0, ny, wp, wg, tol, below)


@njit(cache=True, nogil=True, parallel=True)
def _cell_planes_kernel(cells, lut, x0, y0, ny, wp, wg, tol, below):  # pragma: no cover - numba
    """Per cell: (a, b, c, has) of z = a + b·dx + c·dy about its lowest point.

    Least squares through the lowest ground points of the 3 × 3 cells around it; a
    level plane through their mean when they do not span a plane. With `below`, a
    cell whose lowest point is not ground gets the plane of its ground neighbours
    when at least three of them are ground and its lowest point lies more than `tol`
    below that plane (`has` = 1); other cells get none (`has` = 0).
    """
    m = cells.shape[0]
    out = np.zeros((m, 4))
    for i in prange(m):
        if not (wg[i] or below):
            continue
        nb = np.empty(9, np.int64)
        cnt = 0
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                j = _cell_row(cells, lut, x0, y0, ny, cells[i, 0] + dx, cells[i, 1] + dy)
                if j >= 0 and wg[j]:
                    nb[cnt] = j
                    cnt += 1
        if cnt == 0 or (not wg[i] and cnt < 3):
            continue
        mx, my, mz, sxx, sxy, sxz, syy, syz, _ = centred_moments(wp, nb, cnt)
        mx -= wp[i, 0]  # the plane is written about the cell's lowest point
        my -= wp[i, 1]
        det = sxx * syy - sxy * sxy
        b = c = 0.0
        if cnt >= 3 and det > 1e-9 * (sxx * syy + 1e-300):
            b = (sxz * syy - syz * sxy) / det
            c = (syz * sxx - sxz * sxy) / det
        a = mz - b * mx - c * my
        if not wg[i] and a - wp[i, 2] <= tol:
            continue  # a lowest point that is not below the ground is an object's
        out[i, 0] = a
        out[i, 1] = b
        out[i, 2] = c
        out[i, 3] = 1.0
    return out


@njit(cache=True, nogil=True, parallel=True)
def _join(p, inv, wp, planes, tol):  # pragma: no cover - numba
    """Points within `tol` (vertically) of their cell's ground plane."""
    n = p.shape[0]
    ok = np.zeros(n, dtype=np.bool_)
    for k in prange(n):
        g = inv[k]
        if planes[g, 3] > 0:
            h = p[k, 2] - (
                planes[g, 0]
                + planes[g, 1] * (p[k, 0] - wp[g, 0])
                + planes[g, 2] * (p[k, 1] - wp[g, 1])
            )
            ok[k] = abs(h) <= tol
    return ok


def _terrain_model(
    pts: np.ndarray, terrain: np.ndarray, cell: float
) -> Callable[[np.ndarray], np.ndarray] | None:
    """Height above the terrain model of the `terrain` mask: a function of point indices.

    The model is the TIN of the median-height terrain point per `cell` m (the terrain
    filter's own cells, absolute coordinates): a low outlier the terrain run accepted
    (multipath below a road, a noise return) does not pull it down. Beyond the TIN's
    real facets the nearest terrain point (XY) is the terrain (a level extension).
    None when the terrain has fewer than 3 points (after the thinning).
    """
    ti = np.flatnonzero(terrain)
    if ti.size < 3:
        return None
    ti = _thin_median(pts, ti, cell)
    if ti.size < 3:
        return None
    xyz = pts - colmin(pts)
    virtual = virtual_hull(xyz, ti, 1.0, colmin(xyz[ti]), colmax(xyz[ti]))
    tin = build_tin(xyz, ti, virtual)
    trees: list[Any] = []  # the terrain points' XY tree, built once when first needed

    def height(idx: np.ndarray) -> np.ndarray:
        h = _height_above_tin(tin, xyz[idx])
        rest = np.flatnonzero(np.isnan(h))
        if rest.size:
            if not trees:
                from scipy.spatial import cKDTree

                trees.append(cKDTree(xyz[ti, :2]))
            _, j = trees[0].query(xyz[idx[rest], :2], workers=tree_workers())
            h[rest] = xyz[idx[rest], 2] - xyz[ti[j], 2]
        return h

    return height


def _on_terrain(
    ground: np.ndarray,
    terrain: np.ndarray,
    distance: float,
    height: Callable[[np.ndarray], np.ndarray] | None,
) -> np.ndarray:
    """`ground` up to `distance` m above the terrain model `height`, plus `terrain` itself."""
    if height is None:  # fewer than 3 terrain points: nothing to hold the ground to
        return ground | terrain if np.count_nonzero(terrain) >= 3 else ground
    gi = np.flatnonzero(ground & ~terrain)
    out = terrain.copy()
    out[gi[~(height(gi) > distance)]] = True
    return out


def _mask(m: Any, n: int, name: str) -> np.ndarray:
    a = np.asarray(m)
    if a.shape != (n,):
        raise InvalidPointsError(f"{name} must have shape ({n},), got {a.shape}")
    return a.astype(bool)


def _thin_median(xyz: np.ndarray, idx: np.ndarray, cell: float) -> np.ndarray:
    """Median-height point per `cell` x `cell` XY cell (ties by coordinates), sorted indices."""
    if cell <= 0 or idx.size == 0:
        return idx
    p = xyz[idx]
    _, inv, cells = thin_lowest(p, cell)
    return np.sort(idx[_median_per_group(inv, p, cells.shape[0])])


@njit(cache=True, nogil=True)
def _before(p, u, v):  # pragma: no cover - numba
    """Row `u` of `p` comes before row `v` in (z, x, y, row) order."""
    if p[u, 2] != p[v, 2]:
        return p[u, 2] < p[v, 2]
    if p[u, 0] != p[v, 0]:
        return p[u, 0] < p[v, 0]
    if p[u, 1] != p[v, 1]:
        return p[u, 1] < p[v, 1]
    return u < v


@njit(cache=True, nogil=True)
def _median_per_group(inv, p, n_groups):  # pragma: no cover - numba
    """Per group of `inv`, the row of `p` at position (m - 1) // 2 in (z, x, y, row) order.

    Rows grouped by a counting sort (:func:`_group_sort`, no group sorted), then each
    group's median selected (quickselect in a strict total order: the row a full
    sort would put there, in O(m)).
    """
    start, rows = _group_sort(inv, p, n_groups, inv.size + 1)
    out = np.empty(n_groups, dtype=np.int64)
    for g in range(n_groups):
        s, m = start[g], start[g + 1] - start[g]
        out[g] = _select(rows[s : s + m], (m - 1) // 2, p)
    return out


@njit(cache=True, nogil=True)
def _select(r, k, p):  # pragma: no cover - numba
    """The row of `r` at position `k` in (z, x, y, row) order; reorders `r` in place."""
    lo, hi = 0, r.size - 1
    while lo < hi:
        # median of three as the pivot, then a three-way split around it
        mid = (lo + hi) // 2
        a, b, c = r[lo], r[mid], r[hi]
        if _before(p, b, a):
            a, b = b, a
        if _before(p, c, b):
            b = c
            if _before(p, b, a):
                b = a
        piv = b
        i, lt, gt = lo, lo, hi
        while i <= gt:
            v = r[i]
            if _before(p, v, piv):
                r[i], r[lt] = r[lt], v
                lt += 1
                i += 1
            elif _before(p, piv, v):
                r[i], r[gt] = r[gt], v
                gt -= 1
            else:
                i += 1
        if k < lt:
            hi = lt - 1
        elif k > gt:
            lo = gt + 1
        else:
            return piv
    return r[lo]


@njit(cache=True, nogil=True)
def _group_sort(inv, p, n_groups, min_size):  # pragma: no cover - numba
    """Rows of `p` by group of `inv`, in (z, x, y, row) order within a group: ``(start, rows)``.

    Groups of fewer than `min_size` rows stay in input order (not sorted). The order of
    ``np.lexsort((y, x, z, inv))`` without sorting every point: a counting sort by group,
    then each group sorted on its own (insertion sort for the few points of a thinning
    cell, merge sort beyond 32). Group g is ``rows[start[g]:start[g + 1]]``.
    """
    n = inv.size
    start = np.zeros(n_groups + 1, dtype=np.int64)
    for i in range(n):
        start[inv[i] + 1] += 1
    big = 0
    for g in range(n_groups):
        big = max(big, start[g + 1])
        start[g + 1] += start[g]
    fill = start[:-1].copy()
    rows = np.empty(n, dtype=np.int64)
    for i in range(n):
        rows[fill[inv[i]]] = i
        fill[inv[i]] += 1
    tmp = np.empty(big, dtype=np.int64)
    for g in range(n_groups):
        s, m = start[g], start[g + 1] - start[g]
        if m < min_size:
            continue
        r = rows[s : s + m]
        if m <= 32:
            for a in range(1, m):
                v = r[a]
                b = a - 1
                while b >= 0 and _before(p, v, r[b]):
                    r[b + 1] = r[b]
                    b -= 1
                r[b + 1] = v
        else:
            w = 1
            while w < m:  # bottom-up merge sort
                for lo in range(0, m, 2 * w):
                    mid = min(lo + w, m)
                    hi = min(lo + 2 * w, m)
                    i, j, k = lo, mid, lo
                    while i < mid and j < hi:
                        if _before(p, r[j], r[i]):
                            tmp[k] = r[j]
                            j += 1
                        else:
                            tmp[k] = r[i]
                            i += 1
                        k += 1
                    while i < mid:
                        tmp[k] = r[i]
                        i += 1
                        k += 1
                    while j < hi:
                        tmp[k] = r[j]
                        j += 1
                        k += 1
                r[:m] = tmp[:m]
                w *= 2
    return start, rows


#: Height (m) of the slab above a return in which `surface_support` counts the returns that make
#: it the start of a surface, and the least share of its cell's returns that slab must hold.
SURFACE_SLAB = 0.05
SURFACE_SHARE = 0.25


def surface_lowest(p: np.ndarray, inv: np.ndarray, lowest: np.ndarray, support: int) -> np.ndarray:
    """Per cell of `inv`, its lowest point that starts a surface (row of `p`).

    A point starts a surface when at least `support` other points of its cell, and a
    quarter of the cell's points in all (:data:`SURFACE_SHARE`), lie in the
    :data:`SURFACE_SLAB` (5 cm) above it. A cell without one gives its lowest point,
    `lowest` (:func:`thin_lowest`'s winners). Points in (z, x, y, row) order, so the
    result does not depend on the input order.
    """
    lowest = np.ascontiguousarray(lowest, dtype=np.int64)
    # only a cell of more than `support` points can hold a surface: the others are not sorted
    start, rows = _group_sort(
        np.ascontiguousarray(inv, dtype=np.int64), np.ascontiguousarray(p, dtype=np.float64),
        lowest.size, int(support) + 1,
    )
    z = np.ascontiguousarray(p[:, 2], dtype=np.float64)
    return _surface_lowest_kernel(start, rows, z, lowest, int(support), SURFACE_SLAB, SURFACE_SHARE)


@njit(cache=True, nogil=True)
def _surface_lowest_kernel(start, rows, z, lowest, support, slab, share):  # pragma: no cover
    out = lowest.copy()
    for g in range(lowest.size):
        s, e = start[g], start[g + 1]
        need = max(support + 1, int(math.ceil(share * (e - s))))
        j = s
        for i in range(s, e - need + 1):
            top = z[rows[i]] + slab
            if j < i:
                j = i
            while j < e and z[rows[j]] <= top:
                j += 1
            if j - i >= need:  # itself and the points up to `slab` above it
                out[g] = rows[i]
                break
    return out


def _thin(xyz: np.ndarray, idx: np.ndarray, cell: float) -> np.ndarray:
    """Lowest point per `cell` × `cell` XY cell (ties by coordinates), sorted indices."""
    if cell <= 0 or idx.size == 0:
        return idx
    return np.sort(idx[thin_lowest(xyz[idx], cell)[0]])


_BORDER_K = 10


def _height_above_tin(tin: TIN, p: np.ndarray) -> np.ndarray:
    """Vertical height (m) of points above their facet; nan outside or on a virtual facet."""
    tri = tin.locate(p[:, :2])
    out = np.full(p.shape[0], np.nan)
    ok = tri >= 0
    ok[ok] = (tin.vsrc[tin.simplices[tri[ok]]] >= 0).all(axis=1)
    if ok.any():
        t0 = tin.vxyz[tin.simplices[tri[ok], 0]]
        nrm = tin.normal[tri[ok]]
        nz = np.maximum(nrm[:, 2], 1e-9)
        out[ok] = ((p[ok] - t0) * nrm).sum(axis=1) / nz
    return out


def _height_above_ground(
    xyz: np.ndarray, ground: np.ndarray, idx: np.ndarray, thin_cell: float, virtual: Any
) -> np.ndarray:
    """Height of points `idx` above the TIN of `ground` (thinned like the densification TIN)."""
    tin = build_tin(xyz, _thin(xyz, np.flatnonzero(ground), thin_cell), virtual)
    return _height_above_tin(tin, xyz[idx])


def _border_counts(
    xyz: np.ndarray,
    lab: np.ndarray,
    src_mask: np.ndarray,
    ground: np.ndarray,
    n_seg: int,
    par: SegmentPTD,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per segment: border points, raised ones and connected ones, against `ground`.

    A border point of segment S is a point of S (in `src_mask`) that has a ground
    point of another segment (or unsegmented) among its `_BORDER_K` nearest
    neighbours of ``ground | src_mask`` within ``par.raised_radius`` m in XY; the
    nearest such point is its partner. With dz the height above that point and dxy
    the XY distance: raised when dz > raised_step and dz > dxy·tan(raised_angle);
    connected when |dz| <= connect_distance + dxy·tan(connect_angle).
    """
    from scipy.spatial import cKDTree

    zero = np.zeros(n_seg, dtype=np.int64)
    src = np.flatnonzero(src_mask)
    pool = np.flatnonzero(ground | src_mask)
    if src.size == 0 or not ground.any():
        return zero, zero.copy(), zero.copy()
    src = src[_may_border(xyz[:, :2], lab, src, np.flatnonzero(ground), float(par.raised_radius))]
    if src.size == 0:
        return zero, zero.copy(), zero.copy()
    tree = cKDTree(xyz[pool, :2])
    k = min(_BORDER_K, pool.size)
    d, j = tree.query(
        xyz[src, :2], k=k, distance_upper_bound=float(par.raised_radius), workers=tree_workers()
    )
    d = d.reshape(src.size, k)
    j = j.reshape(src.size, k)
    ok = np.isfinite(d)
    nb = pool[np.where(ok, j, 0)]
    other = ok & ground[nb] & ((lab[nb] != lab[src][:, None]) | (lab[nb] < 0))
    first = np.argmax(other, axis=1)
    has = other[np.arange(src.size), first]
    src = src[has]
    d = d[np.flatnonzero(has), first[has]]
    q = nb[np.flatnonzero(has), first[has]]
    if src.size == 0:
        return zero, zero.copy(), zero.copy()
    dz = xyz[src, 2] - xyz[q, 2]
    ls = lab[src]
    up = (dz > par.raised_step) & (dz > d * math.tan(math.radians(par.raised_angle)))
    ok = np.abs(dz) <= par.connect_distance + d * math.tan(math.radians(par.connect_angle))
    return (
        np.bincount(ls, minlength=n_seg),
        np.bincount(ls[up], minlength=n_seg),
        np.bincount(ls[ok], minlength=n_seg),
    )


def _may_border(
    xy: np.ndarray, lab: np.ndarray, src: np.ndarray, ground: np.ndarray, r: float
) -> np.ndarray:
    """Mask of the `src` points that may have a `ground` point of another label within `r`.

    Such a neighbour lies in the point's `r` m cell or next to it, so a point is kept when a
    label other than its own (unsegmented: -1) occurs among the ground points of those nine
    cells: every border point is kept, and the interior of a large segment is not searched.
    """
    from scipy.ndimage import maximum_filter, minimum_filter

    pts = np.concatenate([src, ground])
    lo = xy[pts].min(axis=0)
    c = np.floor((xy[pts] - lo) / r).astype(np.int64)
    shape = tuple(int(v) for v in c.max(axis=0) + 1)
    if shape[0] * shape[1] > 4 * pts.size:  # a sparse cloud over a wide area: search all
        return np.ones(src.size, dtype=bool)
    g = c[src.size :]
    big = np.iinfo(np.int64).max
    low = np.full(shape, big, dtype=np.int64)
    high = np.full(shape, -big, dtype=np.int64)
    np.minimum.at(low, (g[:, 0], g[:, 1]), lab[ground])
    np.maximum.at(high, (g[:, 0], g[:, 1]), lab[ground])
    low = minimum_filter(low, size=3, mode="constant", cval=big)
    high = maximum_filter(high, size=3, mode="constant", cval=-big)
    s = c[: src.size]
    own = lab[src]
    return (low[s[:, 0], s[:, 1]] < own) | (high[s[:, 0], s[:, 1]] > own)


def _border_tests(
    xyz: np.ndarray,
    lab: np.ndarray,
    src_mask: np.ndarray,
    ground: np.ndarray,
    n_seg: int,
    par: SegmentPTD,
) -> tuple[np.ndarray, np.ndarray]:
    """Per segment: (connected, raised) flags from its border points (`_border_counts`).

    Raised when at least `raised_ratio` of the border points are raised (and
    raised_step > 0); connected when at least `connect_ratio` are connected.
    Segments with fewer than 3 border points are neither.
    """
    n_b, n_up, n_ok = _border_counts(xyz, lab, src_mask, ground, n_seg, par)
    raised = (n_b >= 3) & (n_up >= par.raised_ratio * n_b - 1e-9) & (par.raised_step > 0)
    conn = (n_b >= 3) & (n_ok >= par.connect_ratio * n_b - 1e-9)
    return conn, raised


#: final roof check (`roof_ratio`): border points a segment needs for the raised test
#: to be re-run on it; the slope range (degrees) of gable roof planes; the least
#: angle (degrees) between the aspects of a pair; the least drop (m) of each
#: centroid under the other's plane (a convex ridge)
_ROOF_MIN_BORDER = 10
_ROOF_SLOPE = (10.0, 60.0)
_ROOF_ASPECT = 135.0
_ROOF_RIDGE_DROP = 0.3


def _roof_check(
    xyz: np.ndarray,
    lab: np.ndarray,
    seg_pt: np.ndarray,
    ground: np.ndarray,
    is_ground_seg: np.ndarray,
    n_seg: int,
    par: SegmentPTD,
) -> np.ndarray:
    """Accepted segments that the final roof check rejects (see `roof_ratio`)."""
    from scipy.spatial import cKDTree

    lab_c = np.maximum(lab, 0)
    # (1) the raised test again, against the final ground
    n_b, n_up, _ = _border_counts(xyz, lab, seg_pt & is_ground_seg[lab_c], ground, n_seg, par)
    out = is_ground_seg & (n_b >= _ROOF_MIN_BORDER) & (n_up >= par.raised_ratio * n_b - 1e-9)
    # (2) gable pairs: planes of all non-object segments (a facet may be unaccepted)
    idx = np.flatnonzero(seg_pt)
    cen, nrm, size = _segment_planes(xyz[idx], lab[idx], n_seg)
    slope = np.degrees(np.arccos(np.clip(nrm[:, 2], 0.0, 1.0)))
    sloped = (size >= 10) & (slope >= _ROOF_SLOPE[0]) & (slope <= _ROOF_SLOPE[1])
    pi = idx[sloped[lab[idx]]]
    if pi.size < 2:
        return out
    # adjacent: a point of one among the nearest neighbours of the other (XY)
    k = min(_BORDER_K, pi.size)
    d, j = cKDTree(xyz[pi, :2]).query(
        xyz[pi, :2], k=k, distance_upper_bound=float(par.raised_radius), workers=tree_workers()
    )
    ok = np.isfinite(d.reshape(pi.size, k))
    a = np.broadcast_to(lab[pi][:, None], ok.shape)[ok]
    b = lab[pi[np.where(ok, j.reshape(pi.size, k), 0)]][ok]
    pairs = np.unique(np.sort(np.column_stack([a, b])[a != b], axis=1), axis=0)
    if pairs.size == 0:
        return out
    s, t = pairs[:, 0], pairs[:, 1]
    hs = nrm[s, :2] / np.linalg.norm(nrm[s, :2], axis=1, keepdims=True)
    ht = nrm[t, :2] / np.linalg.norm(nrm[t, :2], axis=1, keepdims=True)
    opposite = (hs * ht).sum(axis=1) <= math.cos(math.radians(_ROOF_ASPECT))
    below_t = ((cen[s] - cen[t]) * nrm[t]).sum(axis=1) < -_ROOF_RIDGE_DROP
    below_s = ((cen[t] - cen[s]) * nrm[s]).sum(axis=1) < -_ROOF_RIDGE_DROP
    pairs = pairs[opposite & below_t & below_s]
    if pairs.size == 0:
        return out
    in_pair = np.zeros(n_seg, dtype=bool)
    in_pair[pairs.ravel()] = True
    n_b, n_up, _ = _border_counts(xyz, lab, seg_pt & in_pair[lab_c], ground, n_seg, par)
    nb, nu = n_b[pairs].sum(axis=1), n_up[pairs].sum(axis=1)
    roof = pairs[(nb >= 3) & (nu >= par.roof_ratio * nb - 1e-9)]
    out[roof.ravel()] = True
    return out & is_ground_seg


def _segment_ptd(
    points: np.ndarray,
    lab: np.ndarray,
    cand: np.ndarray,
    object_segments: Any,
    par: SegmentPTD,
    radius: float,
    feature_idx: Any = None,
    progress: ProgressCallback | None = None,
    given_seeds: np.ndarray | None = None,
) -> SegmentPTDResult:
    n = points.shape[0]
    n_seg = int(lab.max()) + 1 if n and lab.max() >= 0 else 0
    empty = np.zeros(n_seg, dtype=bool)
    if n == 0 or not cand.any():
        return SegmentPTDResult(np.zeros(n, dtype=bool), lab, empty, empty.copy(), 0, (), 0, radius)
    xyz, cand2, _ = prepare(points, cand, 0.0, 1.0)
    if object_segments is None:
        if feature_idx is None:
            feats = segment_features(xyz, lab, k_feat=int(par.k_feat))
        else:  # dense cloud: features of the segmentation sample (same labels, ~8 pts/m²)
            feats = segment_features(xyz[feature_idx], lab[feature_idx], k_feat=int(par.k_feat))
        obj = detect_object_segments(
            feats,
            orientation_thr=par.orientation_thr,
            scatter_thr=par.scatter_thr,
            min_facade_points=int(par.min_facade_points),
        )
        # façades by orientation alone (not vegetation) may hold steep terrain
        facade = obj & ~vegetation_segments(feats, scatter_thr=par.scatter_thr)
    else:
        obj = np.asarray(object_segments, dtype=bool)
        if obj.shape != (n_seg,):
            raise InvalidPointsError(f"object_segments must have shape ({n_seg},), got {obj.shape}")
        facade = np.zeros(n_seg, dtype=bool)  # object flags given: all are final
    crit = par.criteria()
    n_user = n_seg
    if n_seg == 0:  # no segment at all: one dummy label keeps the indexing simple
        n_seg = 1
        obj = np.zeros(1, dtype=bool)
        facade = np.zeros(1, dtype=bool)
    lab_c = np.maximum(lab, 0)
    obj_pt = (lab >= 0) & obj[lab_c]
    usable = cand & ~obj_pt  # candidates outside object segments
    seg_pt = usable & (lab >= 0)
    unseg_pt = usable & (lab < 0)
    ground = np.zeros(n, dtype=bool)
    is_ground_seg = np.zeros(n_seg, dtype=bool)
    if not seg_pt.any() and (par.unsegmented == "drop" or not unseg_pt.any()):
        warnings.warn(
            "segment-PTD: no non-object segment; nothing is ground",
            DegenerateGeometryWarning,
            stacklevel=3,
        )
        return SegmentPTDResult(ground, lab, obj[:n_user], is_ground_seg[:n_user], 0, (), 0, radius)
    # 1-2. seed points (robust lowest per cell) -> seed segments, all their points ground
    pool = np.flatnonzero(usable if par.unsegmented == "point_ptd" else seg_pt)
    seeds = None
    if given_seeds is not None:
        # ground of an earlier run (the terrain pass): no seed cells, no screening
        in_pool = np.zeros(n, dtype=bool)
        in_pool[pool] = True
        seeds = given_seeds[in_pool[given_seeds]]  # sorted, distinct (flatnonzero)
        if seeds.size >= 3:
            virtual = virtual_hull(xyz, seeds, par.cell_size, colmin(xyz[pool]), colmax(xyz[pool]))
        else:
            seeds = None
    if seeds is None:
        seeds, virtual = initial_seeds(xyz, pool, par, crit)
    if par.seed_segments:
        seed_labels = np.unique(lab[seeds])
        is_ground_seg[seed_labels[seed_labels >= 0]] = True
    ground[seeds] = True
    ground |= seg_pt & is_ground_seg[lab_c]
    n_seed_points = int(ground.sum())
    thin_cell = par.min_edge_length / math.sqrt(2.0) if par.min_edge_length > 0 else 0.0

    def densify_from(base: np.ndarray, open_: np.ndarray, progress: Any = None) -> DensifyState:
        """Densify the TIN of the (thinned) `base` ground with the `open_` candidates."""
        in_tin = np.zeros(n, dtype=bool)
        in_tin[_thin(xyz, np.flatnonzero(base), thin_cell)] = True
        st = DensifyState(ground=base.copy(), in_tin=in_tin, open_=open_, added=[])
        tin = densify(
            xyz,
            st,
            virtual,
            crit,
            max_iter=int(par.max_iter),
            min_gain_frac=float(par.min_gain_frac),
            progress=progress,
            final_tin=par.final_distance > 0,
        )
        if par.final_distance > 0 and tin is not None:
            final_pass(xyz, st, tin, par.final_distance)
        return st
    seg_size = np.bincount(lab[seg_pt], minlength=n_seg)
    vetoed = np.zeros(n_seg, dtype=bool)  # raised segments, rejected for good
    accepted: list[int] = []
    unseg_ground = np.zeros(n, dtype=bool)
    mixed_ground = np.zeros(n, dtype=bool)
    # 3-4. densify the TIN point-wise, then decide per segment by vote; repeat until stable
    report(progress, 0.1)
    for it in range(int(par.max_iter)):
        # iteration `it` reports into half of what remains of [0.1, 0.9] (unknown count)
        span = stage(progress, 0.9 - 0.8 * 0.5**it, 0.9 - 0.8 * 0.5 ** (it + 1))
        open_ = seg_pt & ~is_ground_seg[lab_c] & ~vetoed[lab_c]
        if par.unsegmented == "point_ptd":
            open_ |= unseg_pt & ~ground
        st = densify_from(ground, open_, span)
        passed = st.ground & ~ground
        unseg_ground = passed & unseg_pt
        n_pass = np.bincount(lab[seg_pt & passed], minlength=n_seg)
        ratio = n_pass / np.maximum(seg_size, 1)
        mixed = ~is_ground_seg & ~obj & (ratio >= par.reject_ratio - 1e-9)
        mixed_ground = seg_pt & passed & mixed[lab_c]
        acc = (
            ~is_ground_seg
            & ~obj
            & ~vetoed
            & (seg_size >= par.min_tested)
            & (n_pass >= par.accept_ratio * seg_size - 1e-9)
            & (n_pass > 0)
        )
        if not acc.any():
            break
        accepted.append(int(acc.sum()))
        is_ground_seg |= acc
        ground |= seg_pt & is_ground_seg[lab_c]
    report(progress, 0.9)
    # 5. leftovers: unsegmented points judged point-wise (or dropped)
    n_pp = int(unseg_ground.sum())
    ground |= unseg_ground | (mixed_ground & ~is_ground_seg[lab_c])
    # 6. raised-segment test against the final ground: roofs / bridges out
    if par.raised_step > 0:
        for _ in range(3):
            src = seg_pt & is_ground_seg[lab_c]
            _, raised = _border_tests(xyz, lab, src, ground, n_seg, par)
            raised &= is_ground_seg
            if not raised.any():
                break
            vetoed |= raised
            is_ground_seg &= ~raised
            ground &= ~((lab >= 0) & raised[lab_c])
        # 6b. the unsegmented points were judged in the last sweep against a TIN that held
        # the segments just rejected (a roof lets its unsegmented eaves and wall tops pass):
        # judge them again, point-wise, against the TIN of the ground that remains
        if par.unsegmented == "point_ptd" and vetoed.any():
            base = ground & ~unseg_ground
            st = densify_from(base, unseg_pt & ~base)
            unseg_ground = st.ground & ~base & unseg_pt
            n_pp = int(unseg_ground.sum())
            ground = base | unseg_ground
    # 7. connection pass: large rejected segments joining the ground smoothly
    if par.connect_min_size > 0:
        big = ~obj & ~vetoed & (seg_size >= par.connect_min_size)
        for _ in range(10):
            open_seg = big & ~is_ground_seg
            if not open_seg.any():
                break
            conn, raised = _border_tests(xyz, lab, seg_pt & open_seg[lab_c], ground, n_seg, par)
            acc = open_seg & conn & ~raised
            if not acc.any():
                break
            accepted.append(int(acc.sum()))
            is_ground_seg |= acc
            ground |= seg_pt & acc[lab_c]
    # 8. below pass: candidates under the final ground surface
    if par.below_pass and ground.any():
        open_ = usable & ~ground
        if par.unsegmented == "drop":
            open_ &= lab >= 0
        oi = np.flatnonzero(open_)
        if oi.size:
            h = _height_above_ground(xyz, ground, oi, thin_cell, virtual)
            ground[oi[h < -par.below_distance]] = True
    # 8b. façade points on trial: within facade_distance of the final ground surface, and
    # below it in a segment the surface passes through (the below pass, on a steep bank)
    if par.facade_distance > 0 and facade.any() and ground.any():
        fi = np.flatnonzero(cand & (lab >= 0) & facade[lab_c] & ~ground)
        if fi.size:
            h = _height_above_ground(xyz, ground, fi, thin_cell, virtual)
            near = np.abs(h) <= par.facade_distance
            crossed = np.zeros(n_seg, dtype=bool)
            crossed[lab[fi[near]]] = True
            ground[fi[near | ((h < -par.below_distance) & crossed[lab[fi]])]] = True
    # 8c. final roof check against the final ground: raised segments, gable pairs
    if par.roof_ratio > 0 and par.raised_step > 0 and is_ground_seg.any():
        roof = _roof_check(xyz, lab, seg_pt, ground, is_ground_seg, n_seg, par)
        if roof.any():
            is_ground_seg &= ~roof
            ground &= ~((lab >= 0) & roof[lab_c])
    # 9. perched-surface test: accepted ground that drops steeply on opposite sides
    if par.perched_step > 0 and ground.any():
        perched = perched_mask(
            points,
            ground,
            cand,
            step=float(par.perched_step),
            angle=float(par.perched_angle),
            radius=float(par.perched_radius),
        )
        ground &= ~perched
        # 9b. an accepted segment the test cut into: the raised test (where it is on) on
        # what is left of it, against the ground that remains (a plane is one surface)
        cut = np.zeros(n_seg, dtype=bool)
        cut[lab[perched & (lab >= 0)]] = True
        cut &= is_ground_seg
        if par.raised_step > 0 and cut.any():
            par_up = replace(par, raised_step=par.perched_step, raised_angle=par.perched_angle)
            n_b, n_up, _ = _border_counts(
                xyz, lab, seg_pt & ground & cut[lab_c], ground, n_seg, par_up
            )
            roof = cut & (n_b >= _ROOF_MIN_BORDER) & (n_up >= par.raised_ratio * n_b - 1e-9)
            is_ground_seg &= ~roof
            ground &= ~((lab >= 0) & roof[lab_c])
    # 10. gap test: a raised surface whose sides drop, across an unsampled corridor, on
    # opposite sides stands on piers (a bridge deck); only its two edges are rejected
    if par.gap_step > 0 and ground.any():
        ground &= ~gap_mask(points, ground, cand, step=float(par.gap_step))
    return SegmentPTDResult(
        ground,
        lab,
        obj[:n_user],
        is_ground_seg[:n_user],
        n_seed_points,
        tuple(accepted),
        n_pp,
        radius,
    )
