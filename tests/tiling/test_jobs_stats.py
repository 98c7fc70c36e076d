"""Per-chunk sufficient statistics merge to exactly the whole-area figures."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from lidarqa.accuracy.checkpoints import residual_statistics
from lidarqa.accuracy.heights import compare_heights, w_test
from lidarqa.errors import InvalidPointsError
from lidarqa.ground.metrics import filter_errors
from lidarqa.tiling.jobs_stats import (
    ConfusionCounts,
    Histogram,
    Moments,
    ResidualMoments,
    WStatistics,
    exact_sum,
    exact_sum_of_squares,
    merge,
)


def _split(n, k, rng):
    """Random cut of range(n) into k parts (some may be empty), as index arrays."""
    perm = rng.permutation(n)
    cuts = np.sort(rng.integers(0, n + 1, size=k - 1))
    return np.split(perm, cuts)


def _merged_in_orders(parts, rng, n_orders=3):
    out = []
    for _ in range(n_orders):
        order = rng.permutation(len(parts))
        out.append(merge(parts[i] for i in order))
    return out


def test_exact_sum_is_exact_where_float_sum_is_not():
    vals = [1e20, 1.0, -1e20, 1e-30, 3.0]
    assert sum(vals) != 4.0  # plain float summation loses the 1.0
    assert exact_sum(vals) == Fraction(4) + Fraction(1e-30)
    sq = exact_sum_of_squares([0.1, 0.3, 1e-200, 1e160])
    assert sq == sum(Fraction(v) ** 2 for v in (0.1, 0.3, 1e-200, 1e160))


def test_exact_sum_rejects_nan():
    with pytest.raises(InvalidPointsError):
        exact_sum([1.0, math.nan])


def test_residual_moments_merge_exactly_and_match_the_kernel():
    rng = np.random.default_rng(1234)
    # heavy-tailed residuals with mixed magnitudes make float sums order dependent
    res = rng.standard_t(3, size=(5000, 3)) * np.array([0.05, 0.05, 0.1])
    res[::97] *= 1e3
    whole = ResidualMoments.of(res).to_dict()
    for k in (2, 7, 40):
        parts = [ResidualMoments.of(res[i]) for i in _split(len(res), k, rng)]
        for merged in _merged_in_orders(parts, rng):
            assert merged.to_dict() == whole  # bit for bit, any cut, any order
    ref = residual_statistics(res).to_dict()
    assert set(ref) == set(whole)
    for key, val in ref.items():
        assert whole[key] == pytest.approx(val, rel=1e-12, abs=1e-15), key


def test_float_sums_of_parts_would_not_be_exact():
    """The reason for exact sums: ordinary partial sums differ with the cut."""
    rng = np.random.default_rng(7)
    x = rng.standard_normal(20000) * 10.0 ** rng.integers(-6, 6, size=20000)
    whole = float(np.sum(x))
    sums = set()
    for k in (2, 3, 5, 11, 29):
        sums.add(sum(float(np.sum(x[i])) for i in _split(len(x), k, rng)))
    assert len(sums | {whole}) > 1
    m = {float(merge(Moments.of(x[i]) for i in _split(len(x), k, rng)).total) for k in (2, 3, 5)}
    assert m == {float(Moments.of(x).total)}


def test_vertical_only_residuals_keep_nan_axes():
    rng = np.random.default_rng(3)
    res = np.full((50, 3), np.nan)
    res[:, 2] = rng.normal(0.02, 0.05, 50)
    parts = [ResidualMoments.of(res[i]) for i in _split(50, 4, rng)]
    d = merge(parts).to_dict()
    assert math.isnan(d["rmse_x"]) and math.isnan(d["rmse_h"])
    assert d["rmse_z"] == pytest.approx(residual_statistics(res).rmse[2], rel=1e-12)
    assert d["n"] == 50


def test_confusion_counts_merge_to_whole_area_filter_errors():
    rng = np.random.default_rng(11)
    ref = rng.random(10000) < 0.6
    pred = np.where(rng.random(10000) < 0.9, ref, ~ref)
    parts = [ConfusionCounts.of(ref[i], pred[i]) for i in _split(10000, 6, rng)]
    merged = merge(parts)
    assert merged.n == 10000
    assert merged.to_dict() == filter_errors(ref, pred).to_dict()


def test_confusion_counts_mask_keeps_core_points_only():
    ref = np.array([1, 1, 0, 0, 1], bool)
    pred = np.array([1, 0, 1, 0, 1], bool)
    core = np.array([1, 1, 1, 1, 0], bool)
    c = ConfusionCounts.of(ref, pred, mask=core)
    assert (c.a, c.b, c.c, c.d) == (1, 1, 1, 1)


def test_histogram_merge_counts_every_value_once():
    rng = np.random.default_rng(5)
    x = rng.normal(0, 1, 3000)
    edges = np.linspace(-2, 2, 17)
    whole = Histogram.of(x, edges)
    assert sum(whole.counts) + whole.under + whole.over == 3000
    assert list(whole.counts) == np.histogram(x[(x >= -2) & (x < 2)], edges)[0].tolist()
    parts = [Histogram.of(x[i], edges) for i in _split(3000, 5, rng)]
    assert merge(parts) == whole
    with pytest.raises(InvalidPointsError):
        whole + Histogram.of(x, np.linspace(-2, 2, 9))


def test_height_and_w_statistics_merge_to_whole_area():
    rng = np.random.default_rng(2024)
    n = 4000
    z = rng.uniform(50, 60, n)
    h = z + rng.normal(0.03, 0.08, n)
    h[rng.choice(n, 20, replace=False)] += 1.5  # gross errors to be flagged
    sm = rng.uniform(0.02, 0.1, n)
    cmp_ = compare_heights(h, sm, z)
    wt = w_test(cmp_.dh, cmp_.sigma_dh)
    whole_w = WStatistics.of(wt.w, wt.outlier, critical=wt.critical)
    whole_dh = Moments.of(cmp_.dh)
    parts = []
    for idx in _split(n, 9, rng):
        c = compare_heights(h[idx], sm[idx], z[idx])  # each chunk tests its own points
        t = w_test(c.dh, c.sigma_dh)
        parts.append((Moments.of(c.dh), WStatistics.of(t.w, t.outlier, critical=t.critical)))
    order = rng.permutation(len(parts))
    dh = merge(parts[i][0] for i in order)
    w = merge(parts[i][1] for i in order)
    assert dh.to_dict() == whole_dh.to_dict()
    assert w.to_dict() == whole_w.to_dict()
    assert w.n_outliers == wt.n_outliers >= 20
    ref = wt.to_dict()
    for key in ("std", "std_without_outliers", "frac_lt1", "frac_lt2"):
        assert w.to_dict()[key] == pytest.approx(ref[key], rel=1e-12)
    assert dh.rms() == pytest.approx(cmp_.rms, rel=1e-12)
    assert dh.std() == pytest.approx(cmp_.std, rel=1e-12)
    assert dh.mean == pytest.approx(cmp_.mean, rel=1e-12)


def test_merge_skips_failed_chunks_and_refuses_nothing():
    m = Moments.of([1.0, 2.0])
    assert merge([None, m, None]) == m
    with pytest.raises(InvalidPointsError):
        merge([None])


def test_moments_pickle_round_trip():
    import pickle

    m = Moments.of([0.1, 0.2, 0.3])
    assert pickle.loads(pickle.dumps(m)) == m
