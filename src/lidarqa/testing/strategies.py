"""Hypothesis strategies for property tests (needs the ``test`` extra: hypothesis).

>>> from hypothesis import given
>>> from lidarqa.testing.strategies import rigid_motions, points_on_plane
>>> @given(rigid_motions(), points_on_plane())
... def test_fit_is_equivariant(motion, plane): ...

Every strategy draws small numbers (angles, offsets, a seed) and builds arrays
with NumPy from them, so examples are cheap and shrink well.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from .._validate import require

require("hypothesis", "test")

from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from .scenes import make_building_scene, rotation_matrix  # noqa: E402

__all__ = [
    "seeds",
    "rotations_deg",
    "rotation_matrices",
    "translations",
    "rigid_motions",
    "unit_vectors",
    "planes",
    "points_on_plane",
    "point_clouds",
    "permutations",
    "building_scenes",
]


def seeds() -> st.SearchStrategy[int]:
    """Seeds for ``numpy.random.default_rng``."""
    return st.integers(min_value=0, max_value=2**32 - 1)


def _angle(limit: float) -> st.SearchStrategy[float]:
    return st.floats(-limit, limit, allow_nan=False, allow_infinity=False)


def rotations_deg(max_angle: float = 180.0, *, z_only: bool = False) -> st.SearchStrategy:
    """(rx, ry, rz) in degrees, each in ``[-max_angle, max_angle]`` (rx = ry = 0 with `z_only`)."""
    if z_only:
        return st.tuples(st.just(0.0), st.just(0.0), _angle(max_angle))
    return st.tuples(_angle(max_angle), _angle(max_angle), _angle(max_angle))


def rotation_matrices(max_angle: float = 180.0, *, z_only: bool = False) -> st.SearchStrategy:
    """3x3 rotation matrices (``Rz @ Ry @ Rx`` of :func:`rotations_deg`)."""
    return rotations_deg(max_angle, z_only=z_only).map(rotation_matrix)


def translations(max_offset: float = 1000.0) -> st.SearchStrategy:
    """(tx, ty, tz) in metres, each in ``[-max_offset, max_offset]``."""
    f = st.floats(-max_offset, max_offset, allow_nan=False, allow_infinity=False)
    return st.tuples(f, f, f)


def rigid_motions(max_angle: float = 180.0, max_offset: float = 1000.0, *,
                  z_only: bool = False) -> st.SearchStrategy:
    """``(rotation_deg, translation)`` pairs, ready for ``rigid_motion(x, *motion)``."""
    return st.tuples(rotations_deg(max_angle, z_only=z_only), translations(max_offset))


def unit_vectors(*, upward: bool = False) -> st.SearchStrategy:
    """Unit 3-vectors, uniformly distributed (``n_z >= 0`` with `upward`)."""

    def build(seed: int) -> np.ndarray:
        v = np.random.default_rng(seed).normal(size=3)
        v /= np.linalg.norm(v)
        if upward and v[2] < 0:
            v = -v
        return v

    return seeds().map(build)


def planes(max_rho: float = 100.0) -> st.SearchStrategy:
    """``(normal, rho)`` with a unit normal, ``n_z >= 0`` and ``|rho| <= max_rho`` (m)."""
    rho = st.floats(-max_rho, max_rho, allow_nan=False, allow_infinity=False)
    return st.tuples(unit_vectors(upward=True), rho)


@st.composite
def points_on_plane(draw: Any, *, min_points: int = 10, max_points: int = 200,
                    extent: float = 20.0, noise: float = 0.0, max_rho: float = 100.0) -> tuple:
    """``(points, normal, rho)``: points spread over an `extent` x `extent` m patch of a plane.

    Points get Gaussian `noise` (m) along the normal.
    """
    normal, rho = draw(planes(max_rho))
    n = draw(st.integers(min_points, max_points))
    rng = np.random.default_rng(draw(seeds()))
    # orthonormal basis of the plane
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    ab = rng.uniform(-0.5 * extent, 0.5 * extent, (n, 2))
    pts = rho * normal + ab[:, :1] * u + ab[:, 1:] * v
    if noise > 0:
        pts = pts + rng.normal(0.0, noise, n)[:, None] * normal
    return pts, normal, float(rho)


def point_clouds(*, min_points: int = 0, max_points: int = 100, extent: float = 100.0,
                 dtype: Any = np.float64) -> st.SearchStrategy:
    """(N, 3) arrays of finite coordinates in ``[-extent, extent]`` (hypothesis-drawn elements)."""
    width: Literal[32, 64] = 32 if np.dtype(dtype) == np.float32 else 64
    elements = st.floats(-extent, extent, allow_nan=False, allow_infinity=False, width=width)
    return st.integers(min_points, max_points).flatmap(
        lambda n: hnp.arrays(dtype, (n, 3), elements=elements))


def permutations(n: int) -> st.SearchStrategy:
    """Index permutations of ``range(n)`` as int64 arrays (for order-independence tests)."""
    return st.permutations(range(n)).map(lambda p: np.asarray(p, dtype=np.int64))


def building_scenes(*, roofs: tuple[str, ...] = ("flat", "gable"), density: float = 5.0,
                    noise: float = 0.02) -> st.SearchStrategy:
    """Random :func:`~lidarqa.testing.make_building_scene` scenes (low density: cheap)."""
    return seeds().map(lambda s: make_building_scene(seed=s, roofs=roofs, density=density,
                                                     noise=noise))
