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
    "kernels_cached",
    "plane_covariance",
    "plane_pair_segment",
    "ransac",
    "segment_planes",
    "surface_growing",
]


def kernels_cached() -> bool:
    """True when numba's on-disk cache holds plane segmentation's compiled kernels.

    The kernels are compiled with ``cache=True``: the first run after installing
    (or upgrading) spends tens of seconds compiling, later runs load them. The
    CLI uses this (with :func:`lidarqa.ground.kernels_cached`) to say so before a
    first run. It asks numba whether the cache index of the kNN and surface
    growing kernels is valid for the installed source.

    Returns
    -------
    bool
        False when a kernel would be compiled on its next call.
    """
    from .._jitcache import kernels_cached as _cached
    from . import _kernels

    return _cached(_kernels.knn_grid, _kernels.surface_growing_kernel)
