"""Edges as intersections of adjacent planes, bounded by their support (:ref:`alg-edges`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_points, check_positive, check_range
from ..errors import DegenerateGeometryError, OptionError
from ..io.vector import Segments
from .planes import PlaneFit
from .segmentation import PlaneSegmentation, segment_planes

__all__ = ["PlanePairSegment", "plane_pair_segment", "extract_edges", "edges_from_segmentation",
           "step_segments", "EDGE_ATTRIBUTES"]

EDGE_ATTRIBUTES = ("plane_a", "plane_b", "angle_deg", "support_a", "support_b", "sigma_line",
                   "sigma_line_max", "length")


@dataclass(frozen=True, eq=False)
class PlanePairSegment:
    """A 3D segment on the intersection line of two planes.

    Attributes
    ----------
    start, end : ndarray of shape (3,)
        Endpoints (m); `start` is the lexicographically smaller (x, then y, then z).
    direction : ndarray of shape (3,)
        Unit direction of the line, from `start` to `end`.
    point : ndarray of shape (3,)
        Point of the line nearest the midpoint of the two plane centroids (m).
    angle_deg : float
        Angle between the two plane normals, in [0, 90] degrees.
    support_a, support_b : int
        Points of each plane within `near_dist` of the line.
    """

    start: np.ndarray
    end: np.ndarray
    direction: np.ndarray
    point: np.ndarray
    angle_deg: float
    support_a: int
    support_b: int

    @property
    def length(self) -> float:
        """Length of the edge segment, in metres."""
        return float(np.linalg.norm(self.end - self.start))

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {"start": self.start.tolist(), "end": self.end.tolist(),
                "direction": self.direction.tolist(), "angle_deg": self.angle_deg,
                "support_a": self.support_a, "support_b": self.support_b, "length": self.length}


def _plane_tuple(pl: Any) -> tuple[np.ndarray, float]:
    if isinstance(pl, PlaneFit):
        return np.asarray(pl.normal, float), float(pl.rho)
    if hasattr(pl, "normal") and hasattr(pl, "rho"):
        return np.asarray(pl.normal, float), float(pl.rho)
    try:
        n, rho = pl
    except (TypeError, ValueError) as exc:
        raise OptionError("a plane must be a PlaneFit or a (normal, rho) pair") from exc
    return np.asarray(n, float).reshape(3), float(rho)


def _unit(n: np.ndarray, name: str) -> np.ndarray:
    ln = float(np.linalg.norm(n))
    if not np.isfinite(ln) or ln < 1e-12:
        raise DegenerateGeometryError(f"{name}: the plane normal is zero or not finite")
    return n / ln


def _line(n1: np.ndarray, rho1: float, n2: np.ndarray, rho2: float, c: np.ndarray,
          min_angle: float) -> tuple[np.ndarray, np.ndarray, float] | None:
    cr = np.cross(n1, n2)
    s = float(np.linalg.norm(cr))
    if s < math.sin(math.radians(min_angle)):
        return None
    u = cr / s
    a = np.vstack([n1, n2, u])
    x0 = np.linalg.solve(a, np.array([rho1, rho2, u @ c]))
    return u, x0, math.degrees(math.asin(min(1.0, s)))


def plane_pair_segment(
    pl1: Any,
    pts1: Any,
    pl2: Any,
    pts2: Any,
    *,
    near_dist: float = 0.10,
    min_angle: float = 5.0,
    q_lo: float = 0.0,
    q_hi: float = 1.0,
    min_support: int = 5,
    return_reason: bool = False,
) -> PlanePairSegment | None | tuple[PlanePairSegment | None, str]:
    """Intersect two planes and bound the line by their supporting points (:ref:`alg-edges`).

    Parameters
    ----------
    pl1, pl2 : PlaneFit or (normal, rho)
        The planes ``normal · p = rho``; normals need not be unit.
    pts1, pts2 : ndarray of shape (N1, 3), (N2, 3)
        Inlier points of each plane (m).
    near_dist : float, default 0.10
        Points within this distance (m) of the line support it.
    min_angle : float, default 5.0
        Planes closer than this angle (degrees) are near-parallel: no segment.
    q_lo, q_hi : float, default 0.0 and 1.0
        Quantiles of the supporting points' positions along the line that bound
        each plane's interval.
    min_support : int, default 5
        Supporting points needed on each plane.
    return_reason : bool, default False
        Also return why no segment was made ("" when one was).

    Returns
    -------
    PlanePairSegment or None
        None when the planes are near-parallel, a plane has fewer than
        `min_support` supporting points, or the two support intervals do not
        overlap (the segment is their intersection). With `return_reason`, a
        ``(segment, reason)`` tuple.

    Examples
    --------
    >>> g = np.arange(0, 5.01, 1.0)
    >>> a = np.array([[x, y, 0.] for x in g for y in np.arange(1, 8.01)])
    >>> b = np.array([[0., y, z] for y in np.arange(2, 9.01) for z in g[:4]])
    >>> s = plane_pair_segment(((0, 0, 1), 0), a, ((1, 0, 0), 0), b, min_support=2)
    >>> s.start.tolist(), s.end.tolist()
    ([0.0, 2.0, 0.0], [0.0, 8.0, 0.0])
    """
    n1, rho1 = _plane_tuple(pl1)
    n2, rho2 = _plane_tuple(pl2)
    s1, s2 = float(np.linalg.norm(n1)), float(np.linalg.norm(n2))
    n1, n2 = _unit(n1, "pl1"), _unit(n2, "pl2")
    rho1, rho2 = rho1 / s1, rho2 / s2
    p1 = as_points(pts1, "pts1", min_points=1)
    p2 = as_points(pts2, "pts2", min_points=1)
    near_dist = check_positive(near_dist, "near_dist")
    min_angle = check_range(min_angle, "min_angle", 0.0, 90.0)
    q_lo = check_range(q_lo, "q_lo", 0.0, 1.0)
    q_hi = check_range(q_hi, "q_hi", 0.0, 1.0)
    if q_lo > q_hi:
        raise OptionError(f"q_lo must be <= q_hi, got {q_lo} > {q_hi}")
    seg, reason = _pair_segment(n1, rho1, p1, n2, rho2, p2, p1.mean(axis=0), p2.mean(axis=0),
                                near_dist, min_angle, q_lo, q_hi, int(min_support))
    return (seg, reason) if return_reason else seg


def _pair_segment(n1, rho1, p1, n2, rho2, p2, c1, c2, near_dist, min_angle, q_lo, q_hi,
                  min_support):
    """Core of :func:`plane_pair_segment` on validated input: (segment or None, reason)."""
    c = (c1 + c2) / 2.0
    line = _line(n1, rho1, n2, rho2, c, min_angle)
    if line is None:
        return None, "near-parallel"
    u, x0, angle = line
    tol = near_dist + 1e-12 * max(1.0, near_dist)
    ivals = []
    supports = []
    for p in (p1, p2):
        d = p - x0
        t = d @ u
        perp = d - t[:, None] * u
        near = np.einsum("ij,ij->i", perp, perp) <= tol * tol
        supports.append(int(near.sum()))
        if near.sum() < max(min_support, 1):
            return None, "too little support"
        tn = t[near]
        lo = np.quantile(tn, q_lo) if q_lo > 0 else tn.min()
        hi = np.quantile(tn, q_hi) if q_hi < 1 else tn.max()
        ivals.append((lo, hi))
    lo = max(ivals[0][0], ivals[1][0])
    hi = min(ivals[0][1], ivals[1][1])
    if not lo < hi:
        return None, "supports do not overlap"
    a = x0 + lo * u
    b = x0 + hi * u
    if tuple(b) < tuple(a):
        a, b = b, a
    direction = (b - a) / np.linalg.norm(b - a)
    return PlanePairSegment(start=a, end=b, direction=direction, point=x0, angle_deg=angle,
                            support_a=supports[0], support_b=supports[1]), ""


def line_sigma(n1: np.ndarray, n2: np.ndarray, var1: np.ndarray, var2: np.ndarray) -> np.ndarray:
    """Standard deviation (m) of a two-plane line's position, perpendicular to the line.

    `var1`, `var2` are the variances (m²) of each plane's position along its normal
    at the evaluation points (see :func:`~lidarqa.geometry.planes.plane_covariance`);
    the displacement of the line is the minimum-norm solution of
    ``[n1; n2] δx = [δ1; δ2]``, so ``Σ = A⁺ diag(var) A⁺ᵀ`` and σ = sqrt(trace Σ).
    """
    a = np.vstack([n1, n2])
    pinv = np.linalg.pinv(a)  # (3, 2)
    g = pinv.T @ pinv  # (2, 2): trace(A⁺ D A⁺ᵀ) = Σ_k D_k (A⁺ᵀA⁺)_kk
    return np.sqrt(np.maximum(np.asarray(var1) * g[0, 0] + np.asarray(var2) * g[1, 1], 0.0))


def _plane_var(seg: PlaneSegmentation, k: int, x: np.ndarray) -> np.ndarray:
    d = x - seg.centroid[k]
    c = seg.covariance[k]
    return c[3, 3] + np.einsum("...i,ij,...j->...", d, c[:3, :3], d)


def auto_near_dist(seg: PlaneSegmentation) -> float:
    """Default support distance (m): 1.2 x the point spacing, clipped to [0.15, 1]."""
    sp = seg.parameters.get("point_spacing")
    if sp is None or not np.isfinite(sp):
        return 0.15
    return float(np.clip(1.2 * sp, 0.15, 1.0))


def edges_from_segmentation(
    points: np.ndarray,
    seg: PlaneSegmentation,
    *,
    near_dist: float | None = None,
    min_angle: float = 10.0,
    q_lo: float = 0.0,
    q_hi: float = 1.0,
    min_support: int = 5,
    min_length: float = 0.5,
    crs: Any = None,
) -> tuple[Segments, list[dict]]:
    """Edges of every adjacent, non-near-parallel segment pair of a segmentation.

    Supporting points of a pair are taken among the inliers of each plane that
    touch the other segment (the contact points of the adjacency), which keeps
    the cost proportional to the segment boundaries. Returns the edges and a
    list of the pairs that were skipped, each with its reason.
    """
    pts = np.asarray(points, dtype=np.float64)
    if near_dist is None:
        near_dist = auto_near_dist(seg)
    rows = []
    skipped = []
    sin_min = math.sin(math.radians(min_angle))
    inl = seg.inliers
    for m, (a, b) in enumerate(seg.adjacency):
        na, nb = seg.normal[a], seg.normal[b]
        if np.linalg.norm(np.cross(na, nb)) < sin_min:
            skipped.append({"plane_a": int(a), "plane_b": int(b), "reason": "near-parallel"})
            continue
        ci = seg.contact_i[seg.contact_ptr[m]:seg.contact_ptr[m + 1]]
        cj = seg.contact_j[seg.contact_ptr[m]:seg.contact_ptr[m + 1]]
        idx = np.unique(np.concatenate([ci, cj]))
        idx = idx[inl[idx]]
        lab = seg.labels[idx]
        pa, pb = pts[idx[lab == a]], pts[idx[lab == b]]
        if len(pa) == 0 or len(pb) == 0:
            skipped.append({"plane_a": int(a), "plane_b": int(b), "reason": "too little support"})
            continue
        # reference point: midpoint of the contact centroids (the edge region), not of the
        # whole planes, so x0 lies near the observed edge
        s, reason = _pair_segment(na, seg.rho[a], pa, nb, seg.rho[b], pb, pa.mean(axis=0),
                                  pb.mean(axis=0), near_dist, min_angle, q_lo, q_hi, min_support)
        if s is None:
            skipped.append({"plane_a": int(a), "plane_b": int(b), "reason": reason})
            continue
        if s.length < min_length:
            skipped.append({"plane_a": int(a), "plane_b": int(b),
                            "reason": "shorter than min_length"})
            continue
        ends = np.stack([s.start, (s.start + s.end) / 2.0, s.end])
        sig = line_sigma(na, nb, _plane_var(seg, a, ends), _plane_var(seg, b, ends))
        if not (np.isfinite(s.start).all() and np.isfinite(s.end).all()):
            skipped.append({"plane_a": int(a), "plane_b": int(b), "reason": "not finite"})
            continue
        rows.append((s, int(a), int(b), float(sig[1]), float(sig.max())))
    n = len(rows)
    edges = Segments(
        ids=np.arange(n, dtype=np.int64),
        start=np.array([r[0].start for r in rows]).reshape(n, 3),
        end=np.array([r[0].end for r in rows]).reshape(n, 3),
        attributes={
            "plane_a": np.array([r[1] for r in rows], dtype=np.int64),
            "plane_b": np.array([r[2] for r in rows], dtype=np.int64),
            "angle_deg": np.array([r[0].angle_deg for r in rows], dtype=np.float64),
            "support_a": np.array([r[0].support_a for r in rows], dtype=np.int64),
            "support_b": np.array([r[0].support_b for r in rows], dtype=np.int64),
            "sigma_line": np.array([r[3] for r in rows], dtype=np.float64),
            "sigma_line_max": np.array([r[4] for r in rows], dtype=np.float64),
            "length": np.array([r[0].length for r in rows], dtype=np.float64),
        },
        crs=crs,
    )
    return edges, skipped


def _simplify_closed(poly: np.ndarray, tolerance: float) -> np.ndarray:
    """Douglas-Peucker on a closed 2-D polygon (vertex order kept); indices of kept vertices."""
    n = len(poly)
    keep = np.zeros(n, dtype=bool)
    d = np.linalg.norm(poly[:, None] - poly[None], axis=2)
    i, j = (int(v) for v in np.unravel_index(int(d.argmax()), d.shape))
    keep[[i, j]] = True
    stack = [(i, j), (j, i)]
    while stack:
        a, b = stack.pop()
        idx = [(a + k) % n for k in range(1, (b - a) % n)]
        if not idx:
            continue
        v = poly[b] - poly[a]
        w = poly[idx] - poly[a]
        dist = np.abs(v[0] * w[:, 1] - v[1] * w[:, 0]) / max(float(np.hypot(*v)), 1e-12)
        k = int(np.argmax(dist))
        if dist[k] > tolerance:
            m = idx[k]
            keep[m] = True
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep)


def outline_segments(
    points: np.ndarray,
    seg: PlaneSegmentation,
    *,
    min_length: float = 2.0,
    tolerance: float = 0.3,
    min_points: int = 30,
    max_slope: float = 75.0,
) -> list[tuple[np.ndarray, np.ndarray, int, int]]:
    """Outline sides of each non-vertical plane segment: ``[(start, end, plane, n_points)]``.

    Airborne scans rarely sample walls, so roof-wall and step edges have no
    second plane to intersect with. The outline of a roof plane stands in for
    them: the 2-D convex hull of the plane's inliers, simplified (Douglas-Peucker,
    `tolerance` m), each side of at least `min_length` m lifted onto the plane.
    The sides lie up to about half a point spacing inside the true outline, and
    a concave roof gets its hull's chord: outlines suit strip-to-strip
    repeatability, where both strips see the same roof the same way.
    """
    from scipy.spatial import ConvexHull, QhullError

    rows = []
    nz_min = math.cos(math.radians(max_slope))
    for k in range(len(seg.normal)):
        m = (seg.labels == k) & seg.inliers
        n = seg.normal[k]
        if m.sum() < min_points or abs(n[2]) < nz_min:
            continue
        xy = points[m, :2]
        try:
            hull = ConvexHull(xy)
        except QhullError:
            continue
        poly = xy[hull.vertices]
        v = poly[_simplify_closed(poly, tolerance)]
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            if np.hypot(*(b - a)) < min_length:
                continue
            ends = np.array([a, b])
            z = (seg.rho[k] - ends @ n[:2]) / n[2]
            rows.append((np.r_[a, z[0]], np.r_[b, z[1]], k, int(m.sum())))
    return rows


def _near_any(start: np.ndarray, end: np.ndarray, edges: Segments, dist: float) -> bool:
    """Whether segment start-end runs along one of `edges` (midpoint within `dist`, < 10°)."""
    if len(edges) == 0:
        return False
    mid = 0.5 * (start + end)
    d = end - start
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    e = edges.end - edges.start
    length = np.maximum(np.linalg.norm(e, axis=1), 1e-12)
    u = e / length[:, None]
    t = np.clip(np.einsum("ij,ij->i", mid - edges.start, u), 0.0, length)
    gap = np.linalg.norm(mid - (edges.start + t[:, None] * u), axis=1)
    parallel = np.abs(u @ d) >= math.cos(math.radians(10.0))
    return bool(np.any((gap <= dist) & parallel))


def extract_edges(
    points: Any,
    *,
    segmentation: PlaneSegmentation | None = None,
    near_dist: float | None = None,
    min_angle: float = 10.0,
    q_lo: float = 0.0,
    q_hi: float = 1.0,
    min_support: int = 5,
    min_length: float = 0.5,
    crs: Any = None,
    left_out: list[dict[str, Any]] | None = None,
    outlines: bool = False,
    steps: bool = False,
    point_spacing: float | None = None,
    **segment_options: Any,
) -> Segments:
    """3D edges of a cloud: intersections of adjacent planes bounded by their support.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres (e.g. building points).
    segmentation : PlaneSegmentation, optional
        A segmentation of `points` from :func:`segment_planes`; computed with
        `segment_options` when omitted.
    near_dist : float or None, default None
        Points within this distance (m) of the intersection line support it and
        bound the edge. None adapts it to the sampling: 1.2 x the segmentation's
        ``point_spacing`` (median distance to the 10th neighbour), clipped to
        [0.15, 1] m, so sparse strips still give enough support.
    min_angle : float, default 10.0
        Pairs of planes closer than this angle (degrees) give no edge.
    q_lo, q_hi : float, default 0 and 1
        Quantiles bounding each plane's support along the line.
    min_support : int, default 5
        Supporting points needed on each plane.
    min_length : float, default 0.5
        Shorter edges (m) are dropped.
    crs : pyproj.CRS, optional
        Stored on the result.
    left_out : list, optional
        Extended with the adjacent pairs that gave no intersection edge, as
        ``{"plane_a", "plane_b", "reason"}`` (see :func:`edges_from_segmentation`).
    outlines : bool, default False
        Also return the outline sides of roof planes (:func:`outline_segments`),
        which stand in for roof-wall and step edges that airborne scans leave
        without a wall plane; the result then has a ``kind`` attribute
        (``"intersection"`` or ``"outline"``). Outline sides along an
        intersection edge are dropped.
    steps : bool, default False
        Also return step edges (:func:`step_segments`): straight runs of roof
        boundary points where the surface next to the roof is lower by at
        least 0.5 m or absent (thin or unseen walls). ``kind`` is then
        ``"step"`` for them; steps along an intersection edge (or, with
        `outlines`, along an outline side) are dropped.

        .. versionadded:: 0.2
    point_spacing : float or None, default None
        Point spacing (m) the step edges are scaled by; None: the segmentation's
        ``point_spacing``. A catalog run fixes it once for every chunk.
    **segment_options
        Passed to :func:`~lidarqa.geometry.segmentation.segment_planes`.

    Returns
    -------
    Segments
        One edge per row, ids 0..n-1, with attributes ``plane_a, plane_b``
        (segment ids), ``angle_deg``, ``support_a, support_b``, ``sigma_line``
        (standard deviation of the line position at the midpoint, m, from the
        plane covariances), ``sigma_line_max`` (largest of start, middle, end)
        and ``length`` (m).
    """
    pts = as_points(points)
    if near_dist is not None:
        near_dist = check_positive(near_dist, "near_dist")
    min_angle = check_range(min_angle, "min_angle", 0.0, 90.0)
    q_lo = check_range(q_lo, "q_lo", 0.0, 1.0)
    q_hi = check_range(q_hi, "q_hi", 0.0, 1.0)
    min_length = check_positive(min_length, "min_length", allow_zero=True)
    if segmentation is None:
        segmentation = segment_planes(pts, **segment_options)
    elif len(segmentation.labels) != len(pts):
        raise OptionError("segmentation was computed for a different number of points")
    if near_dist is None:
        near_dist = auto_near_dist(segmentation)
    edges, skipped = edges_from_segmentation(pts, segmentation, near_dist=near_dist,
                                             min_angle=min_angle, q_lo=q_lo, q_hi=q_hi,
                                             min_support=int(min_support),
                                             min_length=min_length, crs=crs)
    if left_out is not None:
        left_out.extend(skipped)
    if outlines:
        edges = _with_extra(edges, outline_segments(pts, segmentation), near_dist, "outline")
    if steps:
        if point_spacing is not None:
            point_spacing = check_positive(point_spacing, "point_spacing")
        edges = _with_extra(edges, step_segments(pts, segmentation, point_spacing=point_spacing),
                            near_dist, "step")
    return edges


def _with_extra(edges: Segments, rows: list, near_dist: float, kind: str) -> Segments:
    """Append one-plane segments (outline sides, steps) not running along `edges`."""
    rows = [r for r in rows if not _near_any(r[0], r[1], edges, max(2.0 * near_dist, 0.5))]
    n0, n1 = len(edges), len(rows)
    start = np.vstack([edges.start, np.array([r[0] for r in rows]).reshape(n1, 3)])
    end = np.vstack([edges.end, np.array([r[1] for r in rows]).reshape(n1, 3)])
    nan = np.full(n1, np.nan)
    extra = {
        "plane_a": np.array([r[2] for r in rows], dtype=np.int64),
        "plane_b": np.full(n1, -1, dtype=np.int64),
        "angle_deg": nan,
        "support_a": np.array([r[3] for r in rows], dtype=np.int64),
        "support_b": np.zeros(n1, dtype=np.int64),
        "sigma_line": nan,
        "sigma_line_max": nan,
        "length": np.linalg.norm(end[n0:] - start[n0:], axis=1),
    }
    attrs = {k: np.concatenate([edges.attributes[k], extra[k]]) for k in EDGE_ATTRIBUTES}
    old = edges.attributes.get("kind", np.array(["intersection"] * n0, dtype=object))
    attrs["kind"] = np.concatenate([np.asarray(old, dtype=object),
                                    np.array([kind] * n1, dtype=object)])
    return Segments(ids=np.arange(n0 + n1, dtype=np.int64), start=start, end=end,
                    attributes=attrs, crs=edges.crs)


# ---------------------------------------------------------------- step edges


def _boundary_gaps(xy: np.ndarray, radius: float, min_gap_deg: float, k: int = 16
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Boundary points of a 2-D point set: ``(is_boundary, gap direction (n, 2))``.

    A point is on the boundary when its neighbours within `radius` leave an
    angular gap wider than `min_gap_deg`; the gap direction is the unit vector
    through the middle of the widest gap (pointing out of the set).
    """
    from scipy.spatial import cKDTree

    n = len(xy)
    kk = min(k + 1, n)
    d, j = cKDTree(xy).query(xy, k=kk, distance_upper_bound=radius)
    d, j = d[:, 1:], j[:, 1:]
    ok = np.isfinite(d)
    jj = np.where(ok, j, 0)
    v = xy[jj] - xy[:, None, :]
    none = 100.0  # sorts after every angle (radians)
    ang = np.where(ok, np.arctan2(v[..., 1], v[..., 0]), none)
    ang.sort(axis=1)
    m = ok.sum(axis=1)
    gap = np.full(n, 2 * np.pi)
    mid = np.zeros(n)
    if ang.shape[1] > 0:
        nxt = np.concatenate([ang[:, 1:], np.full((n, 1), none)], axis=1)
        inner = np.where(nxt < none, nxt - ang, -1.0)
        last = np.take_along_axis(ang, np.maximum(m - 1, 0)[:, None], axis=1)[:, 0]
        wrap = np.where(m > 0, ang[:, 0] + 2 * np.pi - last, 2 * np.pi)
        ki = np.argmax(inner, axis=1)
        gi = inner[np.arange(n), ki]
        use_wrap = wrap >= gi
        gap = np.where(use_wrap, wrap, gi)
        start = np.where(use_wrap, last, ang[np.arange(n), ki])
        mid = np.where(m > 0, start + gap / 2.0, 0.0)
    is_b = gap > math.radians(min_gap_deg)
    return is_b, np.stack([np.cos(mid), np.sin(mid)], axis=1)


def _fit_lines_2d(xy: np.ndarray, *, tolerance: float, min_points: int, max_gap: float,
                  min_length: float, rng: np.random.Generator, iterations: int = 200
                  ) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Straight runs of 2-D points by sequential RANSAC: ``[(start_xy, end_xy, n_points)]``.

    Each accepted line is refitted by least squares (principal axis) to its
    inliers, split where consecutive inliers are more than `max_gap` apart
    along it, and every run of at least `min_points` points and `min_length`
    metres becomes a segment through its extreme projections.
    """
    out: list[tuple[np.ndarray, np.ndarray, int]] = []
    left = np.ones(len(xy), dtype=bool)
    while left.sum() >= min_points:
        p = xy[left]
        n = len(p)
        a = rng.integers(0, n, iterations)
        b = rng.integers(0, n, iterations)
        d = p[b] - p[a]
        ln = np.hypot(d[:, 0], d[:, 1])
        good = ln > 1e-9
        if not good.any():
            break
        a, d, ln = a[good], d[good], ln[good]
        nrm = np.stack([-d[:, 1], d[:, 0]], axis=1) / ln[:, None]
        res = np.abs((p[None, :, :] - p[a][:, None, :]) @ nrm[..., None])[..., 0]  # (it, n)
        cnt = (res <= tolerance).sum(axis=1)
        best = int(np.argmax(cnt))
        if cnt[best] < min_points:
            break
        inl = res[best] <= tolerance
        q = p[inl]
        c = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - c, full_matrices=False)
        u = vt[0]
        inl = np.abs((p - c) @ np.array([-u[1], u[0]])) <= tolerance
        q = p[inl]
        t = (q - c) @ u
        order = np.argsort(t, kind="stable")
        t, q = t[order], q[order]
        cuts = np.flatnonzero(np.diff(t) > max_gap) + 1
        for run_t, run_q in zip(np.split(t, cuts), np.split(q, cuts), strict=True):
            if len(run_t) < min_points or run_t[-1] - run_t[0] < min_length:
                continue
            cc = run_q.mean(axis=0)
            _, _, w = np.linalg.svd(run_q - cc, full_matrices=False)
            uu = w[0]
            tt = (run_q - cc) @ uu
            out.append((cc + tt.min() * uu, cc + tt.max() * uu, len(run_t)))
        idx = np.flatnonzero(left)
        left[idx[inl]] = False
    return out


def step_segments(
    points: np.ndarray,
    seg: PlaneSegmentation,
    *,
    min_step: float = 0.5,
    min_length: float = 1.0,
    min_points: int = 6,
    max_slope: float = 75.0,
    seed: int = 0,
    point_spacing: float | None = None,
) -> list[tuple[np.ndarray, np.ndarray, int, int]]:
    """Step edges of roof planes: ``[(start, end, plane, n_points)]``.

    A step edge is where a roof plane ends and the surface next to it is lower
    by at least `min_step` metres, or absent (airborne scans see little of
    thin walls, and a selection of building points leaves the ground out).
    Boundary points of each non-vertical plane are its inliers whose
    neighbours (within twice the point spacing, in plan) leave an angular gap
    wider than 120 degrees and the plane does not resume beyond the gap (a
    hole in the sampling); a boundary point is a step point when no point
    of the cloud outside its plane lies in that gap (in the half-plane facing
    it, within the same radius) higher than the roof plus `min_step`, or
    higher than the roof minus `min_step` and more than 0.75 point spacings
    out (the top of the roof's own wall, just below the eave, does not
    count). A boundary against a higher surface is left out: there the roof meets the
    foot of a taller wall, which each strip occludes differently; a boundary
    against a surface at roof height is a ridge or an intersection, found by
    the plane-pair model. Straight runs of step points (sequential RANSAC with
    a tolerance of half the point spacing, split at gaps wider than three
    spacings) of at least `min_points` points and `min_length` metres become
    segments, lifted onto their roof plane. The line runs through the
    outermost points, so it lies about half a point spacing inside the true
    edge; both strips of a survey share that bias, which is what matters for
    strip-to-strip repeatability. `seed` makes the RANSAC sampling
    reproducible; points are put in a canonical order first, so the result
    does not depend on the input order. Each plane's sampling is seeded with
    `seed` and its first point (in x, y, z order), not with its number: a chunk
    of a catalog that sees the same roof draws the same samples. `point_spacing`
    (m) scales the radii; default the segmentation's ``point_spacing``.
    """
    from scipy.spatial import cKDTree

    sp = seg.parameters.get("point_spacing") if point_spacing is None else point_spacing
    sp = float(sp) if sp is not None and np.isfinite(sp) else 0.5
    radius = 2.0 * sp
    nz_min = math.cos(math.radians(max_slope))
    tree = cKDTree(points[:, :2])
    rows = []
    for k in range(len(seg.normal)):
        n = seg.normal[k]
        if abs(n[2]) < nz_min:
            continue
        idx = np.flatnonzero((seg.labels == k) & seg.inliers)
        if len(idx) < max(min_points, 10):
            continue
        order = np.lexsort((points[idx, 2], points[idx, 1], points[idx, 0]))
        idx = idx[order]
        xy = points[idx, :2]
        is_b, g = _boundary_gaps(xy, radius, 120.0)
        # a gap the plane itself closes further out is a hole in the sampling, not its edge
        own = cKDTree(xy)
        probe = xy + 1.5 * radius * g
        dd, _ = own.query(probe, k=1, distance_upper_bound=0.75 * radius)
        bidx = np.flatnonzero(is_b & ~np.isfinite(dd))
        if len(bidx) < min_points:
            continue
        # look for anything at roof height in the gap (half-plane facing out)
        nb = tree.query_ball_point(xy[bidx], radius)
        step = np.ones(len(bidx), dtype=bool)
        lens = np.fromiter((len(v) for v in nb), dtype=np.int64, count=len(nb))
        if lens.sum():
            flat = np.concatenate([np.asarray(v, dtype=np.int64) for v in nb])
            owner = np.repeat(np.arange(len(bidx)), lens)
            other = seg.labels[flat] != k
            rel = points[flat, :2] - xy[bidx][owner]
            out = np.einsum("ij,ij->i", rel, g[bidx][owner])  # distance out of the roof (m)
            zroof = (seg.rho[k] - points[flat, :2] @ n[:2]) / n[2]
            dz = points[flat, 2] - zroof
            # a surface continuing at roof height (beyond the eave's own wall points, which
            # hang just below it), or anything clearly above the roof
            level = (dz > -min_step) & (out > 0.75 * sp)
            above = (dz > min_step) & (out > 0)
            blocked = np.zeros(len(bidx), dtype=bool)
            np.logical_or.at(blocked, owner, other & (level | above))
            step = ~blocked
        sxy = xy[bidx[step]]
        if len(sxy) < min_points:
            continue
        rng = np.random.default_rng([seed, *points[idx[0]].astype(np.float64).view(np.uint64)])
        for a, b, cnt in _fit_lines_2d(sxy, tolerance=0.5 * sp, min_points=min_points,
                                       max_gap=3.0 * sp, min_length=min_length, rng=rng):
            ends = np.array([a, b])
            z = (seg.rho[k] - ends @ n[:2]) / n[2]
            rows.append((np.r_[a, z[0]], np.r_[b, z[1]], k, cnt))
    return rows
