"""Numba kernels shared by several subpackages (private).

:func:`centred_moments` gives the mean and the centred second moments of a point
subset (geometry's planarity, ground's segment planes); :func:`grid_keys` numbers
the cells of an XY grid (ground's seed cells and density measures). Like every
kernel they trust their inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["centred_moments", "grid_keys", "sort_runs_lex"]


@njit(cache=True, nogil=True)
def centred_moments(pts, rows, cnt):  # pragma: no cover - numba
    """Mean (x, y, z) and centred second-moment sums (xx, xy, xz, yy, yz, zz).

    Of ``pts[rows[:cnt]]``, in two passes (no cancellation at large coordinates).
    """
    mx = 0.0
    my = 0.0
    mz = 0.0
    for a in range(cnt):
        j = rows[a]
        mx += pts[j, 0]
        my += pts[j, 1]
        mz += pts[j, 2]
    mx /= cnt
    my /= cnt
    mz /= cnt
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for a in range(cnt):
        j = rows[a]
        dx = pts[j, 0] - mx
        dy = pts[j, 1] - my
        dz = pts[j, 2] - mz
        c00 += dx * dx
        c01 += dx * dy
        c02 += dx * dz
        c11 += dy * dy
        c12 += dy * dz
        c22 += dz * dz
    return mx, my, mz, c00, c01, c02, c11, c12, c22


@njit(cache=True, nogil=True, parallel=True)
def grid_keys(x, y, cell, lo_x, lo_y, span_y):  # pragma: no cover - numba
    """Row-major number of the `cell`-sized XY grid cell of each point, one pass.

    ``(floor(x / cell) - lo_x) * span_y + floor(y / cell) - lo_y`` as int64, with
    `lo_x`, `lo_y` the smallest cell indices and `span_y` the number of rows.
    """
    n = x.shape[0]
    key = np.empty(n, np.int64)
    for i in prange(n):
        key[i] = np.int64(np.floor(x[i] / cell) - lo_x) * span_y + np.int64(
            np.floor(y[i] / cell) - lo_y
        )
    return key


@njit(cache=True, nogil=True)
def _lex_less(pts, a, b):  # pragma: no cover - numba
    if pts[a, 0] != pts[b, 0]:
        return pts[a, 0] < pts[b, 0]
    if pts[a, 1] != pts[b, 1] or pts.shape[1] < 3:
        return pts[a, 1] < pts[b, 1]
    return pts[a, 2] < pts[b, 2]


@njit(cache=True, nogil=True)
def sort_runs_lex(perm, key_sorted, pts):  # pragma: no cover - numba
    """Sort each run of equal keys of `perm` by (x, y[, z]) in place (stable).

    `pts` has 2 or 3 columns; `key_sorted` is the key of ``perm[i]``, sorted. Geometry's
    canonical order and ground's Morton order both end with it.
    """
    n = perm.shape[0]
    s = 0
    while s < n:
        e = s + 1
        while e < n and key_sorted[e] == key_sorted[s]:
            e += 1
        if e - s > 16:
            # sort the run by x first (O(g log g)); the insertion pass then only fixes x-ties
            xs = np.empty(e - s)
            for i in range(s, e):
                xs[i - s] = pts[perm[i], 0]
            o = np.argsort(xs, kind="mergesort")
            tmp = perm[s:e].copy()
            for i in range(e - s):
                perm[s + i] = tmp[o[i]]
        for i in range(s + 1, e):
            v = perm[i]
            j = i - 1
            while j >= s and _lex_less(pts, v, perm[j]):
                perm[j + 1] = perm[j]
                j -= 1
            perm[j + 1] = v
        s = e
    return perm
