"""Edges and corners found chunk by chunk (anchor-in-core rule) equal the in-memory run."""

from __future__ import annotations

import numpy as np
import pytest

from lidarqa.io.vector import PointSet, Segments
from lidarqa.testing import make_building_scene
from lidarqa.tiling.jobs_vector import (
    dedupe_points,
    dedupe_segments,
    in_core,
    keep_anchored,
    merge_vector_parts,
    vector_features,
)


def _grid(points, size, buffer, origin):
    """(id, core, buffered mask) of a regular chunk grid over the points' extent."""
    lo = np.floor((points[:, :2].min(0) - origin) / size).astype(int)
    hi = np.floor((points[:, :2].max(0) - origin) / size).astype(int)
    for r in range(lo[1], hi[1] + 1):
        for c in range(lo[0], hi[0] + 1):
            x0, y0 = origin[0] + c * size, origin[1] + r * size
            core = (x0, y0, x0 + size, y0 + size)
            buf = in_core(points, (x0 - buffer, y0 - buffer, x0 + size + buffer,
                                   y0 + size + buffer))
            yield f"c{c:04d}_r{r:04d}", core, buf


@pytest.fixture(scope="module")
def scene():
    return make_building_scene(seed=1, roofs=("gable", "flat", "gable", "flat"), density=10)


def _chunked(points, kind, size=45.0, buffer=15.0, origin=(-29.0, -25.0)):
    parts, cores = [], []
    for cid, core, buf in _grid(points, size, buffer, np.asarray(origin)):
        cores.append(core)
        parts.append((cid, vector_features(points[buf], kind=kind, core=core)))
    return merge_vector_parts(parts), cores


def _crosses(a, b, cores):
    """Which segments a->b cross a core border (their endpoints lie in different cores)."""
    ca = np.full(len(a), -1)
    cb = np.full(len(b), -1)
    for k, core in enumerate(cores):
        ca[in_core(a, core)] = k
        cb[in_core(b, core)] = k
    return ca != cb


def test_in_core_is_half_open_and_partitions_the_plane():
    rng = np.random.default_rng(0)
    p = np.vstack([rng.uniform(-10, 10, (500, 2)), [[0, 0], [5, 5], [-5, 0]]])
    cores = [(x, y, x + 5, y + 5) for x in range(-10, 10, 5) for y in range(-10, 10, 5)]
    count = sum(in_core(p, c).astype(int) for c in cores)
    assert (count == 1).all()


def test_chunked_edges_equal_the_in_memory_edges(scene):
    pts = scene.points[scene.classification == 6]
    whole = vector_features(pts, kind="edges")
    merged, cores = _chunked(pts, "edges")
    # the grid really cuts buildings: some whole-area edges cross a core border
    assert _crosses(whole.start, whole.end, cores).sum() >= 3
    assert len(merged) == len(whole)
    # each in-memory edge is found exactly once (endpoints within 5 cm, either orientation)
    for s, e in zip(whole.start, whole.end, strict=True):
        d_same = np.maximum(np.linalg.norm(merged.start - s, axis=1),
                            np.linalg.norm(merged.end - e, axis=1))
        d_flip = np.maximum(np.linalg.norm(merged.start - e, axis=1),
                            np.linalg.norm(merged.end - s, axis=1))
        assert (np.minimum(d_same, d_flip) < 0.05).sum() == 1
    # each true ridge/eave/wall edge of the scene is found once, not twice
    truth_mid = 0.5 * (scene.edges.start + scene.edges.end)
    mid = 0.5 * (merged.start + merged.end)
    roof = np.isin(scene.edges.attributes["kind"], ["ridge", "eave", "wall"])
    for m in truth_mid[roof]:
        assert (np.linalg.norm(mid - m, axis=1) < 1.0).sum() <= 1
    assert np.array_equal(merged.ids, np.arange(len(merged)))
    assert len(set(merged.attributes["chunk"].tolist())) > 1  # kept by several chunks


def test_chunked_corners_equal_the_in_memory_corners(scene):
    pts = scene.points[scene.classification == 6]
    whole = vector_features(pts, kind="corners")
    merged, cores = _chunked(pts, "corners")
    assert len(whole) > 5
    assert len(merged) == len(whole)
    d = np.linalg.norm(merged.xyz[:, None, :] - whole.xyz[None, :, :], axis=2)
    assert ((d < 0.05).sum(axis=0) == 1).all()  # each whole-area corner once
    assert ((d < 0.05).sum(axis=1) == 1).all()  # and nothing else


def test_chunk_order_does_not_change_the_merged_output(scene):
    pts = scene.points[scene.classification == 6]
    parts = [(cid, vector_features(pts[buf], kind="corners", core=core))
             for cid, core, buf in _grid(pts, 45.0, 15.0, np.array([-29.0, -25.0]))]
    a = merge_vector_parts(parts)
    b = merge_vector_parts(parts[::-1])
    assert np.array_equal(a.xyz, b.xyz)
    assert np.array_equal(a.attributes["chunk"], b.attributes["chunk"])


def test_keep_anchored_uses_the_midpoint():
    seg = Segments(np.arange(2), [[0, 0, 0], [8, 8, 0]], [[4, 0, 0], [12, 8, 0]])
    kept = keep_anchored(seg, (0, 0, 5, 5))  # midpoints (2, 0) in, (10, 8) out
    assert kept.ids.tolist() == [0]


def test_dedupe_keeps_the_first_of_near_duplicates():
    ps = PointSet(np.arange(4), [[0, 0, 0], [0.01, 0, 0], [1, 0, 0], [0.02, 0.0, 0.0]])
    assert dedupe_points(ps, tolerance=0.05).ids.tolist() == [0, 2]
    seg = Segments(np.arange(3), [[0, 0, 0], [5, 0, 0], [0, 1, 0]],
                   [[5, 0, 0], [0.01, 0, 0], [5, 1, 0]])
    assert dedupe_segments(seg, tolerance=0.05).ids.tolist() == [0, 2]  # flipped duplicate


def test_features_from_planes_cut_by_the_read_box_are_flagged(scene):
    pts = scene.points[scene.classification == 6]
    lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
    whole_box = (lo[0] - 5, lo[1] - 5, hi[0] + 5, hi[1] + 5)
    f = vector_features(pts, kind="edges", box=whole_box)
    assert len(f) > 5 and f.attributes["at_buffer_edge"].sum() == 0
    cut = (lo[0] - 5, lo[1] - 5, lo[0] + 9.0, hi[1] + 5)  # cuts through the first buildings
    sel = in_core(pts, cut)
    assert sel.sum() > 100
    g = vector_features(pts[sel], kind="edges", box=cut)
    assert g.attributes["at_buffer_edge"].sum() >= 1
    open_sides = (-np.inf, -np.inf, np.inf, np.inf)  # nothing beyond: nothing is cut
    assert vector_features(pts[sel], kind="edges", box=open_sides).attributes[
        "at_buffer_edge"].sum() == 0
