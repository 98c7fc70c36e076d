"""Relative strip accuracy on synthetic strips with known offsets and noise (issue #14)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.accuracy import _swaths_kernels as K
from lidarqa.accuracy.swaths import QUALITY_LEVELS, assess_swaths, auto_cell_size
from lidarqa.errors import DegenerateGeometryError, InvalidPointsError, OptionError
from lidarqa.testing.strips import make_strip_scene, strip_surface_z


def _cell_q00(points: np.ndarray, cell_size: float, centres: np.ndarray) -> np.ndarray:
    """Oracle: (XᵀX)⁻¹[0,0] of a plane fit per cell, one plain design matrix per cell."""
    h = 0.5 * cell_size
    corner = centres.min(axis=0) - h
    ij = np.floor((points[:, :2] - corner) / cell_size).astype(np.int64)
    cij = np.floor((centres - corner) / cell_size).astype(np.int64)
    key = ij[:, 0] * 1_000_003 + ij[:, 1]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    out = np.empty(len(centres))
    for k, ((cx, cy), (ci, cj)) in enumerate(zip(centres, cij, strict=True)):
        want = ci * 1_000_003 + cj
        lo, hi = np.searchsorted(sorted_key, [want, want + 1])
        p = points[order[lo:hi]]
        x = np.column_stack([np.ones(len(p)), p[:, 0] - cx, p[:, 1] - cy])
        out[k] = np.linalg.inv(x.T @ x)[0, 0]
    return out


def _analytic_rmsdz(scene, report, pair) -> tuple[float, float]:
    """Expected RMSDz of a pair from the exact design of every compared cell."""
    grid = next(g for g in report.grids if (g.strip_a, g.strip_b) == pair)
    rows, cols = np.nonzero(np.isfinite(grid.dz))
    cs = grid.cell_size
    centres = np.column_stack([grid.x0 + (cols + 0.5) * cs, grid.y1 - (rows + 0.5) * cs])
    qa = _cell_q00(scene.points[scene.strip == pair[0]], cs, centres)
    qb = _cell_q00(scene.points[scene.strip == pair[1]], cs, centres)
    var_cell = scene.noise**2 * (qa + qb)
    # smooth cells are all ground (z = z0 + 0.01 x): a shift dx changes its height by -0.01 dx
    t = scene.offset(*pair)
    dz_true = t[2] - scene.params.get("ground_slope", 0.01) * t[0]
    return float(np.sqrt(dz_true**2 + var_cell.mean())), float(np.sqrt(0.5 * var_cell.mean()))


def test_zero_offset_rmsdz_is_sqrt2_cell_sigma():
    scene = make_strip_scene(2, noise=0.03, length=200.0, seed=11)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0)
    (pair,) = rep.pairs
    expected, sigma_cell = _analytic_rmsdz(scene, rep, (1, 2))
    assert pair.n_cells > 3000
    assert pair.rmsdz == pytest.approx(np.sqrt(2) * sigma_cell, rel=0.05)
    assert pair.rmsdz == pytest.approx(expected, rel=0.05)
    assert abs(pair.mean) < 3 * pair.std / np.sqrt(pair.n_cells)


@pytest.mark.parametrize("seed", [1, 2])
def test_two_strips_rmsdz_and_offset(seed):
    truth = [[0.0, 0.0, 0.0], [0.06, -0.04, 0.05]]
    scene = make_strip_scene(2, offsets=truth, noise=0.02, seed=seed)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0)
    (pair,) = rep.pairs
    expected, _ = _analytic_rmsdz(scene, rep, (1, 2))
    assert pair.rmsdz == pytest.approx(expected, rel=0.05)
    (off,) = rep.pair_offsets
    t = scene.offset(1, 2)
    for est, sd, true in zip(
        (off.dx, off.dy, off.dz), (off.sigma_dx, off.sigma_dy, off.sigma_dz), t, strict=True
    ):
        assert abs(est - true) <= 3 * sd
        assert abs(est - true) <= 0.01
    # E4 of two strips: the spread of their two heights, |dz| / √2
    assert rep.e4 == pytest.approx(abs(off.dz) / np.sqrt(2), rel=1e-6)


def test_three_strip_network_recovers_every_strip():
    truth = np.array([[0.0, 0.0, 0.0], [0.05, -0.03, 0.04], [-0.02, 0.07, -0.03]])
    scene = make_strip_scene(3, offsets=truth, noise=0.02, seed=5)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, reference_strip=1)
    assert rep.reference_strip == 1
    assert [(p.strip_a, p.strip_b) for p in rep.pairs] == [(1, 2), (2, 3)]  # 1 and 3 do not meet
    for p in rep.pairs:
        expected, _ = _analytic_rmsdz(scene, rep, (p.strip_a, p.strip_b))
        assert p.rmsdz == pytest.approx(expected, rel=0.05)
    net = {o.strip_b: o for o in rep.network_offsets}
    assert set(net) == {1, 2, 3}
    for s in (2, 3):
        o, t = net[s], scene.offset(1, s)
        for est, sd, true in zip(
            (o.dx, o.dy, o.dz), (o.sigma_dx, o.sigma_dy, o.sigma_dz), t, strict=True
        ):
            assert abs(est - true) <= max(3 * sd, 1e-4)
            assert abs(est - true) <= 0.01
    assert rep.e4 == pytest.approx(np.std(truth[:, 2], ddof=1), abs=0.005)


def test_network_with_a_loop_adjusts_redundant_pairs():
    # 70 % side overlap: strips 1 and 3 also meet, so the three pairs close a loop
    truth = np.array([[0.0, 0.0, 0.0], [0.05, -0.03, 0.04], [-0.02, 0.07, -0.03]])
    scene = make_strip_scene(3, offsets=truth, noise=0.02, overlap=0.7, length=60.0, seed=8)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, reference_strip=1)
    assert [(p.strip_a, p.strip_b) for p in rep.pairs] == [(1, 2), (1, 3), (2, 3)]
    net = {o.strip_b: o for o in rep.network_offsets}
    pair = {(o.strip_a, o.strip_b): o for o in rep.pair_offsets}
    for s in (2, 3):
        o, t = net[s], scene.offset(1, s)
        for est, sd, true in zip(
            (o.dx, o.dy, o.dz), (o.sigma_dx, o.sigma_dy, o.sigma_dz), t, strict=True
        ):
            assert abs(est - true) <= 3 * sd and abs(est - true) <= 0.01
        # the loop adds a second path from strip 1: the network is at least as precise
        p = pair[(1, s)]
        assert o.sigma_dz <= p.sigma_dz * 1.0001 and o.sigma_dx <= p.sigma_dx * 1.0001
    # the pair 2→3 measured alone agrees with the network's (1→3) − (1→2)
    d12 = np.array([net[2].dx, net[2].dy, net[2].dz])
    d13 = np.array([net[3].dx, net[3].dy, net[3].dz])
    d23 = np.array([pair[(2, 3)].dx, pair[(2, 3)].dy, pair[(2, 3)].dz])
    assert np.abs(d13 - d12 - d23).max() < 0.01


@pytest.mark.slow  # ~30 s: 1000 Monte Carlo strip pairs
def test_sigma_calibrated_by_monte_carlo():
    """Reported σ over the empirical spread of 600 independent scenes: within [0.9, 1.1]."""
    truth = [[0.0, 0.0, 0.0], [0.03, -0.02, 0.02]]
    est, sig = [], []
    for seed in range(600):
        scene = make_strip_scene(
            2, offsets=truth, noise=0.03, length=50.0, strip_width=40.0, seed=seed
        )
        rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, return_grids=False)
        (o,) = rep.pair_offsets
        est.append((o.dx, o.dy, o.dz))
        sig.append((o.sigma_dx, o.sigma_dy, o.sigma_dz))
    est, sig = np.array(est), np.array(sig)
    ratio = sig.mean(axis=0) / est.std(axis=0, ddof=1)
    assert np.all((ratio >= 0.9) & (ratio <= 1.1)), ratio
    bias = np.abs(est.mean(axis=0) - np.array(truth[1]))
    assert np.all(bias <= 3 * est.std(axis=0, ddof=1) / np.sqrt(len(est)) + 2e-4)


def test_rotations_optional_and_small():
    scene = make_strip_scene(2, offsets=[[0, 0, 0], [0.04, 0.02, -0.03]], seed=3)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, rotations=True)
    (o,) = rep.pair_offsets
    assert o.rotations is not None and len(o.sigma_rotations) == 3
    for r, s in zip(o.rotations, o.sigma_rotations, strict=True):
        assert abs(r) <= 4 * s  # no rotation in the scene
    assert abs(o.dz - (-0.03)) <= 0.01


def test_repeatability_matches_noise_and_quality_level():
    scene = make_strip_scene(2, noise=0.02, seed=4)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, quality_level="QL0")
    assert rep.thresholds["repeatability"] == QUALITY_LEVELS["QL0"][0]
    whole = assess_swaths(scene.points, scene.strip, cell_size=1.0, range_cell=1.0)
    for r, w in zip(rep.repeatability, whole.repeatability, strict=True):
        assert r.rmse == pytest.approx(0.02, rel=0.05)
        # default range cells: ~2 point spacings, about 4 points: range ≈ 2σ (USGS practice)
        assert r.range_cell == 0.5 and r.n_range_cells > 3 * r.n_cells
        assert 1.4 * r.rmse < r.median_range < 2.8 * r.rmse
        assert r.passed == (r.median_range <= 0.04)
        # whole 1 m cells: ~16 points, range ≈ 3.5σ
        assert w.range_cell == 1.0 and w.n_range_cells == w.n_cells
        assert 3.0 * w.rmse < w.median_range < 4.2 * w.rmse
    noisy = make_strip_scene(2, noise=0.04, seed=4)
    rep2 = assess_swaths(noisy.points, noisy.strip, cell_size=1.0, max_roughness=0.1)
    assert all(not r.passed for r in rep2.repeatability)  # ~0.08 m ranges > 0.06 m


def test_sub_cell_ranges_match_a_per_sub_cell_oracle():
    rng = np.random.default_rng(7)
    pts = np.column_stack(
        [rng.uniform(0, 5, 2000), rng.uniform(0, 3, 2000), rng.normal(10.0, 0.05, 2000)]
    )
    grid = K.grid_for(pts[:, :2], 1.0)
    keys, sums = K.cell_sums(pts, grid, 10.0)
    planes = K.fit_cell_planes(keys, sums, 10.0, min_points=4, min_spread=0.0)
    selected = planes.ok.copy()
    selected[::4] = False  # some cells left out
    sub_keys, ranges = K.residual_ranges(pts, grid, planes, selected, split=3, min_points=3)
    got = dict(zip(sub_keys.tolist(), ranges.tolist(), strict=True))
    cell = grid.cell_of(pts[:, :2])
    sel = np.flatnonzero(selected)
    want = {}
    for i, k in enumerate(sel):
        cx, cy = grid.centres(planes.keys[k : k + 1])[0]
        p = pts[cell == planes.keys[k]]
        r = p[:, 2] - (planes.a[k] + planes.b[k] * (p[:, 0] - cx) + planes.c[k] * (p[:, 1] - cy))
        col = np.minimum(((p[:, 0] - (cx - 0.5)) * 3).astype(int), 2)
        row = np.minimum(((p[:, 1] - (cy - 0.5)) * 3).astype(int), 2)
        for rr in range(3):
            for cc in range(3):
                m = (row == rr) & (col == cc)
                if m.sum() >= 3:
                    want[i * 9 + rr * 3 + cc] = float(np.ptp(r[m]))
    assert set(got) == set(want)
    for key, v in want.items():
        assert got[key] == pytest.approx(v, abs=1e-12)


def test_pass_fail_against_thresholds():
    scene = make_strip_scene(2, offsets=[[0, 0, 0], [0, 0, 0.12]], noise=0.01, seed=6)
    rep = assess_swaths(scene.points, scene.strip, cell_size=1.0, quality_level="QL2")
    (p,) = rep.pairs
    assert not p.passes_rmsdz and p.passes_max == (p.max_abs <= 0.16)
    assert p.rmsdz > 0.08 and not rep.passed
    rep3 = assess_swaths(scene.points, scene.strip, cell_size=1.0, quality_level="QL3")
    assert rep3.pairs[0].passes_rmsdz


def test_order_independent_and_ids_kept():
    scene = make_strip_scene(2, offsets=[[0, 0, 0], [0.02, 0, 0.01]], seed=7, first_id=706)
    a = assess_swaths(scene.points, scene.strip, cell_size=1.0)
    perm = np.random.default_rng(0).permutation(len(scene.points))
    b = assess_swaths(scene.points[perm], scene.strip[perm], cell_size=1.0)
    assert a.strips == (706, 707)
    assert a.pairs[0].rmsdz == pytest.approx(b.pairs[0].rmsdz, rel=1e-9)
    assert a.pair_offsets[0].dx == pytest.approx(b.pair_offsets[0].dx, rel=1e-6, abs=1e-9)
    np.testing.assert_array_equal(np.isfinite(a.grids[0].dz), np.isfinite(b.grids[0].dz))


def test_chunked_sums_equal_whole():
    scene = make_strip_scene(2, seed=8)
    pts = scene.points[scene.strip == 1]
    grid = K.grid_for(scene.points[:, :2], 1.0)
    whole = K.cell_sums(pts, grid, 100.0)
    parts = [K.cell_sums(pts[i::3], grid, 100.0) for i in range(3)]
    merged = K.merge_sums(parts)
    np.testing.assert_array_equal(whole[0], merged[0])
    np.testing.assert_allclose(whole[1], merged[1], rtol=1e-9, atol=1e-9)


def test_auto_cell_size_follows_density():
    dense = make_strip_scene(2, density=16.0, seed=1)
    sparse = make_strip_scene(2, density=1.0, seed=1)
    assert auto_cell_size(dense.points, dense.strip) == 1.0
    assert auto_cell_size(sparse.points, sparse.strip) == 4.0


def test_surface_is_what_the_scene_samples():
    scene = make_strip_scene(2, noise=0.0, seed=2)
    z = strip_surface_z(scene.points[:, :2])
    np.testing.assert_allclose(scene.points[:, 2], z, atol=1e-9)


# ---- bad input: clear errors
def test_one_strip_only():
    scene = make_strip_scene(2, seed=1)
    with pytest.raises(InvalidPointsError, match="one flight strip"):
        assess_swaths(scene.points, np.ones(len(scene.points), dtype=np.int64))


def test_strips_that_do_not_overlap():
    scene = make_strip_scene(2, overlap=-0.2, seed=1)
    with pytest.raises(DegenerateGeometryError, match="overlap"):
        assess_swaths(scene.points, scene.strip, cell_size=1.0)


def test_no_smooth_surface():
    scene = make_strip_scene(2, noise=0.5, seed=1)
    with pytest.raises(DegenerateGeometryError, match="no smooth surface"):
        assess_swaths(scene.points, scene.strip, cell_size=1.0)


def test_bad_options():
    scene = make_strip_scene(2, seed=1)
    with pytest.raises(OptionError):
        assess_swaths(scene.points, scene.strip, quality_level="QL9")
    with pytest.raises(InvalidPointsError):
        assess_swaths(scene.points, scene.strip[:-1])
    with pytest.raises(InvalidPointsError):
        assess_swaths(scene.points, scene.strip.astype(float))


def test_cell_planes_match_per_cell_lstsq_oracle():
    """The batched normal equations against one plain lstsq per cell (random cloud)."""
    rng = np.random.default_rng(1234)
    pts = np.column_stack(
        [rng.uniform(0, 6, 3000), rng.uniform(0, 4, 3000), rng.normal(50.0, 0.3, 3000)]
    )
    pts[:, 2] += 0.2 * pts[:, 0] - 0.1 * pts[:, 1]
    grid = K.grid_for(pts[:, :2], 1.0)
    keys, sums = K.cell_sums(pts, grid, 50.0)
    planes = K.fit_cell_planes(keys, sums, 50.0, min_points=4, min_spread=0.0)
    cell = grid.cell_of(pts[:, :2])
    centres = grid.centres(keys)
    for k, key in enumerate(keys):
        p = pts[cell == key]
        x = np.column_stack([np.ones(len(p)), p[:, 0] - centres[k, 0], p[:, 1] - centres[k, 1]])
        coef, *_ = np.linalg.lstsq(x, p[:, 2], rcond=None)
        r = p[:, 2] - x @ coef
        assert planes.ok[k]
        np.testing.assert_allclose([planes.a[k], planes.b[k], planes.c[k]], coef, rtol=0, atol=1e-9)
        assert planes.rms[k] == pytest.approx(np.sqrt(r @ r / (len(p) - 3)), rel=1e-6)
        assert planes.q00[k] == pytest.approx(np.linalg.inv(x.T @ x)[0, 0], rel=1e-9)


def test_strip_with_little_smooth_surface_is_not_judged():
    scene = make_strip_scene(3, noise=0.02, seed=12)
    p = scene.points
    patch = (p[:, 0] < 3.0) & (p[:, 1] > 60.0) & (p[:, 1] < 63.0)
    keep = (scene.strip != 3) | patch  # strip 3: a 3 m × 3 m patch only
    rep = assess_swaths(scene.points[keep], scene.strip[keep], cell_size=1.0)
    rep3 = next(r for r in rep.repeatability if r.strip == 3)
    assert not rep3.assessed and rep3.n_cells < 10
    assert all(r.assessed for r in rep.repeatability if r.strip != 3)
    assert any("strip 3" in f for f in rep.flags)


def test_surface_class_mask_defaults_and_fallback():
    from lidarqa.accuracy.swaths import surface_class_mask

    cls = np.array([1, 2, 5, 6, 7, 17])
    np.testing.assert_array_equal(surface_class_mask(cls, 6), [0, 1, 0, 1, 0, 0])
    unclassified = np.array([0, 1, 1, 7, 18])
    np.testing.assert_array_equal(surface_class_mask(unclassified, 5), [1, 1, 1, 0, 0])
    assert surface_class_mask(None, 3).all()


def test_cluster_robust_sigma_close_to_formal_for_independent_noise():
    scene = make_strip_scene(2, offsets=[[0, 0, 0], [0.02, 0.01, 0.03]], length=200.0, seed=13)
    (o,) = assess_swaths(scene.points, scene.strip, cell_size=1.0).pair_offsets
    formal = np.array([o.sigma_dx, o.sigma_dy, o.sigma_dz])
    ratio = np.array(o.sigma_robust) / formal
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio  # ~40 blocks of 10 m: a noisy estimate
