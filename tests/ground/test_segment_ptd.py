"""Segment features (§1.3) and segment-based PTD (§1.4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarqa.errors import DegenerateGeometryWarning, InvalidPointsError, OptionError
from lidarqa.ground import (
    PTD,
    SegmentPTD,
    default_grow_radius,
    detect_object_segments,
    filter_errors,
    point_scatterness,
    segment_features,
    segment_ptd,
)


def _plane(normal_axis, n=1000, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    uv = rng.uniform(0, 10, (n, 2))
    w = rng.normal(0, noise, n) if noise else np.zeros(n)
    if normal_axis == "z":
        return np.column_stack([uv, w])
    return np.column_stack([w, uv])  # vertical plane x = 0


def test_orientation_vertical_and_horizontal():
    pts = np.vstack([_plane("z", 400), _plane("x", 400) + [20, 0, 0]])
    lab = np.repeat([0, 1], 400)
    f = segment_features(pts, lab)
    assert f.orientation[0] == pytest.approx(0.0, abs=0.5)
    assert f.orientation[1] == pytest.approx(90.0, abs=0.5)


def test_scatterness_values():
    rng = np.random.default_rng(1234)
    cube = rng.uniform(0, 1, (1000, 3))
    assert np.nanmean(point_scatterness(cube, k=10)) > 0.4
    noisy = _plane("z", 1000, noise=0.02)
    sc = float(np.nanmean(point_scatterness(noisy, k=10)))
    assert 0.02 < sc < 0.2
    g = np.mgrid[0:30, 0:30].reshape(2, -1).T.astype(float)
    assert np.nanmax(point_scatterness(np.column_stack([g, np.zeros(len(g))]))) < 1e-6


@pytest.mark.parametrize("shape", ["isotropic", "planar", "linear", "coincident"])
def test_scatterness_equals_the_lapack_eigenvalues(shape):
    # the closed-form eigenvalues against numpy.linalg.eigvalsh of the same covariances
    rng = np.random.default_rng(7)
    scale = {"isotropic": (1, 1, 1), "planar": (1, 1, 1e-4), "linear": (1, 1e-2, 1e-2),
             "coincident": (0, 0, 0)}[shape]
    pts = rng.normal(size=(3000, 3)) * scale + [5.0e5, 6.0e6, 100.0]
    got = point_scatterness(pts, k=10)
    c = pts - pts.mean(axis=0)
    _, nb = cKDTree(c).query(c, k=10)
    d = c[nb] - c[nb].mean(axis=1, keepdims=True)
    w = np.clip(np.linalg.eigvalsh(np.einsum("nki,nkj->nij", d, d) / 10), 0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        ref = np.where(w[:, 2] > 0, np.sqrt(w[:, 0] / w[:, 2]), np.nan)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    np.testing.assert_allclose(got[~np.isnan(ref)], ref[~np.isnan(ref)], rtol=1e-5, atol=1e-7)


def test_object_rule():
    pts = np.vstack(
        [
            _plane("z", 400),
            _plane("x", 400) + [20, 0, 0],
            np.random.default_rng(0).uniform(0, 1, (400, 3)) + [40, 0, 0],
        ]
    )
    lab = np.repeat([0, 1, 2], 400)
    obj = detect_object_segments(segment_features(pts, lab))
    assert obj.tolist() == [False, True, True]


def _car_curb_scene(seed=0):
    """100×100 m ground in two segments with a 0.3 m curb, plus a car box (4 sides + roof)."""
    rng = np.random.default_rng(seed)
    g = np.mgrid[0:100, 0:100].reshape(2, -1).T.astype(float) + 0.5
    zg = np.where(g[:, 0] < 50, 0.0, 0.3) + rng.normal(0, 0.02, len(g))
    lab_g = np.where(g[:, 0] < 50, 0, 1)
    car_x0, car_x1, car_y0, car_y1, h = 20.2, 24.6, 60.2, 62.0, 1.5
    inside = (g[:, 0] > car_x0) & (g[:, 0] < car_x1) & (g[:, 1] > car_y0) & (g[:, 1] < car_y1)
    g, zg, lab_g = g[~inside], zg[~inside], lab_g[~inside]
    parts, labs = [np.column_stack([g, zg])], [lab_g]
    zs = np.arange(0.0, h + 1e-9, 0.25)
    for k, (a, b, fixed, axis) in enumerate(
        [
            (car_x0, car_x1, car_y0, "y"),
            (car_x0, car_x1, car_y1, "y"),
            (car_y0, car_y1, car_x0, "x"),
            (car_y0, car_y1, car_x1, "x"),
        ]
    ):
        u = np.arange(a, b + 1e-9, 0.25)
        uu, zz = np.meshgrid(u, zs)
        uu, zz = uu.ravel(), zz.ravel()
        if axis == "y":
            p = np.column_stack([uu, np.full(uu.size, fixed), zz])
        else:
            p = np.column_stack([np.full(uu.size, fixed), uu, zz])
        parts.append(p + rng.normal(0, 0.01, p.shape))
        labs.append(np.full(len(p), 2 + k))
    rx, ry = np.meshgrid(np.arange(car_x0, car_x1, 0.25), np.arange(car_y0, car_y1, 0.25))
    roof = np.column_stack([rx.ravel(), ry.ravel(), np.full(rx.size, h)])
    parts.append(roof + rng.normal(0, 0.01, roof.shape))
    labs.append(np.full(len(roof), 6))
    return np.vstack(parts), np.concatenate(labs)


def test_segment_ptd_car_and_curb():
    pts, lab = _car_curb_scene()
    r = SegmentPTD().run(pts, labels=lab)
    assert r.ground_mask[lab == 0].all() and r.ground_mask[lab == 1].all()
    assert not r.ground_mask[lab >= 2].any()
    assert r.object_segments[2:6].all()  # car sides are façade-like
    # the functional form gives the same mask
    np.testing.assert_array_equal(segment_ptd(pts, lab, r.object_segments), r.ground_mask)


def test_point_ptd_takes_car_side_bottom_rows():
    pts, lab = _car_curb_scene()
    g = PTD().ground_mask(pts)
    side = (lab >= 2) & (lab <= 5)
    assert g[side & (pts[:, 2] < 0.1)].any()  # lower parts of the object accepted


def test_segment_ptd_with_surface_growing_on_synthetic_scene():
    from lidarqa.testing import make_scene

    sc = make_scene(seed=3, size=(60.0, 60.0), density=4.0)
    r = SegmentPTD().run(sc.points)
    e = filter_errors(sc.is_ground, r.ground_mask)
    assert np.isfinite(r.grow_radius) and r.grow_radius > 0
    assert e.total < 0.10


def test_default_grow_radius_scales_with_density():
    rng = np.random.default_rng(0)
    sparse = rng.uniform(0, 100, (10_000, 2))  # 1 pt/m²
    dense = rng.uniform(0, 100, (160_000, 2))  # 16 pts/m²
    r1 = default_grow_radius(np.column_stack([sparse, np.zeros(len(sparse))]))
    r2 = default_grow_radius(np.column_stack([dense, np.zeros(len(dense))]))
    assert r1 == pytest.approx(2.5, rel=0.2)
    assert r2 == pytest.approx(2.5 / 4, rel=0.2)


def test_permutation_invariance_segment_ptd():
    pts, lab = _car_curb_scene(1)
    perm = np.random.default_rng(5).permutation(len(pts))
    a = SegmentPTD().ground_mask(pts, labels=lab)
    b = SegmentPTD().ground_mask(pts[perm], labels=lab[perm])
    np.testing.assert_array_equal(a[perm], b)


def test_no_object_free_segment_warns():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (200, 3))
    with pytest.warns(DegenerateGeometryWarning):
        g = SegmentPTD(unsegmented="drop").ground_mask(pts, labels=np.zeros(200, dtype=int))
    assert not g.any()


def test_bad_input():
    assert SegmentPTD().ground_mask(np.zeros((0, 3))).shape == (0,)
    g = SegmentPTD().ground_mask(np.array([[0.0, 0, 0], [1, 0, 0]]))
    assert g.shape == (2,)
    line = np.column_stack([np.zeros(30), np.zeros(30), np.linspace(0, 10, 30)])
    with pytest.warns(
        DegenerateGeometryWarning
    ):  # a vertical line is façade-like: nothing is ground
        g = SegmentPTD().ground_mask(line)
    assert g.shape == (30,) and not g.any()
    flat = np.column_stack([np.random.default_rng(0).uniform(0, 30, (400, 2)), np.full(400, 2.0)])
    assert SegmentPTD().ground_mask(flat).mean() > 0.99
    with pytest.raises(InvalidPointsError):
        SegmentPTD().ground_mask(np.array([[0.0, 0, np.nan]] * 4))
    with pytest.raises(InvalidPointsError):
        SegmentPTD().ground_mask(flat, labels=np.zeros(3))
    with pytest.raises(OptionError):
        SegmentPTD(unsegmented="keep")


def _terrain_block_curb():
    """60×60 m terrain grid (1 m), a 10×10 m block at +3 m and a 10×10 m curb patch at +0.2 m."""
    g = np.mgrid[0:60, 0:60].reshape(2, -1).T.astype(float) + 0.5
    block = (g[:, 0] > 10) & (g[:, 0] < 20) & (g[:, 1] > 10) & (g[:, 1] < 20)
    curb = (g[:, 0] > 35) & (g[:, 0] < 45) & (g[:, 1] > 35) & (g[:, 1] < 45)
    z = 0.01 * g[:, 0] + np.where(block, 3.0, 0.0) + np.where(curb, 0.2, 0.0)
    lab = np.where(block, 1, np.where(curb, 2, 0))
    return np.column_stack([g, z]), lab


def test_border_tests_raised_block_connected_curb():
    from lidarqa.ground.segment_ptd import _border_tests

    pts, lab = _terrain_block_curb()
    par = SegmentPTD(raised_step=2.0)
    ground = lab == 0
    conn, raised = _border_tests(pts, lab, lab > 0, ground, 3, par)
    assert raised.tolist() == [False, True, False]  # the block is a step up, the curb is not
    assert conn.tolist() == [False, False, True]  # the curb patch joins the terrain smoothly
    # the test is relative to other segments: the terrain is never raised against itself
    _, raised0 = _border_tests(pts, lab, lab >= 0, np.ones(len(pts), dtype=bool), 3, par)
    assert not raised0[0] and raised0[1]


def test_raised_segment_removed_and_curb_connected():
    pts, lab = _terrain_block_curb()
    # the block is accepted by the vote (a large iteration distance lets the TIN climb it)
    loose = dict(iter_distance=4.0, iter_angle=60.0, cell_size=30.0, min_tested=1)
    base = SegmentPTD(**loose).run(pts, labels=lab)
    assert base.ground_mask[lab == 1].all()
    r = SegmentPTD(**loose, raised_step=2.0).run(pts, labels=lab)
    assert not r.ground_mask[lab == 1].any()
    assert r.ground_mask[lab != 1].all()
    # a strict vote rejects the curb patch; the connection pass takes it back
    strict = dict(iter_distance=0.1, iter_angle=1.0, cell_size=30.0, final_distance=0.0)
    s0 = SegmentPTD(**strict).run(pts, labels=lab)
    s1 = SegmentPTD(**strict, connect_min_size=20).run(pts, labels=lab)
    if not s0.ground_mask[lab == 2].all():
        assert s1.ground_mask[lab == 2].all()
    assert not s1.ground_mask[lab == 1].any()


def test_below_pass_takes_points_under_the_ground_surface():
    rng = np.random.default_rng(0)
    g = np.mgrid[0:80, 0:80].reshape(2, -1).T.astype(float) + 0.5
    pit = ((g - 30.0) ** 2).sum(axis=1) < 9.0
    z = np.where(pit, -2.0, 0.0) + rng.normal(0, 0.01, len(g))
    pts = np.column_stack([g, z])
    lab = np.where(pit, -1, 0)  # pit points unsegmented, the rest one segment
    strict = dict(iter_distance=0.1, iter_angle=1.0, cell_size=20.0, final_distance=0.0)
    a = SegmentPTD(**strict).ground_mask(pts, labels=lab)
    b = SegmentPTD(**strict, below_pass=True).ground_mask(pts, labels=lab)
    assert a[~pit].all() and a[pit].mean() < 0.5  # the strict densification misses the pit
    assert b.all()
    with pytest.raises(OptionError):
        SegmentPTD(below_distance=-1.0)
    with pytest.raises(OptionError):
        SegmentPTD(connect_min_size=1.5)


def test_permutation_invariance_als_preset():
    from lidarqa.ground import ALS_SEGMENT_PARAMS

    pts, lab = _car_curb_scene(2)
    perm = np.random.default_rng(7).permutation(len(pts))
    f = SegmentPTD(**ALS_SEGMENT_PARAMS)
    a = f.ground_mask(pts, labels=lab)
    b = f.ground_mask(pts[perm], labels=lab[perm])
    np.testing.assert_array_equal(a[perm], b)


@pytest.mark.parametrize("cell", [1e-300, 1e-12, 1e150])
def test_thinning_cells_never_overflow(cell):
    """A cell far finer (or coarser) than the points' extent: no int64 overflow, same winners.

    `--min-edge-length 1e-300` once gave int64-overflowed cell keys and a segfault.
    """
    from lidarqa.ground.segment_ptd import _thin

    rng = np.random.default_rng(4)
    xyz = np.column_stack([rng.uniform(6.5e5, 6.6e5, 500), rng.uniform(6.8e6, 6.81e6, 500),
                           rng.uniform(0, 50, 500)])
    xyz[1, :2] = xyz[0, :2]  # a shared position: one cell at any size
    idx = np.arange(500)
    kept = _thin(xyz, idx, cell)
    if cell < 1.0:  # every distinct position is its own cell: all but the higher duplicate
        expect = np.delete(idx, 1 if xyz[1, 2] > xyz[0, 2] else 0)
    else:  # one cell holds everything: the lowest point
        expect = np.array([int(np.argmin(xyz[:, 2]))])
    np.testing.assert_array_equal(kept, expect)


def test_ground_with_tiny_min_edge_length():
    """The API path of the same option: a ground mask, as with no thinning at all."""
    from lidarqa.ground import classify_ground
    from lidarqa.testing import make_scene

    pts = make_scene(seed=3, size=(40.0, 40.0), density=4.0).points
    a = classify_ground(pts, min_edge_length=1e-300).ground_mask
    b = classify_ground(pts, min_edge_length=0.0).ground_mask
    assert 0 < a.sum() < len(a)
    np.testing.assert_array_equal(a, b)
