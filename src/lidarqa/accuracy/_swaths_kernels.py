"""Private kernels of :mod:`lidarqa.accuracy.swaths`: per-cell plane statistics.

Everything here works on sums per grid cell (count, Σx, Σy, Σz, Σx², Σxy, Σy²,
Σxz, Σyz, Σz² in coordinates local to the cell centre), so a block can be
processed in chunks and the sums added before the planes are solved: the
per-cell planes, and everything built from them, do not depend on how the
points were split (as long as chunks are aligned on the grid, or their sums
are added per cell key).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_SUMS = 10  # n, sx, sy, sz, sxx, sxy, syy, sxz, syz, szz


@dataclass(frozen=True)
class Grid:
    """A square grid anchored at (x0, y0) (lower-left corner), `nx` × `ny` cells.

    Attributes
    ----------
    x0, y0 : float
        Lower-left corner (m).
    cell_size : float
        Side of a cell (m).
    nx, ny : int
        Number of columns and rows; a cell's flat key is ``iy * nx + ix``.
    """

    x0: float
    y0: float
    cell_size: float
    nx: int
    ny: int

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Flat cell key (iy * nx + ix) of each xy (int64)."""
        ix = np.floor((xy[:, 0] - self.x0) / self.cell_size).astype(np.int64)
        iy = np.floor((xy[:, 1] - self.y0) / self.cell_size).astype(np.int64)
        np.clip(ix, 0, self.nx - 1, out=ix)
        np.clip(iy, 0, self.ny - 1, out=iy)
        return iy * self.nx + ix

    def centres(self, keys: np.ndarray) -> np.ndarray:
        """Cell centres (M, 2) of flat keys."""
        iy, ix = np.divmod(keys, self.nx)
        return np.column_stack(
            [self.x0 + (ix + 0.5) * self.cell_size, self.y0 + (iy + 0.5) * self.cell_size]
        )


def grid_for(xy: np.ndarray, cell_size: float) -> Grid:
    """A grid snapped to multiples of `cell_size` that covers every xy.

    Parameters
    ----------
    xy : ndarray of shape (N, 2)
        Points (or corners of an extent) to cover (m).
    cell_size : float
        Side of a cell (m).

    Returns
    -------
    Grid
        Anchored at the multiple of `cell_size` at or below the smallest x and y,
        so grids of neighbouring chunks share their cells.
    """
    lo = np.floor(xy.min(axis=0) / cell_size) * cell_size
    hi = xy.max(axis=0)
    n = np.maximum(np.floor((hi - lo) / cell_size).astype(np.int64) + 1, 1)
    return Grid(float(lo[0]), float(lo[1]), float(cell_size), int(n[0]), int(n[1]))


def cell_sums(points: np.ndarray, grid: Grid, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """Sufficient statistics of the points per occupied cell.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z (m).
    grid : Grid
        The cells.
    z0 : float
        Height the z sums are taken about (m), the same for every chunk.

    Returns
    -------
    keys : ndarray of shape (M,) int64
        Flat keys of the occupied cells, ascending.
    sums : ndarray of shape (M, 10)
        n, Σx, Σy, Σz, Σx², Σxy, Σy², Σxz, Σyz, Σz² per cell, with x, y relative
        to the cell centre and z to `z0`: additive over chunks.
    """
    keys = grid.cell_of(points[:, :2])
    ukeys, inv = np.unique(keys, return_inverse=True)
    centres = grid.centres(ukeys)
    dx = points[:, 0] - centres[inv, 0]
    dy = points[:, 1] - centres[inv, 1]
    dz = points[:, 2] - z0
    m = len(ukeys)
    cols = (np.ones_like(dx), dx, dy, dz, dx * dx, dx * dy, dy * dy, dx * dz, dy * dz, dz * dz)
    sums = np.empty((m, N_SUMS))
    for j, c in enumerate(cols):
        sums[:, j] = np.bincount(inv, weights=c, minlength=m)
    return ukeys, sums


def merge_sums(
    parts: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray]:
    """Add the per-cell sums of several chunks (same grid and z0)."""
    keys = np.concatenate([k for k, _ in parts])
    sums = np.concatenate([s for _, s in parts])
    ukeys, inv = np.unique(keys, return_inverse=True)
    out = np.zeros((len(ukeys), N_SUMS))
    np.add.at(out, inv, sums)
    return ukeys, out


@dataclass(frozen=True)
class CellPlanes:
    """Planes z = a + b·dx + c·dy fitted per cell (dx, dy from the cell centre)."""

    keys: np.ndarray  # (M,) int64
    n: np.ndarray  # (M,) points
    a: np.ndarray  # height at the cell centre (absolute, m)
    b: np.ndarray  # ∂z/∂x
    c: np.ndarray  # ∂z/∂y
    q00: np.ndarray  # (XᵀX)⁻¹[0, 0]: var(a) = σ² q00
    q: np.ndarray  # (M, 3, 3) (XᵀX)⁻¹: cov(a, b, c) = σ² q
    rms: np.ndarray  # residual RMS with n - 3 degrees of freedom (m)
    spread: np.ndarray  # smallest standard deviation of the xy distribution (m)
    ok: np.ndarray  # bool: enough points and a well-spread design


def fit_cell_planes(
    keys: np.ndarray, sums: np.ndarray, z0: float, *, min_points: int, min_spread: float
) -> CellPlanes:
    """Solve the 3×3 normal equations of every cell at once."""
    n, sx, sy, sz, sxx, sxy, syy, sxz, syz, szz = sums.T
    safe_n = np.maximum(n, 1.0)
    mx, my = sx / safe_n, sy / safe_n
    vxx = np.maximum(sxx / safe_n - mx * mx, 0.0)
    vyy = np.maximum(syy / safe_n - my * my, 0.0)
    vxy = sxy / safe_n - mx * my
    # smallest eigenvalue of the 2x2 xy covariance
    half_tr = 0.5 * (vxx + vyy)
    disc = np.sqrt(np.maximum(0.25 * (vxx - vyy) ** 2 + vxy * vxy, 0.0))
    spread = np.sqrt(np.maximum(half_tr - disc, 0.0))
    ok = (n >= max(min_points, 4)) & (spread >= min_spread)
    m = len(keys)
    mat = np.empty((m, 3, 3))
    mat[:, 0, 0], mat[:, 0, 1], mat[:, 0, 2] = n, sx, sy
    mat[:, 1, 0], mat[:, 1, 1], mat[:, 1, 2] = sx, sxx, sxy
    mat[:, 2, 0], mat[:, 2, 1], mat[:, 2, 2] = sy, sxy, syy
    rhs = np.column_stack([sz, sxz, syz])
    mat[~ok] = np.eye(3)
    inv = np.linalg.inv(mat)
    p = np.einsum("mij,mj->mi", inv, rhs)
    sse = szz - np.einsum("mi,mi->m", p, rhs)
    dof = np.maximum(n - 3.0, 1.0)
    rms = np.sqrt(np.maximum(sse, 0.0) / dof)
    nan = np.where(ok, 1.0, np.nan)
    return CellPlanes(
        keys=keys,
        n=n.astype(np.int64),
        a=(p[:, 0] + z0) * nan,
        b=p[:, 1] * nan,
        c=p[:, 2] * nan,
        q00=inv[:, 0, 0] * nan,
        q=inv * nan[:, None, None],
        rms=rms * nan,
        spread=spread,
        ok=ok,
    )


def residual_extremes(
    points: np.ndarray,
    grid: Grid,
    planes: CellPlanes,
    selected: np.ndarray,
    *,
    split: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Highest and lowest plane residual and point count per (sub-)cell.

    The mergeable part of :func:`residual_ranges`. Chunks of a block give parts
    that :func:`merge_extremes` combines exactly (max, min, sum per key).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z (m).
    grid : Grid
        The cells of `planes`.
    planes : CellPlanes
        Per-cell planes (``keys``, ``a``, ``b``, ``c``).
    selected : ndarray of shape (M,) bool
        The cells of `planes` whose residuals count.
    split : int, default 1
        Sub-cells per side of a cell.

    Returns
    -------
    keys : ndarray of int64
        Keys of the selected cells (``split == 1``, from ``planes.keys[selected]``)
        or sub-cells (``cell_index * split² + row * split + col``, cell_index into
        the selected cells) that hold points.
    hi, lo : ndarray of float
        Highest and lowest residual (m) per key.
    count : ndarray of int64
        Points per key.
    """
    sel_keys = planes.keys[selected]
    empty = np.empty(0, dtype=np.int64)
    if len(sel_keys) == 0 or len(points) == 0:
        return empty, np.empty(0), np.empty(0), empty
    keys = grid.cell_of(points[:, :2])
    pos = np.searchsorted(sel_keys, keys)
    pos = np.minimum(pos, len(sel_keys) - 1)
    inside = sel_keys[pos] == keys
    pos = pos[inside]
    pts = points[inside]
    idx = np.flatnonzero(selected)[pos]
    centres = grid.centres(sel_keys[pos])
    dx = pts[:, 0] - centres[:, 0]
    dy = pts[:, 1] - centres[:, 1]
    r = pts[:, 2] - (planes.a[idx] + planes.b[idx] * dx + planes.c[idx] * dy)
    if split <= 1:
        sub = pos.astype(np.int64)
    else:
        size = grid.cell_size / split
        h = 0.5 * grid.cell_size
        col = np.clip(np.floor((dx + h) / size).astype(np.int64), 0, split - 1)
        row = np.clip(np.floor((dy + h) / size).astype(np.int64), 0, split - 1)
        sub = pos * split * split + row * split + col
    ukeys, inv, counts = np.unique(sub, return_inverse=True, return_counts=True)
    hi = np.full(len(ukeys), -np.inf)
    lo = np.full(len(ukeys), np.inf)
    np.maximum.at(hi, inv, r)
    np.minimum.at(lo, inv, r)
    if split <= 1:
        ukeys = sel_keys[ukeys]
    return ukeys, hi, lo, counts.astype(np.int64)


def merge_extremes(
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Combine :func:`residual_extremes` parts of several chunks (same planes).

    Parameters
    ----------
    parts : list of tuple
        ``(keys, hi, lo, count)`` per chunk.

    Returns
    -------
    tuple
        ``(keys, hi, lo, count)`` with every key once: the max of `hi`, the min
        of `lo` and the sum of `count` over the parts.
    """
    parts = [p for p in parts if len(p[0])]
    if not parts:
        e = np.empty(0, dtype=np.int64)
        return e, np.empty(0), np.empty(0), e
    keys = np.concatenate([p[0] for p in parts])
    ukeys, inv = np.unique(keys, return_inverse=True)
    hi = np.full(len(ukeys), -np.inf)
    lo = np.full(len(ukeys), np.inf)
    n = np.zeros(len(ukeys), dtype=np.int64)
    np.maximum.at(hi, inv, np.concatenate([p[1] for p in parts]))
    np.minimum.at(lo, inv, np.concatenate([p[2] for p in parts]))
    np.add.at(n, inv, np.concatenate([p[3] for p in parts]))
    return ukeys, hi, lo, n


def residual_ranges(
    points: np.ndarray,
    grid: Grid,
    planes: CellPlanes,
    selected: np.ndarray,
    *,
    split: int = 1,
    min_points: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Max − min of the plane residuals of the points in each selected cell.

    With ``split > 1`` every selected cell is divided into ``split × split``
    sub-cells and the range is taken per sub-cell (residuals still about the
    whole cell's plane); only sub-cells with at least `min_points` points count.
    Returns ``(keys, ranges)``: the cell keys of ``planes.keys[selected]``, or
    for sub-cells ``cell_index * split² + row * split + col`` with cell_index
    into the selected cells.
    """
    return ranges_from_extremes(
        residual_extremes(points, grid, planes, selected, split=split),
        min_points=min_points if split > 1 else 1,
    )


def ranges_from_extremes(
    extremes: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], *, min_points: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """``(keys, max − min)`` of the (sub-)cells with at least `min_points` points.

    Parameters
    ----------
    extremes : tuple
        ``(keys, hi, lo, count)`` from :func:`residual_extremes` or
        :func:`merge_extremes`.
    min_points : int, default 3
        Fewest points a (sub-)cell needs.

    Returns
    -------
    keys : ndarray of int64
    ranges : ndarray of float
        Max − min residual (m) per kept key.
    """
    keys, hi, lo, n = extremes
    keep = n >= min_points
    return keys[keep], (hi - lo)[keep]
