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


def ign_block(base: Path):
    """The six IGN 50 m tiles as a folder of links and merged into one file, under `base`.

    Returns ``(folder, merged_path, merged)`` with ``merged`` the laspy ``LasData``.
    """
    import laspy
    import numpy as np

    files = sorted((SHARED / "ign-lidarhd").glob("test_data_770*.laz"))
    assert len(files) == 6
    folder = base / "tiles"
    folder.mkdir()
    for f in files:
        (folder / f.name).symlink_to(f)
    las = [laspy.read(f) for f in files]
    assert all(np.array_equal(x.header.offsets, las[0].header.offsets) for x in las)
    merged = laspy.LasData(las[0].header)
    merged.points = laspy.ScaleAwarePointRecord(
        np.concatenate([x.points.array for x in las]), las[0].header.point_format,
        las[0].header.scales, las[0].header.offsets)
    merged.update_header()
    merged.write(base / "merged.laz")
    return folder, base / "merged.laz", merged
