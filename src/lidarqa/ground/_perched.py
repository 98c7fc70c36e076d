"""Perched-surface test: accepted ground that drops steeply on opposite sides is not terrain.

Terrain is a continuous surface. Where accepted ground sits more than a storey
above the lowest candidates around it, and that drop is steep (a wall, not a
slope) on *opposite* sides, the accepted points lie on something that stands on
the terrain: a roof reached from the hillside, a bridge deck, a wall top. A
terrace edge, a cut or an embankment drops on one side only, or at the grade of a
slope on both, and is kept.

The test runs on a raster (cell :data:`CELL` m, aligned to absolute coordinates,
so a tile of a cloud sees the same cells as the whole cloud): per cell the highest
accepted ground point and the lowest candidate. A cell is *perched* when at least
two cells within `radius` lie more than `step` m lower at a grade steeper than
`angle` degrees, and the directions to those cells are spread (the mean of their
unit vectors is shorter than :data:`SPREAD`: they are not all on one side). The
accepted points of a perched cell within :data:`TOP_BAND` m of its highest ground
point are rejected. Loops run over raster offsets (a few hundred), never over points.

Only the part of a surface that sees steep drops on both sides is caught: a deck
or roof 5 m above its surroundings entirely up to about 6 m wide, along its
middle up to about 9 m (at 45°; the reach grows with the drop), wider ones not.
Spreading the rejection over the rest of a raised surface at the same level was
tried and removed: on the ISPRS samples it leaked onto hillsides and terraces
next to houses. Segment-PTD instead judges an accepted segment this test cuts into
as a whole, by its raised border (:class:`~lidarqa.ground.SegmentPTD`, `perched_step`).
"""

from __future__ import annotations

import math

import numpy as np

from .._arrays import colmax, colmin

__all__ = ["perched_mask", "CELL", "SPREAD", "TOP_BAND"]

#: raster cell (m)
CELL = 1.0
#: a full raster is used up to this many cells per point (plus _RASTER_MIN); beyond it,
#: only the occupied cells (same result, slower lookups)
_RASTER_PER_POINT = 4
_RASTER_MIN = 1_000_000
#: largest mean resultant length of the steep-drop directions (0 = evenly spread, 1 = one side)
SPREAD = 0.6
#: points of a perched cell this close (m) below its highest accepted point are rejected
TOP_BAND = 0.5


def perched_mask(
    points: np.ndarray,
    ground: np.ndarray,
    candidates: np.ndarray,
    *,
    step: float,
    angle: float,
    radius: float,
) -> np.ndarray:
    """Accepted ground points on a perched surface (see the module docstring).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Coordinates, metres (absolute: the raster is aligned to them).
    ground : ndarray of bool, shape (N,)
        Accepted ground.
    candidates : ndarray of bool, shape (N,)
        Points that could be ground (their lowest per cell is the reference below).
    step : float
        Smallest drop (m) that counts; > 0.
    angle : float
        Smallest grade (degrees) of a drop that counts.
    radius : float
        Search radius (m) for the drops.

    Returns
    -------
    ndarray of bool, shape (N,)
        True for the accepted ground points to reject.
    """
    n = points.shape[0]
    out = np.zeros(n, dtype=bool)
    if n == 0 or not ground.any():
        return out
    base = np.floor(colmin(points[:, :2]) / CELL)
    ij = np.floor(points[:, :2] / CELL) - base
    span = colmax(ij) + 1.0
    if span[0] * span[1] >= 2.0**62:  # no real cloud: the cell keys would overflow
        return out
    ij = ij.astype(np.int64)
    ni, nj = int(span[0]), int(span[1])
    flat = ij[:, 0] * nj + ij[:, 1]
    pad = int(math.ceil(radius / CELL))
    if ni * nj <= _RASTER_PER_POINT * n + _RASTER_MIN:  # a raster about the cloud's size
        top = np.full(ni * nj, -np.inf)
        np.maximum.at(top, flat[ground], points[ground, 2])
        low = np.full(ni * nj, np.inf)
        np.minimum.at(low, flat[candidates], points[candidates, 2])
        # cells that could be perched: some candidate within the window lies > step lower
        from scipy import ndimage

        win = np.hypot(*np.mgrid[-pad : pad + 1, -pad : pad + 1]) * CELL <= radius
        lowest = ndimage.minimum_filter(
            low.reshape(ni, nj), footprint=win, mode="constant", cval=np.inf
        )
        cells = np.flatnonzero(np.isfinite(top) & (top - lowest.ravel() > step))
        lowp = np.pad(low.reshape(ni, nj), pad, constant_values=np.inf)

        def low_at(ci, cj, di, dj):
            return lowp[ci + pad + di, cj + pad + dj]

        def top_of(keys):
            return top[keys]

    else:  # sparse or scattered cloud: occupied cells only, looked up by key
        gk = np.unique(flat[ground])
        gtop = np.full(gk.size, -np.inf)
        np.maximum.at(gtop, np.searchsorted(gk, flat[ground]), points[ground, 2])
        ck = np.unique(flat[candidates])
        clow = np.full(ck.size, np.inf)
        np.minimum.at(clow, np.searchsorted(ck, flat[candidates]), points[candidates, 2])
        cells = gk

        def low_at(ci, cj, di, dj):
            a, b = ci + di, cj + dj
            q = a * nj + b
            pos = np.minimum(np.searchsorted(ck, q), ck.size - 1)
            ok = (a >= 0) & (a < ni) & (b >= 0) & (b < nj) & (ck[pos] == q)
            return np.where(ok, clow[pos], np.inf)

        def top_of(keys):
            pos = np.minimum(np.searchsorted(gk, keys), gk.size - 1)
            return np.where(gk[pos] == keys, gtop[pos], -np.inf)

    if cells.size == 0:
        return out
    ci, cj = cells // nj, cells % nj
    t = top_of(cells)
    sx = np.zeros(cells.size)
    sy = np.zeros(cells.size)
    cnt = np.zeros(cells.size, dtype=np.int64)
    grade = math.tan(math.radians(angle))
    for di in range(-pad, pad + 1):
        for dj in range(-pad, pad + 1):
            r = math.hypot(di, dj)
            if r == 0 or r * CELL > radius:
                continue
            drop = t - low_at(ci, cj, di, dj)
            # the two points may sit anywhere in their cells: one cell less of run
            steep = (drop > step) & (drop > grade * (r - 1.0) * CELL)
            sx += steep * (di / r)
            sy += steep * (dj / r)
            cnt += steep
    flagged = (cnt >= 2) & (np.hypot(sx, sy) < SPREAD * np.maximum(cnt, 1))
    bad_keys = cells[flagged]
    pos = np.minimum(np.searchsorted(bad_keys, flat), max(bad_keys.size - 1, 0))
    in_bad = (bad_keys[pos] == flat) if bad_keys.size else np.zeros(n, dtype=bool)
    out = ground & in_bad & (points[:, 2] >= top_of(flat) - TOP_BAND)
    return out

