"""Small array helpers shared by the kernels."""

from __future__ import annotations

import numpy as np

__all__ = ["colmin", "colmax"]


def colmin(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=0)`` of a 2-D array, one contiguous pass per column.

    NumPy reduces ``(N, 3)`` arrays along axis 0 some 10× slower than it reduces
    each strided column on its own (56 ms vs 4 ms for 2 M points); same values.
    """
    return np.array([a[:, k].min() for k in range(a.shape[1])], dtype=a.dtype)


def colmax(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=0)`` of a 2-D array (see :func:`colmin`)."""
    return np.array([a[:, k].max() for k in range(a.shape[1])], dtype=a.dtype)
