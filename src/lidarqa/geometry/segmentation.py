"""Surface-growing segmentation and plane segmentation (ALGORITHMS.md §1.2).

:func:`surface_growing` labels points into smooth planar segments (seed surfaces
grown by proximity and distance to the segment plane). :func:`segment_planes`
adds a least-squares plane per segment and the segment adjacency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import OptionError
from . import _kernels as K

__all__ = ["surface_growing", "segment_planes", "PlaneSegmentation", "SEED_METHODS"]

SEED_METHODS = ("hough", "pca", "ransac")
_METHOD_CODE = {"pca": 0, "hough": 1, "ransac": 2}


def _check_int(value: Any, name: str, lo: int) -> int:
    try:
        v = int(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be an integer, got {value!r}") from exc
    if v != value or v < lo:
        raise OptionError(f"{name} must be an integer >= {lo}, got {value!r}")
    return v


def canonical_order(points: np.ndarray) -> np.ndarray:
    """Permutation sorting points lexicographically by (x, y, z): an order-free index."""
    return np.lexsort((points[:, 2], points[:, 1], points[:, 0]))


def surface_growing(
    points: Any,
    *,
    k_seed: int = 20,
    seed_dist: float = 0.15,
    min_seed_points: int = 10,
    hough_angle_step: float = 3.0,
    grow_radius: float = 0.5,
    grow_dist: float = 0.2,
    refit_growth: float = 0.2,
    min_segment_size: int = 10,
    seed_method: str = "pca",
    seed: int = 0,
) -> np.ndarray:
    """Segment points into planar surfaces by seed detection and surface growing.

    Trial points are visited in ascending order of the planarity residual
    λ₃/(λ₁+λ₂+λ₃) of their `k_seed` nearest neighbours (ties: lexicographic
    x, y, z). Around the next unlabelled trial point, a seed plane is found from
    its unlabelled neighbours and accepted when at least `min_seed_points` lie
    within `seed_dist` of it. The segment then grows: unlabelled points within
    `grow_radius` of a segment point and within `grow_dist` of the segment plane
    join; the plane is refitted (total least squares) whenever the segment has
    grown by `refit_growth`. Segments smaller than `min_segment_size` are
    released (label -1).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres.
    k_seed : int, default 20
        Neighbourhood size (points, including the trial point) for planarity and
        seed detection; N is used when N < k_seed.
    seed_dist : float, default 0.15
        Distance (m) of seed points to the seed plane; also the Hough ρ bin width.
    min_seed_points : int, default 10
        Points needed within `seed_dist` of the seed plane to accept a seed.
    hough_angle_step : float, default 3.0
        Angular step (degrees) of the Hough normal directions (tilt and azimuth).
    grow_radius : float, default 0.5
        Neighbourhood radius (m, 3D) of growing.
    grow_dist : float, default 0.2
        Maximum distance (m) of a joining point to the segment plane.
    refit_growth : float, default 0.2
        Relative growth (fraction) after which the segment plane is refitted.
    min_segment_size : int, default 10
        Segments with fewer points are released (-1).
    seed_method : {"pca", "hough", "ransac"}, default "pca"
        How the seed plane is found in the neighbourhood: one total-least-squares
        fit plus one refit on its inliers ("pca", fastest), a 3D Hough transform
        over normal directions and ρ bins ("hough", §1.2), or 200 three-point
        RANSAC hypotheses ("ransac", randomised by `seed` and the trial point).
    seed : int, default 0
        Random seed for ``seed_method="ransac"``.

    Returns
    -------
    ndarray of shape (N,), int64
        Segment label per point, -1 for unsegmented points. Labels are numbered
        0, 1, ... in the order the segments were found, which does not depend on
        the input order of the points.

    Raises
    ------
    InvalidPointsError
        If `points` is not a finite (N, 3) array.
    OptionError
        If an option is out of range.

    Notes
    -----
    Fewer than 3 distinct points give all -1. The kernel is a numba loop over a
    hashed voxel grid (cell = `grow_radius`), so memory stays O(N).

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(10.), np.arange(10.)), -1).reshape(-1, 2)
    >>> pts = np.column_stack([g, np.zeros(100)])
    >>> np.unique(surface_growing(pts, grow_radius=1.5)).tolist()
    [0]
    """
    pts_in = as_points(points)
    k_seed = _check_int(k_seed, "k_seed", 3)
    seed_dist = check_positive(seed_dist, "seed_dist")
    min_seed_points = _check_int(min_seed_points, "min_seed_points", 3)
    hough_angle_step = check_range(hough_angle_step, "hough_angle_step", 0.0, 90.0, lo_open=True)
    grow_radius = check_positive(grow_radius, "grow_radius")
    grow_dist = check_positive(grow_dist, "grow_dist")
    refit_growth = check_positive(refit_growth, "refit_growth", allow_zero=True)
    min_segment_size = _check_int(min_segment_size, "min_segment_size", 1)
    check_choice(seed_method, SEED_METHODS, "seed_method")
    seed = _check_int(seed, "seed", 0)

    n = len(pts_in)
    labels_out = np.full(n, -1, dtype=np.int64)
    if n < 3:
        return labels_out
    perm = canonical_order(pts_in)
    pts = pts_in[perm]
    if _fewer_than_3_distinct(pts):
        return labels_out
    pts = pts - pts.mean(axis=0)
    pts = np.ascontiguousarray(pts)

    k = min(k_seed, n)
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
    _, knn = tree.query(pts, k=k, workers=-1)
    knn = np.ascontiguousarray(knn.reshape(n, k), dtype=np.int64)
    planarity = K.planarity_knn(pts, knn)
    trial_order = np.lexsort((np.arange(n), planarity)).astype(np.int64)

    cx, cy, cz, nyz, nz, cell_keys, cell_start, order, max_cell = K.build_grid(pts, grow_radius)
    dirs = K.hough_directions(hough_angle_step) if seed_method == "hough" else np.zeros((1, 3))
    labels = K.surface_growing_kernel(
        pts, trial_order, knn, k, _METHOD_CODE[seed_method], seed_dist, min_seed_points, dirs,
        seed, grow_radius * grow_radius, grow_dist, refit_growth, min_segment_size,
        cx, cy, cz, nyz, nz, cell_keys, cell_start, order, max_cell)
    labels_out[perm] = labels
    return labels_out


def _fewer_than_3_distinct(sorted_pts: np.ndarray) -> bool:
    """True if a lexicographically sorted array has fewer than 3 distinct rows."""
    change = np.any(sorted_pts[1:] != sorted_pts[:-1], axis=1)
    return int(change.sum()) + 1 < 3
