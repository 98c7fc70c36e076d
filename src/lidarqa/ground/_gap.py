"""Gap test: accepted ground whose sides drop, across an unsampled gap, on opposite sides.

A bridge deck stands on piers over lower ground. Its sides are vertical drops: between
a deck's edge and the lower ground beyond it the cloud holds no return at an
intermediate height. An embankment's side is a slope and carries such returns. In a
sparse cloud (2 m between points) the two have the same grade between their nearest
returns, so the grade alone cannot tell them apart (the perched test, step 9 of
segment-PTD, does not reach a deck there); the empty corridor can.

For an accepted ground point `p` and an accepted ground point `q` within :data:`RADIUS`
m, more than `step` m lower at a grade steeper than :data:`ANGLE`, the drop p→q is
*clean* when no candidate lies in the corridor between them (strictly between the two
along the line in XY, within :data:`HALF_WIDTH` m of it) at a height in the middle of
the drop (more than :data:`BAND` of the drop above `q` and below `p`). Only drops to a
lower *surface* count: `q` needs :data:`SUPPORT` other accepted ground points within
:data:`SUPPORT_RADIUS` m at its level (within half a step), so a few low outliers the
filter accepted are no lower ground. A point is an *edge* when at least two of its steep
drops, and at least :data:`CLEAN_SHARE` of them, are clean; its drop direction is the
mean direction of its clean drops. Two edges within :data:`RADIUS` m of each other, at
the same level (within half a step), whose drops point away from each other (directions
more than 120° apart, each lying behind the other's drop) are the two sides of one raised
surface: both are rejected. A terrace edge, a cut or a pit drops to one side or inwards
(the two rims of a pit drop towards each other); an embankment's sides are not clean.

Neighbourhoods come from numba kernels over grids of the points that never hold all
pairs: the tested points go in chunks of :data:`CHUNK`, each chunk's steep drops are
found, filtered, checked and summed per point before the next chunk's, so memory is
bounded on large sparse tiles (no Python loop over points; the result does not depend
on the chunk size). Per point, the clean drops are summed in the order of their lower
ends' coordinates: the result depends on the coordinates only, never on the input
order.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = [
    "gap_mask",
    "RADIUS",
    "ANGLE",
    "HALF_WIDTH",
    "BAND",
    "SUPPORT",
    "SUPPORT_RADIUS",
    "CLEAN_SHARE",
    "OPPOSITE",
]

#: search radius (m) for the drops and for the opposite edge
RADIUS = 12.0
#: least grade (degrees) of a drop between two returns
ANGLE = 30.0
#: half width (m) of the corridor between the two ends of a drop
HALF_WIDTH = 1.5
#: a corridor return counts when it lies more than this share of the drop above the
#: lower end and below the upper end
BAND = 0.2
#: accepted ground points around the lower end of a drop, at its level (a surface)
SUPPORT = 3
#: radius (m) of that support
SUPPORT_RADIUS = 3.0
#: least share of a point's steep drops that are clean for it to be an edge
CLEAN_SHARE = 0.8
#: two edges face away from each other when the cosine of their drop directions is
#: below minus this (more than 120° apart)
OPPOSITE = 0.5


#: tested points per chunk: a chunk's drops are filtered, checked and summed per point
#: before the next chunk's are searched, so memory stays bounded on large sparse tiles
#: (the result does not depend on it)
CHUNK = 4096
#: least cell size (m) of the neighbour grids
_CELL = 4.0
#: the most cells of a neighbour grid (a larger extent gets larger cells)
_MAX_CELLS = 1 << 20
#: margin (m) on the cells scanned around a disc or a corridor: the tests on each
#: point are exact, the margin only keeps rounding from hiding a cell
_MARGIN = 1e-3


@njit(cache=True, nogil=True)
def _bucket(key, idx, start):  # pragma: no cover
    """`idx` in the order of their cells `key` (CSR `start`), stable: a counting sort."""
    fill = start[:-1].copy()
    order = np.empty(key.size, dtype=np.int64)
    for i in range(key.size):
        order[fill[key[i]]] = idx[i]
        fill[key[i]] += 1
    return order


def _grid(
    xyz: np.ndarray, idx: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points `idx` bucketed on a square grid in XY.

    Returns the origin, cell size and shape; the CSR start per cell; the points in cell
    order; the lowest and highest z per cell.
    """
    xy = xyz[idx, :2]
    org = xy.min(axis=0)
    ext = xy.max(axis=0) - org
    cell = max(_CELL, math.sqrt(float(ext[0] + 1.0) * float(ext[1] + 1.0) / _MAX_CELLS))
    c = np.floor((xy - org) / cell).astype(np.int64)
    shape = c.max(axis=0) + 1
    key = c[:, 0] * shape[1] + c[:, 1]
    count = np.bincount(key, minlength=int(shape[0] * shape[1]))
    start = np.zeros(count.size + 1, dtype=np.int64)
    np.cumsum(count, out=start[1:])
    order = _bucket(key, idx.astype(np.int64), start)
    z = xyz[order, 2]
    full = np.flatnonzero(count)
    zr = np.empty((count.size, 2))
    zr[:, 0], zr[:, 1] = np.inf, -np.inf
    zr[full, 0] = np.minimum.reduceat(z, start[full])
    zr[full, 1] = np.maximum.reduceat(z, start[full])
    geo = np.array([org[0], org[1], cell, shape[0], shape[1]], dtype=np.float64)
    return geo, start, order, zr


@njit(cache=True, nogil=True, inline="always")
def _span(lo, hi, o, cell, m):  # pragma: no cover
    """Cells [a, b] of one axis that a coordinate range [lo, hi] touches (clipped)."""
    a = int(math.floor((lo - o) / cell))
    b = int(math.floor((hi - o) / cell))
    return min(max(a, 0), m), max(min(b, m - 1), -1)


@njit(cache=True, nogil=True, parallel=True)
def _drops(
    xyz, tested, geo, start, order, zr, r2, scan, step, grade, fill, off, out_p, out_q
):  # pragma: no cover
    """Per tested point p, the ground q within sqrt(r2) m (XY) more than `step` lower.

    Only at about the grade or steeper (a superset: the exact test follows in numpy).
    Counts them when not `fill`, else writes p and q from `off`.
    """
    m = tested.size
    cnt = np.zeros(m, dtype=np.int64)
    ox, oy, cell, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    for k in prange(m):
        p = tested[k]
        px, py, pz = xyz[p, 0], xyz[p, 1], xyz[p, 2]
        i0, i1 = _span(px - scan, px + scan, ox, cell, nx)
        j0, j1 = _span(py - scan, py + scan, oy, cell, ny)
        c = 0
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if pz - zr[i * ny + j, 0] <= step:  # nothing low enough in the cell
                    continue
                for t in range(start[i * ny + j], start[i * ny + j + 1]):
                    q = order[t]
                    h = pz - xyz[q, 2]
                    if h <= step:
                        continue
                    d0 = px - xyz[q, 0]
                    d1 = py - xyz[q, 1]
                    d2 = d0 * d0 + d1 * d1
                    if d2 > r2 or (d0 == 0.0 and d1 == 0.0):
                        continue
                    if h <= math.sqrt(d2) * grade - 1e-9:
                        continue
                    if fill:
                        out_p[off[k] + c] = p
                        out_q[off[k] + c] = q
                    c += 1
        cnt[k] = c
    return cnt


@njit(cache=True, nogil=True, parallel=True)
def _support(xyz, pts, geo, start, order, r2, scan, dz):  # pragma: no cover
    """Per point of `pts`, the grid's points within sqrt(r2) m (XY) and `dz` m in z.

    The point itself is counted.
    """
    m = pts.size
    cnt = np.zeros(m, dtype=np.int64)
    ox, oy, cell, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    for k in prange(m):
        q = pts[k]
        qx, qy, qz = xyz[q, 0], xyz[q, 1], xyz[q, 2]
        i0, i1 = _span(qx - scan, qx + scan, ox, cell, nx)
        j0, j1 = _span(qy - scan, qy + scan, oy, cell, ny)
        c = 0
        for i in range(i0, i1 + 1):
            for t in range(start[i * ny + j0], start[i * ny + j1 + 1]):
                j = order[t]
                d0 = qx - xyz[j, 0]
                d1 = qy - xyz[j, 1]
                if d0 * d0 + d1 * d1 <= r2 and abs(qz - xyz[j, 2]) < dz:
                    c += 1
        cnt[k] = c
    return cnt


@njit(cache=True, nogil=True, parallel=True)
def _sort_groups(xyz, first, q):  # pragma: no cover
    """`q` with each group ``q[first[g]:first[g + 1]]`` sorted by x, then y, then z.

    Stable, like a lexsort.
    """
    q = q.copy()
    for g in prange(first.size - 1):
        a, b = first[g], first[g + 1]
        if b - a <= 64:  # insertion sort
            for k in range(a + 1, b):
                v = q[k]
                vx, vy, vz = xyz[v, 0], xyz[v, 1], xyz[v, 2]
                t = k - 1
                while t >= a:
                    u = q[t]
                    ux, uy = xyz[u, 0], xyz[u, 1]
                    if ux < vx or (ux == vx and (uy < vy or (uy == vy and xyz[u, 2] <= vz))):
                        break
                    q[t + 1] = u
                    t -= 1
                q[t + 1] = v
        else:  # least significant key first, each pass stable
            seg = q[a:b].copy()
            for c in (2, 1, 0):
                key = np.empty(seg.size)
                for k in range(seg.size):
                    key[k] = xyz[seg[k], c]
                seg = seg[np.argsort(key, kind="mergesort")]
            q[a:b] = seg
    return q


@njit(cache=True, nogil=True, inline="always")
def _clean(xyz, geo, start, order, zr, p, q, r2, band, half_width):  # pragma: no cover
    """True when no candidate within sqrt(r2) m of p (XY) is in the corridor of p→q.

    At mid height; only the grid cells around the corridor are scanned.
    """
    ox, oy, cell, nx, ny = geo[0], geo[1], geo[2], int(geo[3]), int(geo[4])
    ax, ay, az = xyz[p, 0], xyz[p, 1], xyz[p, 2]
    dx, dy = xyz[q, 0] - ax, xyz[q, 1] - ay
    ll = dx * dx + dy * dy
    if ll <= 0.0:
        return True
    length = math.sqrt(ll)
    h = az - xyz[q, 2]
    lo, hi = xyz[q, 2] + band * h, az - band * h
    w = half_width + _MARGIN
    i0, i1 = _span(min(ax, ax + dx) - w, max(ax, ax + dx) + w, ox, cell, nx)
    j0, j1 = _span(min(ay, ay + dy) - w, max(ay, ay + dy) + w, oy, cell, ny)
    for i in range(i0, i1 + 1):
        for jc in range(j0, j1 + 1):
            if zr[i * ny + jc, 1] <= lo or zr[i * ny + jc, 0] >= hi:
                continue  # nothing at mid height in the cell
            for t in range(start[i * ny + jc], start[i * ny + jc + 1]):
                j = order[t]
                z = xyz[j, 2]
                if z <= lo or z >= hi:
                    continue
                ex, ey = xyz[j, 0] - ax, xyz[j, 1] - ay
                s = (ex * dx + ey * dy) / ll
                if s <= 0.0 or s >= 1.0:
                    continue
                if abs(dx * ey - dy * ex) / length <= half_width and ex * ex + ey * ey <= r2:
                    return False
    return True


@njit(cache=True, nogil=True, parallel=True)
def _clean_drops(
    xyz, geo, start, order, zr, drop_p, drop_q, first, r2, band, half_width, share
):  # pragma: no cover
    """Per drop (p, q), grouped by p from `first`: True when clean.

    A point stops at the first unclean drop that leaves it too few clean ones to be an
    edge (``dead`` True; its other drops are left False).
    """
    out = np.zeros(drop_p.size, dtype=np.bool_)
    n = first.size - 1
    dead = np.zeros(n, dtype=np.bool_)
    for g in prange(n):
        n_drop = first[g + 1] - first[g]
        need = share * n_drop - 1e-9
        bad = 0
        for k in range(first[g], first[g + 1]):
            if _clean(xyz, geo, start, order, zr, drop_p[k], drop_q[k], r2, band, half_width):
                out[k] = True
            else:
                bad += 1
                if n_drop - bad < 2 or n_drop - bad < need:
                    dead[g] = True
                    break
    return out, dead


def gap_mask(
    points: np.ndarray,
    ground: np.ndarray,
    candidates: np.ndarray,
    *,
    step: float,
) -> np.ndarray:
    """Accepted ground on a surface with clean drops on opposite sides (module docstring).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Coordinates, metres.
    ground : ndarray of bool, shape (N,)
        Accepted ground: the points tested and the lower ends of drops.
    candidates : ndarray of bool, shape (N,)
        Points that could be ground: a return of one in a corridor makes a drop a slope.
    step : float
        Least drop (m): the clearance under a deck; > 0.

    Returns
    -------
    ndarray of bool, shape (N,)
        True for the accepted ground points to reject.
    """
    from scipy.spatial import cKDTree

    n = points.shape[0]
    out = np.zeros(n, dtype=bool)
    gi = np.flatnonzero(ground)
    ci = np.flatnonzero(candidates)
    if gi.size < 2 or ci.size == 0:
        return out
    xyz = np.ascontiguousarray(points, dtype=np.float64)
    # tested points: some ground lies > step lower within RADIUS (cells of RADIUS m,
    # aligned to absolute coordinates; the 3 x 3 block around a cell holds its disc)
    cell = np.floor(xyz[gi, :2] / RADIUS).astype(np.int64)
    cell -= cell.min(axis=0) - 1
    nj = int(cell[:, 1].max()) + 2
    key = cell[:, 0] * nj + cell[:, 1]
    ck, inv = np.unique(key, return_inverse=True)
    low = np.full(ck.size, np.inf)
    np.minimum.at(low, inv, xyz[gi, 2])
    lowest = np.full(gi.size, np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            kk = key + di * nj + dj
            pos = np.minimum(np.searchsorted(ck, kk), ck.size - 1)
            lowest = np.minimum(lowest, np.where(ck[pos] == kk, low[pos], np.inf))
    ti = gi[xyz[gi, 2] - lowest > step]
    if ti.size == 0:
        return out
    geo_g, start_g, order_g, zr_g = _grid(xyz, gi)
    geo_c, start_c, order_c, zr_c = _grid(xyz, ci)
    r2 = RADIUS * RADIUS
    grade = math.tan(math.radians(ANGLE))
    surface = np.zeros(n, dtype=np.int8)  # lower ends: 0 not seen, 1 on a surface, -1 not
    n_drop = np.zeros(n, dtype=np.int64)
    n_clean = np.zeros(n, dtype=np.int64)
    sx = np.zeros(n)
    sy = np.zeros(n)
    none = np.zeros(0, dtype=np.int64)
    for c0 in range(0, ti.size, CHUNK):
        tc = ti[c0 : c0 + CHUNK]
        args = (xyz, tc, geo_g, start_g, order_g, zr_g, r2, RADIUS + _MARGIN, step, grade)
        cnt = _drops(*args, False, none, none, none)
        off = np.zeros(tc.size, dtype=np.int64)
        np.cumsum(cnt[:-1], out=off[1:])
        pi = np.empty(int(cnt.sum()), dtype=np.int64)
        qi = np.empty_like(pi)
        _drops(*args, True, off, pi, qi)
        dist = np.hypot(xyz[qi, 0] - xyz[pi, 0], xyz[qi, 1] - xyz[pi, 1])
        drop = xyz[pi, 2] - xyz[qi, 2]
        steep = (drop > step) & (drop > dist * grade) & (dist > 0)
        pi, qi, dist = pi[steep], qi[steep], dist[steep]
        if pi.size == 0:
            continue
        # the lower end lies on a surface: accepted ground around it at its level
        uq = np.unique(qi)
        uq = uq[surface[uq] == 0]
        if uq.size:
            support = (
                _support(
                    xyz,
                    uq,
                    geo_g,
                    start_g,
                    order_g,
                    SUPPORT_RADIUS * SUPPORT_RADIUS,
                    SUPPORT_RADIUS + _MARGIN,
                    0.5 * step,
                )
                - 1
            )  # less the point itself
            surface[uq] = np.where(support >= SUPPORT, 1, -1)
        keep = surface[qi] == 1
        pi, qi = pi[keep], qi[keep]
        if pi.size == 0:
            continue
        # per point, its drops in the order of their lower ends' coordinates
        # (pi is sorted: the drops come per tested point, in the order of `ti`)
        hp, first, n_hp = np.unique(pi, return_index=True, return_counts=True)
        first = np.append(first, pi.size)
        qi = _sort_groups(xyz, first, qi)
        dist = np.hypot(xyz[qi, 0] - xyz[pi, 0], xyz[qi, 1] - xyz[pi, 1])
        loc = np.repeat(np.arange(hp.size), n_hp)
        clean, dead = _clean_drops(
            xyz, geo_c, start_c, order_c, zr_c, pi, qi, first, r2,
            float(BAND), float(HALF_WIDTH), float(CLEAN_SHARE),
        )  # fmt: skip
        ux = (xyz[qi, 0] - xyz[pi, 0]) / dist
        uy = (xyz[qi, 1] - xyz[pi, 1]) / dist
        n_drop[hp] = n_hp
        n_clean[hp] = np.where(dead, 0, np.bincount(loc[clean], minlength=hp.size))
        sx[hp] = np.bincount(loc[clean], weights=ux[clean], minlength=hp.size)
        sy[hp] = np.bincount(loc[clean], weights=uy[clean], minlength=hp.size)
    norm = np.hypot(sx, sy)
    edge = np.flatnonzero(
        ground & (n_clean >= 2) & (n_clean >= CLEAN_SHARE * n_drop - 1e-9) & (norm > 0)
    )
    if edge.size < 2:
        return out
    u = np.column_stack([sx[edge], sy[edge]]) / norm[edge, None]
    pr = cKDTree(xyz[edge, :2]).query_pairs(RADIUS, output_type="ndarray")
    if pr.size == 0:
        return out
    a, b = pr[:, 0], pr[:, 1]
    dab = xyz[edge[b], :2] - xyz[edge[a], :2]
    facing_away = (
        ((u[a] * u[b]).sum(axis=1) < -OPPOSITE)
        & ((dab * u[a]).sum(axis=1) < 0)  # b lies behind a's drop, a behind b's
        & ((dab * u[b]).sum(axis=1) > 0)
        & (np.abs(xyz[edge[a], 2] - xyz[edge[b], 2]) < 0.5 * step)
    )
    out[edge[a[facing_away]]] = True
    out[edge[b[facing_away]]] = True
    return out
