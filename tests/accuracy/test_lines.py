"""Line-segment matching and modified LHD (ALGORITHMS.md §3; Poreba & Goulette 2013)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from lidarqa.accuracy import _lines_kernels as K
from lidarqa.accuracy._lines_synthetic import make_segment_sets
from lidarqa.accuracy.lines import (
    auto_threshold,
    detection_rate,
    hausdorff,
    match_segments,
    olhd,
    primary_lhd,
    segment_distance,
    segment_distances,
)
from lidarqa.errors import (
    CRSMismatchError,
    DegenerateGeometryError,
    InvalidPointsError,
    LidarQAError,
    OptionError,
)
from lidarqa.io.vector import Segments

MODEL = [[0, 0, 0], [10, 0, 0]]

# ---------------------------------------------------------------- §3.1 vectors

SIX = [
    ([[2, 1, 0], [6, 1, 0]], 0, 0, 1, 1.0),
    ([[6, 1, 0], [2, 1, 0]], 0, 0, 1, 1.0),
    ([[12, 0, 1], [16, 0, 1]], 0, 6, 1, math.sqrt(37)),
    ([[8, 0, 2], [14, 0, 2]], 0, 4, 2, math.sqrt(20)),
    ([[4, -1, 0], [6, 1, 0]], 2, 0, 0, math.sqrt(40)),
    ([[3, 0, 1], [3, 4, 1]], 4, 0, math.sqrt(5), math.sqrt(165)),
]


@pytest.mark.parametrize(("t", "d_theta", "d_par", "d_perp", "d"), SIX)
@pytest.mark.parametrize("rotate", ["shorter", "test"])
def test_six_segment_pair_distances(t, d_theta, d_par, d_perp, d, rotate):
    got = segment_distance(t, MODEL, weight=10, rotate=rotate)
    assert got == pytest.approx((d_theta, d_par, d_perp, d), abs=1e-9)
    # with "shorter" the model→test distance is the same
    assert segment_distance(MODEL, t)[3] == pytest.approx(d, abs=1e-9)


def test_numba_kernel_matches_reference_on_vectors():
    t = np.array([x[0] for x in SIX], float)
    m = np.array([MODEL] * len(SIX), float)
    ct, ut, lt = K.prepare(t[:, 0], t[:, 1], np.zeros(3))
    cm, um, lm = K.prepare(m[:, 0], m[:, 1], np.zeros(3))
    k = np.arange(len(SIX))
    out = K.pair_distances(ct, ut, lt, cm, um, lm, k, k, weight=10.0, rotate_test=False)
    assert out == pytest.approx(np.array([x[1:] for x in SIX], float), abs=1e-9)


def test_weight_multiplies_squared_angle_distance():
    t = [[4, -1, 0], [6, 1, 0]]  # dθ = 2, d∥ = d⊥ = 0
    assert segment_distance(t, MODEL, weight=1)[3] == pytest.approx(2.0)
    assert segment_distance(t, MODEL, weight=0)[3] == pytest.approx(0.0)


def test_rotate_test_is_asymmetric_and_rotates_the_test_segment():
    long_t = [[0, 1, 0], [20, 1.5, 0]]  # the test segment is the longer one
    m = [[8, 0, 0], [12, 0, 0]]
    shorter = segment_distance(long_t, m, rotate="shorter")
    test = segment_distance(long_t, m, rotate="test")
    # rotate="test": the (longer) test segment is turned parallel to the model about (10, 1.25)
    assert test[2] == pytest.approx(1.25)
    # rotate="shorter": the model segment is turned parallel to the test one:
    # d⊥ = distance of (10, 0) to the test line
    u = np.array([20, 0.5, 0]) / np.hypot(20, 0.5)
    w = np.array([10, 0, 0]) - np.array([0, 1, 0])
    assert shorter[2] == pytest.approx(np.linalg.norm(w - (w @ u) * u))
    assert test[3] != pytest.approx(segment_distance(m, long_t, rotate="test")[3])


# ---------------------------------------------------------------- §3.2 vectors


def test_knee_with_peak():
    r = auto_threshold([0.10, 0.12, 0.15, 0.18, 0.20, 1.50, 1.60, 2.0], sensitivity=0.1)
    assert r.second_diff == pytest.approx([0.01, 0, -0.01, 1.28, -1.20, 0.30], abs=1e-12)
    assert r.peak_index == 3
    assert r.threshold == pytest.approx(0.20)
    assert r.found


def test_knee_end_jump():
    r = auto_threshold([0.1, 0.11, 0.12, 0.13, 5.0])
    assert r.threshold == pytest.approx(0.13) and r.found


def test_knee_none_falls_back():
    r = auto_threshold([0.1, 0.2, 0.3])
    assert r.threshold == pytest.approx(0.3) and not r.found and r.reason == "no peak"


def test_knee_order_free_and_few_values():
    r = auto_threshold([2.0, 0.10, 1.6, 0.15, 0.12, 0.18, 1.5, 0.20])
    assert r.threshold == pytest.approx(0.20)
    r2 = auto_threshold([0.4, 0.1])
    assert r2.threshold == pytest.approx(0.4) and not r2.found and r2.reason == "too few segments"


# ---------------------------------------------------------------- §3.3 vectors

T_TOY = np.array(
    [[(0, 0.2, 0), (10, 0.2, 0)], [(0, 5, 0), (0, 5, 3)], [(20, 20, 0), (25, 20, 0)]], float
)
M_TOY = np.array(
    [[(0, 0, 0), (10, 0, 0)], [(0, 5.3, 0), (0, 5.3, 4)], [(0, 10, 0), (4, 10, 0)]], float
)


def test_olhd_toy():
    d = segment_distances(T_TOY, M_TOY)[3]
    assert d == pytest.approx(
        np.array([[0.2, 13.928747, 9.8], [10.931606, 0.3, 10.931606], [25.0, 29.395408, 22.36068]]),
        abs=1e-6,
    )
    cor = np.zeros((3, 3), bool)
    cor[0, 0] = cor[1, 1] = True
    r = match_segments(T_TOY, M_TOY, ground_truth=cor)
    assert r.threshold_tm == pytest.approx(0.3) and r.threshold_mt == pytest.approx(0.3)
    assert r.threshold_found_tm and r.threshold_found_mt
    ti, mi, _ = r.pairs_tm()
    assert list(zip(ti.tolist(), mi.tolist(), strict=True)) == [(0, 0), (1, 1)]
    ti, mi, _ = r.pairs_mt()
    assert list(zip(ti.tolist(), mi.tolist(), strict=True)) == [(0, 0), (1, 1)]
    assert r.olhd_tm == pytest.approx((10 * 0.2 + 4 * 0.3) / 14)
    assert r.olhd_tm == pytest.approx(0.228571, abs=1e-6)
    assert r.olhd_mt == pytest.approx(0.223077, abs=1e-6)
    assert r.lhd == pytest.approx(0.228571, abs=1e-6)
    assert r.ground_truth["detection_rate_tm"] == 1.0 and r.ground_truth["detection_rate_mt"] == 1.0
    assert (r.ground_truth["tp_tm"], r.ground_truth["tn_tm"]) == (2, 7)
    r_all = match_segments(T_TOY, M_TOY, denominator="all")
    assert r_all.olhd_tm == pytest.approx(3.2 / 18)
    assert r_all.olhd_tm == pytest.approx(0.177778, abs=1e-6)
    # baselines: nearest distances exact, Gao–Leung primary LHD, classic OHD with d
    assert r.nearest_tm == pytest.approx([0.2, 0.3, 22.36068], abs=1e-5)
    assert r.nearest_mt == pytest.approx([0.2, 0.3, 9.8], abs=1e-9)
    assert r.gao_leung_tm == pytest.approx((10 * 0.2 + 3 * 0.3 + 5 * 22.360680) / 18, abs=1e-5)
    assert r.hausdorff_tm == pytest.approx(22.36068, abs=1e-5) and r.hausdorff_mt == pytest.approx(
        9.8
    )


def test_to_dict_keys_exact():
    r = match_segments(T_TOY, M_TOY)
    base = {
        "p",
        "q",
        "threshold_tm",
        "threshold_mt",
        "olhd_tm",
        "olhd_mt",
        "lhd",
        "n_pairs_tm",
        "n_pairs_mt",
        "threshold_found_tm",
        "threshold_found_mt",
    }
    assert set(r.to_dict()) == base
    gt = [(0, 0), (1, 1)]
    extra = {f"{k}_{s}" for k in ("tp", "fp", "fn", "tn", "detection_rate") for s in ("tm", "mt")}
    assert set(match_segments(T_TOY, M_TOY, ground_truth=gt).to_dict()) == base | extra


def test_olhd_helpers():
    assert olhd([0.2, 0.3], [10, 4]) == pytest.approx(3.2 / 14)
    assert olhd([0.2, 0.3], [10, 4], total_weight=18) == pytest.approx(3.2 / 18)
    assert math.isnan(olhd([], []))
    assert primary_lhd([1.0, 3.0], [1.0, 1.0]) == pytest.approx(2.0)
    a = np.array([[0.0, 0, 0], [1, 0, 0]])
    b = np.array([[0.0, 0, 0], [4, 0, 0]])
    assert hausdorff(a, b) == pytest.approx((1.0, 3.0, 3.0))
    assert hausdorff(a, b, metric=lambda x, y: float(np.abs(x - y).sum())) == pytest.approx(
        (1.0, 3.0, 3.0)
    )


# [S-PG] Tables 1–2: (p, q, FN, FP, computed DR %, reported %)
TABLES = [
    (36, 28, 0, 1, 99.9008, 99.90),
    (36, 28, 1, 2, 99.7024, 99.70),
    (36, 41, 2, 5, 99.5257, 99.53),
    (33, 32, 2, 2, 99.6212, 99.62),
    (33, 32, 2, 3, 99.5265, 99.53),
    (28, 41, 1, 2, 99.7387, 99.74),
    (36, 64, 1, 9, 99.5660, 99.57),
    (36, 64, 1, 8, 99.6094, 99.61),
    (28, 64, 2, 10, 99.3304, 99.33),
    (28, 64, 2, 18, 98.8839, 98.88),
    (41, 64, 2, 7, 99.6570, 99.66),
    (41, 64, 2, 9, 99.5808, 99.54),  # does not reproduce: 99.54 would need FN + FP = 12
]


@pytest.mark.parametrize(("p", "q", "fn", "fp", "computed", "reported"), TABLES)
def test_detection_rates_of_seed_tables(p, q, fn, fp, computed, reported):
    dr = 100 * detection_rate(p, q, fn, fp)
    assert dr == pytest.approx(computed, abs=5e-5)
    if (p, q, fn, fp) == (41, 64, 2, 9):
        assert round(dr, 2) != reported  # the discrepancy recorded in ALGORITHMS.md §3.3
        assert 100 * detection_rate(p, q, 2, 10) == pytest.approx(99.54, abs=5e-3)
    else:
        assert round(dr, 2) == reported


# ---------------------------------------------------------------- synthetic truth


@pytest.mark.parametrize(("seed", "noise", "n"), [(0, 0.02, 400), (1, 0.05, 400), (2, 0.02, 1500)])
def test_synthetic_known_pairing_detection_rate(seed, noise, n):
    s = make_segment_sets(n_model=n, seed=seed, noise=noise)
    r = match_segments(s.test, s.model, ground_truth=s.truth_ids())
    g = r.ground_truth
    assert g["detection_rate_tm"] >= 0.995 and g["detection_rate_mt"] >= 0.995
    # and stronger than the rate: almost every true pair found, few false ones
    n_true = len(s.truth)
    assert g["tp_tm"] >= 0.98 * n_true and g["tp_mt"] >= 0.98 * n_true
    assert g["fp_tm"] <= 0.02 * n_true and g["fp_mt"] <= 0.02 * n_true
    assert r.threshold_found_tm and r.threshold_found_mt
    # the LHD reflects the applied offset (~0.1 m motion + noise), well below the threshold
    assert 0.0 < r.lhd < r.threshold_tm


def test_synthetic_with_large_offset_and_utm_coordinates():
    s = make_segment_sets(
        n_model=300, seed=3, translation=(1.5, -1.0, 0.4), origin=(770000.0, 6277000.0, 50.0)
    )
    r = match_segments(s.test, s.model, ground_truth=s.truth_ids())
    assert (
        r.ground_truth["detection_rate_tm"] >= 0.995
        and r.ground_truth["detection_rate_mt"] >= 0.995
    )
    assert r.cutoff >= max(r.threshold_tm, r.threshold_mt) > 1.0  # the cutoff was raised to δ


def test_synthetic_from_building_scene_edges():
    from lidarqa.testing import make_building_scene, rigid_motion

    scene = make_building_scene(seed=4)
    model = scene.edges
    assert len(model) >= 6
    centre = model.start.mean(axis=0)
    moved = rigid_motion(model, (0.0, 0.0, 0.2), (0.1, 0.05, 0.02), center=centre)
    rng = np.random.default_rng(1234)
    test = Segments(
        moved.ids,
        moved.start + rng.normal(0, 0.02, moved.start.shape),
        moved.end + rng.normal(0, 0.02, moved.end.shape),
    )
    truth = [(i, i) for i in model.ids.tolist()]
    r = match_segments(test, model, ground_truth=truth)
    g = r.ground_truth
    assert g["detection_rate_tm"] >= 0.995 and g["detection_rate_mt"] >= 0.995
    assert g["tp_tm"] == len(model) and g["tp_mt"] == len(model)


# ---------------------------------------------------------------- pruning == dense


def _random_sets(rng, p, q, extent=30.0, lmax=8.0):
    def make(n):
        c = rng.uniform(0, extent, (n, 3))
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        length = rng.uniform(0.3, lmax, n)
        return np.stack([c - 0.5 * length[:, None] * u, c + 0.5 * length[:, None] * u], axis=1)

    return make(p), make(q)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("rotate", ["shorter", "test"])
def test_pruned_equals_dense(seed, rotate):
    rng = np.random.default_rng(1234 + seed)
    t, m = _random_sets(rng, 60 + 10 * seed, 50)
    # half of the test set near the model, so there is a knee
    t[:30] = m[:30] + rng.normal(0, 0.05, (30, 2, 3))
    dense = match_segments(t, m, rotate=rotate, cutoff=1e6)  # every pair evaluated
    assert len(dense.pair_test) == len(t) * len(m)
    for cutoff in (None, 0.05, 0.5, 3.0):
        r = match_segments(t, m, rotate=rotate, cutoff=cutoff)
        assert len(r.pair_test) < len(dense.pair_test) or cutoff == 3.0
        np.testing.assert_array_equal(r.nearest_tm, dense.nearest_tm)
        np.testing.assert_array_equal(r.nearest_mt, dense.nearest_mt)
        np.testing.assert_array_equal(r.nearest_model, dense.nearest_model)
        assert r.threshold_tm == dense.threshold_tm and r.threshold_mt == dense.threshold_mt
        assert r.to_dict() == dense.to_dict()
        for get in ("pairs_tm", "pairs_mt"):
            a, b = getattr(r, get)(), getattr(dense, get)()
            for x, y in zip(a, b, strict=True):
                np.testing.assert_array_equal(x, y)
    # and the kernel agrees with the plain-NumPy dense reference
    d = segment_distances(t, m, rotate=rotate)[3]
    dd = np.full(d.shape, np.nan)
    dd[dense.pair_test, dense.pair_model] = dense.pair_d_tm
    np.testing.assert_allclose(dd, d, rtol=0, atol=1e-9)
    dmt = segment_distances(m, t, rotate=rotate)[3]
    dd[dense.pair_test, dense.pair_model] = dense.pair_d_mt
    np.testing.assert_allclose(dd, dmt.T, rtol=0, atol=1e-9)


def test_pruned_equals_dense_with_very_unequal_lengths():
    rng = np.random.default_rng(99)
    t, m = _random_sets(rng, 80, 70, extent=40.0, lmax=60.0)
    t[:40] = m[:40] + rng.normal(0, 0.05, (40, 2, 3))
    dense = match_segments(t, m, cutoff=1e6)
    for cutoff in (None, 0.01, 0.3):
        r = match_segments(t, m, cutoff=cutoff)
        assert r.to_dict() == dense.to_dict()
        np.testing.assert_array_equal(r.nearest_mt, dense.nearest_mt)
        np.testing.assert_array_equal(r.pairs_tm()[2], dense.pairs_tm()[2])


def test_lower_bound_of_pruning_holds():
    rng = np.random.default_rng(1234)
    t, m = _random_sets(rng, 200, 200, extent=10.0)
    for rotate in ("shorter", "test"):
        d = segment_distances(t, m, rotate=rotate)[3]
        ct = t.mean(axis=1)
        cm = m.mean(axis=1)
        lt = np.linalg.norm(t[:, 1] - t[:, 0], axis=1)
        lm = np.linalg.norm(m[:, 1] - m[:, 0], axis=1)
        r = np.linalg.norm(ct[:, None] - cm[None], axis=2)
        bound = np.maximum(0, r - 0.5 * np.abs(lt[:, None] - lm[None]))
        assert (d >= bound - 1e-9).all()


# ---------------------------------------------------------------- hypothesis properties

coord = st.floats(-50, 50, allow_nan=False, allow_infinity=False)
seg = (
    st.lists(coord, min_size=6, max_size=6)
    .map(lambda v: np.array(v, float).reshape(2, 3))
    .filter(lambda s: np.linalg.norm(s[1] - s[0]) > 1e-3)
)


def _rotation(a, b, c):
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", [a, b, c], degrees=True).as_matrix()


angle = st.floats(-180, 180, allow_nan=False)
shift = st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3, max_size=3)


@settings(max_examples=150, deadline=None)
@given(t=seg, m=seg, a=angle, b=angle, c=angle, s=shift)
def test_distance_invariant_to_common_rigid_motion(t, m, a, b, c, s):
    rot = _rotation(a, b, c)
    for rotate in ("shorter", "test"):
        lt, lm = np.linalg.norm(t[1] - t[0]), np.linalg.norm(m[1] - m[0])
        assume(abs(lt - lm) > 1e-6)  # at exact ties the rotated segment switches
        d0 = np.array(segment_distance(t, m, rotate=rotate))
        d1 = np.array(segment_distance(t @ rot.T + s, m @ rot.T + s, rotate=rotate))
        np.testing.assert_allclose(d1, d0, rtol=1e-7, atol=1e-7)


@settings(max_examples=150, deadline=None)
@given(t=seg, m=seg)
def test_shorter_rotation_is_symmetric(t, m):
    assume(abs(np.linalg.norm(t[1] - t[0]) - np.linalg.norm(m[1] - m[0])) > 1e-9)
    a = np.array(segment_distance(t, m))
    b = np.array(segment_distance(m, t))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    assert (a >= 0).all() and a[3] >= a[2] - 1e-12


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), a=angle, s=shift)
def test_matching_invariant_to_rigid_motion_and_symmetric(seed, a, s):
    rng = np.random.default_rng(seed)
    t, m = _random_sets(rng, 25, 20, extent=20.0)
    t[:12] = m[:12] + rng.normal(0, 0.03, (12, 2, 3))
    r0 = match_segments(t, m)
    rot = _rotation(a / 3, -a / 5, a)
    r1 = match_segments(t @ rot.T + s, m @ rot.T + s)
    np.testing.assert_allclose(r1.nearest_tm, r0.nearest_tm, rtol=1e-7, atol=1e-7)
    assert r1.threshold_tm == pytest.approx(r0.threshold_tm, abs=1e-7)
    # symmetric distance: swapping the sets swaps the directions
    rs = match_segments(m, t)
    np.testing.assert_allclose(rs.nearest_tm, r0.nearest_mt, rtol=0, atol=1e-12)
    assert rs.threshold_mt == r0.threshold_tm and rs.n_pairs_mt == r0.n_pairs_tm
    assert rs.olhd_tm == pytest.approx(r0.olhd_mt, rel=1e-12, nan_ok=True)
    assert rs.lhd == pytest.approx(r0.lhd, rel=1e-12, nan_ok=True)


# ---------------------------------------------------------------- bad input


def test_zero_length_segment_raises():
    with pytest.raises(DegenerateGeometryError, match="zero-length"):
        segment_distance([[1, 1, 1], [1, 1, 1]], MODEL)
    t = T_TOY.copy()
    t[1, 1] = t[1, 0]
    with pytest.raises(DegenerateGeometryError, match="zero-length.*id 1"):
        match_segments(t, M_TOY)
    with pytest.raises(ValueError):  # also a ValueError, as the spec says
        match_segments(M_TOY, t)


def test_empty_sets_raise():
    with pytest.raises(InvalidPointsError, match="test segment set is empty"):
        match_segments(np.empty((0, 2, 3)), M_TOY)
    with pytest.raises(InvalidPointsError, match="model segment set is empty"):
        match_segments(T_TOY, np.empty((0, 2, 3)))
    with pytest.raises(InvalidPointsError):
        match_segments(np.zeros((3, 3)), M_TOY)
    bad = T_TOY.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InvalidPointsError, match="NaN"):
        match_segments(bad, M_TOY)


def test_few_segments_fall_back_and_are_flagged():
    r = match_segments(T_TOY[:2], M_TOY)
    assert not r.threshold_found_tm and r.auto_tm.reason == "too few segments"
    assert r.threshold_tm == pytest.approx(0.3)  # the largest nearest distance
    assert r.threshold_found_mt  # q = 3: the reverse direction still has a knee
    r1 = match_segments(T_TOY[:1], M_TOY[:1])
    assert r1.p == r1.q == 1 and not r1.threshold_found_tm and not r1.threshold_found_mt
    assert r1.n_pairs_tm == 1 and r1.olhd_tm == pytest.approx(0.2)


def test_fixed_threshold():
    r = match_segments(T_TOY, M_TOY, threshold=10.0)
    assert r.threshold_tm == r.threshold_mt == 10.0
    assert not r.threshold_found_tm and r.auto_tm.reason == "fixed"
    assert r.n_pairs_tm == 3  # 0.2, 0.3 and 9.8 are ≤ 10
    assert match_segments(T_TOY, M_TOY, threshold=0.25).n_pairs_tm == 1


def test_crs_mismatch_raises():
    from pyproj import CRS

    t = Segments(np.arange(3), T_TOY[:, 0], T_TOY[:, 1], crs=CRS.from_epsg(2154))
    m = Segments(np.arange(3), M_TOY[:, 0], M_TOY[:, 1], crs=CRS.from_epsg(32632))
    with pytest.raises(CRSMismatchError):
        match_segments(t, m)
    m.crs = CRS.from_epsg(2154)
    assert match_segments(t, m).n_pairs_tm == 2


def test_bad_options_raise():
    for kw in (
        {"rotate": "model"},
        {"denominator": "some"},
        {"weight": -1},
        {"sensitivity": float("nan")},
        {"threshold": -0.1},
        {"cutoff": 0},
    ):
        with pytest.raises(OptionError):
            match_segments(T_TOY, M_TOY, **kw)
    with pytest.raises(OptionError, match="model id"):
        match_segments(T_TOY, M_TOY, ground_truth=[(0, 7)])
    with pytest.raises(OptionError, match="shape"):
        match_segments(T_TOY, M_TOY, ground_truth=np.zeros((2, 2), bool))
    with pytest.raises(LidarQAError):
        detection_rate(0, 3, 0, 0)


def test_extracted_edges_of_a_synthetic_building_match_the_true_edges():
    edges = pytest.importorskip("lidarqa.geometry.edges", reason="edge extraction not available")
    from lidarqa.testing import make_building_scene

    scene = make_building_scene(seed=4)
    found = edges.extract_edges(scene.points[scene.classification == 6])
    assert len(found) >= 5
    r = match_segments(found, scene.edges)
    # every extracted edge lies on a true edge (2 cm noise): all paired, LHD of a few cm
    assert r.n_pairs_tm == len(found)
    assert r.nearest_tm.max() < 0.1
    assert 0.0 < r.lhd < 0.05


def test_independent_of_input_order():
    s = make_segment_sets(n_model=300, seed=8)
    r0 = match_segments(s.test, s.model)
    rng = np.random.default_rng(1234)
    pt, pm = rng.permutation(len(s.test)), rng.permutation(len(s.model))
    r1 = match_segments(s.test.subset(pt), s.model.subset(pm))
    d0, d1 = r0.to_dict(), r1.to_dict()
    for k in d0:
        assert d1[k] == pytest.approx(d0[k], rel=1e-12), k

    def ids(r, get):
        ti, mi, _ = getattr(r, get)()
        return sorted(zip(r.test_ids[ti].tolist(), r.model_ids[mi].tolist(), strict=True))

    assert ids(r0, "pairs_tm") == ids(r1, "pairs_tm") and ids(r0, "pairs_mt") == ids(r1, "pairs_mt")
