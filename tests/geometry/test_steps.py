"""Step edges: roof boundaries over a lower or missing surface, as airborne scans see them (#14)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.geometry.edges import extract_edges, step_segments
from lidarqa.geometry.segmentation import segment_planes
from lidarqa.testing import make_building_scene, roof_points, score_edges


@pytest.fixture(scope="module")
def als_roofs():
    """Roof points of a flat and a gable building at an ALS density (10 pts/m²), no walls."""
    scene = make_building_scene(seed=1, density=10.0)
    return scene, roof_points(scene)


def test_steps_recover_the_eaves_and_keep_the_ridge(als_roofs):
    scene, pts = als_roofs
    plain = extract_edges(pts)
    steps = extract_edges(pts, steps=True)
    kinds = np.asarray(steps.attributes["kind"])
    assert (kinds == "intersection").sum() == len(plain)  # the plane-pair edges are kept
    s0 = score_edges(plain, scene.edges, max_rms=0.4, min_overlap=0.5)
    s1 = score_edges(steps, scene.edges, max_rms=0.4, min_overlap=0.5)
    found0, n = s0.found_of_kind(scene.edges, "eave")
    found1, _ = s1.found_of_kind(scene.edges, "eave")
    assert n == 6 and found0 == 0  # no wall points: no roof-wall intersection
    assert found1 == n  # every eave is a step edge
    # gable ends (verges) are short, sloped runs: most are found at this density (3 of 4)
    verges, nv = s1.found_of_kind(scene.edges, "verge")
    assert nv == 4 and verges >= 2 and s0.found_of_kind(scene.edges, "verge")[0] == 0
    # the ridge (roof-roof intersection) is found at this density, and only once
    assert s1.found_of_kind(scene.edges, "ridge") == (1, 1)
    ridge = np.asarray(scene.edges.attributes["kind"]) == "ridge"
    r0, r1 = scene.edges.start[ridge][0], scene.edges.end[ridge][0]
    u = (r1 - r0) / np.linalg.norm(r1 - r0)
    mids = 0.5 * (steps.start + steps.end) - r0
    near_ridge = np.linalg.norm(mids - np.outer(mids @ u, u), axis=1) < 0.5
    assert near_ridge.sum() == 1 and kinds[near_ridge][0] == "intersection"


def test_step_segments_lie_on_their_roof(als_roofs):
    _, pts = als_roofs
    seg = segment_planes(pts)
    rows = step_segments(pts, seg)
    assert rows
    for a, b, k, n in rows:
        for p in (a, b):
            assert p @ seg.normal[k] - seg.rho[k] == pytest.approx(0.0, abs=1e-9)
        assert n >= 6 and np.linalg.norm(b - a) >= 1.0
        from scipy.spatial import ConvexHull, Delaunay

        xy = pts[(seg.labels == k) & seg.inliers, :2]
        hull = Delaunay(xy[ConvexHull(xy).vertices])
        mid = 0.5 * (a[:2] + b[:2])
        assert hull.find_simplex(mid) >= 0  # inside the roof


def test_steps_do_not_depend_on_the_input_order(als_roofs):
    _, pts = als_roofs
    perm = np.random.default_rng(1234).permutation(len(pts))
    a = extract_edges(pts, steps=True)
    b = extract_edges(pts[perm], steps=True)
    key = lambda e: np.sort(np.round(np.hstack([e.start, e.end]), 6), axis=0)  # noqa: E731
    np.testing.assert_allclose(key(a), key(b), atol=1e-6)


def test_no_step_where_the_neighbouring_surface_is_at_roof_height():
    """A terrace 0.2 m below the roof (< 0.5 m) is no step, nor are holes in the sampling."""
    rng = np.random.default_rng(1234)
    xy = rng.uniform(0, 20, (6000, 2))
    inner = (np.abs(xy[:, 0] - 10) < 5) & (np.abs(xy[:, 1] - 10) < 5)
    z = np.where(inner, 3.0, 2.8) + rng.normal(0, 0.01, len(xy))
    pts = np.c_[xy, z]
    roof_only = pts[inner]
    seg_all = segment_planes(pts)
    seg_roof = segment_planes(roof_only)
    # alone, the roof's four sides are steps (nothing next to it)
    assert len(step_segments(roof_only, seg_roof)) >= 4
    # with the terrace next to it (random sampling: holes), only the outer boundary is a step
    for a, b, _k, _n in step_segments(pts, seg_all):
        mid = 0.5 * (a[:2] + b[:2])
        assert np.min(np.r_[mid, 20 - mid]) < 1.0
