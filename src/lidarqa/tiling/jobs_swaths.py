"""Relative accuracy of flight strips (``lidarqa swaths``) over a whole catalog.

:func:`lidarqa.accuracy.swaths.assess_swaths` compares strips through planes
fitted per grid cell in each strip. On a catalog the grid is laid once over the
whole block (cells of ``cell_size`` on multiples of the cell size) and every
cell is **owned by exactly one chunk**: the chunk whose core holds the cell's
centre (clamped into the catalog's bounds, so edge cells are owned too). A
chunk reads its core plus a buffer of one cell and a metre, which holds every
point of every cell it owns, and gives back for each strip

* the planes of its owned cells, fitted from all their points, exactly as one
  in-memory run fits them, and
* the smallest and largest plane residual and the point count of every range
  cell (sub-cell) of its owned *smooth* cells, for each split the merge may
  choose (the split depends on the mean point count of the strip's smooth cells
  over the whole block; 1 to :data:`MAX_SPLIT`, or the one fixed by
  ``range_cell``).

The merge concatenates the owned cells of every chunk (no cell is counted
twice, none is cut) and hands them to
:func:`~lidarqa.accuracy.swaths.swaths_from_planes`: overlap differences, DZ
grids, repeatability, offsets and the network are those of one run over the
whole block. The default cell size comes from a first, light pass that
measures each strip's density over the whole block, as the single-file
default does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..errors import InvalidPointsError, OptionError

if TYPE_CHECKING:
    from ..accuracy.swaths import Grid, SwathReport
    from ._types import PathsInput
    from .apply import CatalogRun
    from .catalog import Catalog
    from .reader import ChunkData
    from .source import Source

__all__ = [
    "MAX_SPLIT",
    "OccupancyTask",
    "SwathCellsTask",
    "catalog_swaths",
    "swaths_buffer",
]

#: Largest split of a smooth cell into range cells prepared by the chunks when
#: ``range_cell`` is not given (enough for up to ~270 points per strip and cell).
MAX_SPLIT = 8


def swaths_buffer(cell_size: float) -> float:
    """Buffer (m) that holds every point of the cells a chunk owns."""
    return float(cell_size) + 1.0


@dataclass(frozen=True)
class _StripCells:
    """One strip's owned cells in one chunk (see the module documentation)."""

    keys: np.ndarray
    sums: np.ndarray
    extremes: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]


def _strip_points(data: ChunkData, by_source_id: bool, classes: Any, all_returns: bool,
                  source_ids: Any = None, core_only: bool = False,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The compared points of a chunk (z in metres) and their strip ids."""
    from ..accuracy.swaths import select_surface
    from ..io.crs import z_to_metres_factor

    cloud = data.cloud
    keep = select_surface(cloud, classes=classes, all_returns=all_returns,
                          where=f"chunk {data.chunk.id}")
    if core_only:
        keep &= data.core
    if by_source_id:
        sid = cloud.point_source_id
        if sid is None:
            raise InvalidPointsError("the catalog has no point_source_id field: no strips")
        sid = np.asarray(sid).astype(np.int64)
    else:
        sid = data.tile_index.astype(np.int64) + 1
    if source_ids is not None:
        keep &= np.isin(sid, source_ids)
    xyz = cloud.xyz[keep]
    xyz[:, 2] *= z_to_metres_factor(cloud.crs)
    return xyz, sid[keep]


@dataclass(frozen=True)
class OccupancyTask:
    """Chunk task: :func:`~lidarqa.accuracy.swaths.strip_occupancy` of the core points."""

    by_source_id: bool
    classes: tuple[int, ...] | None
    all_returns: bool
    source_ids: tuple[int, ...] | None = None

    def __call__(self, data: ChunkData) -> dict[int, tuple[int, np.ndarray]]:
        """Occupied cells of each strip in the chunk's core."""
        from ..accuracy.swaths import strip_occupancy

        if len(data.cloud) == 0:
            return {}
        xyz, sid = _strip_points(data, self.by_source_id, self.classes, self.all_returns,
                                 self.source_ids, core_only=True)
        return strip_occupancy(xyz, sid)


@dataclass(frozen=True)
class SwathCellsTask:
    """Chunk task: ``{strip: _StripCells}`` for the cells the chunk owns.

    On one region (the whole area, e.g. one file) the task plans what the merge
    would otherwise need from a first pass or from every chunk: with ``grid``
    None it takes the cell size from its own points' occupancy (the whole
    area's) and lays the grid over `clamp`; with ``splits`` None it prepares
    only the split :func:`~lidarqa.accuracy.swaths.range_plan` chooses for each
    strip (and 1, the fall-back). The part is then ``(grid, cells)``.

    Parameters
    ----------
    grid : Grid or None
        The block's cell grid; None: planned from the region (one region only).
    z0 : float
        Reference height of the sums (numerics only).
    clamp : (xmin, ymin, xmax, ymax)
        Catalog bounds, to which cell centres are clamped before the ownership test.
    by_source_id : bool
        Strips are ``point_source_id``; else one strip per file (tile index + 1).
    classes, all_returns
        Point selection (:func:`lidarqa.accuracy.swaths.select_surface`).
    min_points, max_roughness, max_slope
        As :func:`~lidarqa.accuracy.swaths.assess_swaths` (which cells are smooth).
    splits : tuple of int or None
        The splits of smooth cells into range cells to prepare; None: planned
        per strip (one region only).
    range_cell : float, optional
        As :func:`~lidarqa.accuracy.swaths.assess_swaths` (used when planning splits).
    cell_target : int
        Points per cell of the planned cell size.
    """

    grid: Grid | None
    z0: float
    clamp: tuple[float, float, float, float]
    by_source_id: bool
    classes: tuple[int, ...] | None
    all_returns: bool
    source_ids: tuple[int, ...] | None
    min_points: int
    max_roughness: float
    max_slope: float
    splits: tuple[int, ...] | None
    range_cell: float | None = None
    cell_target: int = 16

    def __call__(
        self, data: ChunkData
    ) -> dict[int, _StripCells] | tuple[Grid | None, dict[int, _StripCells]]:
        """Per-strip plane fits of the chunk's core cells (with the grid when planned here)."""
        from ..accuracy.swaths import (
            cell_size_from_occupancy,
            cell_sums,
            grid_for,
            merge_extremes,
            range_plan,
            ranges_from_extremes,
            strip_occupancy,
            strip_planes,
        )

        if len(data.cloud) == 0:
            return {} if self.grid is not None else (None, {})
        xyz, sid = _strip_points(data, self.by_source_id, self.classes, self.all_returns,
                                 self.source_ids)
        grid = self.grid
        if grid is None:
            size = cell_size_from_occupancy(strip_occupancy(xyz, sid), target=self.cell_target)
            b = self.clamp
            grid = grid_for(np.array([[b[0], b[1]], [b[2], b[3]]]), size)
        out: dict[int, _StripCells] = {}
        for s in np.unique(sid).tolist():
            pts = xyz[sid == s]
            keys, sums = cell_sums(pts, grid, self.z0)
            centres = grid.centres(keys)
            np.clip(centres[:, 0], self.clamp[0], self.clamp[2], out=centres[:, 0])
            np.clip(centres[:, 1], self.clamp[1], self.clamp[3], out=centres[:, 1])
            own = data.chunk.core_mask(centres)
            if not own.any():
                continue
            keys, sums = keys[own], sums[own]
            planes = strip_planes(keys, sums, self.z0, cell_size=grid.cell_size,
                                  min_points=self.min_points)
            tan = np.tan(np.radians(self.max_slope))
            with np.errstate(invalid="ignore"):
                smooth = (planes.ok & (planes.rms <= self.max_roughness)
                          & (planes.b**2 + planes.c**2 <= tan**2))
            ext = {}
            planned = self.splits is None
            if planned:  # the split the merge's range_plan picks; 1 only as its fall-back
                _, need = range_plan(planes, cell_size=grid.cell_size,
                                     max_roughness=self.max_roughness,
                                     max_slope=self.max_slope, range_cell=self.range_cell)
                splits: tuple[int, ...] = (max(need, 1),)
            else:
                splits = cast("tuple[int, ...]", self.splits)
            for k in splits:
                ext[k] = self._extremes(pts, grid, planes, smooth, keys, k)
            if planned and 1 not in ext and not len(
                    ranges_from_extremes(merge_extremes([ext[splits[0]]]), min_points=3)[1]):
                ext[1] = self._extremes(pts, grid, planes, smooth, keys, 1)
            out[int(s)] = _StripCells(keys, sums, ext)
        return out if self.grid is not None else (grid, out)

    @staticmethod
    def _extremes(pts: np.ndarray, grid: Grid, planes: Any, smooth: np.ndarray,
                  keys: np.ndarray, k: int) -> tuple:
        """Residual extremes of the range cells (split `k`), keyed block-wide."""
        from ..accuracy.swaths import residual_extremes

        sub, hi, lo, n = residual_extremes(pts, grid, planes, smooth, split=k)
        # cell index into this chunk's smooth cells -> the block-wide cell key
        cell = keys[smooth][sub // (k * k)] if k > 1 else sub
        return (cell * (k * k) + sub % (k * k) if k > 1 else cell, hi, lo, n)


def catalog_swaths(
    sources: PathsInput | Catalog | Source,
    *,
    by_source_id: bool = False,
    classes: Sequence[int] | None = None,
    all_returns: bool = False,
    source_ids: Sequence[int] | None = None,
    cell_size: float | None = None,
    range_cell: float | None = None,
    min_points: int = 8,
    max_roughness: float = 0.05,
    max_slope: float = 10.0,
    one_region: bool | None = None,
    **options: object,
) -> CatalogRun[SwathReport]:
    """:func:`~lidarqa.accuracy.swaths.assess_swaths` over a catalog of tiles.

    Parameters
    ----------
    sources : Catalog, path, folder, glob, .vpc or a list of those
    by_source_id : bool, default False
        Strips are the ``point_source_id`` values; else one strip per file (a
        delivery of strip files).
    classes, all_returns
        Point selection, as ``lidarqa swaths``.
    source_ids : sequence of int, optional
        Only these strips.
    cell_size : float, optional
        Default: :func:`~lidarqa.accuracy.swaths.auto_cell_size` of all the
        compared points (a first, light pass over the chunks).
    one_region : bool, optional
        Read the whole area as one region (default: for one file without
        ``chunk_size`` or ``buffer``, see :func:`~lidarqa.tiling.apply.region_chunks`):
        the in-memory run, one read, the cell size and range cells planned in it.
    range_cell, min_points, max_roughness, max_slope, **options
        As :func:`~lidarqa.accuracy.swaths.assess_swaths` (quality_level,
        estimate_offsets, rotations, reference_strip, ...), plus the catalog
        options ``chunk_size``, ``buffer`` (default :func:`swaths_buffer`),
        ``origin``, ``engine``, ``progress``, ``retries``, ``skip_failed``,
        ``order_seed``, ``skip_bad``, ``crs``.

    Returns
    -------
    CatalogRun
        ``value`` the :class:`~lidarqa.accuracy.swaths.SwathReport`; ``extra``
        holds ``labels`` (strip id -> name) and ``cell_size``.
    """
    from ..accuracy.swaths import (
        CELL_TARGET_POINTS,
        assess_options,
        cell_size_from_occupancy,
        grid_for,
        merge_extremes,
        range_split,
        strip_planes,
        swaths_from_planes,
    )
    from . import make_chunks
    from .jobs_api import COMMON_KEYS, CatalogRun, _run, _split, open_sources

    opts: dict[str, Any] = options  # the same dict: what is left are assess_swaths options
    common = {k: opts.pop(k) for k in list(opts) if k in COMMON_KEYS}
    assess_options(min_points=min_points, max_roughness=max_roughness, max_slope=max_slope,
                   range_cell=range_cell, cell_size=cell_size, **opts)
    open_opts, chunk_opts, run_opts = _split(common)
    catalog = open_sources(sources, **open_opts)
    cls = tuple(int(c) for c in classes) if classes else None
    labels = ({} if by_source_id
              else {k + 1: str(t.path) for k, t in enumerate(catalog.tiles)})

    sel: dict[str, Any] = {
        "by_source_id": bool(by_source_id), "classes": cls, "all_returns": bool(all_returns),
        "source_ids": tuple(int(v) for v in source_ids) if source_ids else None,
    }
    b = catalog.bounds
    # reference height of the plane sums (numerics only): the middle of the catalog's z range
    z0 = float(np.round(0.5 * sum(catalog.zrange), 1))
    if one_region is None:
        one_region = (not catalog.is_catalog and chunk_opts["chunk_size"] is None
                      and chunk_opts["buffer"] is None)
    target = max(CELL_TARGET_POINTS, 2 * min_points)
    if cell_size is None and not one_region:
        # the densities behind the default cell size, over every point (first pass)
        occ_chunks = make_chunks(catalog, chunk_size=chunk_opts["chunk_size"], buffer=0.0,
                                 origin=chunk_opts["origin"])
        occ_outcomes, occ_parts = _run(catalog, occ_chunks, OccupancyTask(**sel), run_opts,
                                       "Density")
        _all_failed(occ_outcomes)
        occupancy: dict[int, tuple[int, np.ndarray]] = {}
        for part in occ_parts:
            for s, (n, keys) in (part or {}).items():
                n0, k0 = occupancy.get(s, (0, np.empty(0, dtype=np.int64)))
                occupancy[s] = (n0 + n, np.union1d(k0, keys))
        if not occupancy:
            raise InvalidPointsError("no point to compare in the catalog (check --classes)")
        cell_size = cell_size_from_occupancy(occupancy, target=target)
    grid = (None if cell_size is None
            else grid_for(np.array([[b[0], b[1]], [b[2], b[3]]]), float(cell_size)))
    if one_region:
        chunks = [catalog.whole_chunk()]
    else:
        assert cell_size is not None  # given, or measured by the first pass above
        if chunk_opts["buffer"] is None:
            chunk_opts["buffer"] = swaths_buffer(cell_size)
        elif chunk_opts["buffer"] < cell_size:
            raise OptionError(f"buffer must be at least the cell size ({cell_size:g} m), "
                              f"got {chunk_opts['buffer']:g}")
        chunks = list(make_chunks(catalog, **chunk_opts))
    if one_region:
        splits = None
    elif range_cell is None:
        splits = tuple(range(1, MAX_SPLIT + 1))
    else:
        assert cell_size is not None
        splits = tuple(sorted({1, range_split(cell_size, range_cell)}))
    task = SwathCellsTask(grid=grid, z0=z0, clamp=(b[0], b[1], b[2], b[3]), **sel,
                          min_points=int(min_points),
                          max_roughness=float(max_roughness), max_slope=float(max_slope),
                          splits=splits, range_cell=range_cell, cell_target=target)
    outcomes, parts = _run(catalog, chunks, task, run_opts, "Strips")
    _all_failed(outcomes)
    if grid is None:  # planned by the one region
        planned, cells0 = parts[0] if parts[0] is not None else (None, {})
        if planned is None:
            raise InvalidPointsError("no point to compare (check --classes)")
        grid, parts, cell_size = planned, [cells0], planned.cell_size
    assert cell_size is not None  # given, measured, or planned by the one region
    per_strip: dict[int, list[Any]] = {}
    for part in parts:
        for s, cells in (part or {}).items():
            per_strip.setdefault(int(s), []).append(cells)
    ids = np.array(sorted(per_strip), dtype=np.int64)
    if by_source_id and len(ids) and not ids.any():
        raise InvalidPointsError(
            "point_source_id is 0 for every point: the tiles do not record flight strips "
            "(give one file per strip instead of --by-source-id)"
        )
    if len(ids) < 2:
        raise InvalidPointsError(
            f"one flight strip only ({', '.join(map(str, ids.tolist()))}): relative accuracy "
            "needs at least two overlapping strips"
        )
    planes, merged = [], []
    for s in ids.tolist():
        cells = per_strip[s]
        keys = np.concatenate([c.keys for c in cells])
        sums = np.concatenate([c.sums for c in cells])
        o = np.argsort(keys, kind="stable")
        planes.append(strip_planes(keys[o], sums[o], z0, cell_size=float(cell_size),
                                   min_points=int(min_points)))
        merged.append({k: merge_extremes([c.extremes[k] for c in cells])
                       for k in cells[0].extremes})
        if by_source_id:
            labels[s] = f"point_source_id {s}"

    def extremes(i: int, selected: np.ndarray, split: int) -> tuple:
        if split not in merged[i]:
            raise OptionError(
                f"strip {ids[i]}: its smooth cells hold so many points that range cells of "
                f"{float(cell_size) / split:g} m are needed; give --range-cell"
            )
        return merged[i][split]

    value = swaths_from_planes(grid, z0, ids, planes, extremes, min_points=int(min_points),
                               max_roughness=float(max_roughness), max_slope=float(max_slope),
                               range_cell=range_cell, **opts)
    return CatalogRun(value, catalog, tuple(chunks), tuple(outcomes),
                      {"labels": {int(k): v for k, v in labels.items() if k in set(ids.tolist())},
                       "cell_size": float(cell_size),
                       "buffer": float(chunk_opts["buffer"] or 0.0)})



def _all_failed(outcomes: Sequence[Any]) -> None:
    """Raise when no chunk succeeded (nothing to merge): the first chunk's error says why."""
    if outcomes and not any(o.ok for o in outcomes):
        from .engine import ChunkFailedError

        first = next(o for o in outcomes if not o.ok)
        raise ChunkFailedError(
            f"every chunk failed ({len(outcomes)}); {first.chunk.id}: {first.error}",
            list(outcomes),
        )
