"""The ground job's tile cache and default grid: less work, the same points and labels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lidarqa.tiling import open_catalog
from lidarqa.tiling.chunks import make_chunks
from lidarqa.tiling.reader import read_chunk, shared_tiles, tile_cache, unshare_tile

FIELDS = ("return_number", "number_of_returns", "classification")


class _Task:
    """A chunk task that declares its fields (and a shared folder), as the ground task does."""

    tile_fields = FIELDS

    def __init__(self, spill: str | None = None) -> None:
        self.tile_spill = spill

    def __call__(self, data):
        return data


def _same(a, b, fields) -> None:
    np.testing.assert_array_equal(a.cloud.xyz, b.cloud.xyz)
    np.testing.assert_array_equal(a.point_index, b.point_index)
    np.testing.assert_array_equal(a.tile_index, b.tile_index)
    np.testing.assert_array_equal(a.core, b.core)
    for k in fields:
        np.testing.assert_array_equal(a.cloud.fields[k], b.cloud.fields[k])


@pytest.mark.parametrize("max_bytes", [512 * 2**20, 600_000, 100_000, 0])
def test_cached_reads_give_the_same_points(scene_tiles, max_bytes):
    # 40 m chunks with a 25 m buffer: strips of tiles, whole tiles, several chunks per
    # tile; 600 kB holds two tiles of about 250 kB (evictions), 100 kB none; 0 is off
    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunks = make_chunks(cat, chunk_size=40.0, buffer=25.0)
    plain = [read_chunk(cat, c) for c in chunks]
    with tile_cache(max_bytes, fields=FIELDS):
        cached = [read_chunk(cat, c) for c in chunks]
        again = [read_chunk(cat, c) for c in reversed(chunks)][::-1]
    for a, b, c in zip(plain, cached, again, strict=True):
        _same(a, b, FIELDS)
        _same(a, c, FIELDS)
        if max_bytes:
            assert set(b.cloud.fields) <= set(FIELDS)


def test_cache_keeps_its_arrays_unchanged(scene_tiles):
    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunk = make_chunks(cat, chunk_size=200.0, buffer=0.0)[0]  # every tile whole
    with tile_cache(fields=FIELDS):
        first = read_chunk(cat, chunk)
        ref = first.cloud.xyz.copy()
        first.cloud.xyz[:] = 0.0  # a job may write into its own arrays
        second = read_chunk(cat, chunk)
    np.testing.assert_array_equal(second.cloud.xyz, ref)


def test_default_ground_grid_has_the_fewest_chunks(scene_tiles, monkeypatch):
    import lidarqa.tiling.ground as ground
    from lidarqa.tiling.chunks import default_chunk_size

    # a target that allows chunks of about one 60 m tile: from (0, 0) the 120 m block
    # (x from 1000, not a multiple of 60) is cut into 3 x 3 chunks, from its corner 2 x 2
    _, paths = scene_tiles
    cat = open_catalog(paths)
    target = cat.density * 90.0**2  # 70 m chunks + 2 x 10 m, snapped to the 60 m tiles
    monkeypatch.setattr(ground, "GROUND_TARGET_POINTS", target)
    x0, y0, x1, y1 = cat.bounds[:4]
    side, origin = ground._ground_grid(cat, buffer=10.0, cell=20.0)
    allowed = default_chunk_size(cat, buffer=10.0, origin=origin, target_points=target)
    assert origin == (x0, y0)
    assert side <= allowed
    assert side % 20.0 == 0.0  # whole seed cells
    n = math.ceil((x1 - x0) / allowed - 1e-9) * math.ceil((y1 - y0) / allowed - 1e-9)
    ours = make_chunks(cat, chunk_size=side, buffer=10.0, origin=origin)
    from_zero = make_chunks(cat, buffer=10.0, target_points=target)
    assert len(ours) == n < len(from_zero)


def test_a_worker_keeps_its_tiles_across_chunks(scene_tiles, monkeypatch):
    # what a Dask worker does per chunk (run_task with a task that declares its fields):
    # the second chunk over the same tiles decompresses nothing, the points are the same
    from lidarqa.tiling import reader
    from lidarqa.tiling.engine import run_task

    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunks = make_chunks(cat, chunk_size=40.0, buffer=25.0)
    plain = [read_chunk(cat, c) for c in chunks]
    opened = _counting_reader(monkeypatch)
    try:
        first = [run_task(cat, c, _Task()) for c in chunks]
        n_first = len(opened)
        again = [run_task(cat, c, _Task()) for c in chunks]
        assert len(opened) == n_first == len(paths)  # each tile decompressed once
    finally:
        reader.clear_worker_tile_cache()
    for a, b, c in zip(plain, first, again, strict=True):
        _same(a, b, FIELDS)
        _same(a, c, FIELDS)
    assert reader._worker_cache is None
    assert reader._active() is None  # nothing left active in this thread


def _counting_reader(monkeypatch) -> list[str]:
    import lidarqa.io.las as las

    opened: list[str] = []
    real = las.LasReader

    class Counting(real):
        def __init__(self, path, *a, **k):
            opened.append(str(path))
            super().__init__(path, *a, **k)

    monkeypatch.setattr(las, "LasReader", Counting)
    return opened


def test_processes_share_the_tiles_they_decompress(scene_tiles, tmp_path, monkeypatch):
    # two local workers of one job (shared_tiles): the second maps what the first saved,
    # decompresses nothing, and reads the same points
    from lidarqa.tiling import reader
    from lidarqa.tiling.engine import run_task

    spill = tmp_path / "spill"
    spill.mkdir()

    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunks = make_chunks(cat, chunk_size=40.0, buffer=25.0)
    plain = [read_chunk(cat, c) for c in chunks]
    opened = _counting_reader(monkeypatch)
    try:
        first = [run_task(cat, c, _Task(str(spill))) for c in chunks]
        assert len(opened) == len(paths)
        assert len([p for p in spill.iterdir() if p.is_dir()]) == len(paths)
        assert not list(spill.glob("*.claim"))
        reader.clear_worker_tile_cache()  # another process: nothing in its memory
        second = [run_task(cat, c, _Task(str(spill))) for c in chunks]
        assert len(opened) == len(paths)  # mapped, not decompressed again
    finally:
        reader.clear_worker_tile_cache()
    for a, b, c in zip(plain, first, second, strict=True):
        _same(a, b, FIELDS)
        _same(a, c, FIELDS)


def test_shared_tiles_folder_goes_with_the_block(scene_tiles, tmp_path):

    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunk = make_chunks(cat, chunk_size=200.0, buffer=0.0)[0]
    plain = read_chunk(cat, chunk)
    folder = tmp_path / "shared"
    with tile_cache(fields=FIELDS), shared_tiles(folder):
        data = read_chunk(cat, chunk)
        assert len(list(folder.iterdir())) == len(paths)
        unshare_tile(str(paths[0]))  # no chunk needs it any more
        assert len(list(folder.iterdir())) == len(paths) - 1
        _same(plain, read_chunk(cat, chunk), FIELDS)  # decompressed again if asked
    _same(plain, data, FIELDS)
    assert not folder.exists()


def test_a_tile_being_decompressed_elsewhere_is_taken_last(scene_tiles, tmp_path, monkeypatch):
    # tile 0 is claimed by another live process: the chunk decompresses the others first,
    # then maps tile 0 once that process has saved it; a claim whose process is gone is
    # taken over
    import os
    import subprocess
    import sys
    import threading

    from lidarqa.tiling import reader

    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunk = make_chunks(cat, chunk_size=200.0, buffer=0.0)[0]
    plain = read_chunk(cat, chunk)
    folder = tmp_path / "shared"
    order: list[str] = []
    real = reader._decompress

    def recording(path, fields):
        order.append(path)
        return real(path, fields)

    monkeypatch.setattr(reader, "_decompress", recording)
    first = cat.tiles[chunk.tiles[0]].path
    with tile_cache(fields=FIELDS), shared_tiles(folder):
        cache = reader._active()
        name = reader._spill_name(cache, reader._tile_key(first, cache))
        with open(name + ".claim", "w") as f:
            f.write(str(os.getppid()))  # alive, not this process
        assert reader._whole_tile(first, cache, wait=False) is None

        def other_process() -> None:
            while len(order) < len(chunk.tiles) - 1:
                threading.Event().wait(0.01)
            reader._save(name, real(first, FIELDS))
            os.unlink(name + ".claim")

        t = threading.Thread(target=other_process)
        t.start()
        data = read_chunk(cat, chunk)
        t.join()
        assert first not in order and len(order) == len(chunk.tiles) - 1
        assert isinstance(reader._whole_tile(first, cache)[0], np.memmap)
    _same(plain, data, FIELDS)

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    order.clear()
    with tile_cache(fields=FIELDS), shared_tiles(folder):
        cache = reader._active()
        name = reader._spill_name(cache, reader._tile_key(first, cache))
        with open(name + ".claim", "w") as f:
            f.write(str(gone.pid))
        assert reader._whole_tile(first, cache, wait=False) is not None
        assert order == [first]


def test_shared_tiles_offers_what_this_process_already_holds(scene_tiles, tmp_path, monkeypatch):
    # the tiles this process decompressed before sharing started (the automatic
    # parameters' sample) are saved for the workers: another process's cache maps them
    from lidarqa.tiling import reader

    _, paths = scene_tiles
    cat = open_catalog(paths)
    chunk = make_chunks(cat, chunk_size=200.0, buffer=0.0)[0]
    folder = tmp_path / "shared"
    with tile_cache(fields=FIELDS):
        read_chunk(cat, chunk)
        with shared_tiles(folder):
            assert len([p for p in folder.iterdir() if p.is_dir()]) == len(paths)
            opened = _counting_reader(monkeypatch)
            other = reader._TileCache(reader.TILE_CACHE_BYTES, FIELDS, str(folder))
            for p in paths:
                xyz, _ = reader._whole_tile(str(p), other)
                assert isinstance(xyz, np.memmap)
            assert opened == []


def test_mapped_tiles_count_against_the_cache_bound(scene_tiles, tmp_path):
    # the pages of a mapped tile stay resident while it is mapped: the bound applies to
    # them as to decompressed ones (a worker's memory, as Dask sees it, stays bounded)
    from lidarqa.tiling import reader

    _, paths = scene_tiles
    folder = tmp_path / "shared"
    folder.mkdir()
    first = reader._TileCache(reader.TILE_CACHE_BYTES, FIELDS, str(folder))
    sizes = []
    for p in paths:
        xyz, fields = reader._whole_tile(str(p), first)
        sizes.append(xyz.nbytes + sum(v.nbytes for v in fields.values()))
    other = reader._TileCache(max(sizes) + 1, FIELDS, str(folder))
    for p in paths:
        assert isinstance(reader._whole_tile(str(p), other)[0], np.memmap)
        assert other.nbytes <= other.max_bytes and len(other.entries) == 1
