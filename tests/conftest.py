"""Shared fixtures: paths to bundled and shared real data (constants live in datapaths.py)."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from datapaths import DATA, HAS_SHARED, SHARED

# catalog jobs keep finished chunks for --resume in a work folder: never the user's cache,
# and removed when the test session ends (xdist workers inherit the controller's folder)
if "LIDARQA_WORK_DIR" not in os.environ:
    os.environ["LIDARQA_WORK_DIR"] = tempfile.mkdtemp(prefix="lidarqa-test-work-")
    atexit.register(shutil.rmtree, os.environ["LIDARQA_WORK_DIR"], ignore_errors=True)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not HAS_SHARED:
        pytest.skip("../shared/lidar-data is not present")
    return SHARED


@pytest.fixture(scope="session")
def demo_tile() -> Path:
    from lidarqa.data import demo_tile

    return demo_tile()


#: Session fixtures too costly to build once per xdist worker: the tests that use one run
#: on one worker (``lidarqa demo`` once; one Dask LocalCluster).
SHARED_SESSION_FIXTURES = ("demo_run", "small_runs")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Group the tests for pytest-xdist (``--dist loadgroup`` in pyproject.toml).

    Each test module runs on one worker, so its module fixtures are built once (as with
    ``--dist loadscope``); the tests sharing an expensive session fixture run on one worker
    too. A test with its own ``xdist_group`` mark keeps it. ``tryfirst``: pytest-xdist
    reads the marks in its own hook of the same name, which would otherwise run first.
    """
    for item in items:
        if item.get_closest_marker("xdist_group"):
            continue
        shared = [f for f in SHARED_SESSION_FIXTURES if f in getattr(item, "fixturenames", ())]
        group = shared[0] if shared else item.nodeid.split("::", 1)[0]
        item.add_marker(pytest.mark.xdist_group(group))
