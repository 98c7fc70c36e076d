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

__all__ = ["Grid", "DensityGrids", "DensityResult", "first_return_mask", "counted_mask",
           "density_result"]

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


def first_return_mask(fields: dict[str, np.ndarray], n: int) -> tuple[np.ndarray, bool]:
    """(first-return mask, has return numbers). Without return numbers every point counts."""
    rn = fields.get("return_number")
    if rn is None or not np.any(rn):
        return np.ones(n, dtype=bool), False
    return np.asarray(rn) == 1, True


def counted_mask(fields: dict[str, np.ndarray], n: int, *, point_format: int) -> np.ndarray:
    """Points that may count for density: not withheld, not flagged or classed as overlap."""
    keep = np.ones(n, dtype=bool)
    w = fields.get("withheld")
    if w is not None:
        keep &= np.asarray(w) == 0
    ov = fields.get("overlap")
    if ov is not None:
        keep &= np.asarray(ov) == 0
    cls = fields.get("classification")
    if point_format < 6 and cls is not None:
        keep &= np.asarray(cls) != 12
    return keep


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
        self.counts: list[np.ndarray] = []  # one flat int32 array per source id slot
        self.slots: dict[int, int] = {}
        self.water = np.zeros(self.fine.nx * self.fine.ny, dtype=np.int32)
        self.firsts = np.zeros(self.fine.nx * self.fine.ny, dtype=np.int32)
        self.occupied = np.zeros(self.void.nx * self.void.ny, dtype=bool)
        self.water_void = np.zeros(self.void.nx * self.void.ny, dtype=bool)
        self.outside = 0
        self.flagged = 0  # first returns left out as overage (overlap flag, legacy class 12)

    def add(self, xy: np.ndarray, *, first: np.ndarray, counted: np.ndarray,
            withheld: np.ndarray | None, classification: np.ndarray | None,
            source_id: np.ndarray | None) -> None:
        """Add one piece of points (`xy` (N, 2+) and per-point masks/fields)."""
        n = len(xy)
        if n == 0:
            return
        usable = first if withheld is None else first & (np.asarray(withheld) == 0)
        # voids: any usable first return fills a cell (another swath's too)
        vi, vin = self.void.index(xy)
        self.occupied[vi[usable & vin]] = True
        fi, fin = self.fine.index(xy)
        self.outside += int(np.count_nonzero(~fin))
        if classification is not None:
            wat = np.asarray(classification) == 9
            if wat.any():
                self.water_void[vi[wat & vin]] = True
                self.water += np.bincount(fi[wat & first & fin], minlength=len(self.water)
                                          ).astype(np.int32)
        self.firsts += np.bincount(fi[usable & fin], minlength=len(self.firsts)).astype(np.int32)
        self.flagged += int(np.count_nonzero(usable & ~counted))
        sel = first & counted & fin
        if not sel.any():
            return
        sid = (np.zeros(int(sel.sum()), dtype=np.int64) if source_id is None
               else np.asarray(source_id)[sel].astype(np.int64))
        cells = fi[sel]
        present = np.flatnonzero(np.bincount(sid)) if len(sid) else np.zeros(0, np.int64)
        for s in present.tolist():  # ids are 16-bit: a bincount beats a hashed unique
            if s not in self.slots:
                self.slots[s] = len(self.counts)
                self.counts.append(np.zeros(self.fine.nx * self.fine.ny, dtype=np.int32))
            m = sid == s
            self.counts[self.slots[s]] += np.bincount(cells[m], minlength=len(self.water)
                                                      ).astype(np.int32)

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


def density_result(grids: DensityGrids, data_bounds: tuple[float, float, float, float]
                   ) -> DensityResult:
    """ANPD, spatial distribution and the density raster of an accumulated tile."""
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
    area = grids.coarse.cell ** 2
    if use.any():
        anpd = float(c_dom[use].sum() / (use.sum() * area))
    else:  # a tile smaller than a density cell: its points over its extent
        w = max(data_bounds[2] - data_bounds[0], 0.0) * max(data_bounds[3] - data_bounds[1], 0.0)
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
