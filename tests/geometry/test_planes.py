"""Plane fits (ALGORITHMS.md §4.1): TLS, explicit z, iterative rejection, RANSAC."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.errors import (
    DataQualityWarning,
    DegenerateGeometryError,
    InvalidPointsError,
    OptionError,
)
from lidarqa.geometry.planes import fit_plane, fit_plane_iterative, plane_covariance, ransac
from lidarqa.testing import cases, rotation_matrix

SPEC_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 0], [0.5, 0.2, 1.0]])


def test_spec_plane_with_outlier() -> None:
    with pytest.warns(DataQualityWarning):
        r = fit_plane_iterative(SPEC_POINTS, rmse_max=0.01)
    assert r.n_iter == 1
    assert r.converged
    assert r.inliers.tolist() == [True] * 5 + [False]
    np.testing.assert_allclose(r.plane.normal, [0, 0, 1], atol=1e-12)
    assert abs(r.plane.rho) < 1e-12
    assert r.plane.rmse < 1e-12


def test_iterative_order_free_and_limits() -> None:
    perm = np.array([5, 2, 0, 4, 1, 3])
    with pytest.warns(DataQualityWarning):
        r = fit_plane_iterative(SPEC_POINTS[perm])
    assert not r.inliers[0] and r.inliers[1:].all()
    rng = np.random.default_rng(1234)
    blob = rng.normal(size=(40, 3))
    r = fit_plane_iterative(blob, rmse_max=1e-6, max_reject_frac=0.25)
    assert not r.converged and "max_reject_frac" in r.reason
    assert r.inliers.sum() == 40 - 10


def test_explicit_z_iterative_and_rank_deficiency() -> None:
    with pytest.warns(DataQualityWarning):
        r = fit_plane_iterative(SPEC_POINTS, model="explicit_z")
    assert r.n_iter == 1
    np.testing.assert_allclose(r.plane.coefficients, [0, 0, 0], atol=1e-12)
    wall = np.array([[0, y, z] for y in range(5) for z in range(5)], dtype=float)
    with pytest.raises(DegenerateGeometryError, match="vertical"):
        fit_plane(wall, method="explicit_z")
    f = fit_plane(wall)  # the orthogonal fit handles walls
    np.testing.assert_allclose(f.normal, [1, 0, 0], atol=1e-12)


@pytest.mark.parametrize("method", ["svd", "eig", "explicit_z"])
def test_fit_known_plane_utm(method: str) -> None:
    rng = np.random.default_rng(1234)
    xy = rng.uniform(0, 20, (2000, 2))
    z = 0.1 * xy[:, 0] - 0.2 * xy[:, 1] + 3 + rng.normal(0, 0.01, 2000)
    p = np.column_stack([xy, z]) + cases.UTM_OFFSET
    f = fit_plane(p, method=method)
    true_n = np.array([-0.1, 0.2, 1.0]) / np.linalg.norm([-0.1, 0.2, 1.0])
    assert np.degrees(np.arccos(min(1, f.normal @ true_n))) < 0.05
    assert abs(f.rmse - 0.01 * (1 if method == "explicit_z" else true_n[2])) < 0.001
    # the plane passes through the true surface at the centroid
    c = f.centroid - cases.UTM_OFFSET
    assert abs(c[2] - (0.1 * c[0] - 0.2 * c[1] + 3)) < 0.003
    assert len(f.residuals) == 2000 and np.isfinite(f.covariance).all()


def test_covariance_matches_monte_carlo() -> None:
    rng = np.random.default_rng(1234)
    xy = rng.uniform(0, 10, (300, 2))
    base = np.column_stack([xy, 0.05 * xy[:, 0]])
    fits = []
    for _ in range(400):
        p = base.copy()
        p[:, 2] += rng.normal(0, 0.02, 300)
        fits.append(fit_plane(p))
    normals = np.array([f.normal for f in fits])
    at = np.array([12.0, 12.0, 0.6])  # outside the data: normal errors matter
    heights = np.array([f.distance(at[None])[0] for f in fits])
    pred_var_n = np.mean([np.diag(f.covariance[:3, :3]) for f in fits], axis=0)
    pred_var_at = np.mean([plane_covariance(f, at) for f in fits])
    np.testing.assert_allclose(normals.var(axis=0)[:2], pred_var_n[:2], rtol=0.25)
    assert abs(heights.var() / pred_var_at - 1) < 0.25


@pytest.mark.parametrize("name", ["collinear", "all_equal", "vertical_line"])
def test_degenerate_point_sets(name: str) -> None:
    with pytest.raises(DegenerateGeometryError):
        fit_plane(getattr(cases, name)())


def test_bad_input() -> None:
    with pytest.raises(InvalidPointsError):
        fit_plane(cases.two_points())
    with pytest.raises(InvalidPointsError):
        fit_plane(cases.with_nan())
    with pytest.raises(OptionError):
        fit_plane(SPEC_POINTS, method="lsq")


def test_ransac_finds_plane_among_outliers() -> None:
    rng = np.random.default_rng(1234)
    xy = rng.uniform(0, 10, (600, 2))
    plane = np.column_stack([xy, 0.3 * xy[:, 1] + rng.normal(0, 0.01, 600)])
    clutter = rng.uniform([0, 0, 0], [10, 10, 5], (400, 3))
    pts = np.vstack([plane, clutter])
    r = ransac(pts, residual_threshold=0.04, seed=3)
    true_n = np.array([0, -0.3, 1.0]) / np.linalg.norm([0, -0.3, 1.0])
    assert np.degrees(np.arccos(min(1, r.plane.normal @ true_n))) < 0.3
    assert r.inliers[:600].mean() > 0.95
    assert r.inliers[600:].mean() < 0.05
    perm = np.random.default_rng(7).permutation(len(pts))
    r2 = ransac(pts[perm], residual_threshold=0.04, seed=3)
    assert np.array_equal(r2.inliers, r.inliers[perm])
    np.testing.assert_allclose(r2.plane.normal, r.plane.normal, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(rot=st.tuples(*[st.floats(-180, 180)] * 3), shift=st.tuples(*[st.floats(-1e5, 1e5)] * 3))
def test_fit_plane_rigid_motion_equivariance(rot: tuple, shift: tuple) -> None:
    pts = cases.tilted_plane(200, seed=1, noise=0.01)
    f = fit_plane(pts)
    r = rotation_matrix(rot)
    g = fit_plane(pts @ r.T + np.array(shift))
    n_moved = r @ f.normal
    assert abs(abs(n_moved @ g.normal) - 1) < 1e-9
    assert abs(g.rmse - f.rmse) < 1e-9
    np.testing.assert_allclose(g.centroid, r @ f.centroid + shift, atol=1e-6)
