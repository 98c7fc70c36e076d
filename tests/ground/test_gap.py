"""Gap test (`gap_step`): a deck on piers over a valley is not ground in a sparse cloud;
an embankment of the same height, whose 1:1.5 sides carry returns, is.

At 2 m between points (0.25 points/m²) the perched test does not reach across the
deck, and the grade between the deck's edge and the nearest valley return is an
embankment's; what differs is the corridor between them: empty beside a deck (a
vertical drop), sampled on an embankment's side. Scenes are built by hand with known
truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.errors import OptionError
from lidarqa.ground import ALS_SEGMENT_PARAMS, SegmentPTD, auto_parameters, measure_cloud
from lidarqa.ground import _gap as G
from lidarqa.ground._gap import gap_mask
from lidarqa.testing import ground_profile

SPACING = 2.0  # 0.25 points/m²


def _valley_deck(seed: int, height: float = 6.0, width: float = 8.0):
    """A road at `height` m crossing a valley on a deck; no return under the deck.

    The valley floor (0 m) is 24 m wide, its sides rise at 45° to the road level. The
    deck's points replace the terrain beneath it. Truth: the deck is not ground where
    the terrain under it lies more than 0.5 m lower.
    """
    rng = np.random.default_rng(seed)
    g = np.arange(0.0, 80.0, SPACING)
    x, y = (a.ravel() for a in np.meshgrid(g, g[:30], indexing="ij"))
    x = x + rng.uniform(-SPACING / 3, SPACING / 3, x.size)
    y = y + rng.uniform(-SPACING / 3, SPACING / 3, y.size)
    terrain = np.clip(np.abs(x - 40.0) - 12.0, 0.0, height)
    on = np.abs(y - 30.0) <= width / 2
    z = np.where(on, height, terrain) + rng.normal(0.0, 0.02, x.size)
    truth = ~on | (terrain > height - 0.5)
    return np.column_stack([x, y, z]), truth


def _filter(**kw):
    return SegmentPTD(**{**ALS_SEGMENT_PARAMS, **kw})


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_deck_over_a_valley_is_not_ground(seed):
    p, truth = _valley_deck(seed)
    deck = ~truth
    old = _filter(gap_step=0.0).ground_mask(p)
    new = _filter().ground_mask(p)
    assert old[deck].mean() > 0.5  # without the test most of the deck is ground
    assert new[deck].mean() < 0.4
    assert not (new & ~old).any()  # the test only rejects
    assert (new & truth).sum() == (old & truth).sum()  # and no terrain


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_embankment_of_the_same_height_stays_ground(seed):
    p, truth = ground_profile("embankment", seed=seed, spacing=SPACING)  # 5 m, 1:1.5 sides
    assert truth.all()
    ones = np.ones(len(p), dtype=bool)
    assert not gap_mask(p, ones, ones, step=4.0).any()
    np.testing.assert_array_equal(_filter().ground_mask(p), _filter(gap_step=0.0).ground_mask(p))


def test_the_empty_corridor_is_what_counts():
    # the same deck profile with returns on 1:1.5 slopes beside it is an embankment
    p, truth = ground_profile("deck", seed=7, spacing=SPACING, width=8.0)
    ones = np.ones(len(p), dtype=bool)
    out = gap_mask(p, ones, ones, step=4.0)
    assert out[~truth].mean() > 0.5 and not out[truth].any()
    side = truth & (np.abs(p[:, 1] - 30.0) < 11.5)  # beside the deck, up to 7.5 m out
    p[side, 2] = np.clip(5.0 - (np.abs(p[side, 1] - 30.0) - 4.0) / 1.5, 0.0, 5.0)
    assert not gap_mask(p, ones, ones, step=4.0).any()


@pytest.mark.parametrize("support", [G.SUPPORT, 0])
def test_low_outliers_are_no_lower_ground(monkeypatch, support):
    # two lines of isolated low returns the filter accepted, 12 m apart, on flat ground:
    # the ground between them drops cleanly to both sides, but onto no surface
    monkeypatch.setattr(G, "SUPPORT", support)
    p, _ = ground_profile("terrace", seed=8, spacing=SPACING)
    ones = np.ones(len(p), dtype=bool)
    col, row = (np.round(p[:, k] / SPACING).astype(int) for k in (0, 1))
    low = np.isin(col, [10, 16]) & (row < 14) & (row % 2 == 0)
    p[low, 2] -= 8.0
    assert gap_mask(p, ones, ones, step=4.0).any() == (support == 0)


def test_independent_of_input_order():
    p, _ = _valley_deck(3)
    perm = np.random.default_rng(0).permutation(len(p))
    ones = np.ones(len(p), dtype=bool)
    a = gap_mask(p, ones, ones, step=4.0)
    b = gap_mask(p[perm], ones, ones, step=4.0)
    assert a.any()
    np.testing.assert_array_equal(a[perm], b)


def test_parameter_validated_and_set_for_sparse_airborne_clouds_only():
    with pytest.raises(OptionError):
        SegmentPTD(gap_step=-1.0)
    assert SegmentPTD().gap_step == 0.0  # Lin & Zhang's set is unchanged
    assert ALS_SEGMENT_PARAMS["gap_step"] == 4.0
    rng = np.random.default_rng(0)
    sparse = np.column_stack([rng.uniform(0, 200, (10000, 2)), rng.normal(0, 0.02, 10000)])
    params, src, regime = auto_parameters(measure_cloud(sparse), "segment-ptd")
    assert regime == "als-sparse" and params["gap_step"] == 4.0
    assert src["gap_step"] == "preset"
    dense = np.column_stack([rng.uniform(0, 60, (36000, 2)), rng.normal(0, 0.02, 36000)])
    params, _, regime = auto_parameters(measure_cloud(dense), "segment-ptd")
    assert regime == "als-dense" and params.get("gap_step", 0.0) == 0.0


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_independent_of_the_chunk_size(monkeypatch, chunk):
    # the tested points go in chunks (bounded memory): any chunk size, the same mask
    p, _ = _valley_deck(4)
    q, _ = ground_profile("deck", seed=5, spacing=SPACING, width=8.0)
    p = np.vstack([p, q + [0.0, 100.0, 0.0]])  # a second deck, beside the first
    ones = np.ones(len(p), dtype=bool)
    cand = ones.copy()
    cand[::5] = False  # fewer candidates than ground
    whole = gap_mask(p, ones, cand, step=4.0)
    assert whole.sum() > 10
    monkeypatch.setattr(G, "CHUNK", chunk)
    np.testing.assert_array_equal(gap_mask(p, ones, cand, step=4.0), whole)
