"""Edge-case point arrays every kernel should survive (shapely ``tests/common.py`` style).

Each case is a function returning a *new* array, so tests may modify it. The
cases come in three groups:

- ``invalid``: must be refused at a public entry point with an
  :class:`~lidarqa.errors.InvalidPointsError` (NaN, inf, wrong shape).
- ``degenerate``: well-formed arrays with too little geometry (empty, 1-2
  points, collinear, all equal, a vertical line, one z value): a kernel gives a
  clear :class:`~lidarqa.errors.LidarQAError` or a defined result, never a hang,
  a bare traceback or NaN coordinates in an output.
- ``numeric``: valid clouds that stress numerics (UTM-sized coordinates,
  float32 input, duplicate xy, duplicate points): results must match the
  well-conditioned equivalent.

Use :func:`point_cases` to parametrise tests::

    @pytest.mark.parametrize("name, points", cases.point_cases("degenerate").items())
    def test_fit_plane_degenerate(name, points): ...
"""

from __future__ import annotations

import numpy as np

from ..errors import OptionError

__all__ = [
    "GROUPS",
    "point_cases",
    "empty",
    "one_point",
    "two_points",
    "collinear",
    "all_equal",
    "vertical_line",
    "single_z",
    "with_nan",
    "with_inf",
    "wrong_shape",
    "flat_1d",
    "utm_plane",
    "float32_plane",
    "duplicate_xy",
    "duplicate_points",
    "tilted_plane",
]

#: UTM-like offset (m) used by :func:`utm_plane`.
UTM_OFFSET = np.array([500_000.0, 5_400_000.0, 300.0])


def tilted_plane(n: int = 200, *, seed: int = 0, noise: float = 0.0,
                 offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """`n` points of ``z = 0.1 x - 0.05 y + 2`` (+ `offset`) over a 20 m square.

    `noise` is the standard deviation (m) of Gaussian noise added to z.
    """
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-10.0, 10.0, (n, 2))
    z = 0.1 * xy[:, 0] - 0.05 * xy[:, 1] + 2.0 + (rng.normal(0.0, noise, n) if noise else 0.0)
    return np.column_stack([xy, z]) + np.asarray(offset, dtype=np.float64)


def empty() -> np.ndarray:
    """(0, 3) float64."""
    return np.zeros((0, 3))


def one_point() -> np.ndarray:
    """A single point."""
    return np.array([[1.0, 2.0, 3.0]])


def two_points() -> np.ndarray:
    """Two distinct points."""
    return np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])


def collinear(n: int = 20) -> np.ndarray:
    """`n` points on a sloping 3D line (no plane is defined)."""
    t = np.linspace(0.0, 10.0, n)[:, None]
    return np.array([1.0, 2.0, 3.0]) + t * np.array([0.6, 0.8, 0.2])


def all_equal(n: int = 10) -> np.ndarray:
    """`n` copies of one point."""
    return np.tile([[5.0, 5.0, 1.0]], (n, 1))


def vertical_line(n: int = 10) -> np.ndarray:
    """`n` points with the same xy and different z."""
    return np.column_stack([np.full(n, 3.0), np.full(n, 4.0), np.linspace(0.0, 9.0, n)])


def single_z(n: int = 100, *, seed: int = 0) -> np.ndarray:
    """`n` random points with one z value (a perfectly flat cloud)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0.0, 10.0, (n, 2)), np.full(n, 7.5)])


def with_nan(n: int = 50) -> np.ndarray:
    """A plane with one NaN z."""
    p = tilted_plane(n)
    p[n // 2, 2] = np.nan
    return p


def with_inf(n: int = 50) -> np.ndarray:
    """A plane with one infinite x."""
    p = tilted_plane(n)
    p[n // 3, 0] = np.inf
    return p


def wrong_shape(n: int = 10) -> np.ndarray:
    """(n, 2): xy only."""
    return tilted_plane(n)[:, :2].copy()


def flat_1d(n: int = 9) -> np.ndarray:
    """A 1-D array of n values (3 rows flattened)."""
    return tilted_plane(n // 3).ravel()


def utm_plane(n: int = 200, *, seed: int = 0, noise: float = 0.0) -> np.ndarray:
    """:func:`tilted_plane` shifted by :data:`UTM_OFFSET` (500 000, 5 400 000, 300) m."""
    return tilted_plane(n, seed=seed, noise=noise, offset=tuple(UTM_OFFSET))


def float32_plane(n: int = 200, *, seed: int = 0) -> np.ndarray:
    """:func:`tilted_plane` as float32 (the exact float32 values, not float64)."""
    return tilted_plane(n, seed=seed).astype(np.float32)


def duplicate_xy(n: int = 100, *, seed: int = 0) -> np.ndarray:
    """A plane where every 10th point is repeated at the same xy, 0.5 m higher."""
    p = tilted_plane(n, seed=seed)
    dup = p[::10].copy()
    dup[:, 2] += 0.5
    return np.concatenate([p, dup])


def duplicate_points(n: int = 100, *, seed: int = 0) -> np.ndarray:
    """A plane sampled twice with identical points (two identical planes)."""
    p = tilted_plane(n, seed=seed)
    return np.concatenate([p, p])


GROUPS: dict[str, tuple] = {
    "invalid": (with_nan, with_inf, wrong_shape, flat_1d),
    "degenerate": (empty, one_point, two_points, collinear, all_equal, vertical_line, single_z),
    "numeric": (utm_plane, float32_plane, duplicate_xy, duplicate_points),
}


def point_cases(group: str | None = None) -> dict[str, np.ndarray]:
    """Fresh edge-case arrays by name, from one group or all of them.

    Parameters
    ----------
    group : {"invalid", "degenerate", "numeric"}, optional
        Default: every case.

    Returns
    -------
    dict of str to ndarray
        ``{"collinear": array(...), ...}`` (new arrays on every call).
    """
    if group is None:
        funcs = [f for g in GROUPS.values() for f in g]
    elif group in GROUPS:
        funcs = list(GROUPS[group])
    else:
        raise OptionError(f"group must be one of {', '.join(map(repr, GROUPS))}; got {group!r}")
    return {f.__name__: f() for f in funcs}
