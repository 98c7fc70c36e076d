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
