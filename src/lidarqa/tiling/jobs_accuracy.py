"""Check-point (vertical) and height-quality jobs on a catalog, equal to one in-memory run.

Both jobs compare the cloud with a *small* set of reference points (surveyed
check points, reference heights). Each reference point is owned by exactly one
chunk: the chunk whose half-open core contains it (the same rule as for vector
features, :mod:`lidarqa.tiling.jobs_vector`). That chunk computes the
per-point values from its buffered points, where the whole neighbourhood the
kernel looks at is present when the buffer is wide enough:

* ``checkpoints --vertical``: the ground TIN around a check point uses ground
  points within ``2 x max_edge`` (so the buffer must be at least that wide);
* ``heights``: a map point's plane uses laser points within the radius it
  grew to (at most ``max_radius``), and a reference point is interpolated in
  the TIN of the map points around it. A chunk uses only map points whose
  search disc lies inside its buffered box, and refuses (an error naming the
  chunk) a reference point whose triangle's circumcircle holds a map point it
  could not fit: then its triangle may differ from the whole run's, and a
  larger buffer is needed. :func:`lidarqa.tiling.jobs_api.catalog_heights`
  chooses a buffer from the map point spacing by default.

The per-point values (a few numbers per reference point) are the sufficient
statistics here: the merge puts them back in the reference order and computes
every figure (RMSE, mean, std, NSSDA/ASPRS, w-tests and data snooping, even
with an estimated common offset) with the same functions as the in-memory
run, so the figures are those of one run over the whole area whatever the
chunking and the completion order.

A default that depends on all check points (the vertical check's ``max_edge``
from the median ground spacing) is found in a first light pass over the
chunks that hold check points (:class:`CheckSpacingTask`); only those chunks
are read at all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DegenerateGeometryError, InvalidPointsError, OptionError
from ..io.vector import PointSet
from .jobs_vector import in_core, open_box, owned

if TYPE_CHECKING:
    from ..accuracy.checkpoints import VerticalCheckReport
    from ..accuracy.heights import HeightReport
    from .chunks import Chunk
    from .reader import ChunkData

#: A chunk (kept as given).
C = TypeVar("C", bound="Chunk")

__all__ = [
    "CheckSpacingTask",
    "HeightsPart",
    "HeightsTask",
    "VerticalPart",
    "VerticalCheckTask",
    "chunks_with_points",
    "max_edge_from_spacing",
    "merge_heights",
    "merge_vertical",
]


def chunks_with_points(chunks: Sequence[C], xy: np.ndarray) -> tuple[C, ...]:
    """The chunks whose core holds at least one of the points `xy` (the only ones to read)."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, np.shape(xy)[-1] if len(xy) else 2)
    return tuple(c for c in chunks if len(p) and owned(p, c).any())


def _metric_xy(xyz: np.ndarray, factor: float) -> np.ndarray:
    """`xyz` with x, y in metres (the chunk grid stays in the CRS's units)."""
    if factor == 1.0:
        return xyz
    out = xyz.copy()
    out[:, :2] *= factor
    return out


def _ground_xy(chunk_data: ChunkData, classes: tuple[int, ...] | None) -> np.ndarray:
    cloud = chunk_data.cloud
    if classes is None:
        return cloud.xyz
    cls = cloud.classification
    if cls is None:
        raise InvalidPointsError("the cloud has no classification field to select ground by")
    return cloud.xyz[np.isin(cls, classes)]


# ============================================================ vertical check


@dataclass(frozen=True, eq=False)
class CheckSpacingTask:
    """First pass of a vertical check without ``max_edge``: local ground spacing at check points.

    Returns ``(index, spacing)`` for the check points in the chunk's core: the
    nominal ground spacing ``r16 * sqrt(pi / 16)`` from the distance to the
    16th nearest distinct ground point (as :func:`vertical_check` does).
    """

    check_xy: np.ndarray
    classes: tuple[int, ...] | None = (2,)

    def __call__(self, chunk_data: ChunkData) -> tuple[np.ndarray, np.ndarray]:
        """``(index, spacing)`` of the check points this chunk owns."""
        from scipy.spatial import cKDTree

        idx = np.flatnonzero(owned(self.check_xy, chunk_data.chunk))
        g = _ground_xy(chunk_data, self.classes)
        if not len(idx) or len(g) == 0:
            return idx, np.full(len(idx), np.nan)
        uxy = np.unique(g[:, :2], axis=0)
        kk = min(16, len(uxy))
        d, _ = cKDTree(uxy).query(self.check_xy[idx, :2], k=kk)
        rk = np.asarray(d).reshape(len(idx), kk)[:, -1]
        return idx, rk * math.sqrt(math.pi / kk)


def max_edge_from_spacing(parts: Sequence[tuple[np.ndarray, np.ndarray] | None]) -> float:
    """Default ``max_edge`` (6 x the median ground spacing) from :class:`CheckSpacingTask` parts."""
    vals = [s for p in parts if p is not None for s in p[1].tolist() if math.isfinite(s)]
    if not vals:
        raise DegenerateGeometryError("no ground points around the check points")
    max_edge = 6.0 * float(np.median(np.asarray(vals)))
    if not max_edge > 0:
        raise DegenerateGeometryError("ground points around the check points have zero spacing")
    return max_edge


@dataclass(frozen=True, eq=False)
class VerticalPart:
    """What one chunk returns for its core check points (index into the check set)."""

    chunk: str
    index: np.ndarray
    tin_z: np.ndarray
    dz: np.ndarray
    flag: np.ndarray
    longest_edge: np.ndarray
    n_ground: int


@dataclass(frozen=True, eq=False)
class VerticalCheckTask:
    """Chunk task of ``checkpoints --vertical`` on a catalog (see the module docstring).

    Parameters
    ----------
    check : PointSet
        All check points (m).
    max_edge, search_radius : float
        Fixed for the whole catalog (m); see :func:`lidarqa.accuracy.checkpoints.vertical_check`.
    classes : tuple of int or None
        Ground classes; None takes every point as ground.
    xy_factor : float
        Horizontal unit to metres.
    bounds : (xmin, ymin, xmax, ymax), optional
        The source's extent: a buffer side beyond it needs no margin (no points
        there), so one region holding the whole area is the in-memory check.
    """

    check: PointSet
    max_edge: float
    search_radius: float | None = None
    classes: tuple[int, ...] | None = (2,)
    xy_factor: float = 1.0
    bounds: tuple[float, float, float, float] | None = None

    def __call__(self, chunk_data: ChunkData) -> VerticalPart:
        """The vertical check of the check points this chunk owns."""
        from ..accuracy.checkpoints import vertical_check
        from ..errors import TilingError

        core = chunk_data.chunk
        b = open_box(core.buffered, self.bounds)
        margin = min(core.core[0] - b[0], core.core[1] - b[1], b[2] - core.core[2],
                     b[3] - core.core[3]) * self.xy_factor
        if margin < 2.0 * self.max_edge:
            raise TilingError(f"chunk {core.id}: the buffer ({margin:g} m) must be at least "
                              f"2 x max_edge = {2 * self.max_edge:g} m for the vertical check")
        idx = np.flatnonzero(owned(self.check.xyz, core))
        cloud = chunk_data.cloud
        g = _ground_xy(chunk_data, self.classes)
        gcore = g[owned(g, core)]
        n_ground = len(np.unique(gcore[:, :2], axis=0)) if len(gcore) else 0
        m = len(idx)
        tin_z, longest = np.full(m, np.nan), np.full(m, np.nan)
        flag = np.full(m, "outside_tin", dtype="<U16")
        if m:
            sub = self.check.subset(idx)
            sub = PointSet(np.arange(m), _metric_xy(sub.xyz, self.xy_factor))  # own numbering
            try:
                r = vertical_check(
                    _metric_xy(cloud.xyz, self.xy_factor), sub,
                    classification=None if self.classes is None else cloud.classification,
                    classes=self.classes if self.classes is not None else (2,),
                    max_edge=self.max_edge, search_radius=self.search_radius,
                )
                order = np.asarray(r.ids, dtype=np.int64)
                tin_z[order], longest[order], flag[order] = r.tin_z, r.longest_edge, r.flag
            except DegenerateGeometryError:
                pass  # < 3 ground points in the chunk: every check point stays outside_tin
        dz = tin_z - self.check.xyz[idx, 2]
        return VerticalPart(chunk=chunk_data.chunk.id, index=idx, tin_z=tin_z, dz=dz, flag=flag,
                            longest_edge=longest, n_ground=n_ground)


def merge_vertical(
    parts: Sequence[VerticalPart | None],
    check: PointSet,
    *,
    max_edge: float,
    search_radius: float | None = None,
    checkpoint_rmse_v: float = 0.0,
) -> VerticalCheckReport:
    """One :class:`~lidarqa.accuracy.checkpoints.VerticalCheckReport` from the chunk parts.

    A check point that no chunk owned (outside the catalog, or in a failed
    chunk) is flagged ``"outside_tin"``. Figures are computed from the
    check points in id order, as in :func:`vertical_check`.
    """
    from ..accuracy.checkpoints import summarise_vertical

    m = len(check)
    tin_z, dz, longest = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)
    flag = np.full(m, "outside_tin", dtype="<U16")
    seen = np.zeros(m, dtype=bool)
    n_ground = 0
    for p in parts:
        if p is None:
            continue
        if seen[p.index].any():
            raise InvalidPointsError(f"chunk {p.chunk}: a check point owned by two chunks")
        seen[p.index] = True
        tin_z[p.index], dz[p.index] = p.tin_z, p.dz
        longest[p.index], flag[p.index] = p.longest_edge, p.flag
        n_ground += p.n_ground
    dz[~seen] = np.nan
    return summarise_vertical(
        check, tin_z, dz, flag, longest, n_ground=n_ground, max_edge=float(max_edge),
        search_radius=float(max_edge / 2 if search_radius is None else search_radius),
        checkpoint_rmse_v=checkpoint_rmse_v)


# ============================================================ heights


_NO_CATALOG = ("covariance", "labels")


@dataclass(frozen=True, eq=False)
class HeightsPart:
    """One chunk's core map point rows and core reference points' TIN values."""

    chunk: str
    map_index: np.ndarray
    map_rows: dict[str, np.ndarray]
    ref_index: np.ndarray
    height: np.ndarray
    sigma: np.ndarray
    inside: np.ndarray
    vertices: np.ndarray
    weights: np.ndarray
    has_tin: bool


_MAP_FIELDS = ("height", "sigma", "sigma_plane", "sigma_block", "sigma_model", "n_points",
               "radius", "distance", "failed", "reason")


@dataclass(frozen=True, eq=False)
class HeightsTask:
    """Chunk task of ``heights`` on a catalog (see the module docstring).

    Parameters
    ----------
    map_xy : ndarray of shape (M, 2)
        All map points (m).
    reference_xyz : ndarray of shape (R, 3)
        All reference points (m).
    options : dict
        Keyword options of :func:`lidarqa.accuracy.heights.assess_heights`
        (not ``covariance`` or ``labels``, which need the whole set;
        ``largest_segment`` only on one region, see
        :func:`~lidarqa.tiling.jobs_api.catalog_heights`).
    classes : tuple of int, optional
        Laser points used (e.g. ground 2 and buildings 6); None = all.
    bounds : (xmin, ymin, xmax, ymax), optional
        The catalog's extent: beyond it there are no laser points, so a fit
        reaching past a buffered box's side that is outside the catalog is
        still the whole run's.
    """

    map_xy: np.ndarray
    reference_xyz: np.ndarray
    options: dict[str, object] = field(default_factory=dict)
    classes: tuple[int, ...] | None = None
    bounds: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        bad = [k for k in _NO_CATALOG if self.options.get(k)]
        if bad:
            raise OptionError(f"heights on a catalog does not support {', '.join(bad)}")

    def __call__(self, chunk_data: ChunkData) -> HeightsPart:
        """Map-point heights and TIN values at the reference points this chunk owns."""
        from ..accuracy.heights import MAX_RADIUS, interpolate_tin, map_point_heights
        from ..errors import TilingError

        chunk = chunk_data.chunk
        pts = _ground_xy(chunk_data, self.classes)
        # no laser point beyond the catalog: a side there is open, and a point beyond the area
        # is owned by the chunk that owns its nearest point of the area
        lo_x, lo_y, hi_x, hi_y = open_box(chunk.buffered, self.bounds)
        mi = np.flatnonzero(in_core(self.map_xy, (lo_x, lo_y, hi_x, hi_y)))
        ri = np.flatnonzero(owned(self.clamp(self.reference_xyz), chunk))
        opts: dict[str, Any] = dict(self.options)
        tin_opts: dict[str, Any] = {"correlation": opts.pop("correlation", 0.0)}
        for k in ("sigma_ref", "alpha", "estimate_offset"):
            opts.pop(k, None)
        mp = map_point_heights(pts, self.map_xy[mi], **opts)
        # A map point is trusted when the disc its fit looked at lies inside the buffered box:
        # the radius grows deterministically, so the whole-area run saw the same laser points.
        r_used = np.where(np.isfinite(mp.radius), mp.radius,
                          float(opts.get("max_radius", MAX_RADIUS)))
        xy = self.map_xy[mi]
        trusted = ((xy[:, 0] - r_used >= lo_x) & (xy[:, 0] + r_used <= hi_x)
                   & (xy[:, 1] - r_used >= lo_y) & (xy[:, 1] + r_used <= hi_y))
        mine = owned(self.clamp(xy), chunk)
        if (mine & ~trusted).any():
            need = float(np.nanmax(r_used[mine & ~trusted]))
            raise TilingError(f"chunk {chunk.id}: map point fits reach {need:g} m, beyond the "
                              "buffer; use a larger buffer")
        vert = np.flatnonzero(trusted & ~mp.failed)
        tin = interpolate_tin(np.column_stack([xy[vert], mp.height[vert]]), mp.sigma[vert],
                              self.reference_xyz[ri, :2], **tin_opts)
        if len(mi) < len(self.map_xy) or not trusted.all():  # else: the whole TIN is here
            self._check_delaunay(chunk.id, xy[vert], tin, mi[trusted],
                                 self.reference_xyz[ri, :2])
        vertices = np.full(tin.vertices.shape, -1, dtype=np.int64)  # map point numbering
        found = tin.vertices >= 0
        vertices[found] = mi[vert][tin.vertices[found]]
        rows = {k: np.asarray(getattr(mp, k))[mine] for k in _MAP_FIELDS}
        return HeightsPart(chunk=chunk.id, map_index=mi[mine], map_rows=rows, ref_index=ri,
                           height=tin.height, sigma=tin.sigma, inside=tin.inside,
                           vertices=vertices, weights=tin.weights, has_tin=tin.has_tin)

    def clamp(self, xy: np.ndarray) -> np.ndarray:
        """`xy` moved into the area's bounds (its owner is then a chunk of the grid)."""
        if self.bounds is None or not len(xy):
            return xy
        b = self.bounds
        return np.column_stack([np.clip(xy[:, 0], b[0], b[2]), np.clip(xy[:, 1], b[1], b[3])])

    def _check_delaunay(self, chunk_id: str, vxy: np.ndarray, tin: Any, used: np.ndarray,
                        ref_xy: np.ndarray) -> None:
        """Refuse a reference point whose triangle may not be a triangle of the whole-area TIN.

        The chunk's triangle is the whole run's when no map point other than the chunk's
        trusted ones (fitted or failed alike in both runs) lies strictly inside its
        circumcircle (Delaunay criterion). Map points exactly on the circle (e.g. the four
        corners of a square of a regular grid) leave the diagonal to the triangulator, in the
        chunk as in the whole run: both are valid TINs, and they may differ.
        """
        from scipy.spatial import cKDTree

        from ..errors import TilingError

        trusted = np.zeros(len(self.map_xy), dtype=bool)
        trusted[used] = True
        outside = np.flatnonzero(~tin.inside)
        if len(outside) and (~trusted).any():
            # outside this chunk's TIN: also outside the whole run's unless a map point this
            # chunk could not fit extends the hull
            from scipy.spatial import Delaunay, QhullError

            hull_pts = np.vstack([vxy, self.map_xy[~trusted, :2]])
            try:
                reach = Delaunay(hull_pts).find_simplex(ref_xy[outside]) >= 0
            except QhullError:
                reach = np.zeros(len(outside), dtype=bool)
            if reach.any():
                raise TilingError(
                    f"chunk {chunk_id}: {int(reach.sum())} reference point(s) outside the map "
                    "points this chunk can fit but possibly inside the whole TIN; use a larger "
                    "buffer")
        inside = np.flatnonzero(tin.inside)
        if not len(inside):
            return
        tri = vxy[tin.vertices[inside]]  # (k, 3, 2)
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1])
                   + c[:, 0] * (a[:, 1] - b[:, 1]))
        sa, sb, sc = (a * a).sum(1), (b * b).sum(1), (c * c).sum(1)
        ux = (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d
        uy = (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d
        centre = np.column_stack([ux, uy])
        rad = np.linalg.norm(a - centre, axis=1)
        tree = cKDTree(self.map_xy[:, :2])
        bad = 0
        worst = 0.0
        for k, near in enumerate(tree.query_ball_point(centre, rad * (1 - 1e-9))):
            if near and not trusted[np.asarray(near)].all():
                bad += 1
                worst = max(worst, 2 * rad[k])
        if bad:
            raise TilingError(
                f"chunk {chunk_id}: {bad} reference point(s) in map-point triangles that reach "
                f"beyond the buffer (up to {worst:.0f} m across); use a larger buffer")


def merge_heights(
    parts: Sequence[HeightsPart | None],
    map_xy: ArrayLike,
    reference_xyz: ArrayLike,
    *,
    options: dict[str, object] | None = None,
) -> HeightReport:
    """One :class:`~lidarqa.accuracy.heights.HeightReport` from the chunk parts.

    Map points no chunk owned are reported failed (``"too_few_points"``, no
    laser point reached them); reference points no chunk owned are outside the
    TIN. Δh statistics, w-tests and data snooping run once over all reference
    points in their input order, as in :func:`assess_heights`.
    """
    from ..accuracy.heights import MapPointHeights, TinInterpolation, summarise_heights

    mxy = np.asarray(map_xy, dtype=np.float64)[:, :2]
    ref = np.asarray(reference_xyz, dtype=np.float64).reshape(-1, 3)
    m, r = len(mxy), len(ref)
    nan = np.full(m, np.nan)
    cols: dict[str, np.ndarray] = {
        "height": nan.copy(), "sigma": nan.copy(), "sigma_plane": nan.copy(),
        "sigma_block": nan.copy(), "sigma_model": nan.copy(),
        "n_points": np.zeros(m, dtype=np.int64), "radius": nan.copy(), "distance": nan.copy(),
        "failed": np.ones(m, dtype=bool), "reason": np.full(m, "too_few_points", dtype=object),
    }
    height, sigma = np.full(r, np.nan), np.full(r, np.nan)
    inside = np.zeros(r, dtype=bool)
    has_tin = False
    vertices, weights = np.full((r, 3), -1, dtype=np.int64), np.full((r, 3), np.nan)
    for p in parts:
        if p is None:
            continue
        for k in _MAP_FIELDS:
            cols[k][p.map_index] = p.map_rows[k]
        height[p.ref_index], sigma[p.ref_index] = p.height, p.sigma
        inside[p.ref_index] = p.inside
        vertices[p.ref_index], weights[p.ref_index] = p.vertices, p.weights
        has_tin |= p.has_tin
    mp = MapPointHeights(xy=mxy, **cols)
    tin = TinInterpolation(height=height, sigma=sigma, inside=inside, vertices=vertices,
                           weights=weights, has_tin=has_tin)
    return summarise_heights(mp, ref, tin, **(options or {}))
