"""Vertical check of a cloud against check points through a ground TIN (lascontrol style)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.accuracy.checkpoints import vertical_check
from lidarqa.errors import DegenerateGeometryError, InvalidPointsError
from lidarqa.io.vector import PointSet
from lidarqa.testing import make_terrain_scene


@pytest.fixture(scope="module")
def terrain():
    # smooth terrain (slope + undulation), no break lines, trees so that not every point is ground
    return make_terrain_scene(
        seed=11, size=(80.0, 80.0), density=10.0, noise=0.02, curbs=0, embankment=False, n_trees=6
    )


def _checks(scene, n=49, margin=10.0, offset_xy=(0.0, 0.0)):
    lo = scene.points[:, :2].min(axis=0) + margin
    hi = scene.points[:, :2].max(axis=0) - margin
    k = int(np.sqrt(n))
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], k), np.linspace(lo[1], hi[1], k))
    xy = np.column_stack([gx.ravel(), gy.ravel()]) + offset_xy
    z = scene.ground_z(xy)
    return PointSet(ids=np.arange(1, len(xy) + 1), xyz=np.column_stack([xy, z]))


def test_recovers_known_offset_within_1cm(terrain):
    offset = 0.137
    pts = terrain.points + [0.0, 0.0, offset]
    chk = _checks(terrain)
    rep = vertical_check(pts, chk, classification=terrain.classification, classes=(2,))
    assert rep.n_check == len(chk)
    assert set(rep.flag.tolist()) == {"ok"}
    assert abs(rep.stats.mean[2] - offset) < 0.01
    # the spread is TIN interpolation of 2 cm noise: small
    assert rep.stats.std[2] < 0.03
    assert rep.nssda.accuracy_z == pytest.approx(1.96 * rep.stats.rmse[2])
    d = rep.to_dict()
    assert d["rmse_x"] is None or np.isnan(d["rmse_x"])
    assert d["vertical"]["flags"]["ok"] == len(chk)


def test_vegetation_excluded_by_class(terrain):
    # with every point in the TIN (tree crowns too) the heights are biased upward
    chk = _checks(terrain)
    ground_only = vertical_check(terrain.points, chk, classification=terrain.classification)
    everything = vertical_check(terrain.points, chk)
    assert abs(ground_only.stats.mean[2]) < 0.01
    assert everything.stats.max_abs[2] >= ground_only.stats.max_abs[2]


def test_outside_and_sparse_flagged(terrain):
    chk = _checks(terrain, n=9)
    g = terrain.points[terrain.classification == 2]
    # carve a 12 m hole of missing ground around the first check point
    hole = np.hypot(*(g[:, :2] - chk.xyz[0, :2]).T) < 6.0
    far = PointSet(ids=np.array([100]), xyz=np.array([[g[:, 0].max() + 50.0, g[:, 1].mean(), 0.0]]))
    both = PointSet(ids=np.concatenate([chk.ids, far.ids]), xyz=np.vstack([chk.xyz, far.xyz]))
    rep = vertical_check(g[~hole], both, max_edge=3.0)
    flags = dict(zip(rep.ids.tolist(), rep.flag.tolist(), strict=True))
    assert flags[100] == "outside_tin"
    assert flags[1] in {"sparse_tin", "no_ground_nearby"}
    assert all(flags[i] == "ok" for i in range(2, 10))
    assert rep.n_check == 8 and any("flagged" in w for w in rep.warnings)


def test_order_independent(terrain):
    chk = _checks(terrain, n=16)
    rng = np.random.default_rng(0)
    perm = rng.permutation(len(terrain.points))
    a = vertical_check(terrain.points, chk, classification=terrain.classification)
    b = vertical_check(
        terrain.points[perm],
        chk.subset(rng.permutation(len(chk))),
        classification=terrain.classification[perm],
    )
    np.testing.assert_allclose(a.dz, b.dz, atol=1e-9)
    assert a.ids.tolist() == b.ids.tolist()


def test_exact_plane_interpolation():
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 50, (2000, 2)) + [700000.0, 6600000.0]
    z = 100 + 0.05 * (xy[:, 0] - 700000) - 0.02 * (xy[:, 1] - 6600000)
    pts = np.column_stack([xy, z])
    cxy = rng.uniform(10, 40, (30, 2)) + [700000.0, 6600000.0]
    cz = 100 + 0.05 * (cxy[:, 0] - 700000) - 0.02 * (cxy[:, 1] - 6600000) - 0.25
    rep = vertical_check(pts, PointSet(np.arange(30), np.column_stack([cxy, cz])))
    np.testing.assert_allclose(rep.dz, 0.25, atol=1e-8)


def test_bad_inputs():
    pts = np.random.default_rng(0).uniform(0, 10, (100, 3))
    chk = PointSet(np.array([1]), np.array([[5.0, 5.0, 0.0]]))
    with pytest.raises(DegenerateGeometryError, match="ground points"):
        vertical_check(pts, chk, classification=np.ones(100, np.uint8))
    with pytest.raises(InvalidPointsError, match="classification"):
        vertical_check(pts, chk, classification=np.ones(5))
    with pytest.raises(InvalidPointsError, match="NaN"):
        vertical_check(pts, PointSet(np.array([1]), np.array([[5.0, np.nan, 0.0]])))
    with pytest.raises(InvalidPointsError, match="duplicate"):
        vertical_check(pts, PointSet(np.array([1, 1]), np.array([[5.0, 5, 0], [6, 6, 0]])))
    line = np.column_stack([np.arange(10.0), np.arange(10.0), np.zeros(10)])
    with pytest.raises(DegenerateGeometryError):
        vertical_check(line, PointSet(np.array([1]), np.array([[5.0, 5.0, 0.0]])), max_edge=100.0)


def test_matches_scipy_linear_interpolation():
    from scipy.interpolate import LinearNDInterpolator

    rng = np.random.default_rng(9)
    xy = rng.uniform(0, 30, (600, 2))
    z = np.sin(xy[:, 0] / 3) + np.cos(xy[:, 1] / 4) + rng.normal(0, 0.05, 600)
    cxy = rng.uniform(3, 27, (40, 2))
    rep = vertical_check(
        np.column_stack([xy, z]), PointSet(np.arange(40), np.column_stack([cxy, np.zeros(40)]))
    )
    order = np.lexsort((xy[:, 1], xy[:, 0]))
    ref = LinearNDInterpolator(xy[order], z[order])(cxy)
    np.testing.assert_allclose(rep.tin_z, ref, atol=1e-9)


def test_real_isprs_sample_leave_out_ground(data_dir):
    """samp24 (ISPRS, real ALS): ground points left out and lowered 10 cm are found 10 cm low."""
    import lidarqa

    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    cls = cloud.classification
    ground = np.flatnonzero(cls == 2)
    pick = np.random.default_rng(0).choice(ground, 100, replace=False)
    keep = np.ones(len(cls), dtype=bool)
    keep[pick] = False
    chk = PointSet(np.arange(100), cloud.xyz[pick] - [0.0, 0.0, 0.10])
    rep = vertical_check(cloud.xyz[keep], chk, classification=cls[keep])
    ok = rep.flag == "ok"
    assert ok.sum() >= 95
    # real terrain, 1 pt/m²: interpolation error is large on slopes, but the median is robust
    assert np.median(rep.dz[ok]) == pytest.approx(0.10, abs=0.03)
    assert set(rep.flag.tolist()) <= {"ok", "outside_tin", "sparse_tin", "no_ground_nearby"}
