"""Accuracy assessment: line-segment matching (modified LHD), check points, height quality."""

from .lines import (
    LineMatch,
    Threshold,
    auto_threshold,
    detection_rate,
    match_segments,
    segment_distance,
    segment_distances,
)

__all__ = [
    "LineMatch",
    "Threshold",
    "auto_threshold",
    "detection_rate",
    "match_segments",
    "segment_distance",
    "segment_distances",
]
