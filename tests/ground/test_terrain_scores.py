"""Terrain-model scores of a ground filter (lidarqa.ground.metrics.terrain_scores).

Oracles: synthetic scenes with known truth (lidarqa.testing), a predicted terrain
shifted by a known offset, a reference thinned by a known share, and real data
(a complete ISPRS reference vs the thinned BC vendor ground).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from datapaths import SHARED, needs_shared
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.errors import InvalidPointsError, OptionError
from lidarqa.ground.metrics import THINNED_RATIO, terrain_scores
from lidarqa.testing import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene(seed=3, size=(60.0, 60.0), density=4.0, origin=(500000.0, 5400000.0, 200.0))


def _shifted(ground: np.ndarray, dz: float):
    """The reference ground, and a copy of it `dz` higher that is the prediction."""
    pts = np.vstack([ground, ground + [0.0, 0.0, dz]])
    n = len(ground)
    ref = np.arange(2 * n) < n
    return pts, ~ref, ref


def test_perfect_prediction_scores_zero(scene):
    g = scene.is_ground
    s = terrain_scores(scene.points, g, g)
    assert s.reason == ""
    assert s.rmse == 0.0 and s.bias == 0.0
    assert s.cells_off == 0.0 and s.objects_taken == 0.0 and s.ground_lost == 0.0
    assert s.n_pred_scored == s.n_ref_scored == int(g.sum())
    # a complete reference: few non-ground points lie on its surface
    assert s.on_surface_ratio < 0.05 and not s.thinned and s.note == ""
    # the cells inside both TINs cover most of the 60 x 60 m scene
    assert 0.8 * 3600 < s.n_cells <= 3600


@settings(max_examples=25, deadline=None)
@given(
    dz=st.floats(-1.5, 1.5).filter(
        lambda v: min(abs(abs(v) - lim) for lim in (0.0, 0.15, 0.3, 0.5)) > 1e-6
    )
)
def test_known_offset_gives_known_scores(dz):
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 30, (400, 2))
    ground = np.column_stack([xy, 0.05 * xy[:, 0] + 0.3 * np.sin(xy[:, 1] / 5)])
    pts, pred, ref = _shifted(ground, dz)
    s = terrain_scores(pts, pred, ref)
    assert s.rmse == pytest.approx(abs(dz), abs=1e-9)
    assert s.bias == pytest.approx(dz, abs=1e-9)
    assert s.cells_off == (1.0 if abs(dz) > 0.5 else 0.0)
    assert s.objects_taken == (1.0 if dz > 0.3 else 0.0)
    assert s.ground_lost == (1.0 if abs(dz) > 0.3 else 0.0)
    # every predicted point (not reference ground) lies on the reference surface iff |dz| <= 0.15
    assert s.on_surface_ratio == pytest.approx(1.0 if abs(dz) <= 0.15 else 0.0)


def test_objects_taken_matches_truth(scene):
    """Everything below 3 m above the true terrain taken as ground: the share above 0.3 m."""
    pts = scene.points
    h = pts[:, 2] - scene.ground_z(pts[:, :2])
    pred = scene.is_ground | ((h < 3.0) & (scene.classification != 7))
    s = terrain_scores(pts, pred, scene.is_ground)
    expected = np.mean(h[pred] > 0.3)
    assert expected > 0.01
    assert s.objects_taken == pytest.approx(expected, abs=0.01)
    assert s.ground_lost == 0.0  # all the reference ground was kept


def test_ground_lost_and_dtm_error_under_a_missing_patch(scene):
    """Predicted ground with a hill's worth of objects: cells off only there."""
    g = scene.is_ground
    pts = scene.points.copy()
    # raise the predicted terrain by 2 m over a 10 x 10 m square: copies of the ground there
    lo = scene.points[:, :2].min(axis=0) + 20.0
    inside = g & np.all((pts[:, :2] >= lo) & (pts[:, :2] < lo + 10.0), axis=1)
    fake = pts[inside] + [0.0, 0.0, 2.0]
    allp = np.vstack([pts, fake])
    ref = np.concatenate([g, np.zeros(len(fake), bool)])
    pred = np.concatenate([g & ~inside, np.ones(len(fake), bool)])
    s = terrain_scores(allp, pred, ref)
    # about 100 of ~3,400 cells are 2 m off (the border cells partly)
    assert 80 / s.n_cells < s.cells_off < 150 / s.n_cells
    assert s.ground_lost == pytest.approx(inside.sum() / g.sum(), rel=0.2)
    # off cells differ by 0.5..2 m, the others by at most 0.5 m
    f = s.cells_off
    assert 0.25 * f < s.rmse**2 <= 4.0 * f + 0.25 * (1.0 - f)
    assert s.bias > 0.0


def test_thinned_reference_is_flagged(scene):
    g = scene.is_ground
    rng = np.random.default_rng(1)
    keep = rng.random(g.size)
    thin = g & (keep < 0.3)  # the vendor kept 30 % of the ground as class 2
    s = terrain_scores(scene.points, g, thin)
    # the dropped ground lies on the thinned surface: about 0.7 / 0.3 of it per kept point
    assert s.on_surface_ratio == pytest.approx(0.7 / 0.3, rel=0.2)
    assert s.thinned and "thinned" in s.note and s.to_dict()["reference_thinned"] is True
    light = g & (keep < 0.97)
    s2 = terrain_scores(scene.points, g, light)
    assert s2.on_surface_ratio < THINNED_RATIO and not s2.thinned


def test_input_order_and_mask(scene):
    g = scene.is_ground
    pred = g | (scene.classification == 3)
    perm = np.random.default_rng(5).permutation(len(g))
    a = terrain_scores(scene.points, pred, g).to_dict()
    b = terrain_scores(scene.points[perm], pred[perm], g[perm]).to_dict()
    assert a == b
    # leaving the low vegetation out of the evaluation = not predicting it (and not
    # counting it on the reference surface)
    m = scene.classification != 3
    left_out = terrain_scores(scene.points, pred, g, mask=m).to_dict()
    perfect = terrain_scores(scene.points, g, g).to_dict()
    r = left_out.pop("reference_on_surface_ratio")
    assert r < perfect.pop("reference_on_surface_ratio")
    assert left_out == perfect


def test_degenerate_inputs():
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    s = terrain_scores(pts, [True] * 4, [True, True, False, False])
    assert "reference" in s.reason and math.isnan(s.rmse)
    d = s.to_dict()
    assert d["rmse_m"] is None and d["n_cells"] == 0
    s = terrain_scores(pts, [True, False, False, False], [True] * 4)
    assert "predicted" in s.reason and s.on_surface_ratio == 0.0
    with pytest.raises(InvalidPointsError):
        terrain_scores(pts, [True] * 3, [True] * 4)
    with pytest.raises(OptionError):
        terrain_scores(pts, [True] * 4, [True] * 4, cell=0.0)


@needs_shared
def test_real_references_thinned_or_complete():
    """The BC vendor ground is thinned; an ISPRS reference is complete."""
    import lidarqa

    for name, thinned in (
        ("lasR-bcts/bcts_4.laz", True),
        ("isprs-filtertest-pdal/samp11-utm.laz", False),
    ):
        cloud = lidarqa.read(SHARED / name)
        cls = np.asarray(cloud.classification)
        s = terrain_scores(cloud.xyz, cls == 2, cls == 2, mask=~np.isin(cls, (7, 18)))
        assert s.thinned is thinned, (name, s.on_surface_ratio)
        assert s.rmse == 0.0


def test_grid_blocks_and_size_limit(scene, monkeypatch):
    """Scoring the grid in small blocks gives the same figures; a huge extent is refused."""
    from lidarqa.ground import metrics

    g = scene.is_ground
    pred = g | (scene.classification == 3)
    whole = terrain_scores(scene.points, pred, g)
    monkeypatch.setattr(metrics, "_BLOCK_CELLS", 100)
    blocks = terrain_scores(scene.points, pred, g)
    assert blocks.n_cells == whole.n_cells and blocks.cells_off == whole.cells_off
    assert blocks.rmse == pytest.approx(whole.rmse, rel=1e-12)
    monkeypatch.setattr(metrics, "MAX_CELLS", 1000)
    big = terrain_scores(scene.points, pred, g)
    assert "larger cell" in big.reason and math.isnan(big.rmse)
    assert big.on_surface_ratio == whole.on_surface_ratio
    assert terrain_scores(scene.points, pred, g, cell=5.0).reason == ""
