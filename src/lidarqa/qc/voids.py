"""Data voids: areas without first returns where a (4 x ANPS)² square fits, minus water.

The tile's extent is cut into cells of ``side / 9`` (``side = 4 x ANPS`` by default) and
a cell is *occupied* when it holds a first return of any swath (a void one swath leaves
and another fills is no void). An empty area is a void where a square of 9 x 9 empty
cells fits (a morphological opening of the empty cells with that square): every void
then holds a first-return-free square of at least ``side x side``, and no scatter of
empty cells in sparse but regular data is one (at the minimum density a square of that
size would hold 16 pulses on average; one without any happens with probability e^-16).
Voids are the connected groups of opened cells (8-connectivity) inside the data extent.

Water is left out: a void touching a cell with a class 9 point (its neighbourhood), or
whose remaining area after subtracting the ``exclude`` polygons is below ``side²``.
The measured area is that of the opened cells, so a void is under-measured by at most
one cell along its border.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["VoidResult", "find_voids", "VOID_CELLS"]

#: Cells across the smallest void square.
VOID_CELLS = 9


@dataclass(frozen=True)
class VoidResult:
    """Voids of one tile.

    Attributes
    ----------
    polygons : tuple of shapely geometries
    areas : tuple of float
        m² of each void (after subtracting the excluded polygons).
    n_water : int
        Empty areas left out as water (class 9 neighbourhood or excluded polygons).
    """

    polygons: tuple[Any, ...]
    areas: tuple[float, ...]
    n_water: int = 0

    @property
    def total_area(self) -> float:
        """Total void area in m²."""
        return float(sum(self.areas))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the voids."""
        return {"n_voids": len(self.areas), "void_area_m2": self.total_area,
                "n_water": self.n_water}


def find_voids(occupied: np.ndarray, *, x0: float, y0: float, cell: float,
               min_side: float, inside: np.ndarray | None = None,
               water: np.ndarray | None = None, exclude: Any = None) -> VoidResult:
    """Voids of an occupancy grid.

    Parameters
    ----------
    occupied : ndarray of bool, shape (rows, cols)
        Row 0 is the south edge; True where a first return lies.
    x0, y0, cell : float
        South-west corner and cell size (m).
    min_side : float
        Side of the smallest void square (m), 4 x ANPS.
    inside : ndarray of bool, optional
        Cells to search (the data extent); default all.
    water : ndarray of bool, optional
        Cells holding a class 9 (water) point.
    exclude : shapely geometry, optional
        Polygons (water bodies, areas to ignore) subtracted from the voids.

    Returns
    -------
    VoidResult
    """
    from scipy import ndimage

    k = max(int(round(min_side / cell)), 1)
    empty = ~occupied
    if inside is not None:
        empty &= inside
    if not empty.any():
        return VoidResult((), ())
    from ._kernels import open_square

    # opening: the union of the k x k squares of empty cells (linear in the cells)
    opened = open_square(empty, k)
    rows = np.flatnonzero(opened.any(axis=1))
    if len(rows) == 0:
        return VoidResult((), ())
    # label and polygonise only the window holding the voids (grown by the water margin)
    cols = np.flatnonzero(opened[rows[0]:rows[-1] + 1].any(axis=0))
    r0, r1 = max(rows[0] - 2, 0), rows[-1] + 3
    c0, c1 = max(cols[0] - 2, 0), cols[-1] + 3
    opened = opened[r0:r1, c0:c1]
    x0, y0 = x0 + c0 * cell, y0 + r0 * cell
    if water is not None:
        water = water[r0:r1, c0:c1]
    labels, n = ndimage.label(opened, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return VoidResult((), ())
    wet = np.zeros(n + 1, dtype=bool)
    if water is not None and water.any():
        near = ndimage.binary_dilation(water, iterations=2)
        wet[np.unique(labels[near & opened])] = True
    import shapely

    geoms = _label_polygons(labels, n, x0, y0, cell)
    keep = [lab for lab in range(1, n + 1) if not wet[lab]]
    n_water = n - len(keep)
    arr = np.empty(len(keep), dtype=object)
    arr[:] = [geoms[lab] for lab in keep]
    if exclude is not None and len(arr):
        # vectorised: only voids whose box meets an excluded polygon are cut (an STRtree
        # query), so the cost is linear in the voids, not voids x exclude polygons
        tree = shapely.STRtree(shapely.get_parts(exclude))
        hit = np.unique(tree.query(arr, predicate="intersects")[0])
        if len(hit):
            arr[hit] = shapely.difference(arr[hit], exclude)
        area = shapely.area(arr)
        gone = shapely.is_empty(arr) | (area < min_side * min_side * 0.999)
        n_water += int(gone.sum())
        arr = arr[~gone]
    areas = shapely.area(arr) if len(arr) else np.zeros(0)
    return VoidResult(tuple(arr.tolist()), tuple(float(a) for a in areas), n_water)


def _label_polygons(labels: np.ndarray, n: int, x0: float, y0: float, cell: float
                    ) -> dict[int, Any]:
    """Polygon of every label 1..n (rasterio's polygonizer when present, else cell runs)."""
    import shapely

    try:
        from rasterio import features
        from rasterio.transform import Affine
    except ImportError:
        from scipy import ndimage

        out = {}
        for lab, sl in enumerate(ndimage.find_objects(labels), start=1):
            rows, cols = np.nonzero(labels[sl] == lab)
            out[lab] = _cells_polygon(rows + sl[0].start, cols + sl[1].start, x0, y0, cell)
        return out
    parts: dict[int, list[Any]] = {}
    tr = Affine(cell, 0.0, x0, 0.0, cell, y0)  # row 0 is the south edge
    for geom, value in features.shapes(labels.astype(np.int32), mask=labels > 0,
                                       connectivity=8, transform=tr):
        parts.setdefault(int(value), []).append(shapely.geometry.shape(geom))
    return {lab: (ps[0] if len(ps) == 1 else shapely.union_all(ps))
            for lab, ps in parts.items()}


def _cells_polygon(rows: np.ndarray, cols: np.ndarray, x0: float, y0: float, cell: float) -> Any:
    """The union of grid cells as one polygon (runs of cells per row, then a coverage union)."""
    import shapely

    order = np.lexsort((cols, rows))
    rows, cols = rows[order], cols[order]
    brk = np.nonzero((np.diff(rows) != 0) | (np.diff(cols) != 1))[0] + 1
    starts = np.r_[0, brk]
    ends = np.r_[brk, len(rows)] - 1
    boxes = shapely.box(x0 + cols[starts] * cell, y0 + rows[starts] * cell,
                        x0 + (cols[ends] + 1) * cell, y0 + (rows[ends] + 1) * cell)
    return shapely.union_all(boxes, grid_size=cell * 1e-3)
