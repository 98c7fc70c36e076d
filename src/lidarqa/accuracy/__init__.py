"""Accuracy assessment: line-segment matching (modified LHD), check points, height quality.

- :mod:`lidarqa.accuracy.lines` — Poreba & Goulette (2013): 3D edge segments matched with the
  modified line-segment Hausdorff distance, for absolute accuracy and repeatability.
- :mod:`lidarqa.accuracy.lines_io` — the inputs of line matching: segment files, or the
  edges of a cloud (per file or per flight strip).
- :mod:`lidarqa.accuracy.checkpoints` and :mod:`lidarqa.accuracy.transforms` — Fang & Huang:
  corners vs check points, least-squares transformations, RMSE to ASPRS (2023) and NSSDA.
- :mod:`lidarqa.accuracy.heights` — Oude Elberink & Vosselman: plane-fitted heights with error
  propagation, TIN precision, w-tests.
- :mod:`lidarqa.accuracy.swaths` — relative accuracy of flight strips: swath-overlap differences,
  smooth-surface repeatability, strip offsets and the measured strip noise E4.
- :mod:`lidarqa.accuracy.roads` — Oude Elberink & Vosselman §2: 3D roads from 2D map polygons,
  each polygon on its own height level, with the map-point precision.
"""

from .checkpoints import (
    CheckpointReport,
    VerticalCheckReport,
    asprs2023_accuracy,
    assess_checkpoints,
    match_points,
    nssda_accuracy,
    residual_statistics,
    rmse_3d,
    vertical_check,
)
from .heights import (
    HeightReport,
    assess_heights,
    compare_heights,
    critical_value,
    densify_polygons,
    empirical_model_sigma,
    fit_plane_height,
    interpolate_tin,
    laser_block_sigma,
    map_point_heights,
    model_sigma,
    read_map_points,
    tin_sigma,
    w_test,
)
from .lines import (
    LineMatch,
    Threshold,
    auto_threshold,
    detection_rate,
    match_segments,
    segment_distance,
    segment_distances,
)
from .swaths import SwathReport, assess_swaths
from .transforms import TRANSFORMS, TransformFit, estimate_transform

__all__ = [
    # swaths
    "SwathReport",
    "assess_swaths",
    # lines
    "LineMatch",
    "Threshold",
    "auto_threshold",
    "detection_rate",
    "match_segments",
    "segment_distance",
    "segment_distances",
    # checkpoints and transforms
    "CheckpointReport",
    "VerticalCheckReport",
    "asprs2023_accuracy",
    "assess_checkpoints",
    "match_points",
    "nssda_accuracy",
    "residual_statistics",
    "rmse_3d",
    "vertical_check",
    "TRANSFORMS",
    "TransformFit",
    "estimate_transform",
    # heights
    "HeightReport",
    "assess_heights",
    "compare_heights",
    "critical_value",
    "densify_polygons",
    "empirical_model_sigma",
    "fit_plane_height",
    "interpolate_tin",
    "laser_block_sigma",
    "map_point_heights",
    "model_sigma",
    "read_map_points",
    "tin_sigma",
    "w_test",
]
