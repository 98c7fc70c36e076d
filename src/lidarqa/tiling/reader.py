"""Reading the points of one chunk (its core and buffer) from the tiles it touches.

Tiles are streamed in pieces of :data:`READ_STEP` points (laspy chunk iterators) and
only the points inside the chunk's buffered box are kept, so memory holds one chunk
plus one piece at a time. A COPC tile that the box covers only in part is read with a
spatial query instead (:func:`lidarqa.io.las.read_copc_box`: only the octree nodes that
meet the box are decompressed), which gives the same points with the same record
numbers. Points come tile by tile (catalog order), in record order within a tile,
which makes every job's input, hence its result, deterministic, whichever way a tile
is read. Core ownership is decided afterwards by the chunk (:meth:`Chunk.core_mask`,
half-open grid cells), never by the reader.

Within :func:`tile_cache` (the ground job runs its chunks in one), a LAZ/LAS tile is
decompressed once: its points (the dimensions asked for only) are kept in a
least-recently-used cache bounded in bytes, and the next chunk that needs a strip of
it takes the strip from memory. Neighbouring chunks each read the tiles under their
buffers, so without it a block of eight tiles in six chunks decompressed 28 tiles.
The cache changes what is decompressed, never which points a chunk gets. A Dask worker
keeps one of its own across the chunks it runs (:func:`worker_tile_cache`).

The processes of one machine (this one and its LocalCluster workers) can also share
what they decompress (:func:`shared_tiles`): the first process that needs a tile
claims it, decompresses it and saves its arrays in a folder of the job; the others map
those files instead of decompressing the tile again, and a chunk takes first the tiles
nobody else is decompressing. Without it, two workers on a block of eight tiles each
decompressed nearly every tile (every chunk's buffer reaches its neighbours).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import threading
import time
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..io.pointcloud import PointCloud
    from .catalog import Catalog
    from .chunks import Chunk

__all__ = [
    "ChunkData",
    "read_chunk",
    "READ_STEP",
    "tile_cache",
    "worker_tile_cache",
    "clear_worker_tile_cache",
    "TILE_CACHE_BYTES",
    "shared_tiles",
    "unshare_tile",
]

#: Points read from a file at a time while streaming.
READ_STEP = 1_000_000
#: Default bound of :func:`tile_cache`, bytes of decompressed points kept.
TILE_CACHE_BYTES = 512 * 2**20
_TOL = 1e-6  # m


class _TileCache:
    """Decompressed tiles (xyz and some fields), least recently used first out."""

    def __init__(
        self, max_bytes: int, fields: tuple[str, ...] | None, spill: str | None = None
    ) -> None:
        self.max_bytes = int(max_bytes)
        self.fields = fields
        #: a folder shared with the other processes of this machine (see shared_tiles)
        self.spill = spill
        self.entries: OrderedDict[tuple, tuple[np.ndarray, dict[str, np.ndarray]]] = (
            OrderedDict()
        )
        self.nbytes = 0
        self.lock = threading.Lock()

    def get(self, key: tuple) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
        with self.lock:
            hit = self.entries.get(key)
            if hit is not None:
                self.entries.move_to_end(key)
            return hit

    def put(self, key: tuple, value: tuple[np.ndarray, dict[str, np.ndarray]]) -> None:
        # arrays mapped from the shared folder count too: the pages a chunk touched stay
        # in this process's resident memory (what Dask's memory limit watches) while mapped
        size = value[0].nbytes + sum(v.nbytes for v in value[1].values())
        if size > self.max_bytes:
            return
        with self.lock:
            if key in self.entries:
                return
            while self.entries and self.nbytes + size > self.max_bytes:
                _, (ox, of) = self.entries.popitem(last=False)
                self.nbytes -= ox.nbytes + sum(v.nbytes for v in of.values())
            self.entries[key] = value
            self.nbytes += size


_cache: _TileCache | None = None
# a worker's lasting cache (kept across the chunks a Dask worker runs), active per thread
_worker_cache: _TileCache | None = None
_local = threading.local()


def _active() -> _TileCache | None:
    cache = getattr(_local, "cache", None)
    return cache if cache is not None else _cache


@contextmanager
def tile_cache(
    max_bytes: int = TILE_CACHE_BYTES, *, fields: Sequence[str] | None = None
) -> Iterator[None]:
    """Keep decompressed tiles in memory for the chunks read in this block (this process).

    Parameters
    ----------
    max_bytes : int, default TILE_CACHE_BYTES
        Bound of the memory the cached points take; 0 caches nothing.
    fields : sequence of str, optional
        Read only these dimensions (besides x, y, z) into each chunk's cloud; default
        every dimension. A job that needs a few (the ground filter: returns and
        classes) keeps the cache, and its chunks, small.
    """
    global _cache
    saved = _cache
    _cache = _TileCache(max_bytes, None if fields is None else tuple(fields))
    try:
        yield
    finally:
        _cache = saved


@contextmanager
def shared_tiles(folder: str | os.PathLike[str] | None) -> Iterator[None]:
    """Share the tiles decompressed in this block with the other processes of this machine.

    Within an active :func:`tile_cache`, every tile this process decompresses is saved
    under `folder` (one sub-folder of ``.npy`` files per tile), and a tile another
    process saved there is mapped instead of decompressed. The local workers of the
    same job get the folder with their task (see :func:`worker_tile_cache`). `folder`
    (created if missing) is removed at the end of the block; None shares nothing.
    """
    cache = _active()
    if folder is None or cache is None or cache.max_bytes <= 0:
        yield
        return
    os.makedirs(folder, exist_ok=True)
    saved = cache.spill
    cache.spill = os.fspath(folder)
    with cache.lock:
        held = [(k, v) for k, v in cache.entries.items() if not isinstance(v[0], np.memmap)]
    for key, value in held:  # what this process already decompressed (its sample)
        name = _spill_name(cache, key)
        if _claim(name):
            try:
                if not os.path.isdir(name):
                    _save(name, value)
            finally:
                with contextlib.suppress(OSError):
                    os.unlink(name + ".claim")
    try:
        yield
    finally:
        cache.spill = saved
        with cache.lock:  # mapped arrays of the folder go with it
            for k in [k for k, v in cache.entries.items() if isinstance(v[0], np.memmap)]:
                del cache.entries[k]
        shutil.rmtree(folder, ignore_errors=True)


def unshare_tile(path: str) -> None:
    """Remove tile `path` from the folder of :func:`shared_tiles` (no chunk needs it any more).

    The folder then holds the tiles under the chunks in progress only, not the catalog's.
    """
    cache = _active()
    if cache is None or cache.spill is None:
        return
    key = _tile_key(path, cache)
    with cache.lock:
        hit = cache.entries.get(key)
        if hit is not None and isinstance(hit[0], np.memmap):
            del cache.entries[key]
    shutil.rmtree(_spill_name(cache, key), ignore_errors=True)


@contextmanager
def worker_tile_cache(
    fields: Sequence[str], max_bytes: int = TILE_CACHE_BYTES, spill: str | None = None
) -> Iterator[None]:
    """The process's lasting tile cache for `fields`, active in this thread for the block.

    What a Dask worker wraps around each chunk read of a job that declares its fields
    (:attr:`GroundTask.tile_fields`): the cache outlives the task, so the next chunk the
    worker runs takes the tiles it shares with this one from memory, as a serial run
    does within :func:`tile_cache`. Inside an active :func:`tile_cache` (the serial
    engine) that cache is used instead. :func:`clear_worker_tile_cache` frees it at the
    end of the job. `spill`: the job's shared folder (:func:`shared_tiles`), for the
    workers of a LocalCluster on this machine.
    """
    global _worker_cache
    if _active() is not None:
        yield
        return
    key = tuple(fields)
    cache = _worker_cache
    if (
        cache is None
        or cache.fields != key
        or cache.max_bytes != int(max_bytes)
        or cache.spill != spill
    ):
        cache = _worker_cache = _TileCache(max_bytes, key, spill)
    _local.cache = cache
    try:
        yield
    finally:
        _local.cache = None


def clear_worker_tile_cache() -> None:
    """Free the worker's lasting tile cache (the engine runs it on every worker after a job)."""
    global _worker_cache
    _worker_cache = None


def _tile_key(path: str, cache: _TileCache) -> tuple:
    st = os.stat(path)
    return (os.path.realpath(path), st.st_size, st.st_mtime_ns, cache.fields)


def _decompress(
    path: str, fields: tuple[str, ...] | None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Every point of tile `path` (xyz and `fields`), decompressed, read-only."""
    from ..io.las import LasReader

    parts_xyz: list[np.ndarray] = []
    parts_fields: dict[str, list[np.ndarray]] = {}
    with LasReader(path) as r:
        for piece in r.chunks(READ_STEP, fields=fields):
            parts_xyz.append(piece.xyz)
            for k, v in piece.fields.items():
                parts_fields.setdefault(k, []).append(v)
    if parts_xyz:
        xyz = np.concatenate(parts_xyz) if len(parts_xyz) > 1 else parts_xyz[0]
        # copies: a view would keep the file's whole point records alive in the cache
        out = {
            k: (np.concatenate(v) if len(v) > 1 else np.array(v[0]))
            for k, v in parts_fields.items()
        }
    else:
        xyz, out = np.empty((0, 3)), {}
    xyz.flags.writeable = False
    for v in out.values():
        v.flags.writeable = False
    return xyz, out


# --- sharing decompressed tiles between the processes of one machine ---------------------
# A tile's arrays live in SPILL/<hash>/ (xyz.npy and one .npy per field), renamed into
# place when complete. SPILL/<hash>.claim (created exclusively, holding the pid) says
# which process is decompressing it; a claim whose process is gone is taken over.

_WAIT = 0.01  # s between looks at a tile another process is decompressing


def _spill_name(cache: _TileCache, key: tuple) -> str:
    assert cache.spill is not None
    return os.path.join(cache.spill, hashlib.sha1(repr(key).encode()).hexdigest()[:24])


def _mapped(folder: str) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """The arrays saved in `folder`, mapped read-only; None if not (yet) there."""
    try:
        names = os.listdir(folder)
        xyz = np.load(os.path.join(folder, "xyz.npy"), mmap_mode="r")
        fields = {
            n[:-4]: np.load(os.path.join(folder, n), mmap_mode="r")
            for n in sorted(names)
            if n.endswith(".npy") and n != "xyz.npy"
        }
    except (OSError, ValueError):
        return None
    return xyz, fields


def _claim(name: str) -> bool:
    """Claim the tile `name` for this process; False when another live process holds it."""
    for _ in range(2):
        try:
            fd = os.open(name + ".claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                with open(name + ".claim", encoding="ascii") as f:
                    pid = int(f.read() or 0)
            except (OSError, ValueError):
                return False  # being written or just released: look again later
            if pid and not _alive(pid):
                try:
                    os.unlink(name + ".claim")  # its process is gone: take it over
                except OSError:
                    pass
                continue
            return False
        except OSError:
            return False  # no room, no rights: decompress without sharing
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(str(os.getpid()))
        return True
    return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _save(name: str, value: tuple[np.ndarray, dict[str, np.ndarray]]) -> bool:
    """Save a tile's arrays as `name` (atomic: a folder renamed into place)."""
    tmp = f"{name}.{os.getpid()}.tmp"
    try:
        os.makedirs(tmp, exist_ok=True)
        np.save(os.path.join(tmp, "xyz.npy"), value[0])
        for k, v in value[1].items():
            np.save(os.path.join(tmp, f"{k}.npy"), v)
        os.rename(tmp, name)
        return True
    except OSError:
        shutil.rmtree(tmp, ignore_errors=True)
        return False


def _shared_tile(
    path: str, key: tuple, cache: _TileCache, wait: bool
) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """Tile `path` through the shared folder: mapped, or decompressed here and saved.

    None when another process is decompressing it and not `wait`.
    """
    name = _spill_name(cache, key)
    while True:
        if os.path.isdir(name):
            hit = _mapped(name)
            if hit is not None:
                return hit
        if _claim(name):
            try:
                if os.path.isdir(name):  # saved between our look and our claim
                    hit = _mapped(name)
                    if hit is not None:
                        return hit
                value = _decompress(path, cache.fields)
                if _save(name, value):
                    return _mapped(name) or value
                return value
            finally:
                with contextlib.suppress(OSError):
                    os.unlink(name + ".claim")
        if not wait:
            return None
        time.sleep(_WAIT)


def _whole_tile(
    path: str, cache: _TileCache, *, wait: bool = True
) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """Every point of tile `path` (xyz, the cache's fields), from the cache or decompressed.

    With a shared folder and not `wait`: None while another process decompresses it.
    """
    key = _tile_key(path, cache)
    hit = cache.get(key)
    if hit is not None:
        return hit
    if cache.spill is not None:
        value = _shared_tile(path, key, cache, wait)
        if value is None:
            return None
    else:
        value = _decompress(path, cache.fields)
    cache.put(key, value)
    return value


def _prefetch(paths: Sequence[str]) -> None:
    """Bring the tiles of a chunk into the active cache, the ones nobody is busy with first.

    Only with a shared folder: a tile that another process is decompressing is taken
    after the others, by then most often mapped from its saved arrays.
    """
    cache = _active()
    if cache is None or cache.spill is None or cache.max_bytes <= 0:
        return
    later = [p for p in paths if _whole_tile(p, cache, wait=False) is None]
    for p in later:
        _whole_tile(p, cache)


@dataclass(eq=False)
class ChunkData:
    """The points of one chunk with its buffer.

    Attributes
    ----------
    cloud : lidarqa.io.PointCloud
        All points of the buffered box, with the dimensions common to its tiles.
    core : ndarray of bool
        True for points of the chunk's core (each catalog point is core in exactly
        one chunk).
    tile_index : ndarray of int32
        Index into ``catalog.tiles`` of each point's file.
    point_index : ndarray of int64
        Record number of each point in its file.
    chunk : Chunk
    """

    cloud: PointCloud
    core: np.ndarray
    tile_index: np.ndarray
    point_index: np.ndarray
    chunk: Chunk

    def __len__(self) -> int:
        return len(self.core)

    @property
    def n_core(self) -> int:
        """Number of core points (the chunk's own points, without its buffer)."""
        return int(self.core.sum())


def _in_box(xyz: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray:
    # widened by _TOL: a core cell's box (origin + index * size) may round a hair inside
    # the points that the grid-index rule puts in it
    return (
        (xyz[:, 0] >= box[0] - _TOL)
        & (xyz[:, 0] <= box[2] + _TOL)
        & (xyz[:, 1] >= box[1] - _TOL)
        & (xyz[:, 1] <= box[3] + _TOL)
    )


def cached_tile(path: str) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """Every point of tile `path` (xyz and the cache's fields) through the active cache.

    None outside :func:`tile_cache` and :func:`worker_tile_cache`. The arrays are the
    cache's own (read-only).
    """
    cache = _active()
    if cache is None or cache.max_bytes <= 0:
        return None
    return _whole_tile(path, cache)  # it waits: never None


def _read_tile_box(
    path: str, box: tuple[float, float, float, float], whole: bool, copc: bool = False
) -> tuple:
    """(xyz, fields, point_index) of the points of `path` inside `box`.

    `copc`: the tile is a COPC file; unless `whole`, read it with a spatial query.
    """
    from ..io.las import LasReader, read_copc_box

    if copc and not whole:
        cloud, idx = read_copc_box(path, box, tol=_TOL)
        return cloud.xyz, (cloud.fields if len(idx) else None), idx
    cache = _active()
    if cache is not None and cache.max_bytes > 0:
        whole_tile = _whole_tile(path, cache)
        assert whole_tile is not None  # it waits for the tile
        txyz, tfields = whole_tile
        if len(txyz) == 0:
            return np.empty((0, 3)), None, np.empty(0, dtype=np.int64)
        if whole:  # copies: the cached arrays stay as read
            return txyz.copy(), {k: v.copy() for k, v in tfields.items()}, np.arange(
                len(txyz), dtype=np.int64
            )
        sel = np.flatnonzero(_in_box(txyz, box))
        if len(sel) == 0:
            return np.empty((0, 3)), None, np.empty(0, dtype=np.int64)
        return txyz[sel], {k: v[sel] for k, v in tfields.items()}, sel.astype(np.int64)

    parts_xyz, parts_idx = [], []
    parts_fields: dict[str, list[np.ndarray]] = {}
    offset = 0
    with LasReader(path) as r:
        for piece in r.chunks(READ_STEP):
            n = len(piece)
            keep = np.ones(n, dtype=bool) if whole else _in_box(piece.xyz, box)
            if keep.all():
                parts_xyz.append(piece.xyz)
                parts_idx.append(np.arange(offset, offset + n, dtype=np.int64))
                for k, v in piece.fields.items():
                    parts_fields.setdefault(k, []).append(v)
            elif keep.any():
                sel = np.nonzero(keep)[0]
                parts_xyz.append(piece.xyz[sel])
                parts_idx.append(sel.astype(np.int64) + offset)
                for k, v in piece.fields.items():
                    parts_fields.setdefault(k, []).append(v[sel])
            offset += n
    if parts_xyz:  # one piece (a tile within READ_STEP points) is used as read, not copied

        def join(v: list[np.ndarray]) -> np.ndarray:
            return v[0] if len(v) == 1 else np.concatenate(v)

        xyz, idx = join(parts_xyz), join(parts_idx)
        fields = {k: join(v) for k, v in parts_fields.items()}
    else:
        xyz = np.empty((0, 3))
        idx = np.empty(0, dtype=np.int64)
        fields = None
    return xyz, fields, idx


def read_chunk(catalog: Catalog, chunk: Chunk) -> ChunkData:
    """Read the points of `chunk` (core + buffer) from every tile it touches.

    Parameters
    ----------
    catalog : Catalog
    chunk : Chunk

    Returns
    -------
    ChunkData
    """
    from ..io import PointCloud

    box = chunk.buffered
    _prefetch([catalog.tiles[t].path for t in chunk.tiles if not catalog.tiles[t].is_copc])
    xyzs, idxs, tids, fieldsets = [], [], [], []
    for t in chunk.tiles:
        tile = catalog.tiles[t]
        xmin, ymin, xmax, ymax = tile.bounds2d
        whole = xmin >= box[0] and xmax <= box[2] and ymin >= box[1] and ymax <= box[3]
        xyz, fields, idx = _read_tile_box(tile.path, box, whole, tile.is_copc)
        if len(xyz) == 0:
            continue
        xyzs.append(xyz)
        idxs.append(idx)
        tids.append(np.full(len(xyz), t, dtype=np.int32))
        fieldsets.append(fields)
    if xyzs:
        xyz = np.concatenate(xyzs) if len(xyzs) > 1 else xyzs[0]
        common = set(fieldsets[0])
        for f in fieldsets[1:]:
            common &= set(f)
        names = [k for k in fieldsets[0] if k in common]
        fields = {
            k: (
                np.concatenate([f[k] for f in fieldsets]) if len(fieldsets) > 1 else fieldsets[0][k]
            )
            for k in names
        }
        point_index = np.concatenate(idxs)
        tile_index = np.concatenate(tids)
    else:
        xyz = np.empty((0, 3))
        fields = {}
        point_index = np.empty(0, dtype=np.int64)
        tile_index = np.empty(0, dtype=np.int32)
    cloud = PointCloud(xyz=xyz, fields=fields, crs=catalog.crs)
    core = chunk.core_mask(xyz)
    return ChunkData(
        cloud=cloud, core=core, tile_index=tile_index, point_index=point_index, chunk=chunk
    )
