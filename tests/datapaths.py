"""Paths of the bundled and shared real data, importable from any test.

Use ``from datapaths import SHARED, HAS_SHARED, needs_shared``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
SHARED = REPO.parent / "shared" / "lidar-data"
HAS_SHARED = SHARED.is_dir()

needs_shared = pytest.mark.skipif(not HAS_SHARED, reason="../shared/lidar-data is not present")
