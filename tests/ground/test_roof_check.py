"""Final roof check of segment-PTD (``roof_ratio``).

A house built into a hillside touches the terrain along its uphill eave, so its
uphill roof plane can be accepted as ground, and the raised test (which needs half
of the border raised) misses it. The final roof check rejects two roof planes that
meet in a convex ridge with opposite aspects when part of their pooled border
stands above the ground; a dyke has the same ridge but meets the terrain at grade
and stays ground. The scene is built by hand with known segments, so the test does
not depend on surface growing.
"""

from __future__ import annotations

import numpy as np
import pytest
from handmade import OFFSET, als_filter, assemble, grid, ground_in_both_orders

from lidarqa.errors import OptionError
from lidarqa.ground import ALS_SEGMENT_PARAMS, SegmentPTD, classify_ground
from lidarqa.io import PointCloud

GRADE = 0.3  # the hillside falls by 0.3 m per m in +x (17°)
PITCH = 20.0  # roof pitch (degrees)
TERRAIN, ROOF, WALL, DYKE = range(4)


def _terrain(x):
    return -GRADE * x


def _scene(seed: int = 0, *, dyke_height: float = 3.0):
    """A 1 pt/m² hillside with a gable-roofed house built into it and a dyke across it.

    Labels: 0 terrain, 1 and 2 the roof planes (ridge along y at x = 35, eaves 0.2 m
    above the uphill terrain, 3.2 m above the downhill terrain), 3 the downhill
    wall, 4 and 5 the dyke's faces (crest at x = 65, `dyke_height` m above the
    hillside, at grade at x = 60 and 70). Returns points, labels and a kind per point.
    """
    rng = np.random.default_rng(seed)
    parts = []
    x, y = grid(0, 100, 0, 60, 1.0, rng)
    keep = ~((x > 30) & (x < 40) & (y > 20) & (y < 32)) & ~((x > 60) & (x < 70))
    parts.append((x[keep], y[keep], _terrain(x[keep]), 0, TERRAIN))
    eave = _terrain(30.0) + 0.2
    rise = np.tan(np.radians(PITCH))
    for lab, (a, b) in ((1, (30, 35)), (2, (35, 40))):
        x, y = grid(a, b, 20, 32, 1.0, rng)
        parts.append((x, y, eave + rise * (5 - np.abs(x - 35)), lab, ROOF))
    h, y = grid(0, 1, 20, 32, 0.5, rng)
    h = np.clip(h, 0.0, 1.0)
    wall_z = _terrain(40.0) + h * (eave - _terrain(40.0))
    parts.append((np.full(y.size, 40.0), y, wall_z, 3, WALL))
    for lab, (a, b) in ((4, (60, 65)), (5, (65, 70))):
        x, y = grid(a, b, 0, 60, 1.0, rng)
        parts.append((x, y, _terrain(x) + dyke_height * (1 - np.abs(x - 65) / 5), lab, DYKE))
    return assemble(parts, 300.0)


def test_without_the_check_the_uphill_roof_plane_is_ground():
    # the scene is a real test: the raised test alone lets half of the roof in
    pts, labels, kind = _scene()
    g = als_filter(roof_ratio=0.0).run(pts, labels=labels).ground_mask
    assert g[labels == 1].all()
    assert not g[labels == 2].any()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_roof_is_rejected_and_the_dyke_and_terrain_stay(seed):
    pts, labels, kind = _scene(seed)
    off = als_filter(roof_ratio=0.0).run(pts, labels=labels).ground_mask
    on = als_filter(roof_ratio=ALS_SEGMENT_PARAMS["roof_ratio"]).run(pts, labels=labels).ground_mask
    assert not on[kind == ROOF].any()
    assert on[kind == DYKE].all() and on[kind == TERRAIN].mean() > 0.99
    # only roof points change
    assert np.array_equal(on[kind != ROOF], off[kind != ROOF])


def test_a_ridge_needs_a_raised_border():
    # the same roof planes, dropped so that both eaves meet the terrain at grade
    # (a ridge of terrain, like the dyke): nothing is raised, nothing is rejected
    pts, labels, kind = _scene()
    drop = np.where(kind == ROOF, 0.2, 0.0)
    pts = pts - np.column_stack([np.zeros((len(pts), 2)), drop])
    keep = kind != WALL
    pts, labels, kind = pts[keep], labels[keep], kind[keep]
    labels[labels > 3] -= 1
    x = pts[:, 0] - OFFSET[0]
    downhill = labels == 2
    # the downhill plane ends at the terrain of x = 40 instead of 3 m above it
    pts[downhill, 2] += (_terrain(40.0) - (_terrain(30.0))) * (x[downhill] - 35) / 5
    on = als_filter().run(pts, labels=labels).ground_mask
    off = als_filter(roof_ratio=0.0).run(pts, labels=labels).ground_mask
    assert on[kind == ROOF].all()
    assert np.array_equal(on, off)


def test_independent_of_input_order():
    pts, labels, kind = _scene(seed=3)
    a, b = ground_in_both_orders(pts, labels)
    assert np.array_equal(a, b)
    assert not a[kind == ROOF].any()


def test_the_automatic_parameters_of_a_sparse_airborne_cloud_set_it():
    pts, labels, kind = _scene()
    r = classify_ground(PointCloud(pts))
    assert r.parameters["roof_ratio"] == ALS_SEGMENT_PARAMS["roof_ratio"] > 0
    assert r.parameter_sources["roof_ratio"] == "preset"
    r0 = classify_ground(PointCloud(pts), roof_ratio=0.0)
    assert r0.parameter_sources["roof_ratio"] == "given"


def test_the_class_default_keeps_lin_and_zhang():
    assert SegmentPTD().roof_ratio == 0.0


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), float("inf"), "x"])
def test_bad_roof_ratio_is_refused(bad):
    with pytest.raises(OptionError, match="roof_ratio"):
        SegmentPTD(roof_ratio=bad)
