"""Check-point statistics, ASPRS Ed. 2 / NSSDA figures, matching, assessment (§5.3)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.accuracy.checkpoints import (
    asprs2023_accuracy,
    assess_checkpoints,
    match_points,
    nssda_accuracy,
    residual_statistics,
    rmse_3d,
)
from lidarqa.accuracy.transforms import rotation_matrix
from lidarqa.errors import DegenerateGeometryError, InvalidPointsError, OptionError
from lidarqa.io.vector import PointSet

# [S-FH] Tables 1-2: (E, N, H) RMSE -> P-RMSE computed (ALGORITHMS.md §5.3) and as reported
FH_TABLES = {
    "A before": ((0.045, 0.019, 0.010), 0.04986, 0.050),
    "A after": ((0.048, 0.048, 0.040), 0.07879, 0.079),
    "B before": ((0.026, 0.034, 0.028), 0.05115, 0.052),
    "B after": ((0.086, 0.083, 0.045), 0.12771, 0.128),
    "System A": ((0.071, 0.063, 0.034), 0.10083, 0.101),
    "System B": ((0.037, 0.041, 0.034), 0.06485, 0.065),
    "System C": ((0.036, 0.029, 0.022), 0.05120, 0.051),
}


@pytest.mark.parametrize("case", list(FH_TABLES))
def test_p_rmse_fang_huang_tables(case):
    enh, computed, reported = FH_TABLES[case]
    p = rmse_3d(*enh)
    assert p == pytest.approx(computed, abs=5e-6)
    assert p == pytest.approx(reported, abs=0.001)
    # the horizontal-only version does not reproduce the table (spec: A before gives 0.0488)
    if case == "A before":
        assert np.hypot(enh[0], enh[1]) == pytest.approx(0.0488, abs=1e-4)


def test_residual_statistics_per_axis():
    r = np.array([(0.01, 0.0, 0.02), (0.0, -0.01, 0.0), (0.0, 0.0, -0.02), (0.03, 0.02, 0.05)])
    s = residual_statistics(r)
    np.testing.assert_allclose(s.mean, r.mean(axis=0))
    np.testing.assert_allclose(s.std, r.std(axis=0, ddof=1))
    np.testing.assert_allclose(s.rmse, np.sqrt((r**2).mean(axis=0)))
    np.testing.assert_allclose(s.max_abs, [0.03, 0.02, 0.05])
    assert s.rmse_h == pytest.approx(np.hypot(s.rmse[0], s.rmse[1]))
    assert s.rmse_3d == pytest.approx(np.sqrt(np.sum(s.rmse**2)))
    s1 = residual_statistics(r, ddof=1)
    np.testing.assert_allclose(s1.rmse, np.sqrt((r**2).sum(axis=0) / 3))
    d = s.to_dict()
    assert {
        "rmse_x",
        "rmse_y",
        "rmse_z",
        "rmse_h",
        "rmse_3d",
        "mean_x",
        "std_z",
        "max_abs_y",
    } <= set(d)


def test_nssda_formulas():
    # equal RMSE: 1.7308·RMSE_r = 2.4477·RMSE_x, and the exact 95 % radius agrees
    a = nssda_accuracy(0.03, 0.03, 0.05, n_check=25)
    assert a.accuracy_r == pytest.approx(1.7308 * np.hypot(0.03, 0.03))
    assert a.accuracy_r == pytest.approx(2.4477 * 0.03, rel=1e-4)
    assert a.accuracy_r_exact == pytest.approx(2.4477 * 0.03, rel=1e-4)
    assert a.accuracy_z == pytest.approx(1.96 * 0.05)
    assert "1.7308" in a.formula and not a.warnings
    # within 5 %: "RMSE_x ≈ RMSE_y", the NSSDA's 1.7308·RMSE_r
    near = nssda_accuracy(0.031, 0.030, np.nan, n_check=25)
    assert "1.7308" in near.formula
    assert near.accuracy_r == pytest.approx(1.7308 * np.hypot(0.031, 0.03))
    # 0.6 <= ratio < 0.95: the NSSDA approximation 2.4477·½(x+y), no warning
    b = nssda_accuracy(0.05, 0.03, np.nan, n_check=25)
    assert b.ratio == pytest.approx(0.6) and "2.4477" in b.formula and not b.warnings
    assert b.accuracy_r == pytest.approx(2.4477 * 0.5 * 0.08)
    # ... which stays within 6 % of the exact 95 % radius in the range the NSSDA allows it
    assert b.accuracy_r == pytest.approx(b.accuracy_r_exact, rel=0.06)
    # ratio < 0.6: the other formula, named, with a warning
    c = nssda_accuracy(0.05, 0.02, 0.01, n_check=25)
    assert c.accuracy_r == pytest.approx(2.4477 * 0.5 * 0.07)
    assert "2.4477" in c.formula and any("0.6" in w for w in c.warnings)
    # the exact bivariate-normal radius lies between the one-axis and equal-axes limits
    assert 1.96 * 0.05 < c.accuracy_r_exact < 2.4477 * 0.05
    # fewer than 20 check points
    assert any("20" in w for w in nssda_accuracy(0.01, 0.01, 0.01, n_check=19).warnings)


def test_nssda_exact_radius_monte_carlo():
    rng = np.random.default_rng(3)
    sx, sy = 0.04, 0.015
    e = rng.normal(0, [sx, sy], size=(400_000, 2))
    empirical = np.quantile(np.hypot(e[:, 0], e[:, 1]), 0.95)
    assert nssda_accuracy(sx, sy, 0.0).accuracy_r_exact == pytest.approx(empirical, rel=0.01)


def test_asprs2023_checkpoint_accuracy_folded_in():
    a = asprs2023_accuracy(
        0.03, 0.04, 0.12, n_check=40, checkpoint_rmse_h=0.02, checkpoint_rmse_v=0.05
    )
    assert a.rmse_h1 == pytest.approx(0.05)
    assert a.rmse_h == pytest.approx(np.sqrt(0.05**2 + 0.02**2))
    assert a.rmse_v == pytest.approx(0.13)
    assert a.rmse_3d == pytest.approx(np.sqrt(a.rmse_h**2 + a.rmse_v**2))
    assert not a.warnings
    few = asprs2023_accuracy(0.03, 0.04, 0.12, n_check=29)
    assert any("30" in w for w in few.warnings)
    assert any("not included" in w for w in few.warnings)
    with pytest.raises(OptionError):
        asprs2023_accuracy(0.1, 0.1, 0.1, n_check=30, checkpoint_rmse_v=-1)


# ------------------------------------------------------------------ matching


def _ps(ids, xyz):
    return PointSet(ids=np.asarray(ids), xyz=np.asarray(xyz, dtype=float))


def test_match_by_id_reports_unmatched():
    chk = _ps([1, 2, 3, 4], [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    mea = _ps(["4", "2", "9"], [[3, 0, 0], [1, 0, 0], [9, 9, 9]])
    m = match_points(mea, chk)
    assert chk.ids[m.check_index].tolist() == [2, 4]
    assert mea.ids[m.measured_index].tolist() == ["2", "4"]
    assert m.unmatched_check == [1, 3] and m.unmatched_measured == ["9"]


def test_match_nearest_one_to_one_within_max_distance():
    chk = _ps(["a", "b", "c"], [[0, 0, 0], [10, 0, 0], [50, 0, 0]])
    mea = _ps([7, 8, 9], [[0.2, 0, 0], [0.1, 0, 0], [10.3, 0, 0]])
    m = match_points(mea, chk, match="nearest", max_distance=1.0)
    pairs = {chk.ids[c]: mea.ids[i] for c, i in zip(m.check_index, m.measured_index, strict=True)}
    assert pairs == {"a": 8, "b": 9}  # a takes the closer one; 7 is left over, c has no partner
    assert m.unmatched_measured == [7] and m.unmatched_check == ["c"]
    # input order does not matter
    m2 = match_points(
        mea.subset([2, 0, 1]), chk.subset([2, 1, 0]), match="nearest", max_distance=1.0
    )
    assert sorted(m2.distance.tolist()) == sorted(m.distance.tolist())


# ---------------------------------------------------------------- assessment


def _survey(n=40, seed=0, noise=0.01):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, 100, (n, 3)) + [600000.0, 4500000.0, 100.0]
    ids = np.array([f"P{i:02d}" for i in range(n)])
    return rng, ids, xyz


def test_assess_none_recovers_known_bias():
    rng, ids, chk = _survey()
    mea = chk + [0.05, -0.03, 0.10] + rng.normal(0, 0.01, chk.shape)
    rep = assess_checkpoints(_ps(ids, mea), _ps(ids, chk), checkpoint_rmse_v=0.02)
    assert rep.n_check == 40 and rep.n_control == 0
    np.testing.assert_allclose(rep.stats.mean, [0.05, -0.03, 0.10], atol=0.005)
    np.testing.assert_allclose(rep.stats.std, 0.01, rtol=0.3)
    assert rep.asprs2023.rmse_v == pytest.approx(np.hypot(rep.stats.rmse[2], 0.02))
    d = rep.to_dict()
    for key in (
        "n_check",
        "n_control",
        "transform",
        "rmse_x",
        "rmse_y",
        "rmse_z",
        "rmse_h",
        "rmse_3d",
        "mean_x",
        "mean_y",
        "mean_z",
        "std_x",
        "std_y",
        "std_z",
        "max_abs_x",
        "max_abs_y",
        "max_abs_z",
        "nssda",
        "asprs2023",
        "residuals",
    ):
        assert key in d, key
    assert {"name", "params", "sigmas", "sigma0"} <= set(d["transform"])
    assert {"accuracy_r", "accuracy_z", "formula"} <= set(d["nssda"])
    assert {"rmse_h", "rmse_v", "rmse_3d", "n_check", "warnings"} <= set(d["asprs2023"])
    assert d["residuals"][0].keys() >= {"id", "dx", "dy", "dz", "role"}
    assert d["residuals"][0]["dz"] == pytest.approx(mea[0, 2] - chk[0, 2])


@pytest.mark.parametrize("method", ["similarity2d", "helmert"])
def test_assess_transform_control_vs_check(method):
    rng, ids, chk = _survey(n=40, seed=1)
    # measured in a local scanner frame: inverse of a known transformation, plus noise
    r = (
        rotation_matrix(0.0, 0.0, 25.0)
        if method == "similarity2d"
        else rotation_matrix(0.3, -0.2, 25.0)
    )
    local = (chk - [600050.0, 4500050.0, 0.0]) @ r + [10.0, 20.0, -90.0]
    mea = local + rng.normal(0, 0.01, chk.shape)
    control = ids[:8]
    rep = assess_checkpoints(_ps(ids, mea), _ps(ids, chk), transform=method, control_ids=control)
    assert rep.n_control == 8 and rep.n_check == 32
    assert set(rep.role[:8]) == {"control"} and set(rep.role[8:]) == {"check"}
    # after the transformation the check residuals are noise-sized
    assert rep.stats.rmse_3d < 0.05
    assert rep.transform.n_points == 8 and rep.transform.sigma0 == pytest.approx(0.01, rel=0.5)
    rot = rep.transform.params["rotation_deg" if method == "similarity2d" else "kappa_deg"]
    assert rot == pytest.approx(25.0, abs=0.05)
    assert rep.control_stats is not None and rep.control_stats.n == 8
    # without control ids everything is control and check, with a warning
    rep2 = assess_checkpoints(_ps(ids, mea), _ps(ids, chk), transform=method)
    assert rep2.n_check == rep2.n_control == 40
    assert any("optimistic" in w for w in rep2.warnings)


def test_assess_warns_below_minimum_counts():
    rng, ids, chk = _survey(n=12)
    rep = assess_checkpoints(_ps(ids, chk + 0.01), _ps(ids, chk))
    assert any("ASPRS" in w and "30" in w for w in rep.warnings)
    assert any("NSSDA" in w and "20" in w for w in rep.warnings)


# ------------------------------------------------------------------ bad input


def test_bad_input_one_point_for_transform():
    with pytest.raises(DegenerateGeometryError, match="at least 2"):
        assess_checkpoints(_ps([1], [[0, 0, 0]]), _ps([1], [[0, 0, 0.1]]), transform="similarity2d")


def test_bad_input_duplicate_ids():
    with pytest.raises(InvalidPointsError, match="duplicate id"):
        assess_checkpoints(_ps([1, 1], [[0, 0, 0], [1, 1, 1]]), _ps([1, 2], [[0, 0, 0], [1, 1, 1]]))


def test_bad_input_ids_do_not_match():
    with pytest.raises(InvalidPointsError, match="no ids in common.*nearest"):
        assess_checkpoints(
            _ps([1, 2], [[0, 0, 0], [1, 1, 1]]), _ps(["a", "b"], [[0, 0, 0], [1, 1, 1]])
        )
    with pytest.raises(InvalidPointsError, match="control id"):
        assess_checkpoints(
            _ps([1, 2, 3], np.eye(3)),
            _ps([1, 2, 3], np.eye(3)),
            transform="similarity2d",
            control_ids=[1, 99],
        )


def test_bad_input_collinear_control():
    _, ids, chk = _survey(n=10)
    line = np.column_stack([np.arange(10.0), np.arange(10.0), np.arange(10.0)])
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        assess_checkpoints(
            _ps(ids, line), _ps(ids, line + 0.01), transform="helmert", control_ids=ids[:4]
        )


def test_bad_input_nan():
    with pytest.raises(InvalidPointsError, match="NaN"):
        assess_checkpoints(
            _ps([1, 2], [[0, 0, np.nan], [1, 1, 1]]), _ps([1, 2], [[0, 0, 0], [1, 1, 1]])
        )


def test_bad_input_no_check_left_and_options():
    with pytest.raises(InvalidPointsError, match="no check points left"):
        assess_checkpoints(
            _ps([1, 2, 3], np.eye(3)),
            _ps([1, 2, 3], np.eye(3)),
            transform="similarity2d",
            control_ids=[1, 2, 3],
        )
    with pytest.raises(OptionError):
        assess_checkpoints(_ps([1], [[0, 0, 0]]), _ps([1], [[0, 0, 0]]), transform="affine")
    with pytest.raises(OptionError):
        assess_checkpoints(_ps([1], [[0, 0, 0]]), _ps([1], [[0, 0, 0]]), match="closest")
