"""Numba kernels shared by several subpackages (private).

:func:`centred_moments` gives the mean and the centred second moments of a point
subset (geometry's planarity, ground's segment planes); :func:`grid_keys` numbers
the cells of an XY grid (ground's seed cells and density measures). Like every
kernel they trust their inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["centred_moments", "grid_keys"]


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
