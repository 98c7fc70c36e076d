"""The LocalCluster's workers run with one thread per library and glibc's own allocator settings."""

from __future__ import annotations

import os

import pytest

from lidarqa.tiling.engine import Engine

pytest.importorskip("distributed")


NAMES = ("MALLOC_TRIM_THRESHOLD_", "NUMBA_NUM_THREADS", "RAYON_NUM_THREADS", "OMP_NUM_THREADS")


def test_workers_keep_glibc_malloc_thresholds_and_one_thread():
    """Dask's MALLOC_TRIM_THRESHOLD_=65536 costs the ground filter 16 % more CPU: not set."""
    if "MALLOC_TRIM_THRESHOLD_" in os.environ:
        pytest.skip("this process sets MALLOC_TRIM_THRESHOLD_ itself: workers inherit it")
    with Engine(workers=1) as eng:
        eng.start()  # a LocalCluster starts on first use
        # os.getenv pickles by reference (a function of this test module would need the
        # workers to import the tests)
        env = {}
        for name in NAMES:
            (value,) = eng.client.run(os.getenv, name).values()
            env[name] = value
    assert env["MALLOC_TRIM_THRESHOLD_"] is None
    assert env["NUMBA_NUM_THREADS"] == env["RAYON_NUM_THREADS"] == env["OMP_NUM_THREADS"] == "1"
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ  # nor leaked into this process


def test_start_warm_runs_the_warm_up_on_every_worker(tmp_path):
    """start_warm starts the cluster and has each worker run warm() without waiting for it."""
    import functools
    import time

    with Engine(workers=2) as eng:
        # os.makedirs pickles by reference; exist_ok: both workers make the same folder
        eng.start_warm(functools.partial(os.makedirs, str(tmp_path / "warmed"), exist_ok=True))
        assert eng.client is not None and eng.n_workers == 2
        t0 = time.monotonic()
        while not (tmp_path / "warmed").is_dir() and time.monotonic() - t0 < 60:
            time.sleep(0.1)
    assert (tmp_path / "warmed").is_dir()


def test_ground_starts_its_cluster_early_only_when_it_will_use_one(scene_tiles):
    """No cluster for one worker, a scheduler address, a given engine or one chunk."""
    from lidarqa.tiling import open_catalog
    from lidarqa.tiling.ground import _early_engine

    _, paths = scene_tiles
    cat = open_catalog(paths)
    args = ((0.0, 0.0), "segment-ptd", 60.0)
    assert _early_engine(cat, None, None, 1, 60.0, *args) is None
    assert _early_engine(cat, None, "tcp://127.0.0.1:1", 2, 60.0, *args) is None
    assert _early_engine(cat, Engine("serial"), None, 2, 60.0, *args) is None
    assert _early_engine(cat, None, None, 2, 1e6, *args) is None  # one chunk
    assert _early_engine(cat, None, None, 2, "bad", *args) is None  # reported by the job
    eng = _early_engine(cat, None, None, 2, 60.0, *args)
    try:
        assert eng is not None and eng.client is not None
    finally:
        if eng is not None:
            eng.close()
