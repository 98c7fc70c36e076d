"""Shared fixtures: paths to bundled and shared real data (constants live in datapaths.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from datapaths import DATA, HAS_SHARED, SHARED


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
