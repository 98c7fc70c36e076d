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
