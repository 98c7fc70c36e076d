"""Dense clouds filtered on their lowest point per cell (segment-PTD ``filter_density``).

Scenes with known truth: the thinned filter must be at least as right as filtering
every point, keep steep ground and curbs, leave low vegetation out, and be
independent of input order; the automatic parameters switch it on for dense
airborne clouds only; catalogs estimate the surface-growing radius the same way.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from wet_street import street_over_echoes

from lidarqa.errors import OptionError
from lidarqa.ground import (
    FILTER_DENSITY,
    SegmentPTD,
    auto_parameters,
    classify_ground,
    filter_errors,
    measure_cloud,
)
from lidarqa.ground.auto import FILTER_MIN_EDGE
from lidarqa.ground.segment_ptd import SURFACE_SHARE, SURFACE_SLAB, surface_lowest, thin_lowest
from lidarqa.testing import make_scene

# the module (its name is shadowed by the function lidarqa.ground.segment_ptd)
segment_ptd_module = sys.modules[thin_lowest.__module__]


def _reference_thin(p: np.ndarray, cell: float):
    """Lowest point per cell by a lexicographic sort (ties by x, y, z, then index)."""
    q = np.floor(p[:, :2] / cell)
    order = np.lexsort((np.arange(len(p)), p[:, 1], p[:, 0], p[:, 2], q[:, 1], q[:, 0]))
    qs = q[order]
    first = np.ones(len(p), dtype=bool)
    first[1:] = (qs[1:] != qs[:-1]).any(axis=1)
    return order[first]


def _rounded_cloud(rng: np.random.Generator, n: int, dup: bool) -> np.ndarray:
    """n points on a 0.1 m lattice (ties in every coordinate), half repeated when `dup`."""
    p = np.round(rng.uniform(-20, 20, (n, 3)), 1) + [600000.0, 6800000.0, 0.0]
    return np.vstack([p, p[: n // 2]]) if dup else p


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 400),
    cell=st.sampled_from([0.05, 0.5, 1.0, 7.3]),
    dup=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_thin_lowest_matches_a_sort_and_ignores_order(n, cell, dup, seed):
    rng = np.random.default_rng(seed)
    p = _rounded_cloud(rng, n, dup)
    win, inv, cells = thin_lowest(p, cell)
    ref = _reference_thin(p, cell)
    assert sorted(map(tuple, p[win])) == sorted(map(tuple, p[ref]))
    # every point maps to its own cell's winner
    np.testing.assert_array_equal(np.floor(p[win[inv], :2] / cell), np.floor(p[:, :2] / cell))
    np.testing.assert_array_equal(cells, np.floor(p[win, :2] / cell))
    assert (p[win[inv], 2] <= p[:, 2]).all()
    perm = rng.permutation(len(p))
    w2, _, _ = thin_lowest(p[perm], cell)
    assert sorted(map(tuple, p[perm][w2])) == sorted(map(tuple, p[win]))


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 600),
    cell=st.sampled_from([0.05, 0.5, 1.4, 7.3, 100.0]),
    dup=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_thin_median_matches_a_lexsort(n, cell, dup, seed):
    # the terrain model's median point per cell: (z, x, y, index) order, middle one;
    # 100 m cells put hundreds of points in one cell (quickselect over many rows)
    rng = np.random.default_rng(seed)
    p = _rounded_cloud(rng, n, dup)
    idx = np.sort(rng.choice(len(p), max(1, len(p) * 3 // 4), replace=False))
    q = p[idx]
    key = np.floor(q[:, :2] / cell)
    order = np.lexsort((np.arange(len(q)), q[:, 1], q[:, 0], q[:, 2], key[:, 1], key[:, 0]))
    ks = key[order]
    starts = np.flatnonzero(np.r_[True, (ks[1:] != ks[:-1]).any(axis=1)])
    ends = np.r_[starts[1:], len(q)]
    ref = np.sort(idx[order[(starts + ends - 1) // 2]])
    np.testing.assert_array_equal(segment_ptd_module._thin_median(p, idx, cell), ref)


@pytest.fixture(scope="module")
def dense_scene():
    return make_scene(seed=3, size=(120.0, 120.0), density=20.0, origin=(600000.0, 6800000.0, 50.0))


def test_auto_switches_it_on_for_dense_clouds_only(dense_scene):
    m = measure_cloud(dense_scene.points)
    p, src, regime = auto_parameters(m, "segment-ptd")
    assert regime == "als-dense"
    assert p["filter_density"] == FILTER_DENSITY and src["filter_density"] == "preset"
    assert p["min_edge_length"] == FILTER_MIN_EDGE and src["min_edge_length"] == "preset"
    rng = np.random.default_rng(0)
    for density in (1.0, 1.4 * FILTER_DENSITY):  # sparse, or too close to the target
        n = int(density * 100 * 100)
        pts = np.column_stack([rng.uniform(0, 100, (n, 2)), rng.normal(0, 0.02, n)])
        chosen = auto_parameters(measure_cloud(pts), "segment-ptd")[0]
        assert "filter_density" not in chosen and "min_edge_length" not in chosen
    # a dense ground-based scan is thinned too, without the airborne terrain-first pass
    mls = auto_parameters(m, "segment-ptd", sensor="mls")[0]
    assert mls["filter_density"] == FILTER_DENSITY and "terrain_density" not in mls
    assert "filter_density" not in auto_parameters(m, "ptd")[0]


def test_as_right_as_filtering_every_point(dense_scene):
    truth = dense_scene.classification == 2
    auto = classify_ground(dense_scene.points)
    assert auto.parameters["filter_density"] == FILTER_DENSITY
    full = classify_ground(dense_scene.points, filter_density=0.0)
    e_auto = filter_errors(truth, auto.ground_mask)
    e_full = filter_errors(truth, full.ground_mask)
    assert e_auto.total <= e_full.total + 0.002, (e_auto.total, e_full.total)
    assert e_auto.kappa >= 0.95
    # the labels cover every candidate: each point carries its cell's segment
    assert auto.details.labels.shape == (len(truth),)


def _slope_with_vegetation(slope_deg: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    n = int(20 * 60 * 60)
    xy = rng.uniform(0, 60, (n, 2))
    z = xy[:, 0] * math.tan(math.radians(slope_deg)) + rng.normal(0, 0.03, n)
    veg = rng.random(n) < 0.2  # a shrub layer 0.4-1.5 m above the ground
    z[veg] += rng.uniform(0.4, 1.5, veg.sum())
    return np.column_stack([xy + [700000.0, 6500000.0], z + 100.0]), ~veg


@pytest.mark.parametrize("slope", [0.0, 20.0, 40.0])
def test_joined_points_follow_the_slope_and_leave_vegetation_out(slope):
    p, truth = _slope_with_vegetation(slope)
    g = SegmentPTD(filter_density=4.0, perched_step=2.0).run(p).ground_mask
    kept = g[truth].mean()
    veg_as_ground = g[~truth].mean()
    assert kept >= 0.97, f"{100 * kept:.1f} % of the ground kept on {slope} deg"
    assert veg_as_ground <= 0.01, f"{100 * veg_as_ground:.2f} % of the shrubs as ground"


def test_independent_of_input_order(dense_scene):
    p = dense_scene.points
    perm = np.random.default_rng(1).permutation(len(p))
    par = SegmentPTD(filter_density=4.0)
    a = par.run(p).ground_mask
    b = par.run(p[perm]).ground_mask
    np.testing.assert_array_equal(a[perm], b)


def test_a_sparse_cloud_is_left_as_it_is():
    # one point per cell: thinning changes nothing, so the result is the full filter's
    rng = np.random.default_rng(2)
    ij = np.stack(np.meshgrid(np.arange(60), np.arange(60)), -1).reshape(-1, 2)
    xy = (ij + rng.uniform(0.1, 0.9, ij.shape)) * 1.0  # one point per 1 m cell
    p = np.column_stack([xy, rng.normal(0, 0.02, len(xy))])
    thin = SegmentPTD(filter_density=1.0).run(p).ground_mask
    full = SegmentPTD().run(p).ground_mask
    np.testing.assert_array_equal(thin, full)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), 1e7])
def test_bad_filter_density_is_refused(bad):
    with pytest.raises(OptionError, match="filter_density"):
        SegmentPTD(filter_density=bad)
    with pytest.raises(OptionError, match="join_distance"):
        SegmentPTD(join_distance=-0.1)


@pytest.mark.parametrize("bad", [-1, 2.5])
def test_bad_surface_support_is_refused(bad):
    with pytest.raises(OptionError, match="surface_support must be an integer >= 0"):
        SegmentPTD(surface_support=bad)


def test_catalog_radius_is_the_thinned_clouds(dense_scene):
    from lidarqa.ground import default_grow_radius
    from lidarqa.tiling.ground import catalog_grow_radius

    p = dense_scene.points
    r_cat = catalog_grow_radius(None, sample=p, filter_density=4.0)
    run = SegmentPTD(filter_density=4.0).run(p)
    assert r_cat == pytest.approx(run.grow_radius, rel=1e-12)
    r_dense = max(0.3, default_grow_radius(p - p.min(axis=0), floor=0.0))
    assert r_cat > 1.5 * r_dense  # 4 pts/m2 instead of 20: a wider radius


def test_switching_the_thinning_off_restores_the_tin_edge(dense_scene):
    p = dense_scene.points
    sub = p[(p[:, 0] < p[:, 0].min() + 40) & (p[:, 1] < p[:, 1].min() + 40)]  # a 40 m corner
    on = classify_ground(sub)
    assert on.parameters["filter_density"] == FILTER_DENSITY
    assert on.parameters["min_edge_length"] == FILTER_MIN_EDGE
    off = classify_ground(sub, filter_density=0.0)
    assert off.parameters["filter_density"] == 0.0
    assert off.parameters["min_edge_length"] == SegmentPTD().min_edge_length
    assert off.parameter_sources["min_edge_length"] == "default"
    mine = classify_ground(sub, filter_density=0.0, min_edge_length=3.0)
    assert mine.parameters["min_edge_length"] == 3.0
    assert mine.parameter_sources["min_edge_length"] == "given"


def _road_with_echoes(seed: int = 5):
    """A dense level road (40 pts/m²) with sparse multipath echoes 0.2-0.5 m below it."""
    rng = np.random.default_rng(seed)
    n = 40 * 30 * 30
    xy = rng.uniform(0, 30, (n, 2))
    z = 0.01 * xy[:, 0] + rng.normal(0, 0.01, n)
    echo = rng.random(n) < 0.004  # about one cell in six holds an echo
    z[echo] -= rng.uniform(0.2, 0.5, echo.sum())
    return np.column_stack([xy + [500.0, 500.0], z + 10.0]), echo


@pytest.mark.parametrize("seed", [5, 6])
def test_join_below_keeps_the_road_above_a_multipath_echo(seed):
    p, echo = _road_with_echoes(seed)
    off = SegmentPTD(filter_density=4.0).run(p).ground_mask
    on = SegmentPTD(filter_density=4.0, join_below=True).run(p).ground_mask
    # without it, the road in a cell whose lowest point is an echo is lost
    assert on[~echo].mean() >= 0.995, f"{100 * on[~echo].mean():.2f} % of the road kept"
    assert on[~echo].mean() > off[~echo].mean()
    # it takes no echo the plain join left out, and drops nothing the plain join took
    np.testing.assert_array_equal(on[echo], off[echo])
    assert not (off & ~on).any()


def test_join_below_is_chosen_for_dense_ground_based_scans_only():
    mls = measure_cloud(*_road_with_echoes()[:1])
    for sensor, want in (("mls", True), ("als", False)):
        params, sources, _ = auto_parameters(mls, "segment-ptd", sensor=sensor)
        assert params.get("join_below", False) is want
        if want:
            assert sources["join_below"] == "preset"


@pytest.mark.parametrize("seed", [0, 1])
def test_surface_support_keeps_the_road_above_a_layer_of_echoes(seed):
    p, echo = street_over_echoes(seed)
    band = (p[:, 0] > 1006.5) & (p[:, 0] < 1013.5) & ~echo
    off = SegmentPTD(filter_density=4.0, surface_support=0).run(p).ground_mask
    on = SegmentPTD(filter_density=4.0).run(p).ground_mask
    # with each cell's lowest return, the echoes are the terrain and the road above is lost
    assert off[echo].all() and off[band].mean() < 0.01
    # a return alone under a dense surface is not the cell's terrain evidence
    assert on[~echo].mean() >= 0.999 and not on[echo].any()
    assert classify_ground(p).ground_mask[~echo].mean() >= 0.999  # the default run


def _surface_lowest_brute(p, inv, n_cells, support):
    out = np.empty(n_cells, dtype=np.int64)
    for g in range(n_cells):
        rows = np.flatnonzero(inv == g)
        rows = rows[np.lexsort((rows, p[rows, 1], p[rows, 0], p[rows, 2]))]
        need = max(support + 1, math.ceil(SURFACE_SHARE * rows.size))
        out[g] = rows[0]
        for r in rows:
            z = p[rows, 2]
            if np.count_nonzero((z >= p[r, 2]) & (z <= p[r, 2] + SURFACE_SLAB)) >= need:
                out[g] = r
                break
    return out


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 200),
    support=st.integers(0, 12),
    step=st.sampled_from([0.01, 0.02, 0.05]),
    seed=st.integers(0, 2**16),
)
def test_surface_lowest_equals_a_brute_force_and_ignores_the_input_order(n, support, step, seed):
    # heights on a grid of `step` (ties and points exactly one slab apart), a few cells
    rng = np.random.default_rng(seed)
    p = np.column_stack(
        [rng.uniform(0, 1.5, (n, 2)), np.round(rng.exponential(0.1, n) / step) * step]
    )
    win, inv, cells = thin_lowest(p, 0.5)
    got = surface_lowest(p, inv, win, support)
    np.testing.assert_array_equal(got, _surface_lowest_brute(p, inv, cells.shape[0], support))
    perm = rng.permutation(n)
    win2, inv2, cells2 = thin_lowest(p[perm], 0.5)
    np.testing.assert_array_equal(cells2, cells)
    np.testing.assert_array_equal(perm[surface_lowest(p[perm], inv2, win2, support)], got)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 300), spread=st.sampled_from([5.0, 5000.0]), seed=st.integers(0, 2**16))
def test_cell_planes_same_with_and_without_the_raster_lookup(n, spread, seed):
    # the raster lookup of neighbour cells (compact cells) and the bisection (scattered
    # cells, or forced here) give the same planes
    rng = np.random.default_rng(seed)
    p = np.round(rng.uniform(0, spread, (n, 3)), 1) + [600000.0, 6800000.0, 0.0]
    win, _, cells = thin_lowest(p, 0.5)
    wp = np.ascontiguousarray(p[win])
    wg = rng.random(win.size) < 0.7
    m = segment_ptd_module
    got = m._cell_planes(cells, wp, wg, 0.15, True)
    empty = np.zeros(0, dtype=np.int64)
    want = m._cell_planes_kernel(cells, empty, 0.0, 0.0, 0, wp, wg, 0.15, True)
    np.testing.assert_array_equal(got, want)
