"""Numba kernels of ``qc``: one pass over a piece of points, and the void opening."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["open_square", "scan_piece"]


@njit(cache=True, nogil=True)
def open_square(empty: np.ndarray, k: int) -> np.ndarray:  # pragma: no cover - numba
    """Morphological opening of the bool grid `empty` by a ``k x k`` square.

    A cell is in the result when some ``k x k`` square of `empty` cells lying wholly
    inside the grid holds it (the union of the squares that fit). Equal to
    ``maximum_filter(minimum_filter(empty, k, mode="constant"), k)`` for odd `k`, in
    O(cells) whatever `k`: runs along the rows, then along the columns.
    """
    ny, nx = empty.shape
    out = np.zeros((ny, nx), dtype=np.bool_)
    if k > nx or k > ny:
        return out
    # row_ok[r, c]: cells (r, c .. c+k-1) all empty
    row_ok = np.zeros((ny, nx), dtype=np.bool_)
    for r in range(ny):
        run = 0
        for c in range(nx):
            run = run + 1 if empty[r, c] else 0
            if run >= k:
                row_ok[r, c - k + 1] = True
    # corner[r, c]: the square with south-west cell (r, c) is all empty
    corner = np.zeros((ny, nx), dtype=np.bool_)
    vrun = np.zeros(nx, dtype=np.int64)
    for r in range(ny):
        for c in range(nx):
            vrun[c] = vrun[c] + 1 if row_ok[r, c] else 0
            if vrun[c] >= k:
                corner[r - k + 1, c] = True
    # dilation: (i, j) is covered by a square with corner in [i-k+1, i] x [j-k+1, j]
    last_row = np.full(nx, -k - 1, dtype=np.int64)
    for i in range(ny):
        last_c = -k - 1
        for j in range(nx):
            if corner[i, j]:
                last_c = j
            if j - last_c < k:  # a corner of row i within k cells to the west
                last_row[j] = i
            if i - last_row[j] < k:
                out[i, j] = True
    return out


@njit(cache=True, nogil=True)
def scan_piece(x, y, z, rn, nr, cls, withheld, overlap, synthetic, key_point, sid, angle,
               all_first, max_returns, legacy_overlap,
               vgrid, fgrid, occupied, water_void, water, firsts, counts, slot_of,
               mins, maxs, by_return, classes, sid_hist, flags, ang_mm):  # pragma: no cover
    """One pass over a piece of points: statistics and grids, accumulated in place.

    Optional fields are empty arrays when the file lacks them. `vgrid` and `fgrid` are
    ``(x0, y0, cell, nx, ny)`` of the void and density (2 x ANPS) grids; `counts` holds
    one row per source-id slot (``slot_of[source id]``). `flags` accumulates withheld,
    overlap, synthetic and key-point counts; `ang_mm` the scan-angle min and max.
    Returns ``(invalid returns, points outside the grid, usable first returns not
    counted for density)``.
    """
    n = len(x)
    has_rn = len(rn) > 0 and len(nr) > 0
    invalid = 0
    outside = 0
    flagged = 0
    vx0, vy0, vc, vnx, vny = vgrid[0], vgrid[1], vgrid[2], int(vgrid[3]), int(vgrid[4])
    fx0, fy0, fc, fnx, fny = fgrid[0], fgrid[1], fgrid[2], int(fgrid[3]), int(fgrid[4])
    for p in range(n):
        xp, yp, zp = x[p], y[p], z[p]
        if xp < mins[0]:
            mins[0] = xp
        if xp > maxs[0]:
            maxs[0] = xp
        if yp < mins[1]:
            mins[1] = yp
        if yp > maxs[1]:
            maxs[1] = yp
        if zp < mins[2]:
            mins[2] = zp
        if zp > maxs[2]:
            maxs[2] = zp
        first = True
        if has_rn:
            r = int(rn[p])
            m = int(nr[p])
            if r < 1 or r > m or m > max_returns:
                invalid += 1
            by_return[min(max(r, 0), 15)] += 1
            first = all_first or r == 1
        c = int(cls[p]) if len(cls) else 0
        classes[c] += 1
        s = int(sid[p]) if len(sid) else 0
        sid_hist[s] += 1
        w = len(withheld) > 0 and withheld[p] != 0
        o = len(overlap) > 0 and overlap[p] != 0
        if w:
            flags[0] += 1
        if o:
            flags[1] += 1
        if len(synthetic) and synthetic[p] != 0:
            flags[2] += 1
        if len(key_point) and key_point[p] != 0:
            flags[3] += 1
        if len(angle):
            a = angle[p]
            if a < ang_mm[0]:
                ang_mm[0] = a
            if a > ang_mm[1]:
                ang_mm[1] = a
        usable = first and not w
        wet = c == 9 and len(cls) > 0
        # void grid: any usable first return fills its cell; water marks its cell
        vi = int(np.floor((xp - vx0) / vc))
        vj = int(np.floor((yp - vy0) / vc))
        if 0 <= vi < vnx and 0 <= vj < vny:
            if usable:
                occupied[vj * vnx + vi] = True
            if wet:
                water_void[vj * vnx + vi] = True
        counted = not w and not o and not (legacy_overlap and c == 12)
        if usable and not counted:
            flagged += 1
        fi = int(np.floor((xp - fx0) / fc))
        fj = int(np.floor((yp - fy0) / fc))
        if not (0 <= fi < fnx and 0 <= fj < fny):
            outside += 1
            continue
        f = fj * fnx + fi
        if wet and first:
            water[f] += 1
        if usable:
            firsts[f] += 1
        if first and counted:
            counts[slot_of[s], f] += 1
    return invalid, outside, flagged
