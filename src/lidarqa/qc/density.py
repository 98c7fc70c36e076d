"""First-return density the USGS way: ANPD, spatial distribution and a density raster.

Which points count
------------------
*First returns* (``return_number == 1``; a file without return numbers counts every
point, and says so), not withheld, and **single swath**: overage is left out in three
ways, in this order:

1. the LAS 1.4 *overlap* flag (PDRF 6-10), which the LBS requires for overage points;
2. class 12 in PDRF 0-5 (the legacy "overlap points" class);
3. when a tile flags no overage at all, unflagged overlap, detected per cell of the
   spatial-distribution grid (2 x ANPS):
   in a cell that holds first returns of several point source ids, only one source id
   counts -- the one with the most first returns over the whole tile (not per cell: a
   per-cell maximum of two swaths' counts is biased upwards). A swath border through a
   cell costs at most that cell's share of the other swath (a fraction of a percent).

Figures
-------
- **ANPD** (first returns per m²): single-swath first returns over the area of the
  density cells (``spec.density_cell``, a multiple of the distribution cell) that lie
  wholly inside the tile's data extent, hold a first return and are not mostly water
  (class 9); cells cut by the tile border do not bias it.
- **Spatial distribution**: share of 2 x ANPS cells wholly inside the data extent, not
  water, holding at least one single-swath first return.
- The **density raster** is the single-swath first returns per m² of each density cell;
  tiles add into one block raster (cells on a tile border get both tiles' points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import TilingError
from .conformance import PointStats, scan_angle_deg

__all__ = ["Grid", "DensityGrids", "DensityResult", "density_result"]

#: Largest grid (cells) a tile may need; a header whose bounds span more is not a tile.
MAX_CELLS = 400_000_000


@dataclass(frozen=True)
class Grid:
    """A regular grid aligned on multiples of `cell` (so tiles' grids line up)."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int

    @classmethod
    def covering(cls, bounds: tuple[float, float, float, float], cell: float) -> Grid:
        """A grid of `cell` m aligned on multiples of the cell that covers `bounds`."""
        xmin, ymin, xmax, ymax = bounds
        x0 = math.floor(xmin / cell) * cell
        y0 = math.floor(ymin / cell) * cell
        nx = max(int(math.floor((xmax - x0) / cell)) + 1, 1)
        ny = max(int(math.floor((ymax - y0) / cell)) + 1, 1)
        if nx * ny > MAX_CELLS:
            raise TilingError(
                f"the header bounds span {(xmax - xmin) / 1000:.1f} x {(ymax - ymin) / 1000:.1f} "
                f"km: too large for a {cell:.2f} m grid (is the header wrong?)")
        return cls(float(x0), float(y0), float(cell), nx, ny)

    def index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(flat cell index, inside mask) of points `xy` (N, 2+)."""
        i = np.floor((xy[:, 0] - self.x0) / self.cell).astype(np.int64)
        j = np.floor((xy[:, 1] - self.y0) / self.cell).astype(np.int64)
        inside = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        return j * self.nx + i, inside

    def inner_mask(self, bounds: tuple[float, float, float, float]) -> np.ndarray:
        """(ny, nx) bool: cells lying wholly inside `bounds`."""
        xmin, ymin, xmax, ymax = bounds
        xs = self.x0 + self.cell * np.arange(self.nx)
        ys = self.y0 + self.cell * np.arange(self.ny)
        cx = (xs >= xmin - 1e-9) & (xs + self.cell <= xmax + 1e-9)
        cy = (ys >= ymin - 1e-9) & (ys + self.cell <= ymax + 1e-9)
        return cy[:, None] & cx[None, :]


class _Acc:
    """Running point statistics of a tile (filled in place by the scan kernel)."""

    def __init__(self) -> None:
        self.n = 0
        self.invalid = 0
        self.has_returns = True
        self.has_sid = False
        self.has_angle = False
        self.mins = np.full(3, np.inf)
        self.maxs = np.full(3, -np.inf)
        self.by_return = np.zeros(16, dtype=np.int64)
        self.classes = np.zeros(256, dtype=np.int64)
        self.sid_hist = np.zeros(65536, dtype=np.int64)
        self.flags = np.zeros(4, dtype=np.int64)
        self.angle = np.array([np.inf, -np.inf])


class DensityGrids:
    """Per-tile accumulator of first-return counts (per source id), water and occupancy.

    Memory is the grids (a few bytes per 2 x ANPS cell and one byte per void cell), not
    the points: a tile is streamed through :meth:`add` piece by piece.
    """

    def __init__(self, bounds2d: tuple[float, float, float, float], *, cell: float,
                 void_cell: float, coarse_factor: int) -> None:
        k = max(int(coarse_factor), 1)
        coarse = cell * k
        self.coarse = Grid.covering(bounds2d, coarse)
        self.fine = Grid(self.coarse.x0, self.coarse.y0, cell, self.coarse.nx * k,
                         self.coarse.ny * k)
        self.k = k
        self.void = Grid.covering(bounds2d, void_cell)
        ncells = self.fine.nx * self.fine.ny
        self._counts = np.zeros((0, ncells), dtype=np.int32)  # one row per source-id slot
        self._slot_of = np.full(65536, -1, dtype=np.int64)
        self.slots: dict[int, int] = {}
        self.water = np.zeros(ncells, dtype=np.int32)
        self.firsts = np.zeros(ncells, dtype=np.int32)
        self.occupied = np.zeros(self.void.nx * self.void.ny, dtype=bool)
        self.water_void = np.zeros(self.void.nx * self.void.ny, dtype=bool)
        self.outside = 0
        self.flagged = 0  # first returns left out as overage (overlap flag, legacy class 12)
        self.has_returns = True  # False once a piece has no (or only zero) return numbers
        self._stats = _Acc()

    @property
    def counts(self) -> list[np.ndarray]:
        """Single-swath first returns per 2 x ANPS cell, one flat array per source id."""
        return [row for row in self._counts if row.any()]

    def scan(self, points: np.ndarray, fields: dict[str, np.ndarray], *,
             point_format: int) -> None:
        """Add one piece of points (`points` (N, 3), `fields` the LAS dimensions).

        One pass (a numba kernel) updates the grids and the tile's point statistics
        (:meth:`stats`): which points count is described in the module's docstring.
        """
        from ._kernels import scan_piece

        n = len(points)
        if n == 0:
            return
        none = np.zeros(0, dtype=np.uint8)

        def get(name: str) -> np.ndarray:
            v = fields.get(name)
            return none if v is None else np.asarray(v)

        rn, nr = get("return_number"), get("number_of_returns")
        has_fields = len(rn) > 0 and len(nr) > 0
        all_first = not (len(rn) and rn.any())
        self.has_returns = self.has_returns and not all_first
        sid = get("point_source_id")
        if len(sid):
            sid = sid.astype(np.uint16, copy=False)
            ids = np.flatnonzero(np.bincount(sid))
            new = [int(i) for i in ids if int(i) not in self.slots]
        else:
            new = [0] if 0 not in self.slots else []
        for i in new:
            self._slot_of[i] = self.slots[i] = len(self.slots)
        if new:
            grown = np.zeros((len(self.slots), self._counts.shape[1]), dtype=np.int32)
            grown[: len(self._counts)] = self._counts
            self._counts = grown
        angle = scan_angle_deg(fields)
        a = self._stats
        v, f = self.void, self.fine
        invalid, outside, flagged = scan_piece(
            points[:, 0], points[:, 1], points[:, 2], rn, nr, get("classification"),
            get("withheld"), get("overlap"), get("synthetic"), get("key_point"), sid,
            none.astype(np.float64) if angle is None else angle,
            all_first, 15 if point_format >= 6 else 5, point_format < 6,
            np.array([v.x0, v.y0, v.cell, v.nx, v.ny], dtype=np.float64),
            np.array([f.x0, f.y0, f.cell, f.nx, f.ny], dtype=np.float64),
            self.occupied, self.water_void, self.water, self.firsts, self._counts,
            self._slot_of, a.mins, a.maxs, a.by_return, a.classes, a.sid_hist, a.flags,
            a.angle)
        a.n += n
        a.invalid += int(invalid)
        a.has_returns = a.has_returns and has_fields
        a.has_angle = a.has_angle or angle is not None
        a.has_sid = a.has_sid or len(sid) > 0
        self.outside += int(outside)
        self.flagged += int(flagged)

    def stats(self) -> PointStats:
        """Statistics of the points scanned so far."""
        a = self._stats
        if a.n == 0:
            return PointStats()
        nz = np.flatnonzero(a.sid_hist)
        return PointStats(
            n=a.n, mins=tuple(float(v) for v in a.mins), maxs=tuple(float(v) for v in a.maxs),
            by_return=tuple(int(c) for c in a.by_return[1:16]) if a.has_returns else (0,) * 15,
            invalid_returns=a.invalid if a.has_returns else 0, has_returns=a.has_returns,
            classes=tuple(int(c) for c in a.classes),
            withheld=int(a.flags[0]), overlap=int(a.flags[1]), synthetic=int(a.flags[2]),
            key_point=int(a.flags[3]),
            source_ids={int(k): int(a.sid_hist[k]) for k in nz} if a.has_sid else {},
            scan_angle_min=float(a.angle[0]) if a.has_angle else np.inf,
            scan_angle_max=float(a.angle[1]) if a.has_angle else -np.inf,
        )

    def single_swath(self) -> np.ndarray:
        """(ny, nx) first returns of one swath per 2 x ANPS cell.

        Where several source ids meet, the cell keeps the one with the most first returns
        over the whole tile (ties: the lower id): a choice made before looking at the
        cell, so the local count is not biased upwards as a per-cell maximum would be.
        """
        if not self.counts:
            return np.zeros((self.fine.ny, self.fine.nx), dtype=np.int64)
        if len(self.counts) == 1:
            dom = self.counts[0]
        elif self.flagged:  # the delivery marks its overage: every unflagged return counts
            dom = np.sum(np.stack(self.counts), axis=0)
        else:
            sids = sorted(self.slots, key=lambda s: (-int(self.counts[self.slots[s]].sum()), s))
            dom = np.zeros_like(self.counts[0])
            for s in sids:
                c = self.counts[self.slots[s]]
                dom = np.where(dom > 0, dom, c)
        return dom.reshape(self.fine.ny, self.fine.nx).astype(np.int64)


@dataclass(frozen=True)
class DensityResult:
    """Density figures of one tile.

    Attributes
    ----------
    anpd : float
        Aggregate nominal pulse density, single-swath first returns per m² (NaN: no cell).
    distribution : float
        Share (0-1) of 2 x ANPS cells holding a first return (NaN: no cell).
    n_cells : int
        Density cells the ANPD was measured over.
    n_distribution_cells : int
    n_multi_swath_cells : int
        2 x ANPS cells where several source ids met without an overlap flag.
    raster : ndarray of shape (rows, cols)
        First returns per m² of each density cell, row 0 south (NaN: no return).
    x0, y0, cell : float
        South-west corner and cell of `raster`.
    """

    anpd: float
    distribution: float
    n_cells: int
    n_distribution_cells: int
    n_multi_swath_cells: int
    raster: np.ndarray
    x0: float
    y0: float
    cell: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the density figures."""
        return {"anpd_per_m2": self.anpd, "distribution": self.distribution,
                "n_cells": self.n_cells, "n_distribution_cells": self.n_distribution_cells,
                "n_multi_swath_cells": self.n_multi_swath_cells}


def density_result(grids: DensityGrids, data_bounds: tuple[float, float, float, float],
                   unit: float = 1.0) -> DensityResult:
    """ANPD, spatial distribution and the density raster of an accumulated tile.

    The grids are laid in the tile's CRS units; `unit` is metres per unit (0.3048006 for
    US survey feet), so densities are per m² whatever the CRS.
    """
    fine = grids.fine
    dom = grids.single_swath()
    water = grids.water.reshape(fine.ny, fine.nx)
    firsts = grids.firsts.reshape(fine.ny, fine.nx)
    multi = 0
    if len(grids.counts) > 1 and not grids.flagged:
        multi = int(np.count_nonzero(np.sum(np.stack(grids.counts) > 0, axis=0) > 1))
    k = grids.k
    cy, cx = grids.coarse.ny, grids.coarse.nx

    def blocks(a: np.ndarray) -> np.ndarray:
        return a.reshape(cy, k, cx, k).sum(axis=(1, 3))

    c_dom, c_water, c_first = blocks(dom), blocks(water), blocks(firsts)
    inner_c = grids.coarse.inner_mask(data_bounds)
    wet_c = c_water * 2 > c_first
    use = inner_c & (c_dom > 0) & ~wet_c
    area = (grids.coarse.cell * unit) ** 2
    if use.any():
        anpd = float(c_dom[use].sum() / (use.sum() * area))
    else:  # a tile smaller than a density cell: its points over its extent
        w = max(data_bounds[2] - data_bounds[0], 0.0) * max(data_bounds[3] - data_bounds[1], 0.0)
        w *= unit * unit
        anpd = float(dom.sum() / w) if w > 0 else math.nan
    inner_f = fine.inner_mask(data_bounds)
    wet_f = water > 0
    if wet_f.any():  # the neighbourhood of water returns is water too
        from scipy.ndimage import binary_dilation

        wet_f = binary_dilation(wet_f, iterations=1)
    cand = inner_f & ~wet_f
    ncand = int(cand.sum())
    dist = float(np.count_nonzero(dom[cand] > 0) / ncand) if ncand else math.nan
    raster = np.where(c_first > 0, c_dom / area, np.nan).astype(np.float64)
    return DensityResult(anpd=anpd, distribution=dist, n_cells=int(use.sum()),
                         n_distribution_cells=ncand, n_multi_swath_cells=multi, raster=raster,
                         x0=grids.coarse.x0, y0=grids.coarse.y0, cell=grids.coarse.cell)
