"""Shared fixtures: paths to bundled and shared real data."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
SHARED = REPO.parent / "shared" / "lidar-data"
HAS_SHARED = SHARED.is_dir()

needs_shared = pytest.mark.skipif(not HAS_SHARED, reason="../shared/lidar-data is not present")


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
