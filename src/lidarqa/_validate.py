"""Validation helpers used once, at public entry points.

Internals trust their inputs; these helpers turn bad input into a
:class:`~lidarqa.errors.LidarQAError` whose message names the argument, what was
expected and what was received.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from .errors import InvalidPointsError, MissingDependencyError, OptionError

__all__ = [
    "as_points",
    "as_mask",
    "check_choice",
    "check_positive",
    "check_range",
    "require",
]


def as_points(
    points: Any,
    name: str = "points",
    *,
    dim: int = 3,
    min_points: int = 0,
    allow_empty: bool = True,
) -> np.ndarray:
    """Return `points` as a C-contiguous ``(N, dim)`` float64 array, or raise.

    Raises :class:`InvalidPointsError` for a wrong shape, non-numeric data,
    NaN/inf, or fewer than `min_points` rows. The input is never modified; a
    copy is made only when the dtype or layout requires it.
    """
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidPointsError(f"{name} must be numeric, got {type(points).__name__}") from exc
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InvalidPointsError(f"{name} must have shape (N, {dim}), got {arr.shape}")
    n = arr.shape[0]
    if n == 0 and not allow_empty:
        raise InvalidPointsError(f"{name} is empty")
    if n < min_points:
        raise InvalidPointsError(f"{name} needs at least {min_points} points, got {n}")
    if n and not np.isfinite(arr).all():
        bad = int((~np.isfinite(arr)).any(axis=1).sum())
        raise InvalidPointsError(f"{name} has {bad} row(s) with NaN or infinite coordinates")
    if n and np.abs(arr).max() > MAX_COORDINATE:
        # squared distances of such values overflow: they are corrupt data, not coordinates
        raise InvalidPointsError(
            f"{name} has coordinates beyond ±{MAX_COORDINATE:g} (largest {np.abs(arr).max():g})"
        )
    return np.ascontiguousarray(arr)


MAX_COORDINATE = 1e15  # metres (or degrees): far beyond any real survey


def as_mask(mask: Any, n: int, name: str = "mask") -> np.ndarray:
    """Return `mask` as a boolean ``(n,)`` array, or raise :class:`InvalidPointsError`."""
    arr = np.asarray(mask)
    if arr.shape != (n,):
        raise InvalidPointsError(f"{name} must have shape ({n},), got {arr.shape}")
    return arr.astype(bool, copy=False)


def check_choice(value: Any, choices: Iterable[Any], name: str) -> Any:
    """Return `value` if it is one of `choices`, else raise :class:`OptionError`."""
    choices = tuple(choices)
    if value not in choices:
        listed = ", ".join(repr(c) for c in choices)
        raise OptionError(f"{name} must be one of {listed}; got {value!r}")
    return value


def check_positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """Return `value` as float if it is finite and > 0 (>= 0 with `allow_zero`)."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be a number, got {value!r}") from exc
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise OptionError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def check_range(
    value: Any,
    name: str,
    lo: float,
    hi: float,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
) -> float:
    """Return `value` as float if it lies in the interval from `lo` to `hi`."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be a number, got {value!r}") from exc
    ok = np.isfinite(v)
    ok &= (v > lo) if lo_open else (v >= lo)
    ok &= (v < hi) if hi_open else (v <= hi)
    if not ok:
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        raise OptionError(f"{name} must be in {left}{lo}, {hi}{right}, got {value!r}")
    return v


def require(module: str, extra: str) -> Any:
    """Import an optional dependency or raise :class:`MissingDependencyError` with a hint."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingDependencyError(
            f"{module} is needed for this; install it with: pip install 'lidarqa[{extra}]'"
        ) from exc
