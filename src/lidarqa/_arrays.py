"""Small array helpers shared by the kernels of several subpackages."""

from __future__ import annotations

import numpy as np

__all__ = ["colmin", "colmax", "spatial_order"]


def colmin(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=0)`` of a 2-D array, one contiguous pass per column.

    NumPy reduces ``(N, 3)`` arrays along axis 0 some 10× slower than it reduces
    each strided column on its own (56 ms vs 4 ms for 2 M points); same values.
    """
    return np.array([a[:, k].min() for k in range(a.shape[1])], dtype=a.dtype)


def colmax(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=0)`` of a 2-D array (see :func:`colmin`)."""
    return np.array([a[:, k].max() for k in range(a.shape[1])], dtype=a.dtype)


def spatial_order(xy: np.ndarray, lo: np.ndarray, cell: float) -> np.ndarray:
    """A permutation that puts points of the same 64x64-cell tile, then cell, together.

    Only for memory locality of KD-tree builds and queries (about 2x faster
    for 10^6 points); results do not depend on it.
    """
    c = np.floor((xy - lo) / cell).astype(np.int64)
    c = np.maximum(c, 0)
    tile = c >> 6
    key = ((tile[:, 0] * (1 << 24) + tile[:, 1]) << 12) + ((c[:, 0] & 63) << 6) + (c[:, 1] & 63)
    return np.argsort(key, kind="stable")
