"""One source for every command: a file, several files, a folder, a glob or a ``.vpc``.

:func:`open_source` turns what a user gives into a :class:`Source`: a catalog of
one or more tiles (headers only) that carries

* the CRS (the files' own, or ``crs=`` / ``--crs`` for files that declare none; a
  file whose own CRS differs from the given one is an error naming both);
* the conversion of heights to metres (the factor of the CRS's vertical unit, e.g.
  US survey feet), applied to every point read, as ``lidarqa.read(..., z_to_metres=True)``;
* the :class:`Selection` of points (classes, point source ids), applied **at read
  time** to every region.

A job reads its regions through the source only: :meth:`Source.read` for one
in-memory region (the whole area), :meth:`Source.read_chunk` for one chunk of a
catalog run. One file and a folder of tiles are therefore read with the same
CRS, the same units and the same selection, by construction. A comparison job
(lines, repeatability, swaths) takes one source per side, each with its own
selection (:meth:`Source.select`).

A point file that is not LAS/LAZ (CSV/XYZ text, PLY) is one region read in memory.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import OptionError

if TYPE_CHECKING:
    from pyproj import CRS

    from ..io.pointcloud import PointCloud
    from ._types import CRSInput, IntsInput, PathsInput
    from .catalog import Catalog, TileInfo
    from .chunks import Chunk
    from .reader import ChunkData

__all__ = ["Selection", "Source", "open_source", "is_catalog_input", "sample_boxes",
           "sample_points"]

_LAS = {".las", ".laz"}


def _ints(value: object, name: str) -> tuple[int, ...] | None:
    if value is None:
        return None
    vals = np.atleast_1d(np.asarray(value)).ravel().tolist()
    if not vals:
        return None
    try:
        return tuple(sorted({int(v) for v in vals}))
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be integers, got {value!r}") from exc


@dataclass(frozen=True)
class Selection:
    """Which points a job sees: classification codes and point source ids (None = all).

    Attributes
    ----------
    classes : tuple of int or None
        ASPRS classification codes kept.
    source_id : tuple of int or None
        Point source ids (flight strips) kept.
    """

    classes: tuple[int, ...] | None = None
    source_id: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "classes", _ints(self.classes, "classes"))
        object.__setattr__(self, "source_id", _ints(self.source_id, "source_id"))

    @classmethod
    def of(cls, classes: IntsInput = None, source_id: IntsInput = None) -> Selection:
        """The selection of `classes` and `source_id` (each one int, ints or None: all)."""
        return cls(_ints(classes, "classes"), _ints(source_id, "source_id"))

    def __bool__(self) -> bool:
        return self.classes is not None or self.source_id is not None

    def mask(self, cloud: PointCloud) -> np.ndarray | None:
        """Boolean mask of the selected points of `cloud`, or None when every point is kept.

        Raises
        ------
        InvalidPointsError
            The cloud lacks the field a selector needs.
        """
        from ..errors import InvalidPointsError

        if not self:
            return None
        keep = np.ones(len(cloud), dtype=bool)
        for name, wanted in (("classification", self.classes),
                             ("point_source_id", self.source_id)):
            if wanted is None:
                continue
            values = cloud.fields.get(name)
            if values is None:
                raise InvalidPointsError(f"cannot select by {name}: the cloud has no {name} field")
            keep &= np.isin(values, np.asarray(wanted))
        return keep

    def describe(self) -> str:
        """``"classes 2,6 and source ids 706"`` (empty when every point is kept).

        The one wording of a selection in messages, summaries and report labels.
        """
        parts = [f"{what} {','.join(map(str, ids))}"
                 for what, ids in (("classes", self.classes), ("source ids", self.source_id))
                 if ids is not None]
        return " and ".join(parts)

    def label(self, name: str) -> str:
        """``"name (classes 6 and source ids 706)"``, or `name` when every point is kept."""
        what = self.describe()
        return f"{name} ({what})" if what else name

    def to_dict(self) -> dict[str, object]:
        """The selection as a JSON-ready dict (classes, source ids; None when all kept)."""
        return {"classes": None if self.classes is None else list(self.classes),
                "source_id": None if self.source_id is None else list(self.source_id)}


def is_catalog_input(paths: Sequence[str] | str) -> bool:
    """True for several paths, a folder, a glob pattern or a ``.vpc`` file."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [str(paths)]
    if len(paths) != 1:
        return True
    p = str(paths[0])
    return (
        Path(p).is_dir()
        or Path(p).suffix.lower() == ".vpc"
        or (any(ch in p for ch in "*?[") and not Path(p).exists())
    )


@dataclass(frozen=True, eq=False)
class Source:
    """What a command reads: tiles (or one in-memory cloud), CRS, units and selection.

    Use :func:`open_source` to make one. The catalog's header properties
    (``tiles``, ``bounds``, ``n_points``, ``density``, ``bad``...) are available
    on the source itself, so a source goes wherever a catalog does
    (:func:`~lidarqa.tiling.make_chunks`, :func:`~lidarqa.tiling.run_chunks`).

    Attributes
    ----------
    catalog : Catalog or None
        The tiles (None for a non-LAS point file, held in `cloud`).
    selection : Selection
    z_factor : float
        Factor that turns the files' heights into metres (1.0 for metres).
    xy_factor : float
        Factor of the horizontal unit to metres (1.0 for metres). Horizontal
        coordinates are read as they are (chunks live in the CRS's units); a job
        that needs metric x, y checks or converts with it.
    paths : tuple of str
        What the user gave.
    cloud : PointCloud or None
        The points of a non-LAS input (one in-memory region).
    """

    catalog: Catalog | None
    selection: Selection = field(default_factory=Selection)
    z_factor: float = 1.0
    xy_factor: float = 1.0
    paths: tuple[str, ...] = ()
    cloud: PointCloud | None = None
    given_crs: CRS | None = None

    # -------------------------------------------------------------- catalog view
    if TYPE_CHECKING:
        # the catalog's header properties, delegated at run time by __getattr__ (typed
        # here only: as properties of the dataclass they would change its fields)
        @property
        def tiles(self) -> tuple[TileInfo, ...]:
            """The catalog's tiles."""

        @property
        def bounds(self) -> tuple[float, float, float, float]:
            """The catalog's ``(xmin, ymin, xmax, ymax)``."""

        @property
        def n_points(self) -> int:
            """The catalog's point count (from the headers)."""

        @property
        def zrange(self) -> tuple[float, float]:
            """The catalog's ``(zmin, zmax)``."""

        @property
        def density(self) -> float:
            """The catalog's points per m² of tile area."""

        @property
        def bad(self) -> tuple[tuple[str, str], ...]:
            """The catalog's files left out, ``(path, reason)``."""

        @property
        def source_ids(self) -> tuple[int, ...] | None:
            """The catalog's file source ids."""

        def tile_size(self) -> float:
            """The catalog's median tile side."""

    @property
    def _memory(self) -> PointCloud:
        # the in-memory cloud (set whenever `catalog` is None)
        return cast("PointCloud", self.cloud)

    def __getattr__(self, name: str) -> object:
        # delegate the catalog's header properties (tiles, bounds, density, bad...)
        if name.startswith("_") or name in ("catalog", "cloud"):
            raise AttributeError(name)
        cat = self.__dict__.get("catalog")
        if cat is None:  # an in-memory file (not LAS/LAZ): its header view from the points
            z = self._memory.xyz[:, 2]
            memory = {"bad": (), "tiles": (), "source_ids": None,
                      "bounds": lambda: self.area_bounds,
                      "zrange": lambda: (float(z.min()), float(z.max())) if len(z) else (0.0, 0.0)}
            if name not in memory:
                raise AttributeError(name)
            v = memory[name]
            return v() if callable(v) else v
        return getattr(cat, name)

    @property
    def crs(self) -> CRS | None:
        """The CRS of the points as read (the horizontal part when heights were converted)."""
        crs = self.native_crs
        if self.z_factor != 1.0 and crs is not None and crs.is_compound:
            return crs.sub_crs_list[0]
        return crs

    @property
    def native_crs(self) -> CRS | None:
        """The files' CRS (with its vertical part); the given one when they declare none."""
        crs = self.catalog.crs if self.catalog is not None else self._memory.crs
        return crs if crs is not None else self.given_crs

    @property
    def is_catalog(self) -> bool:
        """True when the user gave a catalog (several files, a folder, a glob, a .vpc)."""
        if self.catalog is None:  # one cloud in memory
            return False
        return is_catalog_input(self.paths) if self.paths else True

    @property
    def n_tiles(self) -> int:
        """Number of tiles (1 for an in-memory cloud)."""
        return len(self.catalog.tiles) if self.catalog is not None else 1

    @property
    def label(self) -> str:
        """The inputs as the user gave them, for messages."""
        return ", ".join(self.paths) if self.paths else "the source"

    def select(self, *, classes: IntsInput = None, source_id: IntsInput = None) -> Source:
        """The same tiles with another selection (e.g. one side of a comparison)."""
        return replace(self, selection=Selection.of(classes, source_id))

    def to_dict(self) -> dict[str, object]:
        """The source as a JSON-ready dict (paths, tile count, CRS, height factor, selection)."""
        from ..io.crs import crs_name

        return {"paths": list(self.paths), "n_tiles": self.n_tiles,
                "catalog": self.is_catalog, "crs": crs_name(self.native_crs),
                "z_factor": self.z_factor, **self.selection.to_dict()}

    # -------------------------------------------------------------- reading
    def _finish(self, cloud: PointCloud) -> tuple[PointCloud, np.ndarray | None]:
        """Selection and unit conversion of freshly read points: (cloud, kept mask)."""
        keep = self.selection.mask(cloud)
        if keep is not None:
            cloud = cloud.subset(keep)
        if self.z_factor != 1.0 and len(cloud):
            xyz = cloud.xyz.copy()
            xyz[:, 2] *= self.z_factor
            cloud.xyz = xyz
            cloud.source = None
        cloud.crs = self.crs
        return cloud, keep

    def read_chunk(self, chunk: Chunk) -> ChunkData:
        """The selected points of one chunk with its buffer (heights in metres).

        Returns
        -------
        ChunkData
            As :func:`lidarqa.tiling.read_chunk`, restricted to the selection.
        """
        from .reader import ChunkData, read_chunk

        if self.catalog is None:
            cloud = self._memory.copy()
            n = len(cloud)
            data = ChunkData(cloud=cloud, core=chunk.core_mask(cloud.xyz),
                             tile_index=np.zeros(n, dtype=np.int32),
                             point_index=np.arange(n, dtype=np.int64), chunk=chunk)
        else:
            data = read_chunk(self.catalog, chunk)
        cloud, keep = self._finish(data.cloud)
        if keep is None:
            return ChunkData(cloud=cloud, core=data.core, tile_index=data.tile_index,
                             point_index=data.point_index, chunk=chunk)
        return ChunkData(cloud=cloud, core=data.core[keep], tile_index=data.tile_index[keep],
                         point_index=data.point_index[keep], chunk=chunk)

    def read(self, *, require_points: bool = True) -> PointCloud:
        """All selected points in memory (one region), heights in metres.

        Parameters
        ----------
        require_points : bool, default True
            Raise when the selection leaves no point.

        Raises
        ------
        NothingToMeasureError
            No point is selected (with `require_points`).
        """
        from ..io import read as read_cloud

        if self.catalog is None:
            cloud = self._memory.copy()
        elif len(self.catalog.tiles) == 1:
            cloud = read_cloud(self.catalog.tiles[0].path, crs=self.given_crs)
        else:
            from .reader import read_chunk

            cloud = read_chunk(self.catalog, self.whole_chunk()).cloud
        if self.catalog is not None and self.catalog.crs is not None:
            cloud.crs = self.catalog.crs
        cloud, _ = self._finish(cloud)
        if require_points and len(cloud) == 0:
            from ..errors import NothingToMeasureError

            what = self.selection.describe()
            raise NothingToMeasureError(
                f"{self.label} has no points" + (f" with {what}" if what else ""))
        return cloud

    # -------------------------------------------------------------- regions
    def whole_chunk(self) -> Chunk:
        """One chunk holding the whole area (the in-memory run's single region)."""
        from .chunks import Chunk

        xmin, ymin, xmax, ymax = self.area_bounds
        tiles = tuple(range(len(self.catalog.tiles))) if self.catalog is not None else (0,)
        size = max(xmax - xmin, ymax - ymin, 1.0) * 2.0 + 2.0
        box = (xmin - 1.0, ymin - 1.0, xmin - 1.0 + size, ymin - 1.0 + size)
        return Chunk(id="c0000_r0000", row=0, col=0, core=box,
                     buffered=(box[0] - 1.0, box[1] - 1.0, box[2] + 1.0, box[3] + 1.0),
                     tiles=tiles, index=(0, 0), size=size, origin=(box[0], box[1]))

    def window(self, box: Sequence[float]) -> Chunk:
        """A region reading exactly `box` ``(xmin, ymin, xmax, ymax)`` (e.g. a sample)."""
        from .chunks import Chunk

        b = _box4(box)
        if self.catalog is None:
            tiles: tuple[int, ...] = (0,)
        else:
            tiles = tuple(i for i, t in enumerate(self.catalog.tiles)
                          if t.bounds[0] <= b[2] and t.bounds[2] >= b[0]
                          and t.bounds[1] <= b[3] and t.bounds[3] >= b[1])
        size = max(b[2] - b[0], b[3] - b[1], 1e-9) * 1.000001
        return Chunk(id="window", row=0, col=0, core=b, buffered=b, tiles=tiles,
                     index=(0, 0), size=size, origin=(b[0], b[1]))

    @property
    def area_bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)``: the tiles' header bounds (an in-memory cloud's extent)."""
        if self.catalog is not None:
            return _box4(self.catalog.bounds)
        xyz = self._memory.xyz
        if not len(xyz):
            return (0.0, 0.0, 0.0, 0.0)
        lo, hi = xyz[:, :2].min(0), xyz[:, :2].max(0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def sample(self, *, side: float = 100.0, min_points: int = 100) -> PointCloud:
        """Selected points of a square window at the centre of the area (a cloud).

        The same window whatever the chunking (:func:`sample_boxes`), so data-driven
        defaults measured on it (point spacing) are the same for a file and for a
        catalog of its tiles. The window grows (x2) until it holds `min_points`
        points or covers the area.
        """
        cloud = None
        for box in sample_boxes(self.area_bounds, side=side):
            cloud = self.read_chunk(self.window(box)).cloud
            if len(cloud) >= min_points:
                break
        return cast("PointCloud", cloud)  # sample_boxes yields at least one box

    def chunks(self, *, chunk_size: float | None = None, buffer: float | None = None,
               origin: tuple[float, float] = (0.0, 0.0)) -> list[Chunk]:
        """The chunk grid of a catalog run (one whole-area chunk for an in-memory cloud)."""
        if self.catalog is None:
            return [self.whole_chunk()]
        from .chunks import make_chunks

        return list(make_chunks(self.catalog, chunk_size=chunk_size, buffer=buffer,
                                origin=origin))


def sample_boxes(bounds: Sequence[float], *, side: float = 100.0) -> Iterable[tuple]:
    """Square windows centred on `bounds`, of side `side`, 2 x `side`... up to covering it."""
    xmin, ymin, xmax, ymax = (float(v) for v in bounds[:4])
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    half = 0.5 * side
    while True:
        box = (cx - half, cy - half, cx + half, cy + half)
        yield box
        if box[0] <= xmin and box[1] <= ymin and box[2] >= xmax and box[3] >= ymax:
            return
        half *= 2.0


def sample_points(xyz: np.ndarray, bounds: Sequence[float], *, side: float = 100.0,
                  min_points: int = 100) -> np.ndarray:
    """The points of `xyz` in the window :meth:`Source.sample` reads (for in-memory runs)."""
    from .reader import _TOL

    p = np.asarray(xyz, dtype=np.float64)
    out = p[:0]
    for box in sample_boxes(bounds, side=side):
        keep = ((p[:, 0] >= box[0] - _TOL) & (p[:, 0] <= box[2] + _TOL)
                & (p[:, 1] >= box[1] - _TOL) & (p[:, 1] <= box[3] + _TOL))
        out = p[keep]
        if len(out) >= min_points:
            break
    return out


def _as_list(paths: PathsInput) -> list[str]:
    if isinstance(paths, (str, os.PathLike)):
        return [os.fspath(paths)]
    return [os.fspath(p) for p in paths]


def open_source(
    paths: PathsInput | Catalog | Source | PointCloud,
    *,
    crs: CRSInput = None,
    classes: IntsInput = None,
    source_id: IntsInput = None,
    skip_bad: bool = False,
    z_to_metres: bool = True,
) -> Source:
    """Open a file, several files, a folder, a glob or a ``.vpc`` as one :class:`Source`.

    Only headers are read. Every region a job reads later goes through the
    source, which applies the CRS, the conversion of heights to metres and the
    selection the same way for one file and for a catalog.

    Parameters
    ----------
    paths : path, glob pattern, folder, .vpc, a list of those, a Catalog/Source, or a PointCloud
        A :class:`~lidarqa.io.PointCloud` already in memory is one region (e.g. the
        report's cached cloud), read with the same selection and units as a file.
    crs : optional
        CRS of inputs that declare none (``--crs``: EPSG code, WKT, pyproj CRS).
        Inputs that declare another CRS are refused (:class:`CRSMismatchError`).
    classes, source_id : int or sequence of int, optional
        The selection, applied to every region at read time.
    skip_bad : bool, default False
        Leave out bad tiles of a catalog (listed in ``source.bad``).
    z_to_metres : bool, default True
        Convert heights to metres when the CRS declares another vertical unit.

    Returns
    -------
    Source

    Examples
    --------
    >>> import lidarqa
    >>> src = lidarqa.open_source("tiles/", classes=[2], crs="EPSG:2154")  # doctest: +SKIP
    >>> cloud = src.read()                                                # doctest: +SKIP
    """
    from ..io.crs import metre_factors, parse_crs, resolve_crs, z_to_metres_factor
    from ..io.pointcloud import PointCloud
    from .catalog import Catalog, open_catalog

    sel = Selection.of(classes, source_id)
    if isinstance(paths, Source):
        src = paths
        return replace(src, selection=sel) if sel else src
    given = parse_crs(crs)
    if isinstance(paths, Catalog):
        catalog, names, cloud = paths, tuple[str, ...](), None
    elif isinstance(paths, PointCloud):
        catalog, names, cloud = None, tuple[str, ...](), paths
    else:
        names = tuple(_as_list(paths))
        if not names:
            raise OptionError("no input given")
        single = len(names) == 1 and not is_catalog_input(names)
        if single and Path(names[0]).suffix.lower() not in _LAS:
            from ..io import read as read_cloud

            catalog, cloud = None, read_cloud(names[0], crs=given)
        else:
            catalog = open_catalog(list(names), skip_bad=skip_bad, crs=given)
            cloud = None
    native = catalog.crs if catalog is not None else (cloud.crs if cloud is not None else None)
    if native is None:
        native = given
    elif catalog is not None and given is not None:
        resolve_crs(native, given, ", ".join(names) or "the catalog")
    # degrees are not scaled to metres (a job needing metres refuses a geographic CRS)
    xy_factor = metre_factors(native)[0]
    z_factor = z_to_metres_factor(native) if z_to_metres else 1.0
    return Source(catalog=catalog, selection=sel, z_factor=float(z_factor),
                  xy_factor=xy_factor, paths=names, cloud=cloud, given_crs=given)


def _box4(v: Sequence[float]) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` as floats from the first four values of `v`."""
    return float(v[0]), float(v[1]), float(v[2]), float(v[3])
