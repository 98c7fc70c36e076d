"""Perched-surface test: decks and roofs that drop steeply on both sides are not ground;
terraces, embankments and 45° slopes are."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.errors import OptionError
from lidarqa.ground import ALS_SEGMENT_PARAMS, SegmentPTD, auto_parameters, measure_cloud
from lidarqa.ground._perched import perched_mask
from lidarqa.testing import ground_profile

OPTS = {"step": 2.0, "angle": 45.0, "radius": 8.0}


def _all(p):
    return np.ones(len(p), dtype=bool)


@pytest.mark.parametrize("spacing", [0.5, 1.0, 2.0])
def test_deck_is_perched_ground_beside_it_is_not(spacing):
    p, truth = ground_profile("deck", seed=1, spacing=spacing)  # 4 m wide, 5 m high
    out = perched_mask(p, _all(p), _all(p), **OPTS)
    assert out[~truth].mean() > 0.9  # the deck
    assert out[truth].mean() < 0.01  # the ground beside it


def test_wide_deck_is_caught_along_its_middle_only():
    p, truth = ground_profile("deck", seed=1, width=8.0)
    out = perched_mask(p, _all(p), _all(p), **OPTS)
    mid = np.abs(p[:, 1] - 30.0) < 0.8
    assert out[mid].mean() > 0.8
    assert not out[np.abs(p[:, 1] - 30.0) > 2.0].any()  # beyond reach of the far side


@pytest.mark.parametrize("kind", ["terrace", "embankment", "slope"])
@pytest.mark.parametrize("spacing", [0.5, 1.0, 2.0])
def test_terrain_break_lines_and_slopes_stay(kind, spacing):
    p, truth = ground_profile(kind, seed=2, spacing=spacing)
    assert truth.all()
    assert not perched_mask(p, _all(p), _all(p), **OPTS).any()


def test_lower_ground_beneath_counts_and_only_accepted_points_are_rejected():
    p, truth = ground_profile("deck", seed=3)
    ground = truth.copy()
    ground[np.flatnonzero(~truth)[:10]] = True  # the filter accepted a few deck points
    out = perched_mask(p, ground, _all(p), **OPTS)
    assert out.sum() == 10 and not (out & ~ground).any()


def test_independent_of_input_order_and_absolute_position():
    p, _ = ground_profile("deck", seed=4, spacing=1.5)
    perm = np.random.default_rng(0).permutation(len(p))
    a = perched_mask(p, _all(p), _all(p), **OPTS)
    b = perched_mask(p[perm], _all(p), _all(p), **OPTS)
    np.testing.assert_array_equal(a[perm], b)
    # the raster is aligned to absolute coordinates: a tile sees the same cells
    sub = p[:, 0] < 40.0
    c = perched_mask(p[sub], _all(p)[sub], _all(p)[sub], **OPTS)
    inner = p[sub, 0] < 30.0  # farther than the search radius from the cut
    np.testing.assert_array_equal(a[sub][inner], c[inner])


def test_segment_ptd_rejects_a_deck_only_with_the_test_on():
    p, truth = ground_profile("deck", seed=5, spacing=1.0)
    base = {**ALS_SEGMENT_PARAMS, "perched_step": 0.0}
    off = SegmentPTD(**base).ground_mask(p)
    on = SegmentPTD(**{**base, "perched_step": 2.0}).ground_mask(p)
    assert not (on & ~off).any()  # the test only ever removes ground
    assert (on & ~truth).sum() < (off & ~truth).sum() or not (off & ~truth).any()
    assert (on & truth).sum() >= 0.97 * (off & truth).sum()


def test_parameters_validated_and_chosen_for_airborne_clouds():
    with pytest.raises(OptionError):
        SegmentPTD(perched_step=-1.0)
    with pytest.raises(OptionError):
        SegmentPTD(perched_angle=90.0)
    assert SegmentPTD().perched_step == 0.0  # Lin & Zhang's set is unchanged
    rng = np.random.default_rng(0)
    dense = np.column_stack([rng.uniform(0, 60, (36000, 2)), rng.normal(0, 0.02, 36000)])
    params, src, regime = auto_parameters(measure_cloud(dense), "segment-ptd")
    assert regime == "als-dense" and params["perched_step"] == 2.0
    assert src["perched_step"] == "preset"  # a constant of the dense preset, not measured
    assert ALS_SEGMENT_PARAMS["perched_step"] == 2.0


@pytest.mark.parametrize("kind", ["deck", "terrace"])
def test_occupied_cell_path_gives_the_same_result(monkeypatch, kind):
    from lidarqa.ground import _perched

    p, _ = ground_profile(kind, seed=6, spacing=1.5)
    p[::7, 2] -= 3.0  # some low candidates too
    ground = np.ones(len(p), dtype=bool)
    ground[::7] = False
    full = perched_mask(p, ground, _all(p), **OPTS)
    monkeypatch.setattr(_perched, "_RASTER_PER_POINT", 0)
    monkeypatch.setattr(_perched, "_RASTER_MIN", 0)
    sparse = perched_mask(p, ground, _all(p), **OPTS)
    assert full.any() or kind == "terrace"
    np.testing.assert_array_equal(full, sparse)


def test_scattered_coordinates_do_not_allocate_a_raster():
    p, _ = ground_profile("deck", seed=7)
    far = np.vstack([p, [[1e12, 0.0, 0.0]]])
    out = perched_mask(far, _all(far), _all(far), **OPTS)
    np.testing.assert_array_equal(out[:-1], perched_mask(p, _all(p), _all(p), **OPTS))
