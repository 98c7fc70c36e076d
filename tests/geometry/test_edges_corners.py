"""Plane-pair segments, corners (ALGORITHMS.md §4.2-4.3) and their extraction from clouds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.errors import DegenerateGeometryError, InvalidPointsError
from lidarqa.geometry import (
    corner_from_planes,
    extract_corners,
    extract_edges,
    fit_plane,
    plane_pair_segment,
    segment_planes,
)
from lidarqa.geometry.corners import corners_from_segmentation
from lidarqa.geometry.edges import edges_from_segmentation
from lidarqa.testing import make_building_scene, rigid_motion, score_corners, score_edges


def _grid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array(np.meshgrid(a, b, indexing="ij")).reshape(2, -1).T


def spec_planes() -> tuple[np.ndarray, np.ndarray]:
    """Plane z=0 (x in [0,5], y in [1,8]) and plane x=0 (y in [2,9], z in [0,3]), 0.1 m grids."""
    g1 = _grid(np.round(np.arange(0, 50.5) / 10, 10), np.round(np.arange(10, 80.5) / 10, 10))
    g2 = _grid(np.round(np.arange(20, 90.5) / 10, 10), np.round(np.arange(0, 30.5) / 10, 10))
    a = np.column_stack([g1, np.zeros(len(g1))])
    b = np.column_stack([np.zeros(len(g2)), g2])
    return a, b


def test_spec_plane_pair_segment() -> None:
    a, b = spec_planes()
    s = plane_pair_segment(fit_plane(a), a, fit_plane(b), b)
    assert s is not None
    np.testing.assert_allclose(s.start, [0, 2, 0], atol=1e-9)
    np.testing.assert_allclose(s.end, [0, 8, 0], atol=1e-9)
    np.testing.assert_allclose(np.abs(s.direction), [0, 1, 0], atol=1e-12)
    assert s.angle_deg == pytest.approx(90.0)
    # (normal, rho) tuples and swapped order give the same canonical segment
    s2 = plane_pair_segment(((1, 0, 0), 0), b, ((0, 0, 2), 0), a)
    np.testing.assert_allclose([s2.start, s2.end], [s.start, s.end], atol=1e-9)


def test_spec_near_parallel_refused() -> None:
    a, b = spec_planes()
    t = np.radians(1.0)
    seg, reason = plane_pair_segment(((0, 0, 1), 0), a, ((0, np.sin(t), np.cos(t)), 0), b,
                                     return_reason=True)
    assert seg is None and reason == "near-parallel"


def test_plane_pair_support_rules() -> None:
    a, b = spec_planes()
    far = b + [0, 0, 1.0]  # the wall starts 1 m above the line: no support near it
    seg, reason = plane_pair_segment(((0, 0, 1), 0), a, ((1, 0, 0), 0), far, return_reason=True)
    assert seg is None and reason == "too little support"
    apart = b + [0, 20.0, 0]  # supports on disjoint stretches of the line
    seg, reason = plane_pair_segment(((0, 0, 1), 0), a, ((1, 0, 0), 0), apart, return_reason=True)
    assert seg is None and reason == "supports do not overlap"
    with pytest.raises(DegenerateGeometryError):
        plane_pair_segment(((0, 0, 0), 0), a, ((1, 0, 0), 0), b)


def test_spec_corners() -> None:
    c = corner_from_planes([((1, 0, 0), 1), ((0, 1, 0), 2), ((0, 0, 1), 3)])
    np.testing.assert_allclose(c.xyz, [1, 2, 3], atol=1e-12)
    c = corner_from_planes([((1, 0, 0), 1), ((0, 1, 0), 2), ((0, 0.6, 0.8), 3)])
    np.testing.assert_allclose(c.xyz, [1, 2, 2.25], atol=1e-12)
    assert c.det == pytest.approx(0.8)
    # explicit-z planes a x + b y + z = c are normalised first
    c = corner_from_planes([((2, 0, 0), 2), ((0, 1, 0), 2), ((0, 0.75, 1), 3.75)])
    np.testing.assert_allclose(c.xyz, [1, 2, 2.25], atol=1e-12)


def test_corner_conditioning_refused() -> None:
    with pytest.raises(DegenerateGeometryError, match="near-parallel"):
        corner_from_planes([((1, 0, 0), 1), ((1, 0, 0), 2), ((0, 0, 1), 3)])
    # three normals in one plane (all walls): no corner
    t = np.radians(60)
    with pytest.raises(DegenerateGeometryError, match="near-coplanar"):
        corner_from_planes([((1, 0, 0), 1), ((0, 1, 0), 2), ((np.cos(t), np.sin(t), 0), 3)])


def test_corner_covariance() -> None:
    c = corner_from_planes([((1, 0, 0), 1), ((0, 1, 0), 2), ((0, 0.6, 0.8), 3)],
                           sigma_rho=[0.01, 0.02, 0.03])
    n = np.array([[1, 0, 0], [0, 1, 0], [0, 0.6, 0.8]])
    ninv = np.linalg.inv(n)
    np.testing.assert_allclose(c.covariance, ninv @ np.diag([1e-4, 4e-4, 9e-4]) @ ninv.T)
    # from fits: the corner's spread matches the propagated covariance (Monte Carlo)
    rng = np.random.default_rng(1234)
    g = rng.uniform(0.2, 4, (300, 2))
    truth = np.array([0.0, 0.0, 0.0])
    xs, covs = [], []
    for _ in range(200):
        zero = np.zeros(300)
        walls = [np.column_stack([zero, g]), np.column_stack([g[:, 0], zero, g[:, 1]]),
                 np.column_stack([g, zero])]
        fits = [fit_plane(w + rng.normal(0, 0.02, w.shape)) for w in walls]
        cc = corner_from_planes(fits)
        xs.append(cc.xyz)
        covs.append(np.diag(cc.covariance))
    xs = np.array(xs)
    assert np.abs(xs.mean(axis=0) - truth).max() < 0.003
    np.testing.assert_allclose(xs.var(axis=0), np.mean(covs, axis=0), rtol=0.3)


# ---------------------------------------------------------------- synthetic buildings

SEEDS = [0, 1, 2]


@pytest.fixture(scope="module")
def scenes() -> dict:
    out = {}
    for seed in SEEDS:
        sc = make_building_scene(seed=seed, roofs=("flat", "gable") * 2, density=20.0, noise=0.02)
        seg = segment_planes(sc.points)
        edges, skipped = edges_from_segmentation(sc.points, seg)
        corners, refused = corners_from_segmentation(seg, sc.points)
        out[seed] = (sc, seg, edges, corners)
    return out


@pytest.mark.parametrize("seed", SEEDS)
def test_building_edges_found(scenes: dict, seed: int) -> None:
    sc, seg, edges, _ = scenes[seed]
    score = score_edges(edges, sc.edges, max_rms=0.03, min_overlap=0.7, min_length=2.0)
    assert score.n_true >= 40
    assert score.recall >= 0.95
    assert np.nanmax(score.rms) <= 0.03
    assert len(edges) <= len(sc.edges)  # no spurious edges
    # every found edge has finite attributes and sane sigma
    assert np.isfinite(edges.start).all() and np.isfinite(edges.end).all()
    sig = edges.attributes["sigma_line"]
    assert (sig > 0).all() and (sig < 0.05).all()
    assert (edges.attributes["angle_deg"] >= 10).all()


@pytest.mark.parametrize("seed", SEEDS)
def test_building_corners_found(scenes: dict, seed: int) -> None:
    sc, _, _, corners = scenes[seed]
    score = score_corners(corners, sc.corners, max_distance=0.03)
    assert score.recall >= 0.95
    d = np.min(np.linalg.norm(corners.xyz[:, None] - sc.corners.xyz[None], axis=2), axis=1)
    assert (d <= 0.05).all()  # no spurious corners
    assert (corners.attributes["det"] >= 0.1).all()
    sig = np.sqrt(corners.attributes["sigma_x"] ** 2 + corners.attributes["sigma_y"] ** 2
                  + corners.attributes["sigma_z"] ** 2)
    assert np.isfinite(sig).all() and (sig < 0.05).all()


def test_segmentation_matches_true_planes(scenes: dict) -> None:
    sc, seg, _, _ = scenes[0]
    assert seg.n_segments == len(sc.planes)
    for k in range(seg.n_segments):
        true = np.bincount(sc.plane_id[seg.labels == k] + 1).argmax() - 1
        tp = sc.planes[true]
        assert np.degrees(np.arccos(min(1.0, abs(seg.normal[k] @ tp.normal)))) < 0.5
        assert seg.rmse[k] < 0.03


def test_identical_planes_give_no_edge_or_corner() -> None:
    # two segments of the same plane (a gap between them) are never intersected
    rng = np.random.default_rng(1234)
    a = np.column_stack([rng.uniform(0, 5, (500, 2)), np.zeros(500)])
    b = a + [5.3, 0, 0]
    pts = np.vstack([a, b]) + rng.normal(0, 0.005, (1000, 3))
    seg = segment_planes(pts, grow_radius=0.2, adjacency_dist=0.6)
    e, skipped = edges_from_segmentation(pts, seg)
    assert len(e) == 0
    assert all(s["reason"] == "near-parallel" for s in skipped)
    assert len(extract_corners(pts)) == 0


@pytest.mark.parametrize("name", ["collinear", "all_equal", "two_points", "empty"])
def test_degenerate_clouds_give_empty_results(name: str) -> None:
    from lidarqa.testing import cases

    pts = getattr(cases, name)()
    e = extract_edges(pts)
    c = extract_corners(pts)
    assert len(e) == 0 and len(c) == 0


def test_bad_cloud_input() -> None:
    with pytest.raises(InvalidPointsError):
        extract_edges(np.zeros((4, 2)))
    with pytest.raises(InvalidPointsError):
        extract_corners(np.array([[0, 0, np.inf]] * 5))


def _small_scene():
    return make_building_scene(seed=5, roofs=("gable",), density=20.0, noise=0.02, spacing=30.0)


@settings(max_examples=4, deadline=None)
@given(rot=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-180, 180)),
       shift=st.tuples(st.floats(-1e5, 1e5), st.floats(-1e5, 1e5), st.floats(-100, 100)))
def test_edges_move_with_rigid_motion(rot: tuple, shift: tuple) -> None:
    sc = _small_scene()
    moved = rigid_motion(sc, rot, shift)
    e0 = extract_edges(sc.points)
    e1 = extract_edges(moved.points)
    s0 = score_edges(e0, sc.edges)
    s1 = score_edges(e1, moved.edges)
    assert s0.recall >= 0.95 and s1.recall >= 0.95
    # the moved result matches the moved truth as well as the original did
    assert np.nanmax(s1.rms) <= 0.03


@settings(max_examples=4, deadline=None)
@given(perm_seed=st.integers(0, 2**32 - 1))
def test_edges_and_corners_do_not_depend_on_input_order(perm_seed: int) -> None:
    sc = _small_scene()
    perm = np.random.default_rng(perm_seed).permutation(len(sc.points))
    s0, s1 = segment_planes(sc.points), segment_planes(sc.points[perm])
    assert np.array_equal(s1.labels, s0.labels[perm])
    e0, _ = edges_from_segmentation(sc.points, s0)
    e1, _ = edges_from_segmentation(sc.points[perm], s1)
    assert len(e0) == len(e1)
    np.testing.assert_allclose(e1.start, e0.start, atol=1e-9)
    np.testing.assert_allclose(e1.end, e0.end, atol=1e-9)
    c0, _ = corners_from_segmentation(s0, sc.points)
    c1, _ = corners_from_segmentation(s1, sc.points[perm])
    np.testing.assert_allclose(c1.xyz, c0.xyz, atol=1e-9)
