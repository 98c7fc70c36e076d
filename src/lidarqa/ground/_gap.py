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

Neighbourhoods come from k-d trees in vectorised calls; the corridors are counted in a
numba kernel over the steep drops (no Python loop over points). Per point, the clean
drops are summed in the order of their lower ends' coordinates: the result depends on
the coordinates only, never on the input order.
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


@njit(cache=True, nogil=True, parallel=True)
def _clean_drops(xyz, start, nbr, drop_p, drop_q, band, half_width):  # pragma: no cover
    """Per drop (p, q): True when no neighbour of p lies in its corridor at mid height."""
    m = drop_p.size
    out = np.ones(m, dtype=np.bool_)
    for k in prange(m):
        p = drop_p[k]
        q = drop_q[k]
        ax, ay, az = xyz[p, 0], xyz[p, 1], xyz[p, 2]
        dx, dy = xyz[q, 0] - ax, xyz[q, 1] - ay
        ll = dx * dx + dy * dy
        if ll <= 0.0:
            continue
        length = math.sqrt(ll)
        h = az - xyz[q, 2]
        lo, hi = xyz[q, 2] + band * h, az - band * h
        for t in range(start[p], start[p + 1]):
            j = nbr[t]
            z = xyz[j, 2]
            if z <= lo or z >= hi:
                continue
            ex, ey = xyz[j, 0] - ax, xyz[j, 1] - ay
            s = (ex * dx + ey * dy) / ll
            if s <= 0.0 or s >= 1.0:
                continue
            if abs(dx * ey - dy * ex) / length <= half_width:
                out[k] = False
                break
    return out


def _pairs(tree_a, tree_b, r: float) -> tuple[np.ndarray, np.ndarray]:
    """All (i, j) with points i of `tree_a` and j of `tree_b` within `r` m in XY."""
    sdm = tree_a.sparse_distance_matrix(tree_b, r, output_type="ndarray")
    return sdm["i"].astype(np.int64), sdm["j"].astype(np.int64)


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
    gtree = cKDTree(xyz[gi, :2])
    a, b = _pairs(cKDTree(xyz[ti, :2]), gtree, RADIUS)
    pi, qi = ti[a], gi[b]
    dist = np.hypot(xyz[qi, 0] - xyz[pi, 0], xyz[qi, 1] - xyz[pi, 1])
    drop = xyz[pi, 2] - xyz[qi, 2]
    steep = (drop > step) & (drop > dist * math.tan(math.radians(ANGLE))) & (dist > 0)
    pi, qi, dist = pi[steep], qi[steep], dist[steep]
    if pi.size == 0:
        return out
    # the lower end lies on a surface: accepted ground around it at its level
    uq = np.unique(qi)
    a, b = _pairs(cKDTree(xyz[uq, :2]), gtree, SUPPORT_RADIUS)
    level = np.abs(xyz[uq[a], 2] - xyz[gi[b], 2]) < 0.5 * step
    support = np.bincount(a[level], minlength=uq.size) - 1  # less the point itself
    on_surface = np.zeros(n, dtype=bool)
    on_surface[uq[support >= SUPPORT]] = True
    keep = on_surface[qi]
    pi, qi, dist = pi[keep], qi[keep], dist[keep]
    if pi.size == 0:
        return out
    # per point, its drops in the order of their lower ends' coordinates
    o = np.lexsort((xyz[qi, 2], xyz[qi, 1], xyz[qi, 0], pi))
    pi, qi, dist = pi[o], qi[o], dist[o]
    # candidate neighbours of the points with a drop (CSR over all points)
    hp = np.unique(pi)
    a, b = _pairs(cKDTree(xyz[hp, :2]), cKDTree(xyz[ci, :2]), RADIUS)
    nb_p, nb = hp[a], ci[b]
    o = np.argsort(nb_p, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(nb_p, minlength=n), out=start[1:])
    clean = _clean_drops(xyz, start, nb[o], pi, qi, float(BAND), float(HALF_WIDTH))
    ux = (xyz[qi, 0] - xyz[pi, 0]) / dist
    uy = (xyz[qi, 1] - xyz[pi, 1]) / dist
    n_drop = np.bincount(pi, minlength=n)
    n_clean = np.bincount(pi[clean], minlength=n)
    sx = np.bincount(pi[clean], weights=ux[clean], minlength=n)
    sy = np.bincount(pi[clean], weights=uy[clean], minlength=n)
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
