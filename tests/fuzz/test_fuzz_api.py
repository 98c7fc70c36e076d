"""Public entry points on degenerate and hostile arrays: a result or a LidarQAError, in time."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hostile import time_limit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import lidarqa.accuracy as acc
import lidarqa.geometry as geo
import lidarqa.ground as gnd
from lidarqa.errors import LidarQAError
from lidarqa.testing.cases import point_cases

pytestmark = pytest.mark.fuzz

HOSTILE_POINTS = {
    **point_cases(),
    "huge": np.full((50, 3), 1e300),
    "mixed-scale": np.vstack([np.random.default_rng(0).normal(size=(40, 3)), [[1e12, 0, 0]]]),
    "int": np.arange(30).reshape(10, 3),
    "list": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    "object": np.array([["a", "b", "c"]], dtype=object),
    "4-columns": np.zeros((10, 4)),
    "none": None,
    "scalar": 3.0,
    # long degenerate lines: neighbour searches run past the grid's last row (a kNN row named
    # a point twice and surface growing overran its queue: heap corruption, abort)
    "line-x": np.column_stack([np.linspace(0, 10, 500), np.zeros(500), np.zeros(500)]),
    "line-z": np.column_stack([np.zeros(500), np.zeros(500), np.linspace(0, 10, 500)]),
}


def _fine(fn, *args, **kwargs):
    """Call; accept any result or a LidarQAError; anything else fails the test."""
    with time_limit(), warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        try:
            return fn(*args, **kwargs)
        except LidarQAError:
            return None


POINT_FUNCS = {
    "ptd_filter": lambda p: gnd.ptd_filter(p),
    "default_grow_radius": lambda p: gnd.default_grow_radius(p),
    "point_scatterness": lambda p: gnd.point_scatterness(p),
    "fit_plane": lambda p: geo.fit_plane(p),
    "fit_plane_iterative": lambda p: geo.fit_plane_iterative(p),
    "ransac": lambda p: geo.ransac(p, seed=0),
    "segment_planes": lambda p: geo.segment_planes(p),
    "surface_growing": lambda p: geo.surface_growing(p),
    "classify_ground": lambda p: gnd.classify_ground(p),
    "extract_edges": lambda p: geo.extract_edges(p),
    "extract_corners": lambda p: geo.extract_corners(p),
    "vertical_check": lambda p: acc.vertical_check(p, acc.checkpoints.PointSet(
        np.arange(3), np.array([[0.5, 0.5, 0], [0.2, 0.1, 0], [9.0, 9.0, 0]]))),
    "map_point_heights": lambda p: acc.map_point_heights(p, np.array([[0.5, 0.5], [0.1, 0.2]])),
    "assess_heights": lambda p: acc.assess_heights(
        p, np.array([[0.5, 0.5]]), np.array([[0.4, 0.4, 0.0]])),
    "fit_plane_height": lambda p: acc.fit_plane_height(p, np.array([[0.5, 0.5]])),
}


@pytest.mark.parametrize("func", sorted(POINT_FUNCS))
@pytest.mark.parametrize("case", sorted(HOSTILE_POINTS))
def test_point_functions_on_hostile_points(func, case):
    _fine(POINT_FUNCS[func], HOSTILE_POINTS[case])


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    func=st.sampled_from(sorted(POINT_FUNCS)),
    pts=arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)),
               elements=st.one_of(st.floats(-1e6, 1e6), st.sampled_from([0.0, 1.0]))),
)
def test_point_functions_random(func, pts):
    _fine(POINT_FUNCS[func], pts)


def test_knn_rows_are_distinct_on_a_line():
    from scipy.spatial import cKDTree

    from lidarqa.geometry import _kernels as K

    line = HOSTILE_POINTS["line-x"]
    kn = K.knn(line - line.mean(axis=0), 10)
    assert all(len(set(row)) == 10 for row in kn.tolist())
    d, _ = cKDTree(line).query(line, 10)
    mine = np.sort(np.linalg.norm(line[kn] - line[:, None], axis=2), axis=1)
    np.testing.assert_allclose(mine, d, atol=1e-12)


def _seg(*rows):
    return np.asarray(rows, dtype=float).reshape(-1, 2, 3)


SEGMENTS = {
    "empty": np.empty((0, 2, 3)),
    "one": _seg([0, 0, 0], [1, 0, 0]),
    "far": _seg([0, 10, 0], [1, 10, 0]),
    "zero-length": _seg([0, 0, 0], [0, 0, 0]),
    "nan": _seg([0, np.nan, 0], [1, 0, 0]),
    "inf": _seg([0, np.inf, 0], [1, 0, 0]),
    "identical": _seg([0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]),
    "huge": _seg([1e300, 0, 0], [-1e300, 0, 0]),
    "vertical": _seg([0, 0, 0], [0, 0, 5]),
    "wrong-shape": np.zeros((3, 3)),
    "tiny": _seg([0, 0, 0], [1e-13, 0, 0]),
}


@pytest.mark.parametrize("a", sorted(SEGMENTS))
@pytest.mark.parametrize("b", ["one", "far", "identical", "vertical", "empty", "nan"])
def test_segment_functions(a, b):
    _fine(acc.match_segments, SEGMENTS[a], SEGMENTS[b])
    _fine(acc.match_segments, SEGMENTS[a], SEGMENTS[b], threshold=0.5)
    _fine(acc.segment_distances, SEGMENTS[a], SEGMENTS[b])
    if len(SEGMENTS[a]) and len(SEGMENTS[b]):
        _fine(acc.segment_distance, SEGMENTS[a][0], SEGMENTS[b][0])


def test_match_segments_without_pairs_in_cutoff():
    """Issue #13: two 1 m segments 10 m apart raised IndexError."""
    r = acc.match_segments(SEGMENTS["one"], SEGMENTS["far"])
    assert r.lhd == pytest.approx(10.0)
    r = acc.match_segments(SEGMENTS["one"], SEGMENTS["far"], threshold=0.5)
    assert r.to_dict()["n_pairs_tm"] == 0 and r.to_dict()["n_pairs_mt"] == 0


def _ps(xyz, ids=None):
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    return acc.checkpoints.PointSet(np.arange(len(xyz)) if ids is None else ids, xyz)


POINTSETS = {
    "empty": _ps(np.empty((0, 3))),
    "one": _ps([[0, 0, 0]]),
    "three-collinear": _ps([[0, 0, 0], [1, 1, 1], [2, 2, 2]]),
    "nan": _ps([[0, np.nan, 0], [1, 1, 1]]),
    "far": _ps([[1e9, 1e9, 0], [1e9 + 1, 1e9, 0], [1e9, 1e9 + 1, 1]]),
    "huge": _ps([[1e308, 0, 0], [0, 1, 1]]),
    "dup-id": _ps([[0, 0, 0], [1, 1, 1]], ids=np.array([1, 1])),
    "square": _ps([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]]),
}


@pytest.mark.parametrize("a", sorted(POINTSETS))
@pytest.mark.parametrize("b", sorted(POINTSETS))
def test_checkpoint_functions(a, b):
    for transform in ("none", "translation", "helmert"):
        _fine(acc.assess_checkpoints, POINTSETS[a], POINTSETS[b], transform=transform)
    _fine(acc.assess_checkpoints, POINTSETS[a], POINTSETS[b], match="nearest", max_distance=0.1)
    _fine(acc.match_points, POINTSETS[a], POINTSETS[b])
    _fine(acc.estimate_transform, POINTSETS[a].xyz, POINTSETS[b].xyz)


@pytest.mark.parametrize("name", sorted(POINTSETS))
def test_vertical_check_on_hostile_check_points(name):
    rng = np.random.default_rng(4)
    cloud = np.column_stack([rng.uniform(-5, 5, (400, 2)), rng.normal(0, 0.01, 400)])
    _fine(acc.vertical_check, cloud, POINTSETS[name])


@pytest.mark.parametrize("values", [np.empty((0, 3)), np.full((3, 3), np.nan), np.zeros(3),
                                    np.ones((1, 3)), np.full((2, 3), 1e308)])
def test_statistics_functions(values):
    _fine(acc.residual_statistics, values)
    _fine(acc.w_test, values[:, 0] if values.ndim == 2 else values, np.ones(len(values)))
    _fine(acc.compare_heights, values.ravel(), np.zeros(values.size), values.ravel())
    for v in (np.nan, -1.0, np.inf, 0.0):
        _fine(acc.nssda_accuracy, v, v, v)
        _fine(acc.asprs2023_accuracy, v, v, v, n_check=3)
        _fine(acc.rmse_3d, v, v, v)
        _fine(acc.model_sigma, v)
    _fine(acc.auto_threshold, values.ravel())
    _fine(acc.interpolate_tin, values, np.ones(len(values)), np.zeros((2, 2)))


@pytest.mark.parametrize("n", [0, 1, 5])
def test_ground_metrics(n):
    a = np.ones(n, dtype=bool)
    _fine(gnd.filter_errors, a, a)
    _fine(gnd.filter_errors, a, np.ones(n + 1, dtype=bool))
    _fine(gnd.filter_errors_from_counts, 0, 0, 0, 0)
    _fine(gnd.filter_errors_from_counts, -1, 2, 3, 4)
