"""Small synthetic deliveries shared by the tiling tests (built once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def scene_tiles(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, list[Path]]:
    """One seeded scene (120 m x 120 m, buildings, trees, returns) cut into 60 m tiles."""
    from lidarqa.testing import make_scene, write_tiles

    scene = make_scene(
        seed=7, size=(120.0, 120.0), density=2.5, returns=True, origin=(1000.0, 2000.0, 50.0)
    )
    folder = tmp_path_factory.mktemp("tiles")
    paths = write_tiles(scene, folder, tile_size=60.0, origin=(1000.0, 2000.0))
    return scene, paths


# Options of the small runs compared byte for byte (fast: 10 m buffer, 20 m seed cells).
SMALL_RUN = {"chunk_size": 60.0, "buffer": 10.0, "cell_size": 20.0, "evaluate": True}


@pytest.fixture(scope="session")
def small_runs(scene_tiles, tmp_path_factory) -> dict[str, object]:
    """``lidarqa ground`` on `scene_tiles` serially and on a 2-worker LocalCluster (shared by
    the determinism and cluster tests, so the LocalCluster starts once)."""
    pytest.importorskip("distributed")
    from lidarqa.tiling.ground import ground_catalog

    _, paths = scene_tiles
    base = tmp_path_factory.mktemp("small-runs")
    return {
        "opts": SMALL_RUN,
        "serial": ground_catalog(paths, base / "serial", workers=1, **SMALL_RUN),
        "two": ground_catalog(paths, base / "two", workers=2, **SMALL_RUN),
    }
