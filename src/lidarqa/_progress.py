"""Progress reporting from pure kernels: an optional callback, never printing.

Long kernels take ``progress=None`` (keyword-only): a callable receiving the
fraction of the work done, a float in [0, 1], non-decreasing. The command
line turns it into a bar with percentage and ETA; a library user may pass any
callable (or nothing). Kernels split their work into weighted stages with
:func:`stage` so that nested steps report into their share of the bar.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["ProgressCallback", "stage", "report", "geometric_fraction"]

ProgressCallback = Callable[[float], None]


class _Stage:
    """A callback reporting into ``[start, end]`` of a parent callback, monotone."""

    __slots__ = ("_parent", "_start", "_span", "_last")

    def __init__(self, parent: ProgressCallback, start: float, end: float) -> None:
        self._parent = parent
        self._start = start
        self._span = end - start
        self._last = -1.0

    def __call__(self, fraction: float) -> None:
        f = min(1.0, max(0.0, float(fraction)))
        if f <= self._last:
            return
        self._last = f
        self._parent(self._start + self._span * f)


def stage(progress: ProgressCallback | None, start: float, end: float) -> ProgressCallback | None:
    """A callback for the part ``[start, end]`` of `progress` (None stays None).

    Examples
    --------
    >>> seen = []
    >>> half = stage(seen.append, 0.5, 1.0)
    >>> half(0.5); half(0.2); half(1.0)
    >>> seen
    [0.75, 1.0]
    """
    if progress is None:
        return None
    return _Stage(progress, start, end)


def report(progress: ProgressCallback | None, fraction: float) -> None:
    """Call `progress` with `fraction` if there is a callback."""
    if progress is not None:
        progress(fraction)


def geometric_fraction(done: float, last_gain: float, previous_gain: float) -> float:
    """Estimated fraction done of an iteration whose gains shrink geometrically.

    After gains ``..., previous_gain, last_gain`` with ``done`` the total so far,
    the remaining gain is about ``last_gain·r/(1-r)`` with ``r = last/previous``
    (capped at 0.9), so the fraction done is ``done / (done + remaining)``.

    Examples
    --------
    >>> round(geometric_fraction(150.0, 50.0, 100.0), 3)
    0.75
    """
    if done <= 0:
        return 0.0
    if previous_gain <= 0 or last_gain <= 0:
        return 1.0 if last_gain <= 0 else 0.5
    r = min(0.9, last_gain / previous_gain)
    remaining = last_gain * r / (1.0 - r)
    return done / (done + remaining)
