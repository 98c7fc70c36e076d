"""A regular grid of chunks with buffers over a catalog.

Every chunk has a *core* square of ``chunk_size`` metres and a *buffered* box, the
core grown by ``buffer`` metres on every side. A job reads the buffered box (so that
a filter sees the neighbourhood of every core point: no edge artifacts) and keeps
the results of core points only. Core membership is decided by grid index,
``col = floor((x - origin_x) / chunk_size)`` (half-open cells), so every point of the
catalog is a core point of exactly one chunk, whatever floating point rounding does
at cell borders. One exception keeps tiles whose data reach their east/north border
exactly (e.g. 770500.00 .. 770650.00) from making an extra column/row of chunks that
would hold only the points on that line: when the catalog's east (north) edge lies
exactly on a grid line, the points on it belong to the last column (row), i.e. the
column index is clamped to the last one (:attr:`Chunk.last`).

Defaults (chosen from the catalog header data):

- ``buffer``: the job's own margin (the ground job asks
  :func:`lidarqa.tiling.ground.ground_buffer`: one seed cell); :data:`DEFAULT_BUFFER`
  = 60 m, the ground filter's default seed cell, when a job names none.
- ``chunk_size``: the side whose *buffered* box holds about :data:`TARGET_POINTS`
  points at the catalog's mean density (points / tile area), i.e.
  ``sqrt(TARGET_POINTS / density) - 2 * buffer``, but at least :data:`MIN_BUFFERS`
  buffers wide (and ``MIN_CHUNK`` m): a chunk then reads at most
  ``(1 + 2 / MIN_BUFFERS)**2`` = 4 times its own area, where a dense cloud with a
  large buffer read 49 times (20 m chunks, 60 m buffer). When the whole catalog fits
  in a chunk of that side it is one chunk (the smallest side from its extent, a
  multiple of the tile size when one fits, that puts the catalog in one grid cell):
  every chunk would have read all of it. Otherwise the side is
  snapped to the tiling: to ``tile_size / k`` (the largest such fraction not above
  it) when smaller than the tile size, to a multiple of the tile size otherwise, so
  chunks line up with tile borders when the tiles do with the origin -- unless the
  snapped chunks would read and filter more than :data:`SNAP_TOLERANCE` times the
  points per core point of the unsnapped side (a buffer reads ``((side + 2 buffer) /
  side)**2`` points per core point: halving a 280 m chunk to fit 305 m tiles costs 57 %
  more work). The side is then the unsnapped one, rounded down to 10 m.
- ``origin``: (0, 0), so chunk borders fall on round coordinates; national tilings
  (e.g. 1 km tiles at multiples of 1000 m) are then aligned with the chunks.
- ``snap`` (used by the ground job): the buffered box's south-west corner is moved
  further out to the filter's seed grid (cells of ``cell_size`` from the catalog's
  south-west corner), so each chunk seeds its TIN in the same cells as one run over
  the whole catalog. On the six adjacent IGN 50 m tiles this raises the agreement of
  chunked and whole-area ground labels from 99.57 % to 99.94 % (50 m chunks).

Chunks whose core touches no tile's header bounds are not created. Chunk ids
(``"c0003_r0012"``, column and row counted from the catalog's south-west chunk) are
stable for a given catalog, chunk size and origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import OptionError

if TYPE_CHECKING:
    from ._types import Tiles
    from .engine import TileRef

__all__ = [
    "Chunk",
    "make_chunks",
    "default_chunk_size",
    "DEFAULT_BUFFER",
    "TARGET_POINTS",
    "MIN_CHUNK",
    "SNAP_TOLERANCE",
    "MIN_BUFFERS",
]

#: Default buffer around each chunk, m (the ground filter's default seed cell).
DEFAULT_BUFFER = 60.0
#: Points aimed at in one buffered chunk when a job names no target of its own: below 2 GB of
#: peak memory per worker for every job (measured on a synthetic 25 pts/m² block of eight
#: 216 m tiles: edges 1.77 GB with 15 chunks of 216 m, 2.65 GB with 6 of 370 m, i.e. 6 M
#: points). The ground job, lighter per point, asks for more (``tiling.ground``).
TARGET_POINTS = 3_500_000
#: Snap the chunk side to the tiling only when that costs at most this much more work: a
#: buffered chunk reads and filters ((side + 2 buffer) / side)**2 points per core point.
SNAP_TOLERANCE = 1.15
#: Smallest default chunk side, m.
MIN_CHUNK = 20.0
#: Smallest default chunk side in buffers: a chunk reads at most (1 + 2 / MIN_BUFFERS)**2
#: times its area, whatever the density (dense TLS/MLS clouds would otherwise get tiny chunks).
MIN_BUFFERS = 2.0
# Header bounds are the exact min/max of the scaled coordinates, so the grid cells a tile
# reaches follow from them with the same formula as the points' (the final pass of a job
# checks that every point was a core point once). Tiles are matched to buffered boxes with
# this tolerance, m.
_EPS = 1e-6


@dataclass(frozen=True)
class Chunk:
    """One cell of the chunk grid.

    Attributes
    ----------
    id : str
        ``"cCCCC_rRRRR"``: stable name (column, row from the south-west chunk).
    row, col : int
        Position in the grid, counted from the catalog's south-west chunk.
    core : tuple of 4 floats
        ``(xmin, ymin, xmax, ymax)``, half-open ``[min, max)``.
    buffered : tuple of 4 floats
        The core grown by the buffer on each side (closed).
    tiles : tuple of int
        Indices into ``catalog.tiles`` of the tiles whose bounds meet ``buffered``.
    index : tuple of 2 int
        Absolute grid index ``(floor((x0 - ox) / size), floor((y0 - oy) / size))``.
    size : float
        Chunk side, m.
    origin : tuple of 2 floats
        Grid origin.
    last : tuple of 2 int, optional
        Absolute grid index of the catalog's last column and row: point indices are
        clamped to them (points exactly on the catalog's east/north edge, when that
        edge is a grid line, belong to the last column/row).
    """

    id: str
    row: int
    col: int
    core: tuple[float, float, float, float]
    buffered: tuple[float, float, float, float]
    tiles: tuple[int, ...]
    index: tuple[int, int] = (0, 0)
    size: float = 0.0
    origin: tuple[float, float] = (0.0, 0.0)
    last: tuple[int, int] | None = None

    def core_mask(self, xy: np.ndarray) -> np.ndarray:
        """Boolean mask of the points of `xy` (N, 2+) whose grid cell is this chunk."""
        ox, oy = self.origin
        gi = np.floor((xy[:, 0] - ox) / self.size)
        gj = np.floor((xy[:, 1] - oy) / self.size)
        if self.last is not None:
            gi = np.minimum(gi, self.last[0])
            gj = np.minimum(gj, self.last[1])
        return (gi == self.index[0]) & (gj == self.index[1])

    def to_dict(self) -> dict[str, object]:
        """The chunk as a JSON-ready dict (id, grid position, core and buffered boxes, tiles)."""
        return {
            "id": self.id,
            "row": self.row,
            "col": self.col,
            "core": list(self.core),
            "buffered": list(self.buffered),
            "tiles": list(self.tiles),
        }


def default_chunk_size(
    catalog: Tiles,
    *,
    buffer: float = DEFAULT_BUFFER,
    origin: tuple[float, float] = (0.0, 0.0),
    target_points: float | None = None,
) -> float:
    """The default chunk side for `catalog` (see the module documentation), m.

    Parameters
    ----------
    catalog : Catalog
    buffer : float, default DEFAULT_BUFFER
        The job's margin, m: the side is at least :data:`MIN_BUFFERS` of it.
    origin : (float, float), default (0, 0)
        The chunk grid's origin (a catalog that fits one chunk is put in one grid cell).
    target_points : float, optional
        Points aimed at in one buffered chunk (default :data:`TARGET_POINTS`): the job's
        memory per point decides it.
    """
    density = catalog.density
    target = TARGET_POINTS if target_points is None else float(target_points)
    floor = max(MIN_CHUNK, MIN_BUFFERS * float(buffer))
    raw = max(math.sqrt(target / density) - 2.0 * buffer, floor)
    tile = catalog.tile_size()
    one = _one_chunk_side(catalog, raw, tile, origin)
    if one is not None:
        return one
    if tile > 0:
        if raw < tile:
            snapped = tile / math.ceil(tile / raw - 1e-9)
        else:
            snapped = tile * math.floor(raw / tile + 1e-9)
        if snapped >= floor and _work(snapped, buffer) <= SNAP_TOLERANCE * _work(raw, buffer):
            return float(snapped)
    step = 10.0 if raw >= 100.0 else 1.0
    return float(max(math.floor(raw / step) * step, floor))


def _one_chunk_side(
    catalog: Tiles, side: float, tile: float, origin: tuple[float, float]
) -> float | None:
    """The smallest side <= `side` that puts the whole catalog in one chunk, or None.

    Multiples of the tile size are tried first (chunks stay aligned with the tiles),
    then whole metres. A side works when the catalog's west and east edges (south and
    north) fall in the same grid column (row), by the rule of :func:`make_chunks` (an
    east/north edge on a grid line opens no column/row).
    """
    b = [t.bounds2d for t in catalog.tiles if t.n_points > 0]
    if not b:
        return None
    arr = np.asarray(b, dtype=float)
    x0, y0 = arr[:, 0].min() - origin[0], arr[:, 1].min() - origin[1]
    x1, y1 = arr[:, 2].max() - origin[0], arr[:, 3].max() - origin[1]
    span = max(x1 - x0, y1 - y0)
    if span > side:
        return None

    def fits(s: float) -> bool:
        return all(math.ceil(hi / s) - 1 <= math.floor(lo / s) for lo, hi in ((x0, x1), (y0, y1)))

    tries = [tile * k for k in range(1, 65) if span <= tile * k <= side] if tile > 0 else []
    start = max(math.ceil(span), 1)
    tries += [float(v) for v in range(start, min(int(math.floor(side)), start + 10_000) + 1)]
    for s in tries:
        if fits(s):
            return float(s)
    return None


def estimated_points(catalog: Tiles, chunk: Chunk | TileRef) -> float:
    """Points in `chunk`'s buffered box, estimated from the tile headers (uniform density)."""
    x0, y0, x1, y1 = chunk.buffered
    total = 0.0
    for i in chunk.tiles:
        t = catalog.tiles[i]
        tx0, ty0, tx1, ty1 = t.bounds[:4]
        area = max(tx1 - tx0, 1e-9) * max(ty1 - ty0, 1e-9)
        w = max(min(x1, tx1) - max(x0, tx0), 0.0)
        h = max(min(y1, ty1) - max(y0, ty0), 0.0)
        total += t.n_points * min(w * h / area, 1.0)
    return total


def _work(size: float, buffer: float) -> float:
    """Points read and filtered per core point for square chunks of side `size`."""
    return ((size + 2.0 * buffer) / size) ** 2


def make_chunks(
    catalog: Tiles,
    *,
    chunk_size: float | None = None,
    buffer: float | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    snap: tuple[float, float, float] | None = None,
    target_points: float | None = None,
) -> tuple[Chunk, ...]:
    """The chunks covering `catalog`, row by row from the south-west.

    Parameters
    ----------
    catalog : Catalog
    chunk_size : float, optional
        Side of a chunk's core, m (default :func:`default_chunk_size`).
    buffer : float, optional
        Margin read around each core, m (default :data:`DEFAULT_BUFFER`); 0 allowed.
    origin : (float, float), default (0, 0)
        A point on the chunk grid lines (alignment).
    snap : (gx, gy, step), optional
        Extend each buffered box's south-west corner down to the grid of `step` metres
        through ``(gx, gy)``. Jobs whose kernels lay a grid from the south-west corner
        of their input (the ground filter's seed cells) use it so every chunk lays its
        grid where one run over the whole catalog would.
    target_points : float, optional
        With the default `chunk_size`: points aimed at in one buffered chunk (default
        :data:`TARGET_POINTS`).
    """
    buffer = DEFAULT_BUFFER if buffer is None else float(buffer)
    if not math.isfinite(buffer) or buffer < 0:
        raise OptionError(f"buffer must be >= 0 m, got {buffer}")
    size = (
        default_chunk_size(catalog, buffer=buffer, origin=origin, target_points=target_points)
        if chunk_size is None
        else float(chunk_size)
    )
    if not math.isfinite(size) or size <= 0:
        raise OptionError(f"chunk size must be > 0 m, got {chunk_size}")
    ox, oy = float(origin[0]), float(origin[1])
    b = np.array([t.bounds2d for t in catalog.tiles], dtype=float).reshape(-1, 4)
    nonempty = np.array([t.n_points > 0 for t in catalog.tiles], dtype=bool)
    if not nonempty.any():
        return ()
    span = b[nonempty, 2:].max(axis=0) - b[nonempty, :2].min(axis=0)
    if float(np.prod(span / size + 2.0)) > 10_000_000:
        raise OptionError(f"chunk size {size:g} m makes too many chunks; choose a larger one")
    c0 = np.floor((b[:, 0] - ox) / size).astype(np.int64)
    c1 = np.floor((b[:, 2] - ox) / size).astype(np.int64)
    r0 = np.floor((b[:, 1] - oy) / size).astype(np.int64)
    r1 = np.floor((b[:, 3] - oy) / size).astype(np.int64)
    # the catalog's last column/row: an east/north edge exactly on a grid line opens no
    # column/row of its own (its points join the last one, see Chunk.core_mask)
    last_c = max(int(np.ceil((b[nonempty, 2].max() - ox) / size)) - 1, int(c0[nonempty].min()))
    last_r = max(int(np.ceil((b[nonempty, 3].max() - oy) / size)) - 1, int(r0[nonempty].min()))
    c0, c1 = np.minimum(c0, last_c), np.minimum(c1, last_c)
    r0, r1 = np.minimum(r0, last_r), np.minimum(r1, last_r)
    cells: set[tuple[int, int]] = set()
    for k in np.nonzero(nonempty)[0]:
        if (c1[k] - c0[k] + 1) * (r1[k] - r0[k] + 1) > 10_000_000:
            raise OptionError(f"chunk size {size} m makes too many chunks; choose a larger one")
        for j in range(int(r0[k]), int(r1[k]) + 1):
            for i in range(int(c0[k]), int(c1[k]) + 1):
                cells.add((j, i))
    gi0 = int(c0[nonempty].min())
    gj0 = int(r0[nonempty].min())
    out = []
    for j, i in sorted(cells):
        core = (ox + i * size, oy + j * size, ox + (i + 1) * size, oy + (j + 1) * size)
        buf = (core[0] - buffer, core[1] - buffer, core[2] + buffer, core[3] + buffer)
        if snap is not None:
            gx, gy, step = snap
            buf = (
                gx + math.floor((buf[0] - gx) / step + 1e-9) * step,
                gy + math.floor((buf[1] - gy) / step + 1e-9) * step,
                buf[2],
                buf[3],
            )
        hit = np.nonzero(
            nonempty
            & (b[:, 0] - _EPS <= buf[2])
            & (b[:, 2] + _EPS >= buf[0])
            & (b[:, 1] - _EPS <= buf[3])
            & (b[:, 3] + _EPS >= buf[1])
        )[0]
        row, col = j - gj0, i - gi0
        out.append(
            Chunk(
                id=f"c{col:04d}_r{row:04d}",
                row=row,
                col=col,
                core=core,
                buffered=buf,
                tiles=tuple(int(t) for t in hit),
                index=(i, j),
                size=size,
                origin=(ox, oy),
                last=(last_c, last_r),
            )
        )
    return tuple(out)
