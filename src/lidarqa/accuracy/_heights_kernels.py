"""Vectorised kernels behind :mod:`lidarqa.accuracy.heights` (:ref:`alg-heights`).

Internals: inputs are trusted (validated in ``heights.py``). No Python loop per
map point or reference point: one cKDTree k-NN query, one ball query, stacked
normal equations reduced with ``np.bincount`` and closed-form 2x2 inverses,
one Delaunay ``find_simplex``.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

EPS = 1e-9
COND_MAX = 1e12

# reasons a map point is not fitted
OK = ""
TOO_FEW = "too_few_points"
TOO_FEW_SEGMENT = "too_few_segment_points"
COLLINEAR = "collinear"


def growth_radius(
    need: np.ndarray, *, radius: float, max_radius: float, growth: float | None
) -> np.ndarray:
    """Smallest radius level radius·growth**j (capped at max_radius) that is >= `need`."""
    need = np.maximum(need, radius)
    if growth is None:
        r = need
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            j = np.ceil(np.log(need / radius) / np.log(growth) - 1e-12)
        j = np.maximum(np.nan_to_num(j, nan=0.0, posinf=0.0), 0.0)
        r = radius * growth**j
        r = np.where(r < need, r * growth, r)
    return np.minimum(r, max_radius)


def neighbourhoods(
    tree: cKDTree | None,
    map_xy: np.ndarray,
    *,
    radius: float,
    max_radius: float,
    min_points: int,
    growth: float | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Laser points used per map point.

    Returns ``(group, index, radius_used, n_found)``: flat arrays of (map point,
    laser point) pairs sorted by map point, the radius used per map point (NaN
    when fewer than `min_points` lie within `max_radius`) and the number of
    laser points found (within `max_radius` for failed map points).
    """
    m = len(map_xy)
    r_used = np.full(m, np.nan)
    n_found = np.zeros(m, dtype=np.int64)
    if tree is None or tree.n == 0 or m == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64), r_used, n_found
    bound = max_radius * (1 + 1e-12)
    dk, _ = tree.query(map_xy, k=[min_points], distance_upper_bound=bound, workers=-1)
    dk = dk[:, 0]
    ok = np.isfinite(dk)
    r_used[ok] = growth_radius(dk[ok], radius=radius, max_radius=max_radius, growth=growth)
    if (~ok).any():
        n_found[~ok] = tree.query_ball_point(map_xy[~ok], bound, return_length=True, workers=-1)
    if not ok.any():
        return np.empty(0, np.int64), np.empty(0, np.int64), r_used, n_found
    ok_idx = np.flatnonzero(ok)
    lists = tree.query_ball_point(
        map_xy[ok_idx], r_used[ok_idx] * (1 + 1e-9), workers=-1, return_sorted=False
    )
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    index = np.fromiter(
        itertools.chain.from_iterable(lists), dtype=np.int64, count=int(counts.sum())
    )
    group = np.repeat(ok_idx, counts)
    n_found[ok_idx] = counts
    return group, index, r_used, n_found


def largest_segment_filter(
    group: np.ndarray, labels_of_entries: np.ndarray, n_groups: int
) -> np.ndarray:
    """Mask of entries whose segment label is the most frequent one of their group.

    Unsegmented entries (label < 0) are dropped; ties go to the smaller label.
    """
    keep = labels_of_entries >= 0
    if not keep.any():
        return keep
    g = group[keep]
    lab = labels_of_entries[keep]
    pairs, counts = np.unique(np.column_stack([g, lab]), axis=0, return_counts=True)
    # per group: max count, then smallest label (pairs are sorted by group, label)
    order = np.lexsort((pairs[:, 1], -counts, pairs[:, 0]))
    pairs = pairs[order]
    first = np.ones(len(pairs), dtype=bool)
    first[1:] = pairs[1:, 0] != pairs[:-1, 0]
    best = np.full(n_groups, -2, dtype=np.int64)
    best[pairs[first, 0]] = pairs[first, 1]
    out = np.zeros(len(group), dtype=bool)
    out[keep] = lab == best[g]
    return out


def fit_planes(
    xyz: np.ndarray,
    group: np.ndarray,
    map_xy: np.ndarray,
    *,
    sigma_z: float,
    posterior: bool,
    eq8_diagonal: bool,
    min_points: int,
) -> dict[str, np.ndarray]:
    """Batched least-squares planes z = −x·p1 − y·p2 + p3, centred per group.

    `xyz` holds the laser points of each entry (gathered), `group` the map point
    of each entry. Groups with fewer than `min_points` entries or a singular
    configuration (condition number of AᵀA > 1e12) get NaN and a reason.
    """
    m = len(map_xy)
    n = np.bincount(group, minlength=m).astype(np.float64)
    has = n > 0
    nn = np.where(has, n, 1.0)
    # relative to the map point first (UTM-sized coordinates), then centred
    rx = xyz[:, 0] - map_xy[group, 0]
    ry = xyz[:, 1] - map_xy[group, 1]
    mx = np.bincount(group, rx, minlength=m) / nn
    my = np.bincount(group, ry, minlength=m) / nn
    mz = np.bincount(group, xyz[:, 2], minlength=m) / nn
    dx = rx - mx[group]
    dy = ry - my[group]
    dz = xyz[:, 2] - mz[group]
    sxx = np.bincount(group, dx * dx, minlength=m)
    syy = np.bincount(group, dy * dy, minlength=m)
    sxy = np.bincount(group, dx * dy, minlength=m)
    sxz = np.bincount(group, dx * dz, minlength=m)
    syz = np.bincount(group, dy * dz, minlength=m)
    det = sxx * syy - sxy * sxy
    half_tr = 0.5 * (sxx + syy)
    lam_max = half_tr + np.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam_min = det / lam_max
        cond = np.maximum(lam_max, n) / np.minimum(lam_min, n)
    enough = n >= max(min_points, 3)
    good = enough & (lam_min > 0) & (cond <= COND_MAX)
    reason = np.where(~enough, TOO_FEW, np.where(good, OK, COLLINEAR)).astype(object)
    d = np.where(good, det, np.nan)
    # normal equations for (p1, p2): M p = g with M = [[sxx, sxy], [sxy, syy]], g = −(sxz, syz)
    gx, gy = -sxz, -syz
    p1 = (syy * gx - sxy * gy) / d
    p2 = (sxx * gy - sxy * gx) / d
    p3 = np.where(good, mz, np.nan)
    # map point relative to the centroid
    ddx, ddy = -mx, -my
    height = -ddx * p1 - ddy * p2 + p3
    if posterior:
        r = dz + dx * p1[group] + dy * p2[group]
        rr = np.bincount(group, r * r, minlength=m)
        with np.errstate(divide="ignore", invalid="ignore"):
            s2 = np.where(n > 3, rr / (n - 3), np.nan)
    else:
        s2 = np.full(m, sigma_z**2)
    q11, q22, q12 = syy / d, sxx / d, -sxy / d
    if eq8_diagonal:
        quad = ddx * ddx * q11 + ddy * ddy * q22
    else:
        quad = ddx * ddx * q11 + 2 * ddx * ddy * q12 + ddy * ddy * q22
    var_plane = s2 * (quad + 1.0 / nn)
    var_plane = np.where(good, var_plane, np.nan)
    return {
        "height": height,
        "sigma_plane": np.sqrt(var_plane),
        "n_used": n.astype(np.int64),
        "centroid_offset": np.column_stack([mx, my]),
        "distance": np.where(has, np.hypot(mx, my), np.nan),
        "p": np.column_stack([p1, p2, p3]),
        "q": np.stack([s2 * q11, s2 * q12, s2 * q22, s2 / nn], axis=1),
        "sigma0": np.sqrt(s2),
        "good": good,
        "reason": reason,
    }


def nearest_used_distance(xyz: np.ndarray, group: np.ndarray, map_xy: np.ndarray) -> np.ndarray:
    """Horizontal distance from each map point to its nearest used laser point."""
    m = len(map_xy)
    out = np.full(m, np.inf)
    if len(group):
        d = np.hypot(xyz[:, 0] - map_xy[group, 0], xyz[:, 1] - map_xy[group, 1])
        np.minimum.at(out, group, d)
    out[~np.isfinite(out)] = np.nan
    return out


def tin_variance(weights: np.ndarray, sigmas: np.ndarray, correlation: float) -> np.ndarray:
    """σ_h² = Σ w²σ² + 2ρ Σ_{k<l} w_k w_l σ_k σ_l = (1−ρ)Σ(wσ)² + ρ(Σ wσ)²."""
    ws = weights * sigmas
    return (1.0 - correlation) * np.sum(ws * ws, axis=-1) + correlation * np.sum(ws, axis=-1) ** 2


def _cross(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray) -> np.ndarray:
    """Twice the signed area of the triangles (p1, p2, p3), row-wise."""
    return (p2[:, 0] - p1[:, 0]) * (p3[:, 1] - p1[:, 1]) - (p2[:, 1] - p1[:, 1]) * (
        p3[:, 0] - p1[:, 0]
    )


def locate(tri: Any, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Containing triangle and barycentric weights per query point (-1 / NaN outside).

    A vectorised visibility walk over the Delaunay neighbours, starting at a
    triangle of each query's nearest vertex, so walks are a few steps long.
    (scipy's ``find_simplex`` walks from one fixed triangle and is ~100x
    slower for 10^5 vertices.) The walk terminates on a Delaunay
    triangulation; queries still unresolved after ``len(simplices)`` steps fall
    back to ``find_simplex``.
    """
    pts, simp, nb = tri.points, tri.simplices, tri.neighbors
    r = len(query)
    found = np.full(r, -1, dtype=np.int64)
    weights = np.full((r, 3), np.nan)
    _, near = cKDTree(pts).query(query)
    cur = tri.vertex_to_simplex[near].astype(np.int64)
    cur[cur < 0] = 0
    active = np.arange(r)
    for _ in range(len(simp) + 1):
        if active.size == 0:
            break
        s = cur[active]
        a, b, c, x = pts[simp[s, 0]], pts[simp[s, 1]], pts[simp[s, 2]], query[active]
        area = _cross(a, b, c)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (
                np.column_stack([_cross(x, b, c), _cross(a, x, c), _cross(a, b, x)]) / area[:, None]
            )
        j = np.argmin(np.nan_to_num(lam, nan=-np.inf), axis=1)
        inside = lam[np.arange(len(s)), j] >= -1e-12
        found[active[inside]] = s[inside]
        weights[active[inside]] = lam[inside]
        moving = active[~inside]
        nxt = nb[s[~inside], j[~inside]]
        cur[moving] = nxt
        active = moving[nxt >= 0]
    if active.size:  # pragma: no cover - not expected on a Delaunay triangulation
        s = tri.find_simplex(query[active])
        ok = s >= 0
        found[active[ok]] = s[ok]
        t = tri.transform[s[ok]]
        bary = np.einsum("ijk,ik->ij", t[:, :2, :], query[active[ok]] - t[:, 2, :])
        weights[active[ok]] = np.column_stack([bary, 1.0 - bary.sum(axis=1)])
    return found, weights


def triangulate_locate(
    vertex_xy: np.ndarray, query_xy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Delaunay TIN over `vertex_xy`; containing triangle and barycentric weights per query.

    Returns ``(vertices (R,3) int64, weights (R,3))`` with -1 / NaN outside the
    TIN or in a triangle of area < EPS, and whether a TIN could be built.
    Vertices are put in a canonical (x, y) order first, so the triangulation of
    cocircular points does not depend on the input order.
    """
    from scipy.spatial import Delaunay, QhullError

    r = len(query_xy)
    verts = np.full((r, 3), -1, dtype=np.int64)
    weights = np.full((r, 3), np.nan)
    if len(vertex_xy) < 3:
        return verts, weights, False
    order = np.lexsort((vertex_xy[:, 1], vertex_xy[:, 0]))
    origin = vertex_xy[order[0]]
    try:
        tri = Delaunay(vertex_xy[order] - origin)
    except (QhullError, ValueError):
        return verts, weights, False
    if r == 0:
        return verts, weights, True
    simplex, w = locate(tri, query_xy - origin)
    inside = simplex >= 0
    s = simplex[inside]
    corners = tri.points[tri.simplices[s]]
    area = 0.5 * np.abs(_cross(corners[:, 0], corners[:, 1], corners[:, 2]))
    ok = (area >= EPS) & np.isfinite(w[inside]).all(axis=1)
    rows = np.flatnonzero(inside)[ok]
    # each triangle's vertices in (x, y) order and its weights recomputed from coordinate
    # differences (exact for nearby points): the same bits whatever subset of vertices (a chunk of
    # a catalog) was triangulated and whatever origin it was shifted by
    vs = order[tri.simplices[s[ok]]]
    cxy = vertex_xy[vs]
    vs = np.take_along_axis(vs, np.lexsort((cxy[..., 1], cxy[..., 0]), axis=-1), axis=-1)
    cxy = vertex_xy[vs]
    a = cxy[:, 0]
    v0, v1, v2 = cxy[:, 1] - a, cxy[:, 2] - a, query_xy[rows] - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    wb = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    wc = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    verts[rows] = vs
    weights[rows] = np.column_stack([1.0 - wb - wc, wb, wc])
    return verts, weights, True


def data_snooping(
    dh: np.ndarray, sigma: np.ndarray, *, critical: float, estimate_offset: bool
) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Iterative data snooping (Baarda): flag max |w| > k, remove, repeat.

    Returns ``(w, outlier, n_passes, offset)``. With ``estimate_offset=False``
    the w values do not change between passes, so the loop is one-pass
    thresholding (the pass count is still that of the iterative procedure).
    With ``estimate_offset=True`` a weighted mean offset is re-estimated on
    the retained points and w uses the redundancy-corrected residual σ; the
    w of a flagged point is the value it had when it was flagged.
    """
    n = len(dh)
    outlier = np.zeros(n, dtype=bool)
    if n == 0:
        return np.empty(0), outlier, 0, float("nan")
    if not estimate_offset:
        w = dh / sigma
        outlier = np.abs(w) > critical
        return w, outlier, int(outlier.sum()) + 1, 0.0
    w = np.full(n, np.nan)
    keep = np.ones(n, dtype=bool)
    passes = 0
    offset = float("nan")
    inv = 1.0 / sigma**2
    while keep.any():
        passes += 1
        wsum = inv[keep].sum()
        offset = float(np.sum(dh[keep] * inv[keep]) / wsum)
        var_res = sigma[keep] ** 2 - 1.0 / wsum
        with np.errstate(divide="ignore", invalid="ignore"):
            wk = (dh[keep] - offset) / np.sqrt(var_res)
        wk = np.where(var_res > 0, wk, 0.0)  # a single retained point has no redundancy
        idx = np.flatnonzero(keep)
        w[idx] = wk
        j = int(np.argmax(np.abs(wk)))  # first occurrence = smaller index
        if abs(wk[j]) > critical:
            outlier[idx[j]] = True
            keep[idx[j]] = False
        else:
            break
    return w, outlier, passes, offset
