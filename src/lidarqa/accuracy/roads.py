"""3D roads from a 2D map: laser points assigned to map polygons at the right height level.

After Oude Elberink & Vosselman, *Quality analysis of 3D road reconstruction*, §2.
The map polygons of a 2D topographic map get heights from airborne laser points:

1. **Smooth segments.** The laser points are split into nodes, one per grid cell
   (`cell_size`) and height layer (a new layer starts at a height gap larger
   than `max_step`); nodes of neighbouring cells whose heights differ by at most
   `max_step` are connected. Connected nodes form piecewise smooth segments;
   segments smaller than `min_area` (cars, signs) are dropped.
2. **Levels per polygon.** Inside each polygon, the nodes are connected only
   through the polygon, so a bridge deck crossing a road polygon, or road points
   seen under a deck, form parts of their own. Parts that continue each other
   (a local plane through one predicts the other within `tolerance`) form one
   height level of the polygon.
3. **Map shift.** A horizontal displacement between map and laser data (P1) is
   estimated by moving all polygons together so that the points on each
   polygon's level fall inside it and the others outside (grid search within
   `max_shift`, refined to 5 mm), using only boundary stretches where the data
   show an edge, and kept at zero unless the gain is significant.
4. **Map growing.** Neighbouring polygons (shared boundary, no overlap) whose
   levels continue each other across the shared boundary are merged into one
   road. Starting from the polygons with the most dominant level, each
   neighbour takes the level that continues the growing road (P2: a polygon
   mostly covered by a deck still gets the road under it); a polygon without
   laser points of its own (P3) joins the neighbouring road it shares the
   longest boundary with, and its heights are extrapolated from that road's
   points with the model error σ_model of the extrapolation distance.
5. **3D map.** Map points every `spacing` metres along each polygon boundary get
   the height of a least-squares plane through the points of their road only
   (the largest smooth segment within a radius that grows until `min_points`
   are found; all of the road's points there where sparse data leave that
   segment too small), with σ = √(σ_plane² + σ_laser_block² + σ_model²) as in
   :func:`lidarqa.accuracy.heights.map_point_heights`. A location on the
   boundaries of roads on different levels gets one height per road. The 3D
   boundaries are triangulated per road into a TIN surface.

All lengths are metres in a projected CRS, heights metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import as_points, check_positive, require
from ..errors import DegenerateGeometryError, InvalidPointsError, OptionError
from . import _roads_kernels as _k
from .heights import (
    CURVATURE,
    MAX_RADIUS,
    MIN_POINTS,
    RADIUS,
    SIGMA_GPS,
    SIGMA_INS,
    SIGMA_POINT,
    SIGMA_REF,
    SIGMA_STRIP,
    HeightComparison,
    WTestResult,
    _freeze,
    compare_heights,
    map_point_heights,
    w_test,
)

__all__ = [
    "RoadMapPoints",
    "RoadReconstruction",
    "RoadComparison",
    "smooth_segments",
    "reconstruct_roads",
    "compare_road_heights",
]

#: status of a polygon after map growing
STATUSES = ("ok", "grown_from_neighbour", "no_points")
# map points along the polygon boundaries: more would not fit in memory
MAX_MAP_POINTS = 10_000_000


# ------------------------------------------------------------------ segments


def smooth_segments(
    points: Any, *, cell_size: float = 1.0, max_step: float = 0.5, min_area: float = 20.0
) -> np.ndarray:
    """Label piecewise smooth surfaces (roads, decks, terrain) in a laser point cloud.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z (m).
    cell_size : float, default 1.0
        Grid cell size (m).
    max_step : float, default 0.5
        Largest height step (m) within a surface between neighbouring cells, and
        the height gap that separates layers in one cell.
    min_area : float, default 20.0
        Segments covering fewer cells than this area (m²) are dropped (label -1):
        cars, traffic signs, isolated points.

    Returns
    -------
    ndarray of shape (N,) int64
        Segment per point, numbered by size (0 = most points), -1 for dropped.

    Examples
    --------
    >>> xy = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    >>> deck = np.column_stack([xy[:100], np.full(100, 8.0)])
    >>> road = np.column_stack([xy, np.zeros(400)])
    >>> lab = smooth_segments(np.vstack([road, deck]), min_area=50)
    >>> sorted(np.unique(lab).tolist()), bool(lab[0] != lab[-1])
    ([0, 1], True)
    """
    pts = as_points(points)
    c = check_positive(cell_size, "cell_size")
    step = check_positive(max_step, "max_step")
    amin = check_positive(min_area, "min_area", allow_zero=True)
    return _segments(pts, c, step, amin)[0]


def _segments(pts: np.ndarray, cell: float, step: float, min_area: float) -> tuple[np.ndarray, ...]:
    node, node_ij, node_xyz, node_count = _k.grid_nodes(pts, cell_size=cell, max_step=step)
    edges = _k.node_edges(node_ij, node_xyz, max_step=step)
    k = len(node_xyz)
    if k == 0:
        return np.empty(0, np.int64), node, node_xyz, node_count, edges
    comp = _k.components(k, edges)
    n_comp = int(comp.max()) + 1
    cells = np.bincount(comp, minlength=n_comp)
    npts = np.bincount(comp, weights=node_count, minlength=n_comp)
    big = cells * cell * cell >= min_area
    # number by size: most points first, ties by first node (order-free)
    order = np.lexsort((np.arange(n_comp), -npts))
    rank = np.full(n_comp, -1, dtype=np.int64)
    kept = order[big[order]]
    rank[kept] = np.arange(len(kept))
    node_label = rank[comp]
    return node_label[node], node, node_xyz, node_count, edges


def auto_cell_size(points: np.ndarray) -> float:
    """Grid cell (m) for smooth segments: 2/√density, at least 1 m.

    The density is the number of points per m² of occupied 5 m cells.
    """
    if len(points) == 0:
        return 1.0
    ij = np.floor((points[:, :2] - points[:, :2].min(axis=0)) / 5.0).astype(np.int64)
    occupied = len(np.unique(ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]))
    density = len(points) / (occupied * 25.0)
    return float(max(1.0, 2.0 / np.sqrt(density)))


# ------------------------------------------------------------------ results


@dataclass(frozen=True, eq=False)
class RoadMapPoints:
    """3D map points: one row per road and boundary location (one row per height level).

    Attributes
    ----------
    xy : ndarray of shape (M, 2)
        Map coordinates (m), as in the input map.
    xy_laser : ndarray of shape (M, 2)
        The same points moved by the map shift onto the laser data (m); heights
        belong to these locations.
    height, sigma, sigma_plane, sigma_block, sigma_model : ndarray of shape (M,)
        Height (m) and its predicted σ with the three terms (m).
    n_points : ndarray of shape (M,) int64
        Laser points of the plane fit.
    distance : ndarray of shape (M,)
        Extrapolation distance s (m) of σ_model.
    road : ndarray of shape (M,) int64
        Road (merged polygons on one level).
    polygon : ndarray of shape (M,) int64
        Index of the (first) polygon the point lies on.
    failed : ndarray of shape (M,) bool
    reason : ndarray of shape (M,) object
        "" or "no_points" (the road has no laser points), "too_few_points", ...
    """

    xy: np.ndarray
    xy_laser: np.ndarray
    height: np.ndarray
    sigma: np.ndarray
    sigma_plane: np.ndarray
    sigma_block: np.ndarray
    sigma_model: np.ndarray
    n_points: np.ndarray
    distance: np.ndarray
    road: np.ndarray
    polygon: np.ndarray
    failed: np.ndarray
    reason: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)

    def __len__(self) -> int:
        return len(self.height)


@dataclass(frozen=True, eq=False)
class RoadReconstruction:
    """Result of :func:`reconstruct_roads`.

    Attributes
    ----------
    map_points : RoadMapPoints
    shift : ndarray of shape (2,)
        Horizontal shift (m) that moves the map onto the laser data.
    shift_estimated : bool
        Whether `shift` was estimated (else given).
    polygons : ndarray of shape (P,) object
        The input polygons (map coordinates).
    polygon_ids : ndarray of shape (P,)
    polygon_road : ndarray of shape (P,) int64
        Road of each polygon (-1: no road, no laser points anywhere near).
    polygon_level : ndarray of shape (P,)
        Median height (m) of the laser points assigned to each polygon (NaN: none).
    polygon_points : ndarray of shape (P,) int64
        Laser points assigned to each polygon (its own level).
    polygon_other : ndarray of shape (P,) int64
        Laser points inside the polygon on other levels (not used).
    polygon_status : ndarray of shape (P,) object
        "ok", "grown_from_neighbour" (no own points: heights extrapolated from
        the neighbouring road) or "no_points".
    assigned : ndarray of shape (N,) int64
        Polygon of each laser point (-1: none).
    labels : ndarray of shape (N,) int64
        Smooth segment of each laser point (-1: dropped).
    rings : list of (polygon, (part, ring), indices)
        Map point rows of each polygon ring, in ring order (ring 0 = exterior).
    triangles : ndarray of shape (T, 3) int64
        TIN triangles (rows of `map_points`), each within one road.
    parameters : dict
    flags : tuple of str
    """

    map_points: RoadMapPoints
    shift: np.ndarray
    shift_estimated: bool
    polygons: np.ndarray
    polygon_ids: np.ndarray
    polygon_road: np.ndarray
    polygon_level: np.ndarray
    polygon_points: np.ndarray
    polygon_other: np.ndarray
    polygon_status: np.ndarray
    assigned: np.ndarray
    labels: np.ndarray
    rings: list = field(repr=False)
    triangles: np.ndarray = field(repr=False)
    parameters: dict = field(default_factory=dict)
    flags: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _freeze(self)

    @property
    def n_roads(self) -> int:
        """Number of distinct roads the polygons were grouped into."""
        r = self.polygon_road[self.polygon_road >= 0]
        return int(len(np.unique(r)))

    def polygons_3d(self) -> list[Any]:
        """One Polygon Z (MultiPolygon Z for multipart input) per input polygon at its road's level.

        Map coordinates; the boundary carries the heights of the map points.
        """
        shapely = require("shapely", "vector")
        mp = self.map_points
        parts: dict[int, dict[int, list[np.ndarray]]] = {}
        for poly, (part, _ring), rows in self.rings:
            xyz = np.column_stack([mp.xy[rows], mp.height[rows]])
            parts.setdefault(poly, {}).setdefault(part, []).append(np.vstack([xyz, xyz[:1]]))
        out = []
        for i in range(len(self.polygons)):
            pp = [shapely.Polygon(rr[0], rr[1:]) for _, rr in sorted(parts.get(i, {}).items())]
            out.append(None if not pp else pp[0] if len(pp) == 1 else shapely.MultiPolygon(pp))
        return out

    def triangles_3d(self) -> list[Any]:
        """The TIN triangles as Polygon Z (map coordinates)."""
        shapely = require("shapely", "vector")
        mp = self.map_points
        xyz = np.column_stack([mp.xy, mp.height])
        if len(self.triangles) == 0:
            return []
        rings = xyz[np.column_stack([self.triangles, self.triangles[:, :1]])]
        return list(shapely.polygons(rings))

    def to_dict(self) -> dict[str, Any]:
        """``results`` of ``lidarqa roads --json``."""
        mp = self.map_points
        ok = ~mp.failed
        s = mp.sigma[ok]
        status = self.polygon_status.astype(str)
        return {
            "shift": [float(self.shift[0]), float(self.shift[1])],
            "shift_estimated": bool(self.shift_estimated),
            "n_polygons": int(len(self.polygons)),
            "n_roads": self.n_roads,
            "n_map_points": int(len(mp)),
            "n_failed": int(mp.failed.sum()),
            "n_triangles": int(len(self.triangles)),
            "sigma_mean": float(s.mean()) if s.size else float("nan"),
            "sigma_p95": float(np.percentile(s, 95)) if s.size else float("nan"),
            "polygons_grown": int((status == "grown_from_neighbour").sum()),
            "polygons_without_points": int((status == "no_points").sum()),
            "points_other_level": int(self.polygon_other.sum()),
            "flags": list(self.flags),
        }


# ------------------------------------------------------------------ validation


def _as_polygons(polygons: Any) -> np.ndarray:
    shapely = require("shapely", "vector")
    geoms = np.asarray(
        list(polygons) if not isinstance(polygons, np.ndarray) else polygons, dtype=object
    ).reshape(-1)
    if geoms.size == 0:
        raise InvalidPointsError("the map is empty: no polygons to reconstruct")
    for i, g in enumerate(geoms):
        if g is None or g.is_empty:
            raise InvalidPointsError(f"polygon {i} is empty")
        if g.geom_type not in ("Polygon", "MultiPolygon"):
            raise InvalidPointsError(f"polygon {i} is a {g.geom_type}, expected Polygon")
        if not g.is_valid:
            raise DegenerateGeometryError(
                f"polygon {i} is not valid ({shapely.is_valid_reason(g)}); "
                "repair self-intersections before reconstruction"
            )
    # multipolygons: one part per row would change the ids; keep them whole
    return geoms


# ------------------------------------------------------------------ helpers


class _PointIndex:
    """Points sorted into square tiles for quick polygon queries."""

    def __init__(self, xy: np.ndarray, tile: float = 32.0) -> None:
        self.xy = xy
        self.tile = tile
        self.origin = xy.min(axis=0) if len(xy) else np.zeros(2)
        ij = np.floor((xy - self.origin) / tile).astype(np.int64)
        self.nj = int(ij[:, 1].max()) + 1 if len(xy) else 1
        key = ij[:, 0] * self.nj + ij[:, 1]
        self.order = np.argsort(key, kind="stable")
        self.key = key[self.order]

    def inside(self, geom: Any) -> np.ndarray:
        import shapely

        if len(self.xy) == 0:
            return np.empty(0, dtype=np.int64)
        x0, y0, x1, y1 = geom.bounds
        i0, j0 = np.floor((np.array([x0, y0]) - self.origin) / self.tile).astype(np.int64)
        i1, j1 = np.floor((np.array([x1, y1]) - self.origin) / self.tile).astype(np.int64)
        j0, j1 = max(j0, 0), min(j1, self.nj - 1)
        parts = []
        for i in range(max(i0, 0), i1 + 1):
            lo = np.searchsorted(self.key, i * self.nj + j0)
            hi = np.searchsorted(self.key, i * self.nj + j1, side="right")
            parts.append(self.order[lo:hi])
        cand = np.concatenate(parts) if parts else np.empty(0, dtype=np.int64)
        if cand.size == 0:
            return cand
        ok = shapely.contains_xy(geom, self.xy[cand, 0], self.xy[cand, 1])
        return np.sort(cand[ok])


@dataclass
class _Level:
    nodes: np.ndarray
    count: int
    inside: int = 0  # points inside the polygon itself (not its margin)


def _levels_in(
    pidx: np.ndarray,
    node: np.ndarray,
    labels: np.ndarray,
    node_xyz: np.ndarray,
    node_count: np.ndarray,
    adj: Any,
    tol: float,
) -> list[_Level]:
    """Height levels of one polygon: parts connected inside it, merged when continuous."""
    from scipy.sparse.csgraph import connected_components

    p = pidx[labels[pidx] >= 0]
    if p.size == 0:
        return []
    nodes, counts = np.unique(node[p], return_counts=True)
    sub = adj[nodes][:, nodes]
    _, comp = connected_components(sub, directed=False)
    n_comp = int(comp.max()) + 1
    csize = np.bincount(comp, weights=counts, minlength=n_comp)
    first = np.full(n_comp, len(nodes))
    np.minimum.at(first, comp, np.arange(len(nodes)))
    order = np.lexsort((first, -csize))[:30]
    levels: list[tuple[list[np.ndarray], float]] = []
    for c in order:
        if csize[c] < 3:
            break
        cn = nodes[comp == c]
        joined = False
        for lv in levels:
            ln = np.concatenate(lv[0])
            pred, dist = _k.local_plane_predict(node_xyz[ln], node_count[ln], node_xyz[cn, :2])
            dz = np.abs(pred - node_xyz[cn, 2])
            if np.median(dz) <= tol + 0.02 * float(np.median(dist)):
                lv[0].append(cn)
                joined = True
                break
        if not joined:
            levels.append(([cn], 0.0))
    out = []
    for parts, _ in levels:
        ln = np.concatenate(parts)
        out.append(_Level(nodes=np.sort(ln), count=int(node_count[ln].sum())))
    out.sort(key=lambda lv: (-lv.count, int(lv.nodes[0])))
    return out


def _neighbours(geoms: np.ndarray) -> list[tuple[int, int, Any]]:
    """Pairs of polygons that share a boundary (>= 1 m) without overlapping (< 1 m²)."""
    import shapely

    tree = shapely.STRtree(geoms)
    a, b = tree.query(shapely.buffer(geoms, 0.05), predicate="intersects")
    out = []
    for i, j in zip(a.tolist(), b.tolist(), strict=True):
        if i >= j:
            continue
        gi, gj = geoms[i], geoms[j]
        if shapely.area(shapely.intersection(gi, gj)) >= 1.0:
            continue
        line = shapely.intersection(shapely.boundary(gj), shapely.buffer(gi.boundary, 0.05))
        if shapely.length(line) >= 1.0:
            out.append((i, j, line))
    return out


def _line_samples(line: Any, step: float = 2.0) -> np.ndarray:
    import shapely

    lines = shapely.get_parts(
        shapely.line_merge(line) if line.geom_type == "MultiLineString" else line
    )
    pts = []
    for ln in lines:
        if ln.geom_type not in ("LineString", "LinearRing") or ln.length <= 0:
            continue
        d = np.arange(0.0, ln.length + 1e-9, step)
        pts.append(shapely.get_coordinates(shapely.line_interpolate_point(ln, d)))
    return np.vstack(pts) if pts else np.empty((0, 2))


def _continuous(la: _Level, lb: _Level, samples: np.ndarray, node_xyz, node_count, tol) -> bool:
    if len(samples) == 0:
        return False
    za, da = _k.local_plane_predict(node_xyz[la.nodes], node_count[la.nodes], samples)
    zb, db = _k.local_plane_predict(node_xyz[lb.nodes], node_count[lb.nodes], samples)
    return bool(np.median(np.abs(za - zb)) <= tol + 0.02 * float(np.median(da + db)))


def _grow(levels, neigh, node_xyz, node_count, tol):
    """Map growing: one level per polygon, roads = polygons whose levels continue each other.

    Each level of a polygon scores its own points inside the polygon plus, for
    every neighbour, the largest of the neighbour's levels that continues it
    across the shared boundary. A polygon mostly covered by a deck thus keeps
    the road under it when its neighbours continue that road, while a sliver of
    deck points in a polygon's margin never outweighs the polygon's own road.
    Neighbours whose chosen levels continue each other are merged into one
    road; a polygon without points joins the neighbouring road with which it
    shares the longest boundary.
    """
    n = len(levels)
    nb: list[list[tuple[int, float, np.ndarray]]] = [[] for _ in range(n)]
    for i, j, line in neigh:
        smp = _line_samples(line)
        # compat[a, b]: level a of i continues level b of j
        compat = np.zeros((len(levels[i]), len(levels[j])), dtype=bool)
        for a, la in enumerate(levels[i]):
            for b, lb in enumerate(levels[j]):
                compat[a, b] = _continuous(la, lb, smp, node_xyz, node_count, tol)
        nb[i].append((j, line.length, compat))
        nb[j].append((i, line.length, compat.T))
    chosen = [-1] * n  # level index, -2 = grown from a neighbour, -3 = nothing
    for i in range(n):
        if not levels[i]:
            continue
        total = sum(lv.inside for lv in levels[i])
        best, best_score = 0, -1.0
        for a, lv in enumerate(levels[i]):
            if lv.inside < 0.02 * total:
                continue  # slivers in the margin
            score = float(lv.inside)
            for j, _length, compat in nb[i]:
                ok = np.flatnonzero(compat[a])
                if ok.size:
                    score += max(levels[j][b].inside for b in ok)
            if score > best_score:
                best, best_score = a, score
        chosen[i] = best
    parent = list(range(n))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(a: int, b: int) -> None:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)

    for i in range(n):
        if chosen[i] < 0:
            continue
        for j, _length, compat in nb[i]:
            if chosen[j] >= 0 and compat[chosen[i], chosen[j]]:
                union(i, j)
    # polygons without points: join the neighbouring road with the longest shared boundary
    for i in range(n):
        if levels[i]:
            continue
        best = None
        for q, length, _c in nb[i]:
            if levels[q] and (best is None or length > best[1]):
                best = (q, length)
        if best is not None:
            chosen[i] = -2
            union(i, best[0])
        else:
            chosen[i] = -3
    roots = [find(i) for i in range(n)]
    _, road = np.unique(roots, return_inverse=True)
    road = road.astype(np.int64)
    # a road with no points at all has no level: -1
    has_pts = np.zeros(road.max() + 1 if n else 0, dtype=bool)
    for i in range(n):
        if chosen[i] >= 0:
            has_pts[road[i]] = True
    road = np.where(has_pts[road], road, -1)
    if (road >= 0).any():
        _, road[road >= 0] = np.unique(road[road >= 0], return_inverse=True)
    return chosen, road


def _fits_level(p: np.ndarray, max_residual: float, k: int = 15) -> np.ndarray:
    """Points within `max_residual` of the median height of their `k` nearest level points.

    Drops the odd point of another surface that a level picked up where two
    surfaces touch (a road end running into lower terrain).
    """
    from scipy.spatial import cKDTree

    if len(p) < 4:
        return np.ones(len(p), dtype=bool)
    kk = min(k, len(p))
    _, idx = cKDTree(p[:, :2]).query(p[:, :2], k=kk)
    med = np.median(p[idx, 2], axis=1)
    return np.abs(p[:, 2] - med) <= max_residual


def _rings(geoms: np.ndarray, spacing: float) -> list[tuple[int, tuple[int, int], np.ndarray]]:
    import shapely

    out = []
    for i, g in enumerate(geoms):
        for k, part in enumerate(shapely.get_parts(g)):
            part = shapely.segmentize(part, spacing)
            rings = [part.exterior, *part.interiors]
            for r, ring in enumerate(rings):
                xy = shapely.get_coordinates(ring)[:-1]
                out.append((i, (k, r), xy))
    return out


def _boundary_samples(geom: Any, step: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Points every `step` along the boundary of a polygon and their outward unit normals."""
    import shapely
    from shapely.geometry.polygon import orient

    xy_all, n_all = [], []
    for part in shapely.get_parts(geom):
        part = orient(part, 1.0)  # exterior counter-clockwise, holes clockwise
        for ring in [part.exterior, *part.interiors]:
            c = shapely.get_coordinates(ring)
            a, b = c[:-1], c[1:]
            seg = b - a
            length = np.hypot(seg[:, 0], seg[:, 1])
            good = length > 0
            a, seg, length = a[good], seg[good], length[good]
            k = np.maximum(np.ceil(length / step).astype(np.int64), 1)
            which = np.repeat(np.arange(len(a)), k)
            t = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k) + 0.5) / k[which]
            xy_all.append(a[which] + seg[which] * t[:, None])
            tang = seg / length[:, None]
            n_all.append(np.column_stack([tang[:, 1], -tang[:, 0]])[which])
    return np.vstack(xy_all), np.vstack(n_all)


def _estimate_shift(
    pts, geoms, chosen, levels, labels, node_xyz, node_count, index, max_shift, tol
) -> np.ndarray | None:
    """The map-to-laser shift that best separates each polygon's level from the rest.

    None when the boundaries show no edges or the best shift is not significant.
    """
    import shapely
    from scipy.spatial import cKDTree

    w = max_shift + 2.0
    sd_all, n_all, sign_all = [], [], []
    for i, g in enumerate(geoms):
        if chosen[i] < 0:
            continue
        lv = levels[i][chosen[i]]
        cand = index.inside(shapely.buffer(g, w))
        if cand.size == 0:
            continue
        bxy, bn = _boundary_samples(g)
        dist, j = cKDTree(bxy).query(pts[cand, :2], distance_upper_bound=w)
        near = np.isfinite(dist)
        cand, j = cand[near], j[near]
        if cand.size == 0:
            continue
        sd = np.einsum("ij,ij->i", pts[cand, :2] - bxy[j], bn[j])
        pred, _ = _k.local_plane_predict(node_xyz[lv.nodes], node_count[lv.nodes], pts[cand, :2])
        sign = np.where(np.abs(pts[cand, 2] - pred) <= tol, 1.0, -1.0)
        sign[labels[cand] < 0] = 0.0
        # only stretches of boundary where the data show an edge count: beyond any possible
        # shift, most points outside must be off the polygon's level (a road continuing into
        # a neighbouring polygon or into terrain at the same height says nothing about a shift)
        piece = j // 50  # 5 m stretches of boundary (samples every 0.1 m)
        far_out = (sd > max_shift) & (sign != 0)
        n_out = np.bincount(piece[far_out], minlength=piece.max() + 1)
        n_off = np.bincount(piece[far_out & (sign < 0)], minlength=piece.max() + 1)
        edge = (n_out >= 2) & (n_off >= 0.5 * n_out)
        keep = edge[piece]
        sd, j, sign = sd[keep], j[keep], sign[keep]
        sd_all.append(sd)
        n_all.append(bn[j])
        sign_all.append(sign)
    if not sd_all:
        return None
    sd, nrm, sign = np.concatenate(sd_all), np.vstack(n_all), np.concatenate(sign_all)
    if not sd.size or not (sign < 0).any():
        return None  # nothing distinguishes a polygon from its surroundings
    best = np.zeros(2)
    for step, half in ((0.15, max_shift), (0.03, 0.15), (0.005, 0.03)):
        g1 = np.arange(-half, half + 1e-9, step)
        cand = best + np.stack(np.meshgrid(g1, g1, indexing="ij"), -1).reshape(-1, 2)
        cand = cand[np.hypot(cand[:, 0], cand[:, 1]) <= max_shift + 1e-9]
        sc = _k.shift_scores(sd, nrm, sign, cand, tau=0.1)
        top = sc >= sc.max() - 1e-9 * max(1.0, abs(sc.max()))
        best = cand[top].mean(axis=0)
    # keep the map where it is unless the shift is significant: each point that changes side
    # adds ±1 to the score, so without a real shift the gain is a random walk of those points
    before = sd < 0
    after = sd - nrm @ best < 0
    changed = before != after
    gain = float(np.sum(sign[changed] * np.where(after[changed], 1.0, -1.0)))
    if gain <= 3.0 * np.sqrt(max(int(changed.sum()), 1)):
        return None
    return best


# ------------------------------------------------------------------ the reconstruction


def reconstruct_roads(
    points: Any,
    polygons: Any,
    *,
    ids: Any = None,
    spacing: float = 10.0,
    shift: Any = None,
    max_shift: float = 1.5,
    margin: float = 0.0,
    cell_size: float | None = None,
    max_step: float = 0.5,
    min_area: float = 20.0,
    tolerance: float = 0.5,
    radius: float = RADIUS,
    max_radius: float = MAX_RADIUS,
    min_points: int = MIN_POINTS,
    sigma_point: float = SIGMA_POINT,
    sigma_gps: float = SIGMA_GPS,
    sigma_ins: float = SIGMA_INS,
    sigma_strip: float = SIGMA_STRIP,
    curvature: float = CURVATURE,
    labels: Any = None,
) -> RoadReconstruction:
    """Reconstruct 3D roads from 2D map polygons and laser points (Oude Elberink & Vosselman §2).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Laser points x, y, z (m): typically ground, road and bridge classes.
    polygons : sequence of shapely Polygon/MultiPolygon
        Road polygons of the 2D map (same projected CRS). They may overlap (a road
        polygon passing under a deck polygon) or tile the plane. A MultiPolygon
        is split into its parts, which keep the feature's id.
    ids : sequence, optional
        Polygon ids (default 0..P-1).
    spacing : float, default 10.0
        Largest distance between map points along a boundary (m).
    shift : array_like of shape (2,), optional
        Known map-to-laser shift (m); estimated when not given. Only boundary
        stretches where the data show an edge (points beyond `max_shift` outside
        the polygon lie mostly off its level) take part; when the best shift
        does not beat zero significantly (gain <= 3√(points changing side)) the
        map stays where it is and the flag ``shift_not_significant`` is set.
    max_shift : float, default 1.5
        Largest map-to-laser shift searched (m); 0 = no shift.
    margin : float, default 0.0
        Points this far outside a (shifted) polygon may still join it (m); a
        margin lets terrain points join where a road ends at lower ground.
    cell_size : float, optional
        Grid cell of the smooth segments (m); by default 2/√density, at least
        1 m, so that neighbouring cells of a surface hold points.
    max_step, min_area : float
        Smooth segments, see :func:`smooth_segments`.
    tolerance : float, default 0.5
        Height difference (m) within which two parts continue each other (plus
        2 cm per metre of extrapolation).
    radius, max_radius, min_points, sigma_point, sigma_gps, sigma_ins, sigma_strip, curvature
        Plane fits and precision, see :func:`lidarqa.accuracy.heights.map_point_heights`.
    labels : ndarray of shape (N,), optional
        Own segment labels (-1 = unusable) instead of :func:`smooth_segments`.

    Returns
    -------
    RoadReconstruction

    Raises
    ------
    InvalidPointsError
        Empty map, non-polygon geometries, bad points.
    DegenerateGeometryError
        Invalid (e.g. self-intersecting) polygons.
    OptionError
        No polygon overlaps the laser points, or a bad option.
    """
    import shapely

    pts = as_points(points)
    geoms = _as_polygons(polygons)
    pid = np.arange(len(geoms)) if ids is None else np.asarray(ids).reshape(-1)
    if len(pid) != len(geoms):
        raise InvalidPointsError(f"ids must have {len(geoms)} entries, got {len(pid)}")
    # a multipart feature may lie on several levels: each part is a polygon of its own
    parts, part_of = shapely.get_parts(geoms, return_index=True)
    if len(parts) != len(geoms):
        geoms, pid = np.asarray(parts, dtype=object), pid[part_of]
    step = check_positive(spacing, "spacing")
    ms = check_positive(max_shift, "max_shift", allow_zero=True)
    marg = check_positive(margin, "margin", allow_zero=True)
    tol = check_positive(tolerance, "tolerance")
    cell = auto_cell_size(pts) if cell_size is None else check_positive(cell_size, "cell_size")
    mstep = check_positive(max_step, "max_step")
    amin = check_positive(min_area, "min_area", allow_zero=True)
    if len(pts):
        x0, y0 = pts[:, :2].min(axis=0)
        x1, y1 = pts[:, :2].max(axis=0)
        hits = shapely.intersects(geoms, shapely.box(x0 - ms, y0 - ms, x1 + ms, y1 + ms))
    else:
        hits = np.zeros(len(geoms), dtype=bool)
    if not hits.any():
        raise OptionError(
            "no map polygon overlaps the laser points: check that map and cloud cover the "
            "same area and use the same CRS"
        )
    outside = ~hits
    boundary = float(shapely.length(shapely.boundary(geoms[hits])).sum())
    if boundary / step > MAX_MAP_POINTS:
        raise OptionError(
            f"spacing {step:g} m would put {boundary / step:.3g} map points on the "
            f"{boundary:.0f} m of polygon boundary (at most {MAX_MAP_POINTS:,}): use a "
            f"spacing of at least {boundary / MAX_MAP_POINTS:.3g} m"
        )
    # segments
    lab_seg, node, node_xyz, node_count, edges = _segments(pts, cell, mstep, amin)
    if labels is not None:
        lab = np.asarray(labels).reshape(-1)
        if lab.shape != (len(pts),):
            raise InvalidPointsError(f"labels must have shape ({len(pts)},), got {lab.shape}")
        lab_seg = lab.astype(np.int64)
    from scipy.sparse import coo_matrix

    k = len(node_xyz)
    adj = coo_matrix(
        (
            np.ones(2 * len(edges)),
            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]),
        ),
        shape=(k, k),
    ).tocsr()
    index = _PointIndex(pts[:, :2])

    def levels_of(regions, strict):
        out, inside = [], []
        for g, g0 in zip(regions, strict, strict=True):
            idx = index.inside(g) if (g is not None and not g.is_empty) else np.empty(0, np.int64)
            inside.append(idx)
            lvs = _levels_in(idx, node, lab_seg, node_xyz, node_count, adj, tol)
            if lvs:
                own = idx if g0 is g else idx[shapely.contains_xy(g0, pts[idx, 0], pts[idx, 1])]
                own_nodes = node[own[lab_seg[own] >= 0]]
                for lv in lvs:
                    lv.inside = int(np.isin(own_nodes, lv.nodes).sum())
            out.append(lvs)
        return out, inside

    neigh = _neighbours(geoms)
    shift_flag = None
    if shift is not None:
        s = np.asarray(shift, dtype=np.float64).reshape(-1)
        if s.shape != (2,) or not np.isfinite(s).all():
            raise OptionError(f"shift must be two finite numbers (dx, dy), got {shift!r}")
        estimated = False
    elif ms > 0:
        cores = shapely.buffer(geoms, -ms)
        lv0, _ = levels_of(cores, cores)
        ch0, _ = _grow(lv0, neigh, node_xyz, node_count, tol)
        est = _estimate_shift(pts, geoms, ch0, lv0, lab_seg, node_xyz, node_count, index, ms, tol)
        estimated = True
        s = np.zeros(2) if est is None else est
        if est is None:  # the data show no significant shift
            shift_flag = "shift_not_significant"
    else:
        s = np.zeros(2)
        estimated = False
    moved = shapely.transform(geoms, lambda c: c + s)
    regions = shapely.buffer(moved, marg) if marg > 0 else moved
    levels, inside = levels_of(regions, moved)
    chosen, road = _grow(levels, neigh, node_xyz, node_count, tol)
    n_poly = len(geoms)
    assigned = np.full(len(pts), -1, dtype=np.int64)
    p_points = np.zeros(n_poly, dtype=np.int64)
    p_other = np.zeros(n_poly, dtype=np.int64)
    p_level = np.full(n_poly, np.nan)
    status = np.empty(n_poly, dtype=object)
    own: list[np.ndarray] = []
    for i in range(n_poly):
        idx = inside[i]
        if chosen[i] >= 0:
            mine = np.isin(node[idx], levels[i][chosen[i]].nodes) & (lab_seg[idx] >= 0)
            mine[mine] = _fits_level(pts[idx[mine]], 0.6 * tol)
            own.append(idx[mine])
            p_points[i] = mine.sum()
            p_other[i] = int((~mine & (lab_seg[idx] >= 0)).sum())
            p_level[i] = float(np.median(pts[idx[mine], 2])) if mine.any() else np.nan
            status[i] = "ok"
        else:
            own.append(np.empty(0, dtype=np.int64))
            p_other[i] = int((lab_seg[idx] >= 0).sum())
            status[i] = "grown_from_neighbour" if road[i] >= 0 else "no_points"
    # a point inside several polygons of one level goes to the first of them
    for i in range(n_poly - 1, -1, -1):
        assigned[own[i]] = i
    # map points: per road, unique laser-frame locations
    rings = _rings(geoms, step)
    ring_xy = np.vstack([r[2] for r in rings]) if rings else np.empty((0, 2))
    ring_poly = (
        np.concatenate([np.full(len(r[2]), r[0]) for r in rings])
        if rings
        else np.empty(0, np.int64)
    )
    ring_road = road[ring_poly]
    key = np.column_stack([ring_road, np.round(ring_xy * 1e6).astype(np.int64)])
    _, first, row_of = np.unique(key, axis=0, return_index=True, return_inverse=True)
    row_of = row_of.reshape(-1)
    # rows numbered in input order of first appearance
    rank = np.argsort(np.argsort(first))
    row_of = rank[row_of]
    first = np.sort(first)
    m = len(first)
    mxy = ring_xy[first]
    mroad = ring_road[first]
    mpoly = ring_poly[first]
    h = np.full(m, np.nan)
    sig = {
        k_: np.full(m, np.nan)
        for k_ in ("sigma", "sigma_plane", "sigma_block", "sigma_model", "distance")
    }
    npts = np.zeros(m, dtype=np.int64)
    failed = np.ones(m, dtype=bool)
    reason = np.full(m, "no_points", dtype=object)
    for r in range(int(road.max()) + 1 if (road >= 0).any() else 0):
        rows = np.flatnonzero(mroad == r)
        members = np.flatnonzero(road == r)
        rp = np.unique(np.concatenate([own[i] for i in members]))
        if rows.size == 0 or rp.size < 3:
            continue
        fit: dict[str, Any] = dict(
            radius=radius,
            max_radius=max_radius,
            min_points=min(min_points, len(rp)) if len(rp) >= 3 else 3,
            sigma_point=sigma_point,
            sigma_gps=sigma_gps,
            sigma_ins=sigma_ins,
            sigma_strip=sigma_strip,
            curvature=curvature,
        )
        res = map_point_heights(pts[rp], mxy[rows] + s, labels=lab_seg[rp], **fit)
        # Where the largest segment near a map point is too small (sparse data cut the
        # road into small grid segments), fit all of the road's points there: they are
        # on the road's level already, and small segments (cars) are not among them.
        retry = np.flatnonzero(res.reason.astype(str) == "too_few_segment_points")
        parts = [(rows, res)]
        if retry.size:
            parts.append((rows[retry], map_point_heights(pts[rp], mxy[rows[retry]] + s, **fit)))
        for rr, rs in parts:
            h[rr] = rs.height
            sig["sigma"][rr] = rs.sigma
            sig["sigma_plane"][rr] = rs.sigma_plane
            sig["sigma_block"][rr] = rs.sigma_block
            sig["sigma_model"][rr] = rs.sigma_model
            sig["distance"][rr] = rs.distance
            npts[rr] = rs.n_points
            failed[rr] = rs.failed
            reason[rr] = rs.reason
    mp = RoadMapPoints(
        xy=mxy,
        xy_laser=mxy + s,
        height=h,
        sigma=sig["sigma"],
        sigma_plane=sig["sigma_plane"],
        sigma_block=sig["sigma_block"],
        sigma_model=sig["sigma_model"],
        n_points=npts,
        distance=sig["distance"],
        road=mroad,
        polygon=mpoly,
        failed=failed,
        reason=reason,
    )
    ring_rows = []
    start = 0
    for poly, rr, xy in rings:
        ring_rows.append((poly, rr, row_of[start : start + len(xy)]))
        start += len(xy)
    tri = _triangulate(mp, moved, road)
    flags = [shift_flag] if shift_flag else []
    if outside.any():
        flags.append("polygons_outside_cloud")
    if (status == "no_points").any():
        flags.append("polygons_without_points")
    if failed.any():
        flags.append("map_points_failed")
    params = {
        "spacing": step,
        "max_shift": ms,
        "margin": marg,
        "cell_size": cell,
        "max_step": mstep,
        "min_area": amin,
        "tolerance": tol,
        "radius": radius,
        "max_radius": max_radius,
        "min_points": min_points,
        "sigma_point": sigma_point,
        "sigma_gps": sigma_gps,
        "sigma_ins": sigma_ins,
        "sigma_strip": sigma_strip,
        "curvature": curvature,
    }
    return RoadReconstruction(
        map_points=mp,
        shift=np.asarray(s, dtype=np.float64),
        shift_estimated=estimated,
        polygons=geoms,
        polygon_ids=pid,
        polygon_road=road,
        polygon_level=p_level,
        polygon_points=p_points,
        polygon_other=p_other,
        polygon_status=status,
        assigned=assigned,
        labels=lab_seg,
        rings=ring_rows,
        triangles=tri,
        parameters=params,
        flags=tuple(flags),
    )


def _triangulate(mp: RoadMapPoints, moved: np.ndarray, road: np.ndarray) -> np.ndarray:
    """Delaunay triangles per road, kept where their centroid lies inside the road's polygons."""
    import shapely
    from scipy.spatial import Delaunay, QhullError

    out = []
    ok = ~mp.failed
    for r in np.unique(mp.road[mp.road >= 0]):
        rows = np.flatnonzero((mp.road == r) & ok)
        if len(rows) < 3:
            continue
        xy = mp.xy_laser[rows]
        try:
            tri = Delaunay(xy).simplices
        except QhullError:
            continue
        cen = xy[tri].mean(axis=1)
        area = shapely.union_all(moved[road == r]).buffer(1e-6)
        inside = shapely.contains_xy(area, cen[:, 0], cen[:, 1])
        out.append(rows[tri[inside]])
    return np.vstack(out).astype(np.int64) if out else np.empty((0, 3), dtype=np.int64)


# ------------------------------------------------------------------ tests against references


@dataclass(frozen=True, eq=False)
class RoadComparison:
    """Reconstructed road heights against reference points, each on its own level.

    Attributes
    ----------
    height, sigma : ndarray of shape (R,)
        Model height (m) and its σ at each reference point (NaN: not on a road).
    road : ndarray of shape (R,) int64
        Road (level) used (-1: none).
    comparison : HeightComparison
    w : WTestResult
    """

    height: np.ndarray
    sigma: np.ndarray
    road: np.ndarray
    comparison: HeightComparison
    w: WTestResult

    def __post_init__(self) -> None:
        _freeze(self)

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "comparison": self.comparison.to_dict(),
            "w": self.w.to_dict(),
            "n_on_road": int((self.road >= 0).sum()),
        }


def compare_road_heights(
    recon: RoadReconstruction,
    reference_xyz: Any,
    *,
    sigma_ref: float = SIGMA_REF,
    alpha: float = 0.001,
    estimate_offset: bool = False,
) -> RoadComparison:
    """Interpolate the road TIN at reference points on the right level and w-test the differences.

    Each reference point (laser frame) is located in the TIN triangles of every
    road; where several levels cover it, the one whose height is nearest the
    reference height is used, so a paint strip under a bridge is compared with
    the lower road. The TIN σ combines the plane and model terms of the three
    vertices as independent and the laser block term as fully correlated (it is
    common to a neighbourhood).
    """
    from .._validate import as_points as _ap
    from .heights import critical_value

    ref = _ap(reference_xyz, "reference_xyz")
    critical_value(alpha)
    mp = recon.map_points
    tri = recon.triangles
    r = len(ref)
    best_h = np.full(r, np.nan)
    best_s = np.full(r, np.nan)
    best_road = np.full(r, -1, dtype=np.int64)
    if len(tri) and r:
        v = mp.xy_laser[tri]  # (T, 3, 2)
        from scipy.spatial import cKDTree

        cen = v.mean(axis=1)
        rad = np.max(np.hypot(*(v - cen[:, None, :]).transpose(2, 0, 1)), axis=1)
        tree = cKDTree(cen)
        cand = tree.query_ball_point(ref[:, :2], r=float(rad.max()) + 1e-6)
        lens = np.array([len(c) for c in cand])
        qi = np.repeat(np.arange(r), lens)
        ti = (
            np.concatenate([np.asarray(c, dtype=np.int64) for c in cand])
            if lens.sum()
            else np.empty(0, np.int64)
        )
        a, b, c = v[ti, 0], v[ti, 1], v[ti, 2]
        p = ref[qi, :2]
        det = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
        good = np.abs(det) > 1e-9
        det = np.where(good, det, 1.0)
        w1 = (
            (b[:, 1] - c[:, 1]) * (p[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (p[:, 1] - c[:, 1])
        ) / det
        w2 = (
            (c[:, 1] - a[:, 1]) * (p[:, 0] - c[:, 0]) + (a[:, 0] - c[:, 0]) * (p[:, 1] - c[:, 1])
        ) / det
        w3 = 1 - w1 - w2
        wts = np.column_stack([w1, w2, w3])
        ins = good & (wts >= -1e-9).all(axis=1)
        qi, ti, wts = qi[ins], ti[ins], wts[ins]
        vid = tri[ti]
        hh = np.sum(wts * mp.height[vid], axis=1)
        indep = mp.sigma_plane[vid] ** 2 + mp.sigma_model[vid] ** 2
        var = np.sum(wts**2 * indep, axis=1) + np.sum(wts * mp.sigma_block[vid], axis=1) ** 2
        err = np.abs(hh - ref[qi, 2])
        order = np.lexsort((ti, err, qi))
        qi, hh, var, ti = qi[order], hh[order], var[order], ti[order]
        firsts = np.ones(len(qi), dtype=bool)
        firsts[1:] = qi[1:] != qi[:-1]
        best_h[qi[firsts]] = hh[firsts]
        best_s[qi[firsts]] = np.sqrt(var[firsts])
        best_road[qi[firsts]] = mp.road[tri[ti[firsts], 0]]
    comp = compare_heights(best_h, best_s, ref[:, 2], sigma_ref=sigma_ref)
    wt = w_test(comp.dh, comp.sigma_dh, alpha=alpha, estimate_offset=estimate_offset)
    return RoadComparison(height=best_h, sigma=best_s, road=best_road, comparison=comp, w=wt)


# ------------------------------------------------------------------ files


def read_road_polygons(path: Any) -> tuple[np.ndarray, np.ndarray, Any]:
    """Read road polygons (GeoPackage/GeoJSON Polygon or MultiPolygon layer).

    Returns
    -------
    polygons : ndarray of shape (P,) object
    ids : ndarray of shape (P,)
        The ``id`` attribute, else 0..P-1.
    crs : pyproj.CRS or None
    """
    from pathlib import Path

    from .._atomic import check_input
    from ..errors import ReadError
    from ..io.vector import read_features

    p = check_input(path)
    shapely = require("shapely", "vector")
    if Path(p).suffix.lower() not in (".gpkg", ".geojson", ".json"):
        raise ReadError(f"cannot read polygons from {p}: use a .gpkg or .geojson file")
    crs, names, geoms, field_data = read_features(p)
    if len(geoms) == 0:
        raise InvalidPointsError(f"{p} holds no polygons: the map is empty")
    kinds = set(shapely.get_type_id(geoms).tolist()) - {3, 6}
    if kinds:
        got = ", ".join(sorted({g.geom_type for g in geoms if g is not None})) or "no geometry"
        raise InvalidPointsError(f"{p} must hold Polygon/MultiPolygon features, got {got}")
    ids = np.asarray(field_data[names.index("id")]) if "id" in names else np.arange(len(geoms))
    geoms = shapely.force_2d(geoms)
    return np.asarray(geoms, dtype=object), ids, crs


def write_roads(
    recon: RoadReconstruction, path: Any, *, crs: Any = None, overwrite: bool = False
) -> Any:
    """Write a reconstruction as a GeoPackage, atomically.

    Layers: ``map_points`` (Point Z with height, σ and its three terms, road,
    polygon id, failed/reason), ``polygons_3d`` (Polygon Z, one per polygon at
    its road's level, with road, status, points used and other-level points)
    and ``tin`` (Polygon Z triangles with their road). Coordinates are those of
    the map; the shift onto the laser data is stored on every map point.
    """
    import os
    import warnings
    from pathlib import Path

    from .._atomic import atomic_path
    from ..errors import WriteError

    pyogrio = require("pyogrio", "vector")
    shapely = require("shapely", "vector")
    p = Path(path)
    if p.suffix.lower() != ".gpkg":
        raise WriteError(f"roads are written as a GeoPackage (.gpkg), got {p.name!r}")
    mp = recon.map_points
    pid = recon.polygon_ids
    ids = np.asarray(pid).astype(str).astype(object)
    layers = []
    pts = shapely.points(np.column_stack([mp.xy, np.nan_to_num(mp.height, nan=0.0)]))
    layers.append(
        (
            "map_points",
            "Point Z",
            pts,
            {
                "road": mp.road,
                "polygon": ids[mp.polygon],
                "height": mp.height,
                "sigma": mp.sigma,
                "sigma_plane": mp.sigma_plane,
                "sigma_block": mp.sigma_block,
                "sigma_model": mp.sigma_model,
                "distance": mp.distance,
                "n_points": mp.n_points,
                "failed": mp.failed.astype(np.int32),
                "reason": mp.reason.astype(str).astype(object),
                "x_laser": mp.xy_laser[:, 0],
                "y_laser": mp.xy_laser[:, 1],
            },
        )
    )
    polys = recon.polygons_3d()
    polys = [shapely.force_3d(g) if g is not None else g for g in polys]
    keep = np.array([g is not None for g in polys])
    multi = any(g is not None and g.geom_type == "MultiPolygon" for g in polys)
    if multi:  # one geometry type per layer
        polys = [
            shapely.multipolygons([g]) if g is not None and g.geom_type == "Polygon" else g
            for g in polys
        ]
    layers.append(
        (
            "polygons_3d",
            "MultiPolygon Z" if multi else "Polygon Z",
            np.asarray(polys, dtype=object)[keep],
            {
                "id": ids[keep],
                "road": recon.polygon_road[keep],
                "status": recon.polygon_status[keep].astype(str).astype(object),
                "level": recon.polygon_level[keep],
                "n_points": recon.polygon_points[keep],
                "n_other_level": recon.polygon_other[keep],
            },
        )
    )
    tri = recon.triangles_3d()
    troad = mp.road[recon.triangles[:, 0]] if len(recon.triangles) else np.empty(0, np.int64)
    layers.append(("tin", "Polygon Z", np.asarray(tri, dtype=object), {"road": troad}))
    crs_wkt = crs.to_wkt() if crs is not None else None
    with atomic_path(p, overwrite=overwrite) as tmp:
        target = tmp.with_suffix(".gpkg")
        try:
            for i, (name, gtype, geoms, fields) in enumerate(layers):
                names = list(fields)
                arrays = [np.asarray(fields[n]) for n in names]
                wkb = (
                    shapely.to_wkb(geoms, output_dimension=3)
                    if len(geoms)
                    else np.empty(0, dtype=object)
                )
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message=".*'crs' was not provided.*")
                    pyogrio.raw.write(
                        str(target),
                        wkb,
                        geometry_type=gtype,
                        field_data=arrays,
                        fields=names,
                        crs=crs_wkt,
                        driver="GPKG",
                        layer=name,
                        encoding="UTF-8",
                        append=i > 0,
                    )
            os.replace(target, tmp)
        except WriteError:
            raise
        except Exception as exc:
            raise WriteError(f"cannot write {p}: {exc}") from exc
        finally:
            if target.exists():
                target.unlink()
    return p
