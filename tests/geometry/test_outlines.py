"""Roof outlines as stand-ins for roof-wall and step edges on airborne scans (issue #14)."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.geometry.edges import extract_edges
from lidarqa.testing import make_building_scene, roof_points, score_edges


@pytest.fixture(scope="module")
def roofs_without_walls():
    """Building points of a synthetic scene with the wall points removed (as ALS sees them)."""
    scene = make_building_scene(seed=1)
    return scene, roof_points(scene)


def test_outlines_recover_eaves_and_verges_without_walls(roofs_without_walls):
    scene, pts = roofs_without_walls
    plain = extract_edges(pts)
    both = extract_edges(pts, outlines=True)
    assert "kind" not in plain.attributes  # default output unchanged
    kinds = np.asarray(both.attributes["kind"])
    assert (kinds == "intersection").sum() == len(plain)
    s0 = score_edges(plain, scene.edges, max_rms=0.4, min_overlap=0.5)
    s1 = score_edges(both, scene.edges, max_rms=0.4, min_overlap=0.5)
    for kind in ("eave", "verge"):
        found0, n = s0.found_of_kind(scene.edges, kind)
        found1, _ = s1.found_of_kind(scene.edges, kind)
        assert n > 0 and found0 == 0  # no wall plane, no roof-wall intersection
        assert found1 == n  # every eave and verge has an outline side
    # the ridge is an intersection; its roofs' hull sides along it are not duplicated
    ridges = [s.found_of_kind(scene.edges, "ridge")[0] for s in (s1, s0)]
    assert ridges[0] == ridges[1] == 1
    out = both.attributes["plane_b"][kinds == "outline"]
    assert np.all(out == -1) and np.all(np.isnan(both.attributes["sigma_line"][kinds == "outline"]))


def test_outline_sides_lie_on_their_roof_plane(roofs_without_walls):
    scene, pts = roofs_without_walls
    from lidarqa.geometry.segmentation import segment_planes

    seg = segment_planes(pts)
    edges = extract_edges(pts, segmentation=seg, outlines=True)
    outline = np.asarray(edges.attributes["kind"]) == "outline"
    plane = edges.attributes["plane_a"][outline]
    for p in (edges.start[outline], edges.end[outline]):
        resid = np.einsum("ij,ij->i", p, seg.normal[plane]) - seg.rho[plane]
        np.testing.assert_allclose(resid, 0.0, atol=1e-9)
