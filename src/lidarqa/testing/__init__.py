"""Seeded synthetic scenes with known truth, edge-case inputs and hypothesis strategies.

>>> from lidarqa.testing import make_building_scene
>>> scene = make_building_scene(seed=1)
>>> scene.points.shape[1], len(scene.planes) > 0
(3, True)

``lidarqa.testing.strategies`` (hypothesis, a test extra) is not imported here.
"""

from __future__ import annotations

from . import cases
from ._shapes import TerrainModel
from .scenes import (
    BuildingSpec,
    Scene,
    TruePlane,
    make_building_scene,
    make_scene,
    make_terrain_scene,
    plane_area,
    rigid_motion,
    rotation_matrix,
)

__all__ = [
    "Scene",
    "TruePlane",
    "BuildingSpec",
    "TerrainModel",
    "make_scene",
    "make_building_scene",
    "make_terrain_scene",
    "rigid_motion",
    "rotation_matrix",
    "plane_area",
    "cases",
]
