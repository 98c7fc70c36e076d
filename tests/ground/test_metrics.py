"""ISPRS filter-test error measures (ALGORITHMS.md §2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.errors import InvalidPointsError
from lidarqa.ground.metrics import filter_errors, filter_errors_from_counts, filter_errors_from_file


def test_spec_row_1():
    e = filter_errors_from_counts(40, 10, 5, 45)
    assert e.type_i == pytest.approx(0.20)
    assert e.type_ii == pytest.approx(0.10)
    assert e.total == pytest.approx(0.15)
    assert e.p_o == pytest.approx(0.85)
    assert e.p_e == pytest.approx(0.50)
    assert e.kappa == pytest.approx(0.70)
    assert e.confusion.tolist() == [[40, 10], [5, 45]]


def test_spec_row_2():
    e = filter_errors_from_counts(9000, 300, 450, 5250)
    assert e.type_i == pytest.approx(0.032258, abs=1e-6)
    assert e.type_ii == pytest.approx(0.078947, abs=1e-6)
    assert e.total == pytest.approx(0.05)
    assert e.p_e == pytest.approx(0.5312, abs=1e-4)
    assert e.kappa == pytest.approx(0.893345, abs=1e-6)


def test_from_labels_matches_counts():
    ref = np.array([1] * 40 + [1] * 10 + [0] * 5 + [0] * 45, dtype=bool)
    pred = np.array([1] * 40 + [0] * 10 + [1] * 5 + [0] * 45, dtype=bool)
    assert filter_errors(ref, pred) == filter_errors_from_counts(40, 10, 5, 45)
    d = filter_errors(ref, pred).to_dict()
    assert d["n_evaluated"] == 100 and d["confusion"]["ref_ground_pred_object"] == 10


def test_mask_excludes_points():
    ref = np.array([True, True, False, False])
    pred = np.array([True, False, True, False])
    e = filter_errors(ref, pred, mask=[True, True, False, True])
    assert (e.a, e.b, e.c, e.d) == (1, 1, 0, 1)


def test_edge_cases():
    assert math.isnan(filter_errors_from_counts(0, 0, 3, 4).type_i)
    assert math.isnan(filter_errors_from_counts(3, 4, 0, 0).type_ii)
    assert math.isnan(filter_errors_from_counts(5, 0, 0, 0).kappa)  # p_e = 1
    with pytest.raises(InvalidPointsError):
        filter_errors_from_counts(0, 0, 0, 0)
    with pytest.raises(InvalidPointsError):
        filter_errors([True, False], [True])


@pytest.mark.parametrize(
    ("t1", "t2", "tot", "w_expected"),
    [
        (3.23, 7.55, 5.40, 0.4977),
        (0.07, 0.39, 0.23, 0.5000),
        (8.85, 8.66, 8.77, 0.5789),
        (4.74, 0.09, 2.86, 0.5957),
    ],
)
def test_lin_zhang_table3_ground_share(t1, t2, tot, w_expected):
    # total = w * I + (1 - w) * II  ->  w = (II - T) / (II - I)
    w = (t2 - tot) / (t2 - t1)
    assert w == pytest.approx(w_expected, abs=5e-4)


def test_lin_zhang_table3_consistency_within_dataset():
    w = lambda i, ii, t: (ii - t) / (ii - i)  # noqa: E731
    assert abs(w(3.23, 7.55, 5.40) - w(0.07, 0.39, 0.23)) < 0.02
    assert abs(w(8.85, 8.66, 8.77) - w(4.74, 0.09, 2.86)) < 0.02
    # "reduced on average by 3.62 %, 7.87 %, 5.54 %"
    assert ((3.23 - 0.07) + (8.85 - 4.74)) / 2 == pytest.approx(3.62, abs=0.02)
    assert ((7.55 - 0.39) + (8.66 - 0.09)) / 2 == pytest.approx(7.87, abs=0.02)
    assert ((5.40 - 0.23) + (8.77 - 2.86)) / 2 == pytest.approx(5.54, abs=0.02)


counts = st.integers(min_value=0, max_value=10_000)


@settings(max_examples=200, deadline=None)
@given(counts, counts, counts, counts)
def test_kappa_range_and_total_identity(a, b, c, d):
    if a + b + c + d == 0:
        return
    e = filter_errors_from_counts(a, b, c, d)
    if not math.isnan(e.kappa):
        assert -1.0 - 1e-12 <= e.kappa <= 1.0 + 1e-12
    assert 0.0 <= e.total <= 1.0
    if a + b and c + d:
        w = (a + b) / (a + b + c + d)
        assert e.total == pytest.approx(w * e.type_i + (1 - w) * e.type_ii)


def test_from_file(data_dir):
    import lidarqa

    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    ref = cloud.classification == 2
    e = filter_errors_from_file(data_dir / "samp24-utm.laz", ref)
    assert e.total == 0.0 and e.kappa == pytest.approx(1.0)
