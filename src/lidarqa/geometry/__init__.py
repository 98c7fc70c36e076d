"""Planes, plane segmentation, edges (plane-pair segments) and corners.

Methods: :ref:`alg-segmentation`, :ref:`alg-planes`, :ref:`alg-edges`, :ref:`alg-corners`.

>>> from lidarqa.geometry import fit_plane, segment_planes, extract_edges, extract_corners
"""

from .corners import Corner, corner_from_planes, extract_corners
from .edges import PlanePairSegment, extract_edges, plane_pair_segment
from .planes import (
    IterativePlaneFit,
    PlaneFit,
    RansacPlane,
    fit_plane,
    fit_plane_iterative,
    plane_covariance,
    ransac,
)
from .segmentation import PlaneSegmentation, segment_planes, surface_growing

__all__ = [
    "Corner",
    "IterativePlaneFit",
    "PlaneFit",
    "PlanePairSegment",
    "PlaneSegmentation",
    "RansacPlane",
    "corner_from_planes",
    "extract_corners",
    "extract_edges",
    "fit_plane",
    "fit_plane_iterative",
    "plane_covariance",
    "plane_pair_segment",
    "ransac",
    "segment_planes",
    "surface_growing",
]
