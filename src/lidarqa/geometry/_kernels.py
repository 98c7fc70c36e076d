"""Numba kernels of the geometry package (private).

Everything here works on centred, canonically sorted float64 coordinates and
trusts its inputs; validation happens in the public modules.
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, njit, prange

from .._arrays import colmax, colmin
from .._gridkernels import centred_moments

# ----------------------------------------------------------------- eigen / fits


@njit(cache=True, nogil=True)
def eigvals_sym3(a00, a01, a02, a11, a12, a22):
    """Eigenvalues (descending) of a symmetric 3x3 matrix, closed form (Smith 1961)."""
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    if p1 <= 1e-300:
        e = np.array([a00, a11, a22])
        e.sort()
        return e[2], e[1], e[0]
    q = (a00 + a11 + a22) / 3.0
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    b00 = (a00 - q) / p
    b11 = (a11 - q) / p
    b22 = (a22 - q) / p
    b01 = a01 / p
    b02 = a02 / p
    b12 = a12 / p
    detb = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
            + b02 * (b01 * b12 - b11 * b02))
    r = detb / 2.0
    if r <= -1.0:
        phi = math.pi / 3.0
    elif r >= 1.0:
        phi = 0.0
    else:
        phi = math.acos(r) / 3.0
    e1 = q + 2.0 * p * math.cos(phi)
    e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    e2 = 3.0 * q - e1 - e3
    return e1, e2, e3


@njit(cache=True, nogil=True)
def planarity_knn(pts, knn):
    """lambda3 / (lambda1+lambda2+lambda3) of each point's k-neighbourhood (N,)."""
    n, k = knn.shape
    out = np.empty(n)
    for i in range(n):
        _, _, _, c00, c01, c02, c11, c12, c22 = centred_moments(pts, knn[i], k)
        tr = c00 + c11 + c22
        if tr <= 0.0:
            out[i] = 1.0  # all points equal: worst possible planarity
            continue
        e1, e2, e3 = eigvals_sym3(c00, c01, c02, c11, c12, c22)
        v = e3 / tr
        out[i] = v if v > 0.0 else 0.0
    return out


@njit(cache=True, nogil=True)
def canonical_normal(nx, ny, nz):
    """Flip a unit normal so n_z >= 0 (if 0: n_x >= 0, then n_y >= 0)."""
    flip = False
    if nz < 0.0:
        flip = True
    elif nz == 0.0:
        if nx < 0.0:
            flip = True
        elif nx == 0.0 and ny < 0.0:
            flip = True
    if flip:
        return -nx, -ny, -nz
    return nx, ny, nz


@njit(cache=True, nogil=True)
def normal_from_moments(n, sx, sy, sz, sxx, sxy, sxz, syy, syz, szz):
    """TLS normal (canonical sign) and mean from first/second moment sums."""
    mx = sx / n
    my = sy / n
    mz = sz / n
    c = np.empty((3, 3))
    c[0, 0] = sxx / n - mx * mx
    c[0, 1] = sxy / n - mx * my
    c[0, 2] = sxz / n - mx * mz
    c[1, 1] = syy / n - my * my
    c[1, 2] = syz / n - my * mz
    c[2, 2] = szz / n - mz * mz
    c[1, 0] = c[0, 1]
    c[2, 0] = c[0, 2]
    c[2, 1] = c[1, 2]
    w, v = np.linalg.eigh(c)
    nx, ny, nz = canonical_normal(v[0, 0], v[1, 0], v[2, 0])
    return nx, ny, nz, mx, my, mz


@njit(cache=True, nogil=True)
def fit_subset(pts, idx, m, ox, oy, oz):
    """TLS plane of pts[idx[:m]] about origin o: (nx, ny, nz, mx, my, mz), mean in the o-frame."""
    sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
    for a in range(m):
        j = idx[a]
        x = pts[j, 0] - ox
        y = pts[j, 1] - oy
        z = pts[j, 2] - oz
        sx += x
        sy += y
        sz += z
        sxx += x * x
        sxy += x * y
        sxz += x * z
        syy += y * y
        syz += y * z
        szz += z * z
    return normal_from_moments(float(m), sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)


# ------------------------------------------------------------------ PRNG


@njit(cache=True, nogil=True)
def splitmix64(state):
    """One step of splitmix64: returns (new_state, random uint64 as int64 bits)."""
    state = (state + np.uint64(0x9E3779B97F4A7C15)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = state
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = z ^ (z >> np.uint64(31))
    return state, z


# ------------------------------------------------------------------ grid search


@njit(cache=True, nogil=True)
def grid_count(pts, queries, r2, cx, cy, cz, nyz, nz, cell_keys, cell_start, order):
    """Number of points within sqrt(r2) of each point `queries` (itself included).

    The grid's cell must be at least sqrt(r2) (see :func:`build_grid`).
    """
    ncell = cell_keys.shape[0]
    out = np.zeros(queries.size, dtype=np.int64)
    for t in range(queries.size):
        q = queries[t]
        px = pts[q, 0]
        py = pts[q, 1]
        pz = pts[q, 2]
        z0 = max(cz[q] - 1, 0)
        z1 = min(cz[q] + 1, nz - 1)
        m = 0
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                col = (cx[q] + dx) * nyz + (cy[q] + dy) * nz
                c = np.searchsorted(cell_keys, col + z0)
                while c < ncell and cell_keys[c] <= col + z1:
                    for a in range(cell_start[c], cell_start[c + 1]):
                        j = order[a]
                        ddx = pts[j, 0] - px
                        ddy = pts[j, 1] - py
                        ddz = pts[j, 2] - pz
                        if ddx * ddx + ddy * ddy + ddz * ddz <= r2:
                            m += 1
                    c += 1
        out[t] = m
    return out


def _grid_side(pts: np.ndarray, cell: float) -> float:
    """The cell side (m) :func:`build_grid` lays for `cell`."""
    # at most 2**20 cells along the widest side: a tiny cell (a user's 1e-300 m radius)
    # would overflow the integer keys and put every point in one cell (a search over
    # all pairs); a wider cell only adds candidates, the callers test the distance
    span = float(np.max(colmax(pts) - colmin(pts))) if len(pts) else 0.0
    return max(float(cell), span / 2.0**20, 1e-9)


def build_grid(pts: np.ndarray, cell: float, offset: np.ndarray | None = None):
    """A hashed voxel grid of cell size `cell` (m) over `pts` (NumPy, vectorised).

    Returns (cx, cy, cz, nyz, nz, cell_keys, cell_start, order, max_count).
    Cells are keyed (ix+1)*nyz + (iy+1)*nz + iz so the +-1 neighbours never wrap.
    With `offset` (what was subtracted from the original coordinates), the grid
    lines lie at multiples of `cell` in the original coordinates: any subset of a
    cloud (a chunk of a catalog) puts its points in the same cells, so a search
    visits neighbours in the same order whatever else was read. Points of a cell
    are in their order in `pts`.
    """
    cell = _grid_side(pts, cell)
    if offset is None:
        ijk = np.floor((pts - colmin(pts)) / cell).astype(np.int64)
    else:
        ijk = np.floor((pts + np.asarray(offset, dtype=np.float64)) / cell).astype(np.int64)
        ijk -= colmin(ijk)
    cx = ijk[:, 0] + 1
    cy = ijk[:, 1] + 1
    cz = ijk[:, 2]
    ny = int(cy.max()) + 2
    nz = int(cz.max()) + 1
    nyz = ny * nz
    key = cx * nyz + cy * nz + cz
    order = np.argsort(key, kind="stable")
    ks = key[order]
    brk = np.flatnonzero(np.diff(ks)) + 1
    starts = np.concatenate([[0], brk, [len(ks)]]).astype(np.int64)
    cell_keys = ks[starts[:-1]]
    max_count = int(np.diff(starts).max()) if len(starts) > 1 else 0
    return cx, cy, cz, nyz, nz, cell_keys, starts, order, max_count


# ------------------------------------------------------------------ seeds


@njit(cache=True, nogil=True)
def _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, dist, flag):
    """Count cand points within dist of the plane (n, mean m in the o-frame); set flag."""
    cnt = 0
    for a in range(m):
        j = cand[a]
        d = nx * (pts[j, 0] - ox - mx) + ny * (pts[j, 1] - oy - my) + nz * (pts[j, 2] - oz - mz)
        if abs(d) <= dist:
            flag[a] = True
            cnt += 1
        else:
            flag[a] = False
    return cnt


@njit(cache=True, nogil=True)
def hough_directions(step_deg):
    """Unit normals on the upper hemisphere in steps of step_deg (tilt 0..90, azimuth 0..360)."""
    nt = int(math.floor(90.0 / step_deg + 1e-9)) + 1
    na = int(math.ceil(360.0 / step_deg - 1e-9))
    out = np.empty((1 + (nt - 1) * na, 3))
    out[0, 0] = 0.0
    out[0, 1] = 0.0
    out[0, 2] = 1.0
    m = 1
    for t in range(1, nt):
        phi = math.radians(t * step_deg)
        for a in range(na):
            psi = math.radians(a * step_deg)
            if abs(phi - math.pi / 2) < 1e-12 and psi >= math.pi - 1e-12:
                continue  # antipodal duplicate of a horizontal normal
            out[m, 0] = math.sin(phi) * math.cos(psi)
            out[m, 1] = math.sin(phi) * math.sin(psi)
            out[m, 2] = math.cos(phi)
            m += 1
    return out[:m]


@njit(cache=True, nogil=True)
def _seed_plane(pts, i, cand, m, method, seed_dist, dirs, rng_seed, flag, tmp):
    """Plane of a seed around trial point i: (ok, nx, ny, nz, mx, my, mz) in the frame of pts[i]."""
    ox = pts[i, 0]
    oy = pts[i, 1]
    oz = pts[i, 2]
    if method == 0:  # pca
        nx, ny, nz, mx, my, mz = fit_subset(pts, cand, m, ox, oy, oz)
        c = _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, seed_dist, flag)
    elif method == 1:  # hough
        rmax = 0.0
        for a in range(m):
            j = cand[a]
            d = math.sqrt((pts[j, 0] - ox) ** 2 + (pts[j, 1] - oy) ** 2 + (pts[j, 2] - oz) ** 2)
            if d > rmax:
                rmax = d
        half = int(math.ceil(rmax / seed_dist)) + 1
        nb = 2 * half + 1
        acc = np.zeros(nb, dtype=np.int64)
        touched = np.empty(m, dtype=np.int64)
        rel = np.empty((m, 3))
        for a in range(m):
            j = cand[a]
            rel[a, 0] = pts[j, 0] - ox
            rel[a, 1] = pts[j, 1] - oy
            rel[a, 2] = pts[j, 2] - oz
        best = -1
        best_d = 0
        best_b = 0
        for d in range(dirs.shape[0]):
            ux = dirs[d, 0]
            uy = dirs[d, 1]
            uz = dirs[d, 2]
            for a in range(m):
                r = ux * rel[a, 0] + uy * rel[a, 1] + uz * rel[a, 2]
                b = int(math.floor(r / seed_dist + 0.5)) + half
                touched[a] = b
                acc[b] += 1
            # the fullest bin of this direction; ties: smaller bin index (then smaller direction)
            for a in range(m):
                b = touched[a]
                if acc[b] > best or (acc[b] == best and d == best_d and b < best_b):
                    best = acc[b]
                    best_d = d
                    best_b = b
            for a in range(m):
                acc[touched[a]] = 0
        ux = dirs[best_d, 0]
        uy = dirs[best_d, 1]
        uz = dirs[best_d, 2]
        rho = (best_b - half) * seed_dist
        k = 0
        for a in range(m):
            j = cand[a]
            r = ux * (pts[j, 0] - ox) + uy * (pts[j, 1] - oy) + uz * (pts[j, 2] - oz)
            if abs(r - rho) <= seed_dist:
                tmp[k] = j
                k += 1
        if k < 3:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        nx, ny, nz, mx, my, mz = fit_subset(pts, tmp, k, ox, oy, oz)
        c = _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, seed_dist, flag)
        return c >= 3, nx, ny, nz, mx, my, mz
    else:  # ransac, 200 three-point hypotheses
        state = np.uint64(rng_seed) * np.uint64(0x2545F4914F6CDD1D) + np.uint64(i)
        best = -1
        bnx = 0.0
        bny = 0.0
        bnz = 1.0
        bmx = 0.0
        bmy = 0.0
        bmz = 0.0
        for _ in range(200):
            state, r1 = splitmix64(state)
            state, r2 = splitmix64(state)
            state, r3 = splitmix64(state)
            a1 = cand[int(r1 % np.uint64(m))]
            a2 = cand[int(r2 % np.uint64(m))]
            a3 = cand[int(r3 % np.uint64(m))]
            ex = pts[a2, 0] - pts[a1, 0]
            ey = pts[a2, 1] - pts[a1, 1]
            ez = pts[a2, 2] - pts[a1, 2]
            fx = pts[a3, 0] - pts[a1, 0]
            fy = pts[a3, 1] - pts[a1, 1]
            fz = pts[a3, 2] - pts[a1, 2]
            nx = ey * fz - ez * fy
            ny = ez * fx - ex * fz
            nz = ex * fy - ey * fx
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nn <= 1e-12:
                continue
            nx /= nn
            ny /= nn
            nz /= nn
            mx = pts[a1, 0] - ox
            my = pts[a1, 1] - oy
            mz = pts[a1, 2] - oz
            c = _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, seed_dist, flag)
            if c > best:
                best = c
                bnx, bny, bnz, bmx, bmy, bmz = nx, ny, nz, mx, my, mz
        if best < 3:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        _count_within(pts, cand, m, bnx, bny, bnz, bmx, bmy, bmz, ox, oy, oz, seed_dist, flag)
        k = 0
        for a in range(m):
            if flag[a]:
                tmp[k] = cand[a]
                k += 1
        nx, ny, nz, mx, my, mz = fit_subset(pts, tmp, k, ox, oy, oz)
        c = _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, seed_dist, flag)
        return c >= 3, nx, ny, nz, mx, my, mz
    if method == 0:
        # one refit on the inliers of the first fit, then recount
        k = 0
        for a in range(m):
            if flag[a]:
                tmp[k] = cand[a]
                k += 1
        if k < 3:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
        nx, ny, nz, mx, my, mz = fit_subset(pts, tmp, k, ox, oy, oz)
        c = _count_within(pts, cand, m, nx, ny, nz, mx, my, mz, ox, oy, oz, seed_dist, flag)
    return c >= 3, nx, ny, nz, mx, my, mz


# ------------------------------------------------------------------ growing


@njit(cache=True, nogil=True)
def surface_growing_kernel(pts, trial_order, knn, knn_k, method, seed_dist, min_seed_points, dirs,
                           rng_seed, grow_r2, grow_dist, refit_growth, min_segment_size,
                           cx, cy, cz, nyz, nz_cells, cell_keys, cell_start, order, max_cell):
    """Surface growing over canonically ordered points; returns labels (N,) int64."""
    n = pts.shape[0]
    labels = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    cand = np.empty(knn_k, dtype=np.int64)
    tmp = np.empty(knn_k, dtype=np.int64)
    flag = np.zeros(knn_k, dtype=np.bool_)
    next_label = 0
    for t in range(n):
        i = trial_order[t]
        if labels[i] != -1:
            continue
        # typed int64 from the start: a literal 0 makes numba compile _seed_plane (and
        # what it calls) a second time for a Literal[int](0) argument (first-run cost)
        m = np.int64(0)
        for a in range(knn_k):
            j = knn[i, a]
            if labels[j] == -1:
                cand[m] = j
                m += 1
        if m < 3 or m < min_seed_points:
            continue
        ok, pnx, pny, pnz, pmx, pmy, pmz = _seed_plane(pts, i, cand, m, method, seed_dist, dirs,
                                                      rng_seed, flag, tmp)
        if not ok:
            continue
        cnt = 0
        for a in range(m):
            if flag[a]:
                cnt += 1
        if cnt < min_seed_points:
            continue
        lab = next_label
        # origin of the moment sums: the trial point (limits round-off)
        ox = pts[i, 0]
        oy = pts[i, 1]
        oz = pts[i, 2]
        sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
        tail = 0
        for a in range(m):
            # a neighbour list may name a point twice (ties on degenerate input): queue it once
            if flag[a] and labels[cand[a]] != lab:
                j = cand[a]
                labels[j] = lab
                queue[tail] = j
                tail += 1
                x = pts[j, 0] - ox
                y = pts[j, 1] - oy
                z = pts[j, 2] - oz
                sx += x
                sy += y
                sz += z
                sxx += x * x
                sxy += x * y
                sxz += x * z
                syy += y * y
                syz += y * z
                szz += z * z
        last_fit = tail
        head = 0
        ncell = cell_keys.shape[0]
        while head < tail:
            q = queue[head]
            head += 1
            # the points within the growing radius of q, in grid order (x, y column,
            # z, then the order in the cell), each tested as it comes: a labelled point
            # (q included) is passed over before its distance is computed (most are,
            # behind the growing front)
            qx = pts[q, 0]
            qy = pts[q, 1]
            qz = pts[q, 2]
            z0 = max(cz[q] - 1, 0)
            z1 = min(cz[q] + 1, nz_cells - 1)
            for ddx in range(-1, 2):
                for ddy in range(-1, 2):
                    col = (cx[q] + ddx) * nyz + (cy[q] + ddy) * nz_cells
                    c = np.searchsorted(cell_keys, col + z0)
                    while c < ncell and cell_keys[c] <= col + z1:
                        for e in range(cell_start[c], cell_start[c + 1]):
                            j = order[e]
                            if labels[j] != -1:  # q itself included
                                continue
                            ex = pts[j, 0] - qx
                            ey = pts[j, 1] - qy
                            ez = pts[j, 2] - qz
                            if ex * ex + ey * ey + ez * ez > grow_r2:
                                continue
                            x = pts[j, 0] - ox
                            y = pts[j, 1] - oy
                            z = pts[j, 2] - oz
                            d = pnx * (x - pmx) + pny * (y - pmy) + pnz * (z - pmz)
                            if abs(d) > grow_dist:
                                continue
                            labels[j] = lab
                            queue[tail] = j
                            tail += 1
                            sx += x
                            sy += y
                            sz += z
                            sxx += x * x
                            sxy += x * y
                            sxz += x * z
                            syy += y * y
                            syz += y * z
                            szz += z * z
                            if tail >= last_fit * (1.0 + refit_growth):
                                pnx, pny, pnz, pmx, pmy, pmz = normal_from_moments(
                                    float(tail), sx, sy, sz, sxx, sxy, sxz, syy, syz, szz)
                                last_fit = tail
                        c += 1
        if tail < min_segment_size:
            for a in range(tail):
                labels[queue[a]] = -1
        else:
            next_label += 1
    return labels


# ------------------------------------------------------------------ kNN on the grid


@njit(cache=True, nogil=True)
def _box_gap(f, side, d, eps):
    """Lower bound (m) along one axis from a point at `f` in its cell to a cell `d` away.

    `side` is the cell side; only the sign of `d` counts (the caller adds the whole cells
    between); `eps` covers the rounding of the cell index.
    """
    if d < 0:
        g = f - eps
    elif d > 0:
        g = side - f - eps
    else:
        return 0.0
    return g if g > 0.0 else 0.0


@njit(cache=True, nogil=True)
def _knn_one(pts, i, k, rmax, cell, cx, cy, cz, nyz, nz, cell_keys, cell_start, order, max_cand,
             out, lo, side, r0=1, by_index=False):
    """Exact k nearest neighbours of pts[i] (including i) by expanding cube rings.

    Starts at ring `r0` (a caller that found ring 1 too small passes 2). Ring r takes
    the points of the (2r+1)^3 cells around the point's cell, in gather order (x, y
    column, then z, then the order in the cell); it answers when its k-th distance is
    within r cells. The cells are visited ring by ring from the point's own, and a cell
    that cannot hold a point within the k-th distance found so far is skipped (its points
    keep their gather rank for ties): the answer is that of a search of every cell of the
    ring.
    `lo` and `side` are the grid's origin and cell side (for the cells' bounds).
    Returns True on success; False if more than `rmax` rings would be needed or a
    ring holds more than `max_cand` points.
    """
    ncell = cell_keys.shape[0]
    px = pts[i, 0]
    py = pts[i, 1]
    pz = pts[i, 2]
    fx = px - (lo[0] + (cx[i] - 1) * side)
    fy = py - (lo[1] + (cy[i] - 1) * side)
    fz = pz - (lo[2] + cz[i] * side)
    eps = 1e-6 * side
    nmax = (2 * rmax + 1) ** 3
    c_id = np.empty(nmax, dtype=np.int64)  # cells of the ring, in gather order
    c_off = np.empty(nmax, dtype=np.int64)  # gather rank of their first point
    c_lb = np.empty(nmax)  # lower bound of their squared distance
    c_ring = np.empty(nmax, dtype=np.int64)  # their ring (Chebyshev distance in cells)
    bestd = np.empty(k)
    besti = np.empty(k, dtype=np.int64)
    bestt = np.empty(k, dtype=np.int64)
    for r in range(r0, rmax + 1):
        m = 0
        nc = 0
        for dx in range(-r, r + 1):
            gx = 0.0 if dx == 0 else max(_box_gap(fx, side, dx, eps) + (abs(dx) - 1) * side, 0.0)
            for dy in range(-r, r + 1):
                jx = cx[i] + dx
                jy = cy[i] + dy
                # past the last row a key would wrap into the next x column (same cells twice)
                if jx < 0 or jy < 0 or jy >= nyz // nz:
                    continue
                gy = 0.0 if dy == 0 else max(_box_gap(fy, side, dy, eps) + (abs(dy) - 1) * side,
                                             0.0)
                base = jx * nyz + jy * nz
                z0 = cz[i] - r
                if z0 < 0:
                    z0 = 0
                z1 = cz[i] + r
                if z1 > nz - 1:
                    z1 = nz - 1
                if z1 < z0:
                    continue
                # cells of one (x, y) column are contiguous in key order
                c = np.searchsorted(cell_keys, base + z0)
                while c < ncell and cell_keys[c] <= base + z1:
                    dz = cell_keys[c] - base - cz[i]
                    gz = 0.0 if dz == 0 else max(
                        _box_gap(fz, side, dz, eps) + (abs(dz) - 1) * side, 0.0)
                    c_id[nc] = c
                    c_off[nc] = m
                    c_lb[nc] = gx * gx + gy * gy + gz * gz
                    c_ring[nc] = max(abs(dx), abs(dy), abs(dz))
                    m += cell_start[c + 1] - cell_start[c]
                    nc += 1
                    c += 1
        if m > max_cand:
            return False
        if m < k:
            continue
        # inner cells first (ring by ring), then a cell only when it may hold a point
        # nearer than the k-th distance found so far
        nb = 0
        for ring in range(r + 1):
            for s in range(nc):
                if c_ring[s] != ring or (nb == k and c_lb[s] > bestd[k - 1]):
                    continue
                c = c_id[s]
                t = c_off[s]
                for e in range(cell_start[c], cell_start[c + 1]):
                    j = order[e]
                    d = (pts[j, 0] - px) ** 2 + (pts[j, 1] - py) ** 2 + (pts[j, 2] - pz) ** 2
                    tk = j if by_index else t
                    t += 1
                    if nb < k:
                        q = nb
                        nb += 1
                    elif d < bestd[k - 1] or (d == bestd[k - 1] and tk < bestt[k - 1]):
                        q = k - 1
                    else:
                        continue
                    while q > 0 and (bestd[q - 1] > d or (bestd[q - 1] == d and bestt[q - 1] > tk)):
                        bestd[q] = bestd[q - 1]
                        besti[q] = besti[q - 1]
                        bestt[q] = bestt[q - 1]
                        q -= 1
                    bestd[q] = d
                    besti[q] = j
                    bestt[q] = tk
        kth = bestd[k - 1]
        if kth <= (r * cell) ** 2:
            if by_index:
                # the k first by (distance, index): ties do not depend on the grid
                for q in range(k):
                    out[q] = besti[q]
                return True
            # strictly closer points in gather order, then the ties at the k-th distance
            # in gather order
            c = 0
            for q in range(k):
                if bestd[q] < kth:
                    c += 1
            # the strictly closer ones by gather rank (insertion sort of <= k entries)
            for q in range(1, c):
                vt = bestt[q]
                vi = besti[q]
                b = q - 1
                while b >= 0 and bestt[b] > vt:
                    bestt[b + 1] = bestt[b]
                    besti[b + 1] = besti[b]
                    b -= 1
                bestt[b + 1] = vt
                besti[b + 1] = vi
            for q in range(k):
                out[q] = besti[q]
            return True
    return False


@njit(cache=True, nogil=True, parallel=True)
def knn_grid(pts, k, cell, cx, cy, cz, nyz, nz, cell_keys, cell_start, order, rmax, max_cand,
             n_chunks, lo, side, by_index=False):
    """The k nearest neighbours of every point (N, k); rows that failed are all -1.

    Works cell by cell: the points of the 27 cells around a cell are gathered once
    into a contiguous buffer, and each point of the cell keeps its k nearest among
    them when the k-th distance is within one cell (exact); other points fall back
    to expanding rings (:func:`_knn_one`). Rows answered in one cell are ordered by
    distance, ties in gather order (`by_index`: by index, which does not depend on the
    grid); rows of the ring search hold their k nearest in gather order (strictly
    closer ones first, then the ties at the k-th distance), not by distance, unless
    `by_index`. The set of each row is the exact k nearest either way.

    The distances to all candidates are computed in one pass; only those within a
    guess of the k-th distance (the previous point's, a little wider) are ranked,
    and the guess is widened to one cell when fewer than k fall within it: the rows
    are those of a ranking of every candidate. `lo` and `side` are the grid's origin
    and cell side (for :func:`_knn_one`).
    """
    n = pts.shape[0]
    out = np.full((n, k), -1, dtype=np.int64)
    ncell = cell_keys.shape[0]
    # a few chunks per thread: buffers are allocated once per chunk
    nblocks = max(1, min(ncell, n_chunks))
    block = (ncell + nblocks - 1) // max(nblocks, 1)
    lim = cell * cell
    for bb in prange(nblocks):
        cand = np.empty(max_cand, dtype=np.int64)
        qx = np.empty(max_cand)
        qy = np.empty(max_cand)
        qz = np.empty(max_cand)
        dist = np.empty(max_cand)
        bestd = np.empty(k)
        besti = np.empty(k, dtype=np.int64)
        bestt = np.empty(k, dtype=np.int64)
        row = np.empty(k, dtype=np.int64)
        c1 = min(ncell, (bb + 1) * block)
        for c in range(bb * block, c1):
            rep = order[cell_start[c]]
            m = 0
            overflow = False
            for dx in range(-1, 2):
                for dy in range(-1, 2):
                    jx = cx[rep] + dx
                    jy = cy[rep] + dy
                    base = jx * nyz + jy * nz
                    z0 = max(cz[rep] - 1, 0)
                    z1 = min(cz[rep] + 1, nz - 1)
                    c2 = np.searchsorted(cell_keys, base + z0)
                    while c2 < ncell and cell_keys[c2] <= base + z1:
                        for a in range(cell_start[c2], cell_start[c2 + 1]):
                            if m >= max_cand:
                                overflow = True
                                break
                            j = order[a]
                            cand[m] = j
                            qx[m] = pts[j, 0]
                            qy[m] = pts[j, 1]
                            qz[m] = pts[j, 2]
                            m += 1
                        c2 += 1
            guess = 0.5 * lim
            for a in range(cell_start[c], cell_start[c + 1]):
                i = order[a]
                ok = False
                if not overflow and m >= k:
                    px = pts[i, 0]
                    py = pts[i, 1]
                    pz = pts[i, 2]
                    for t in range(m):
                        dist[t] = (qx[t] - px) ** 2 + (qy[t] - py) ** 2 + (qz[t] - pz) ** 2
                    g = min(guess, lim)
                    while True:
                        nb = 0
                        for t in range(m):
                            d = dist[t]
                            if d > g:
                                continue
                            j = cand[t]
                            tk = j if by_index else t
                            if nb < k:
                                q = nb
                                nb += 1
                            elif d < bestd[k - 1] or (d == bestd[k - 1] and tk < bestt[k - 1]):
                                q = k - 1
                            else:
                                continue
                            while q > 0 and (bestd[q - 1] > d
                                             or (bestd[q - 1] == d and bestt[q - 1] > tk)):
                                bestd[q] = bestd[q - 1]
                                besti[q] = besti[q - 1]
                                bestt[q] = bestt[q - 1]
                                q -= 1
                            bestd[q] = d
                            besti[q] = j
                            bestt[q] = tk
                        # k within the guess: the k-th distance is within it, so every
                        # point nearer (or tied) was ranked
                        if nb >= k or g >= lim:
                            break
                        g = lim
                    if nb >= k:  # then bestd[k - 1] <= g <= lim
                        for t in range(k):
                            out[i, t] = besti[t]
                        ok = True
                        guess = 1.3 * bestd[k - 1]
                if not ok:
                    # ring 1 is what was just gathered: when it did not overflow,
                    # the search goes on from ring 2
                    if _knn_one(pts, i, k, rmax, cell, cx, cy, cz, nyz, nz, cell_keys, cell_start,
                                order, max_cand, row, lo, side, 1 if overflow else 2, by_index):
                        for t in range(k):
                            out[i, t] = row[t]
    return out


def knn(pts: np.ndarray, k: int, *, by_index: bool = False) -> np.ndarray:
    """Exact k nearest neighbours (including the point itself) of every point, (N, k) int64.

    A row is the set of the k nearest; it is not always ordered by distance (see
    :func:`knn_grid`). `by_index`: rows ordered by (distance, index), so ties do not
    depend on the grid (the same neighbours for a point in any subset holding them, in
    the same order).

    A hashed grid sized from the occupied-cell density answers most queries in one
    ring of cells (numba, parallel); the few points that need more rings are
    answered by a cKDTree. Best with spatially sorted `pts` (memory locality).
    """
    n = len(pts)
    k = min(k, n)
    cell = knn_cell_size(pts, k)
    # refine the density estimate from the occupancy of the cells actually used
    g = None
    for _ in range(6):
        g = build_grid(pts, cell)
        counts = np.diff(g[6])
        occ = float((counts.astype(np.float64) ** 2).sum() / counts.sum())  # point-weighted
        dens = occ / (cell * cell)
        new = 1.6 * math.sqrt(k / (math.pi * dens))
        if 0.8 * cell <= new <= 1.25 * cell:
            break  # converged: the grid just built is the one to search
        cell = new
        g = None
    if g is None:
        g = build_grid(pts, cell)
    cx, cy, cz, nyz, nz, cell_keys, cell_start, order, max_cell = g
    max_cand = int(min(max(343 * max_cell, k), 2_000_000))
    out = knn_grid(pts, k, cell, cx, cy, cz, nyz, nz, cell_keys, cell_start, order, 3, max_cand,
                   8 * get_num_threads(), colmin(pts), _grid_side(pts, cell), by_index)
    bad = np.flatnonzero(out[:, 0] < 0)
    if len(bad):
        from scipy.spatial import cKDTree

        if not by_index:
            _, idx = cKDTree(pts).query(pts[bad], k=k)
            out[bad] = np.asarray(idx, dtype=np.int64).reshape(len(bad), k)
        else:
            kk = min(k + 8, n)  # a few more, to order ties by index as the grid search does
            d, idx = cKDTree(pts).query(pts[bad], k=kk)
            d = np.asarray(d, dtype=np.float64).reshape(len(bad), kk)
            idx = np.asarray(idx, dtype=np.int64).reshape(len(bad), kk)
            o = np.lexsort((idx, d), axis=-1)[:, :k]
            out[bad] = np.take_along_axis(idx, o, axis=1)
    return out


def knn_cell_size(pts: np.ndarray, k: int) -> float:
    """Cell size (m) of the grid used by :func:`knn` for the canonical spatial sort."""
    return cell_size(np.ptp(pts, axis=0), len(pts), k)


def cell_size(extent: np.ndarray, n: int, k: int) -> float:
    """Cell edge (m) expected to hold about k/2 points of a surface sampled with n points.

    The surface area is taken as the largest of the three projected bounding-box
    areas; the cell is never smaller than 1e-5 of the largest extent.
    """
    ex, ey, ez = (float(v) for v in extent)
    area = max(ex * ey, ex * ez, ey * ez, 1e-12)
    cell = 1.6 * math.sqrt(max(k, 1) / (math.pi * max(n, 1) / area))
    cell = max(cell, max(ex, ey, ez) / 1e5)  # bounds the grid dimensions
    return cell if math.isfinite(cell) and cell > 0 else 1.0


# ------------------------------------------------------------------ per-segment planes


def segment_planes_tls(pts: np.ndarray, labels: np.ndarray, n_labels: int):
    """TLS plane of every label 0..n_labels-1 from moment sums (vectorised).

    Returns (count (L,), mean (L,3), normal (L,3) canonical sign, eigvals (L,3) ascending,
    eigvecs (L,3,3) as columns); the mean is in the frame of `pts`.
    """
    ok = labels >= 0
    lab = labels[ok]
    p = pts[ok]
    cnt = np.bincount(lab, minlength=n_labels).astype(np.float64)
    safe = np.maximum(cnt, 1.0)
    mean = np.column_stack([np.bincount(lab, p[:, a], n_labels) for a in range(3)]) / safe[:, None]
    d = p - mean[lab]
    cov = np.empty((n_labels, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            v = np.bincount(lab, d[:, a] * d[:, b], n_labels) / safe
            cov[:, a, b] = v
            cov[:, b, a] = v
    w, v = np.linalg.eigh(cov)
    normal = v[:, :, 0].copy()
    zero_x = (normal[:, 0] == 0) & (normal[:, 1] < 0)
    flip = (normal[:, 2] < 0) | ((normal[:, 2] == 0) & ((normal[:, 0] < 0) | zero_x))
    normal[flip] *= -1.0
    return cnt, mean, normal, w, v


# ------------------------------------------------------------------ adjacency


@njit(cache=True, nogil=True)
def contact_pairs(pts, labels, r2, cx, cy, cz, nyz, nz, cell_keys, cell_start, order):
    """Point pairs (i, j) with labels[i] != labels[j], both >= 0, within sqrt(r2) (grid cell >= r).

    Only cells whose 27-neighbourhood holds more than one label are examined
    in detail, so the cost is proportional to the segment boundaries.
    """
    ncell = cell_keys.shape[0]
    lo = np.full(ncell, np.iinfo(np.int64).max, dtype=np.int64)
    hi = np.full(ncell, -1, dtype=np.int64)
    for c in range(ncell):
        for a in range(cell_start[c], cell_start[c + 1]):
            lab = labels[order[a]]
            if lab >= 0:
                if lab < lo[c]:
                    lo[c] = lab
                if lab > hi[c]:
                    hi[c] = lab
    cap = 1024
    out_i = np.empty(cap, dtype=np.int64)
    out_j = np.empty(cap, dtype=np.int64)
    m = 0
    for c in range(ncell):
        if hi[c] < 0:
            continue
        rep = order[cell_start[c]]
        ix = cx[rep]
        iy = cy[rep]
        iz = cz[rep]
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    jz = iz + dz
                    if jz < 0 or jz >= nz:
                        continue
                    key = (ix + dx) * nyz + (iy + dy) * nz + jz
                    c2 = np.searchsorted(cell_keys, key)
                    if c2 >= ncell or cell_keys[c2] != key or c2 < c or hi[c2] < 0:
                        continue
                    if lo[c] == hi[c] and lo[c2] == hi[c2] and lo[c] == lo[c2]:
                        continue
                    for a in range(cell_start[c], cell_start[c + 1]):
                        i = order[a]
                        li = labels[i]
                        if li < 0:
                            continue
                        b0 = cell_start[c2]
                        if c2 == c:
                            b0 = a + 1
                        for b in range(b0, cell_start[c2 + 1]):
                            j = order[b]
                            lj = labels[j]
                            if lj < 0 or lj == li:
                                continue
                            d = ((pts[i, 0] - pts[j, 0]) ** 2 + (pts[i, 1] - pts[j, 1]) ** 2
                                 + (pts[i, 2] - pts[j, 2]) ** 2)
                            if d <= r2:
                                if m >= cap:
                                    cap *= 2
                                    ni = np.empty(cap, dtype=np.int64)
                                    nj = np.empty(cap, dtype=np.int64)
                                    ni[:m] = out_i[:m]
                                    nj[:m] = out_j[:m]
                                    out_i = ni
                                    out_j = nj
                                out_i[m] = i
                                out_j[m] = j
                                m += 1
    return out_i[:m], out_j[:m]
