"""Seeded synthetic scenes with exactly known truth, edge-case inputs, scoring helpers.

Scenes (every maker takes ``seed=`` and returns a :class:`Scene`):

- :func:`make_scene`: terrain (slope, undulation, curbs, optional embankment),
  flat and gable buildings with observed walls, cars, trees, shrubs, outliers.
- :func:`make_building_scene`: buildings on a planar ground (edge/corner tests).
- :func:`make_terrain_scene`: bare terrain with break lines (ground tests).
- :func:`make_plane_pair`, :func:`make_corner`: two planes at a given angle,
  three planes at a corner.
- :func:`make_strip_scene`: overlapping flight strips over ground and hip roofs
  with known per-strip offsets and height noise (:class:`StripScene`).
- :func:`make_interchange`: two roads crossing on two levels (deck, ramps, cars,
  sparse points under the deck), map polygons shifted, paint-strip references
  (returns an :class:`InterchangeScene`).

A :class:`Scene` holds ``points``, ``classification`` (ASPRS), ``is_ground``,
``object_id``, ``plane_id``, ``planes`` (:class:`TruePlane`), ``edges``
(:class:`~lidarqa.io.vector.Segments`), ``corners``
(:class:`~lidarqa.io.vector.PointSet`), ``params``, ``fields`` and the terrain
model (``scene.ground_z(xy)``). :func:`rigid_motion` moves points and truth
together; :func:`score_edges` / :func:`score_corners` score detections against
the truth; :func:`sample_checkpoints` gives true ground check points;
:mod:`lidarqa.testing.cases` has edge-case arrays; :func:`write_tiles` /
:func:`write_block` write scenes as tiled deliveries (catalog tests, benchmarks);
:func:`make_delivery` writes a LAS 1.4 delivery with known density and planted defects
(``lidarqa qc`` tests).
Hypothesis strategies live in ``lidarqa.testing.strategies`` (needs the ``test``
extra; not imported here).

>>> from lidarqa.testing import make_building_scene
>>> scene = make_building_scene(seed=1)
>>> scene.points.shape[1], len(scene.planes) > 0
(3, True)
"""

from . import cases
from ._shapes import TerrainModel
from .delivery import Delivery, make_delivery
from .interchange import InterchangeScene, make_interchange
from .profiles import ground_profile
from .scenes import (
    BuildingSpec,
    Scene,
    TruePlane,
    make_building_scene,
    make_corner,
    make_plane_pair,
    make_scene,
    make_terrain_scene,
    plane_area,
    rigid_motion,
    roof_points,
    rotation_matrix,
    sample_checkpoints,
)
from .scoring import CornerScore, EdgeScore, score_corners, score_edges
from .strips import StripScene, make_strip_scene
from .tiles import write_block, write_tiles

__all__ = [
    "Delivery",
    "make_delivery",
    "Scene",
    "TruePlane",
    "BuildingSpec",
    "TerrainModel",
    "make_scene",
    "make_building_scene",
    "roof_points",
    "make_terrain_scene",
    "make_plane_pair",
    "make_corner",
    "rigid_motion",
    "rotation_matrix",
    "plane_area",
    "sample_checkpoints",
    "score_edges",
    "score_corners",
    "EdgeScore",
    "CornerScore",
    "cases",
    "ground_profile",
    "write_tiles",
    "write_block",
    "StripScene",
    "make_strip_scene",
    "InterchangeScene",
    "make_interchange",
]
