"""Least-squares transformations (ALGORITHMS.md §5.1-5.2): spec vectors, Monte Carlo, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.accuracy.transforms import (
    TRANSFORMS,
    estimate_transform,
    euler_angles,
    fit_helmert,
    fit_similarity2d,
    rotation_matrix,
)
from lidarqa.errors import DegenerateGeometryError, InvalidPointsError, LidarQAError, OptionError

SIM_SRC = np.array([(0, 0, 10), (10, 0, 11), (0, 10, 12)], float)
SIM_LIN = np.array([[0.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # a = 0, b = 2
SIM_T = np.array([5.0, -3.0, 1.5])
PERTURB = np.array([(0.01, 0, 0.02), (0, -0.01, 0), (0, 0, -0.02)])

HELMERT_A = np.array([(0, 0, 0), (10, 0, 0), (0, 10, 0), (0, 0, 10), (3, 4, 5)], float)


# ------------------------------------------------------------------ spec vectors


def test_similarity_two_points_exact():
    fit = fit_similarity2d([[0, 0, 0], [10, 0, 1]], [[5, -3, 1.5], [5, 17, 2.5]])
    for k, v in dict(a=0.0, b=2.0, c=5.0, d=-3.0, e=1.5).items():
        assert fit.params[k] == pytest.approx(v, abs=1e-12)
    assert fit.params["scale"] == pytest.approx(2.0)
    assert fit.params["rotation_deg"] == pytest.approx(90.0)
    assert np.abs(fit.residuals).max() < 1e-12
    # no horizontal redundancy: sigmas of a..d undefined, said so
    assert np.isnan(fit.sigmas["a"]) and fit.notes


def test_similarity_three_points_noisy_spec():
    tgt = SIM_SRC @ SIM_LIN.T + SIM_T + PERTURB
    fit = fit_similarity2d(SIM_SRC, tgt)
    expected = dict(a=0.0, b=1.99975, c=5.0025, d=-3.0025, e=1.5)
    for k, v in expected.items():
        assert fit.params[k] == pytest.approx(v, abs=1e-9), k
    rmse = np.sqrt(np.mean(fit.residuals**2, axis=0))
    np.testing.assert_allclose(rmse, [0.0054006, 0.0035355, 0.0163299], atol=5e-8)
    assert np.sqrt(np.sum(rmse**2)) == pytest.approx(0.0175594, abs=5e-8)
    # residuals are model minus target
    np.testing.assert_allclose(fit.apply(SIM_SRC) - tgt, fit.residuals, atol=1e-12)
    # dof = 3n - 5 = 4; sigma0 pools horizontal (dof 2) and vertical (dof 2)
    assert fit.dof == 4
    vv = np.sum(fit.residuals**2)
    assert fit.sigma0 == pytest.approx(np.sqrt(vv / 4))
    assert fit.sigma0_v == pytest.approx(np.sqrt(np.sum(fit.residuals[:, 2] ** 2) / 2))
    # sigma of e = sigma0_v / sqrt(n)
    assert fit.sigmas["e"] == pytest.approx(fit.sigma0_v / np.sqrt(3))


def test_helmert_exact_recovery():
    r0 = rotation_matrix(10.0, 0.0, 30.0)  # R_z(30°)·R_x(10°)
    np.testing.assert_allclose(r0[0], [0.866025, -0.492404, 0.086824], atol=5e-7)
    tgt = np.array([100.0, 200.0, 50.0]) + 1.5 * HELMERT_A @ r0.T
    fit = fit_helmert(HELMERT_A, tgt)
    assert fit.scale == pytest.approx(1.5, abs=1e-12)
    np.testing.assert_allclose(fit.rotation, r0, atol=1e-12)
    np.testing.assert_allclose(fit.translation, [100, 200, 50], atol=1e-12)
    np.testing.assert_allclose(fit.rotation[0], [0.866025, -0.492404, 0.086824], atol=5e-7)
    assert fit.params["kappa_deg"] == pytest.approx(30.0, abs=1e-10)
    assert fit.params["omega_deg"] == pytest.approx(10.0, abs=1e-10)
    assert fit.params["phi_deg"] == pytest.approx(0.0, abs=1e-10)
    assert fit.sigma0 < 1e-12 and fit.dof == 3 * 5 - 7


def test_helmert_fixed_scale_exact_and_utm():
    r0 = rotation_matrix(-2.0, 1.0, 123.0)
    a = HELMERT_A * 7 + np.array([512000.0, 5403000.0, 250.0])
    tgt = np.array([-1000.0, 20.0, 3.0]) + a @ r0.T
    fit = estimate_transform(a, tgt, method="helmert-fixed-scale")
    assert fit.scale == 1.0 and fit.sigmas["scale"] == 0.0
    np.testing.assert_allclose(fit.rotation, r0, atol=1e-12)
    assert np.abs(fit.residuals).max() < 1e-8  # UTM-sized coordinates, no loss
    assert fit.param_names == ("tx", "ty", "tz", "omega_deg", "phi_deg", "kappa_deg")


def test_euler_roundtrip():
    for angles in [(10, 20, 30), (-45, 60, -170), (0, -89, 5)]:
        np.testing.assert_allclose(euler_angles(rotation_matrix(*angles)), angles, atol=1e-9)


def test_none_transform_residuals():
    src = np.array([[0, 0, 0], [1, 2, 3.0]])
    fit = estimate_transform(src, src + [0.1, -0.2, 0.3], method="none")
    np.testing.assert_allclose(fit.residuals, [[-0.1, 0.2, -0.3]] * 2)
    assert fit.params == {} and fit.to_dict()["name"] == "none"


def test_to_dict_keys():
    tgt = SIM_SRC @ SIM_LIN.T + SIM_T + PERTURB
    d = fit_similarity2d(SIM_SRC, tgt).to_dict()
    assert {"name", "params", "sigmas", "sigma0"} <= set(d)
    assert set(d["params"]) == {"a", "b", "c", "d", "e", "scale", "rotation_deg", "tx", "ty", "tz"}


# ------------------------------------------------------------------- Monte Carlo


def _monte_carlo(method, lin, t0, n_trials=1000, noise=0.01, seed=1234, antithetic=False):
    """Estimate ``method`` on ``n_trials`` noisy copies of one exact point set.

    With ``antithetic=True`` every noise draw is used twice, with both signs
    (antithetic variates): the first-order effect of the noise cancels in the
    mean of each pair, so the mean over all estimates differs from the truth only
    by the estimator's own (second-order) bias. Returns ``2 * n_trials`` rows then,
    pairs adjacent.
    """
    rng = np.random.default_rng(seed)
    src = rng.uniform(-50, 50, (8, 3)) + np.array([500000.0, 5400000.0, 300.0])
    tgt = t0 + src @ lin.T
    truth = estimate_transform(src, tgt, method=method)
    names = truth.param_names
    tv = np.array([truth.params[k] for k in names])
    signs = (1.0, -1.0) if antithetic else (1.0,)
    est = np.empty((n_trials * len(signs), len(names)))
    sig = np.empty_like(est)
    for i in range(n_trials):
        eps = rng.normal(0.0, noise, tgt.shape)
        for j, sign in enumerate(signs):
            f = estimate_transform(src, tgt + sign * eps, method=method)
            est[i * len(signs) + j] = [f.params[k] for k in names]
            sig[i * len(signs) + j] = [f.sigmas[k] for k in names]
    return names, tv, est, sig


MC_CASES = {
    "similarity2d": (
        np.array([[0.8, -0.6, 0], [0.6, 0.8, 0], [0, 0, 1]])
        * [[1.0002], [1.0002], [1]],  # a, b; z shift
        np.array([-499000.0, -5399000.0, 20.0]),
    ),
    "helmert": (1.0002 * rotation_matrix(1.0, -2.0, 35.0), np.array([-499000.0, -5399000.0, 20.0])),
    "helmert-fixed-scale": (
        rotation_matrix(1.0, -2.0, 35.0),
        np.array([-499000.0, -5399000.0, 20.0]),
    ),
}


@pytest.mark.parametrize("method", list(MC_CASES))
def test_monte_carlo_unbiased_and_sigmas(method):
    """1000 antithetic pairs of noisy trials: estimates centred on the truth, sigmas honest.

    The issue's criterion, per parameter: the mean of the estimates lies within
    2 standard errors (empirical spread / sqrt(number of estimates)) of the truth.
    Antithetic pairs make this a test of bias alone: a plain Monte Carlo mean
    also moves by chance and, with 5-7 parameters, misses 2 SE in about a quarter
    of the runs (that design is checked over many seeds in
    test_monte_carlo_bias_calibration).
    """
    lin, t0 = MC_CASES[method]
    names, truth, est, sig = _monte_carlo(method, lin, t0, antithetic=True)
    n = len(est)
    spread = est.std(axis=0, ddof=1)
    if method.startswith("helmert"):
        assert truth[5] == pytest.approx(35.0, abs=1e-9)  # noiseless data give the truth back
    z = (est.mean(axis=0) - truth) / (spread / np.sqrt(n))
    assert np.all(np.abs(z) < 2.0), dict(zip(names, z, strict=True))
    # the reported sigma (RMS over trials) matches the empirical spread within 10 %
    reported = np.sqrt(np.mean(sig**2, axis=0))
    ratio = reported / spread
    assert np.all(np.abs(ratio - 1) < 0.10), dict(zip(names, ratio, strict=True))


@pytest.mark.parametrize("method", ["similarity2d", "helmert"])
def test_monte_carlo_bias_calibration(method):
    """Over 10 independent runs of 300 trials the 2-SE criterion holds at its nominal rate."""
    lin, t0 = MC_CASES[method]
    zs = []
    for seed in range(10):
        _, truth, est, _ = _monte_carlo(method, lin, t0, n_trials=300, seed=seed)
        zs.append((est.mean(axis=0) - truth) / (est.std(axis=0, ddof=1) / np.sqrt(len(est))))
    zs = np.array(zs)
    # no bias: the z scores average to ~0 (SE of a 10-run mean is 0.32)
    assert np.all(np.abs(zs.mean(axis=0)) < 1.0), zs.mean(axis=0)
    # within 2 SE in >= 85 % of (run, parameter) cases (nominal 95.4 %)
    assert np.mean(np.abs(zs) < 2.0) >= 0.85, np.abs(zs).max(axis=0)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize("method", ["similarity2d", "helmert", "helmert-fixed-scale"])
def test_one_point_refused(method):
    with pytest.raises(DegenerateGeometryError, match="at least"):
        estimate_transform([[0, 0, 0]], [[1, 1, 1]], method=method)


def test_helmert_two_points_refused():
    with pytest.raises(DegenerateGeometryError, match="at least 3"):
        fit_helmert([[0, 0, 0], [1, 0, 0]], [[0, 0, 0], [1, 0, 0]])


@pytest.mark.parametrize("method", ["helmert", "helmert-fixed-scale"])
def test_collinear_refused(method):
    src = np.column_stack([np.arange(6.0), 2 * np.arange(6.0), 3 * np.arange(6.0)]) + 1e5
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        estimate_transform(src, src + 1, method=method)


def test_similarity_coincident_xy_refused():
    src = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, 5.0], [1.0, 2.0, 9.0]])
    with pytest.raises(DegenerateGeometryError, match="coincide"):
        fit_similarity2d(src, src)


def test_similarity_collinear_is_fine():
    # a 2D similarity is determined by two distinct points, so collinear points are fine
    src = np.column_stack([np.arange(5.0), np.arange(5.0), np.zeros(5)])
    fit = fit_similarity2d(src, src * [2, 2, 1] + 1)
    assert fit.params["scale"] == pytest.approx(2.0)


def test_nan_and_shape_refused():
    src = np.array([[0, 0, 0], [1, 0, 0], [0, 1, np.nan]])
    with pytest.raises(InvalidPointsError, match="NaN"):
        estimate_transform(src, np.zeros((3, 3)), method="helmert")
    with pytest.raises(InvalidPointsError, match="same number"):
        estimate_transform(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(OptionError, match="method"):
        estimate_transform(np.zeros((3, 3)), np.zeros((3, 3)), method="affine")


def test_errors_are_lidarqa_errors():
    assert all(issubclass(e, LidarQAError) for e in (DegenerateGeometryError, InvalidPointsError))
    assert set(TRANSFORMS) == {"none", "similarity2d", "helmert", "helmert-fixed-scale"}


def test_order_independence():
    rng = np.random.default_rng(5)
    src = rng.uniform(0, 100, (10, 3))
    tgt = 3 + 1.01 * src @ rotation_matrix(2, 3, 40).T + rng.normal(0, 0.01, src.shape)
    perm = rng.permutation(10)
    for m in ("similarity2d", "helmert"):
        f1 = estimate_transform(src, tgt, method=m)
        f2 = estimate_transform(src[perm], tgt[perm], method=m)
        for k in f1.params:
            assert f1.params[k] == pytest.approx(f2.params[k], rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(f1.residuals[perm], f2.residuals, atol=1e-10)


def test_random_exact_transforms_recovered():
    """50 random exact Helmert and similarity transformations are recovered exactly."""
    rng = np.random.default_rng(99)
    for _ in range(50):
        src = rng.uniform(-100, 100, (int(rng.integers(3, 12)), 3)) + rng.uniform(-1e6, 1e6, 3)
        angles = rng.uniform([-30, -30, -180], [30, 30, 180])
        s, t = rng.uniform(0.5, 2.0), rng.uniform(-1e5, 1e5, 3)
        fit = fit_helmert(src, t + s * src @ rotation_matrix(*angles).T)
        np.testing.assert_allclose(
            [fit.params[k] for k in ("omega_deg", "phi_deg", "kappa_deg")], angles, atol=1e-7
        )
        assert fit.scale == pytest.approx(s, rel=1e-10)
        np.testing.assert_allclose(fit.translation, t, rtol=0, atol=1e-4 * max(1.0, s))
        assert np.abs(fit.residuals).max() < 1e-6
        k = angles[2]
        a, b = s * np.cos(np.radians(k)), s * np.sin(np.radians(k))
        lin = np.array([[a, -b, 0], [b, a, 0], [0, 0, 1]])
        fit2 = fit_similarity2d(src, t + src @ lin.T)
        assert fit2.params["rotation_deg"] == pytest.approx(k, abs=1e-8)
        assert fit2.params["scale"] == pytest.approx(s, rel=1e-10)
        assert fit2.params["e"] == pytest.approx(t[2], abs=1e-6)


# ------------------------------------------------ parameters about the centroid


def _survey_case(seed=16, noise=0.01):
    """5 control points within 150 m on a national grid, a small known Helmert."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 150, (5, 3)) * [1, 1, 0.2] + [770400.0, 6277500.0, 20.0]
    r0 = rotation_matrix(0.002, -0.003, 0.01)
    s0, t0 = 1.00004, np.array([1.2, -0.8, 0.35])
    exact = t0 + s0 * src @ r0.T
    tgt = exact + rng.normal(0, noise, src.shape)
    # the same transformation written about the source centroid X0
    x0 = src.mean(axis=0)
    t_centroid = t0 + (s0 * r0 - np.eye(3)) @ x0
    return src, tgt, x0, t_centroid


@pytest.mark.parametrize("method", ["helmert", "helmert-fixed-scale"])
def test_helmert_translation_about_centroid_has_cm_sigma(method):
    src, tgt, x0, t_centroid = _survey_case()
    fit = estimate_transform(src, tgt, method=method)
    t = np.array([fit.params[k] for k in ("tx", "ty", "tz")])
    sig = np.array([fit.sigmas[k] for k in ("tx", "ty", "tz")])
    shift = tgt.mean(axis=0) - src.mean(axis=0)
    np.testing.assert_allclose(fit.origin, x0, atol=1e-9)
    # within metres (in fact millimetres) of the centroid shift, with cm sigmas
    assert np.abs(t - shift).max() < 1.0
    assert np.all(sig < 0.05) and np.all(sig > 0)
    if method == "helmert":
        np.testing.assert_allclose(t, t_centroid, atol=4 * sig.max())
    # the same transformation: both forms map the control points identically
    np.testing.assert_allclose(x0 + t + (src - x0) @ fit.linear.T, fit.apply(src), atol=1e-6)
    d = fit.to_dict()
    assert d["origin"] == pytest.approx(dict(zip("xyz", x0, strict=True)))
    assert d["translation_at_coordinate_origin"] == pytest.approx(fit.translation.tolist())


def test_helmert_centroid_sigma_matches_monte_carlo():
    """σ(tx, ty, tz) about the centroid are the spread of the estimates."""
    src, tgt, *_ = _survey_case(noise=0.0)
    rng = np.random.default_rng(3)
    est, sig = [], []
    for _ in range(300):
        f = fit_helmert(src, tgt + rng.normal(0, 0.01, tgt.shape))
        est.append([f.params[k] for k in ("tx", "ty", "tz")])
        sig.append([f.sigmas[k] for k in ("tx", "ty", "tz")])
    ratio = np.std(est, axis=0) / np.sqrt(np.mean(np.square(sig), axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio


def test_similarity2d_translation_about_centroid():
    src, tgt, x0, _ = _survey_case()
    fit = fit_similarity2d(src, tgt)
    shift = tgt.mean(axis=0) - src.mean(axis=0)
    np.testing.assert_allclose([fit.params[k] for k in ("tx", "ty", "tz")], shift, atol=1e-9)
    assert max(fit.sigmas[k] for k in ("tx", "ty", "tz")) < 0.05
    # the paper's c, d at the coordinate origin carry the rotation lever arm
    assert fit.sigmas["c"] > 10 * fit.sigmas["tx"]
    np.testing.assert_allclose(fit.origin, x0)
