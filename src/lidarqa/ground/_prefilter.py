"""Private pre-filters for ground filtering: low outliers."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._tin import tree_workers

__all__ = ["low_outliers"]


def low_outliers(
    xyz: np.ndarray, *, distance: float, radius: float, k: int = 16, rank: int = 2
) -> np.ndarray:
    """Points lying more than `distance` (m) below their `rank`-th lowest neighbour.

    Neighbours are the `k` nearest points within `radius` (m, horizontal), the
    point itself excluded. Using the 2nd lowest neighbour rather than the lowest
    also catches pairs of low outliers (multipath echoes often come in small
    clusters). Points with fewer than `rank` neighbours are not flagged.
    """
    n = xyz.shape[0]
    if n <= rank:
        return np.zeros(n, dtype=bool)
    kk = min(k + 1, n)
    tree = cKDTree(xyz[:, :2])
    d, j = tree.query(xyz[:, :2], k=kk, distance_upper_bound=radius, workers=tree_workers())
    d = d[:, 1:]
    j = j[:, 1:]
    valid = np.isfinite(d)
    zn = np.where(valid, xyz[np.minimum(j, n - 1), 2], np.inf)
    zn.sort(axis=1)
    ref = zn[:, rank - 1]
    return np.isfinite(ref) & (xyz[:, 2] < ref - distance)
