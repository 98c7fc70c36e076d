"""Hypothesis strategies and truth scoring helpers of lidarqa.testing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.io.vector import PointSet, Segments
from lidarqa.testing import (
    make_building_scene,
    rigid_motion,
    rotation_matrix,
    sample_checkpoints,
    score_corners,
    score_edges,
)
from lidarqa.testing.strategies import (
    permutations,
    planes,
    point_clouds,
    points_on_plane,
    rigid_motions,
    rotation_matrices,
    unit_vectors,
)


@settings(deadline=None)
@given(rotation_matrices())
def test_rotation_matrices_are_rotations(r: np.ndarray) -> None:
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)


@settings(deadline=None)
@given(points_on_plane(noise=0.0))
def test_points_on_plane_lie_on_it(sample: tuple) -> None:
    pts, n, rho = sample
    assert n[2] >= 0 and np.linalg.norm(n) == pytest.approx(1.0)
    assert np.abs(pts @ n - rho).max() < 1e-9 * max(1.0, abs(rho))
    assert pts.shape[0] >= 10


@settings(deadline=None)
@given(points_on_plane(), rigid_motions())
def test_rigid_motion_keeps_points_on_moved_plane(sample: tuple, motion: tuple) -> None:
    pts, n, rho = sample
    rot_deg, t = motion
    moved = rigid_motion(pts, rot_deg, t)
    r = rotation_matrix(rot_deg)
    n2 = r @ n
    rho2 = rho + n2 @ np.asarray(t)
    assert np.abs(moved @ n2 - rho2).max() < 1e-8


@settings(deadline=None)
@given(point_clouds(min_points=1, max_points=30), st.data())
def test_point_clouds_and_permutations(points: np.ndarray, data: st.DataObject) -> None:
    assert points.ndim == 2 and points.shape[1] == 3 and np.isfinite(points).all()
    perm = data.draw(permutations(len(points)))
    assert sorted(perm.tolist()) == list(range(len(points)))


@settings(deadline=None)
@given(unit_vectors(upward=True), planes())
def test_unit_vectors(v: np.ndarray, plane: tuple) -> None:
    assert np.linalg.norm(v) == pytest.approx(1.0) and v[2] >= 0
    assert plane[0][2] >= 0


@settings(max_examples=10, deadline=None)
@given(rigid_motions(max_offset=1e5))
def test_scene_truth_survives_any_motion(motion: tuple) -> None:
    scene = make_building_scene(seed=1, roofs=("gable",), density=2.0)
    m = rigid_motion(scene, *motion)
    for s, e, a, b in zip(m.edges.start, m.edges.end, m.edges.attributes["plane_a"],
                          m.edges.attributes["plane_b"], strict=True):
        for k in (a, b):
            assert np.abs(m.planes[k].distance(np.array([s, e]))).max() < 1e-7


# --------------------------------------------------------------------- scoring


def _fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    c = points.mean(axis=0)
    n = np.linalg.svd(points - c, full_matrices=False)[2][-1]
    return n, float(n @ c)


def _oracle_edges(scene) -> Segments:
    """Edges from planes fitted to the TRUE plane labels: what a perfect segmentation gives."""
    starts, ends = [], []
    for a, b in zip(scene.edges.attributes["plane_a"], scene.edges.attributes["plane_b"],
                    strict=True):
        pa, pb = scene.points[scene.plane_id == a], scene.points[scene.plane_id == b]
        (na, ra), (nb, rb) = _fit(pa), _fit(pb)
        u = np.cross(na, nb)
        u /= np.linalg.norm(u)
        p0 = np.linalg.lstsq(np.array([na, nb, u]), np.array([ra, rb, 0.0]), rcond=None)[0]
        near = np.concatenate([pa, pb])
        w = near - p0
        dist = np.linalg.norm(w - (w @ u)[:, None] * u, axis=1)
        t = (w @ u)[dist < 0.25]
        starts.append(p0 + t.min() * u)
        ends.append(p0 + t.max() * u)
    return Segments(np.arange(len(starts)), np.array(starts), np.array(ends))


def test_oracle_segmentation_meets_the_3cm_target() -> None:
    """With the true labels, plane fits give >= 95 % of edges > 2 m within 3 cm and 70 % overlap."""
    scene = make_building_scene(seed=21, roofs=("flat", "gable") * 2)
    found = _oracle_edges(scene)
    score = score_edges(found, scene.edges)
    assert score.n_true >= 40
    assert score.recall >= 0.95
    assert np.nanmax(score.rms) < 0.03


def test_score_edges_and_corners_criteria() -> None:
    truth = Segments(np.arange(2), [[0, 0, 0], [0, 0, 5]], [[10, 0, 0], [1, 0, 5]],
                     {"kind": np.array(["eave", "ridge"])})
    # offset by 2 cm: found; offset by 4 cm: not; half length: not (overlap 0.5)
    found = Segments(np.arange(3), [[0, 0.02, 0], [0, 0.04, 0], [0, 0, 0]],
                     [[10, 0.02, 0], [10, 0.04, 0], [5, 0, 0]])
    s = score_edges(found, truth)
    assert s.n_true == 1 and s.matched.tolist() == [0]  # the 1 m edge is below min_length
    assert s.rms[0] == pytest.approx(0.02) and s.overlap[0] == pytest.approx(1.0)
    s = score_edges(found.subset([1, 2]), truth)
    assert s.recall == 0.0
    s = score_edges(found, truth, min_length=0.5, kinds=("ridge",))
    assert s.n_true == 1 and s.n_matched == 0
    assert s.to_dict()["recall"] == 0.0
    c = score_corners(PointSet(np.arange(2), [[0, 0, 0.02], [9, 9, 9]]),
                      PointSet(np.arange(2), [[0, 0, 0], [5, 5, 5]]))
    assert c.matched.tolist() == [0, -1] and c.recall == 0.5


def test_checkpoints_are_on_open_terrain() -> None:
    from lidarqa.testing import make_scene

    scene = make_scene(seed=4, size=(80.0, 80.0), embankment=True)
    cp = sample_checkpoints(scene, 60, seed=2)
    assert len(cp) == 60 and cp.ids[0] == "CP0001"
    np.testing.assert_allclose(cp.xyz[:, 2], scene.ground_z(cp.xyz[:, :2]))
    other = scene.points[~scene.is_ground, :2]
    d = np.min(np.linalg.norm(other[None] - cp.xyz[:, None, :2], axis=2), axis=1)
    assert d.min() >= 2.0
