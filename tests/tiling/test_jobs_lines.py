"""Strip-pair line repeatability over a chunked block equals the in-memory comparison."""

from __future__ import annotations

import numpy as np
import pytest
from chunkgrid import grid_chunks, run_fake

from lidarqa.io import PointCloud
from lidarqa.testing import make_building_scene
from lidarqa.tiling.jobs_lines import StripEdgesTask, merge_strip_edges, strip_pairs
from lidarqa.tiling.jobs_vector import fixed_auto_options, vector_features


@pytest.fixture(scope="module")
def scene():
    return make_building_scene(seed=2, roofs=("gable", "flat", "gable"), density=8, strips=3,
                               strip_offset=(0.05, -0.03, 0.04))


def test_every_strip_pair_over_the_block_equals_the_in_memory_run(scene):
    b = scene.classification == 6
    sid = scene.fields["point_source_id"]
    cloud = PointCloud(scene.points[b], {"classification": scene.classification[b],
                                         "point_source_id": sid[b]})
    # data-driven defaults (growing radius, support distance) fixed once for the whole block,
    # as the catalog commands do, so every chunk segments with the same parameters
    seg_opts, edge_opts = fixed_auto_options(cloud.xyz)
    whole = {int(s): vector_features(cloud.xyz[cloud.point_source_id == s], kind="edges",
                                     segment_options=seg_opts, options=edge_opts)
             for s in np.unique(cloud.point_source_id)}
    chunks = grid_chunks(cloud, 40.0, 15.0, origin=(-27.0, -23.0))
    parts = run_fake(cloud, chunks, StripEdgesTask(segment_options=seg_opts,
                                                   edge_options=edge_opts))
    merged = merge_strip_edges(parts[::-1])
    assert sorted(merged) == sorted(whole) and len(merged) == 3
    for s in whole:
        assert len(merged[s]) == len(whole[s]), s  # each edge once, none lost
        assert len(set(merged[s].attributes["chunk"].tolist())) > 1  # the strip spans chunks
    # the plain knee: the whole-area edges carry no point spacing to bound it by
    rows_m = strip_pairs(merged, auto="knee")
    rows_w = strip_pairs(whole, auto="knee")
    assert len(rows_m) == 3  # every pair of the three strips
    for rm, rw in zip(rows_m, rows_w, strict=True):
        assert (rm["test"], rm["model"]) == (rw["test"], rw["model"])
        assert rm["n_pairs_tm"] == rw["n_pairs_tm"]
        for k in ("olhd_tm", "olhd_mt", "lhd", "threshold_tm", "threshold_mt"):
            assert rm[k] == pytest.approx(rw[k], abs=1e-9), k
    # by default each pair's threshold is kept in its strips' sampling band
    for row in strip_pairs(merged):
        lo, hi = row["threshold_floor_m"], row["threshold_ceiling_m"]
        assert 0 < lo < hi and lo <= row["threshold_tm"] <= hi and lo <= row["threshold_mt"] <= hi
    # the merge does not depend on the chunk completion order
    again = merge_strip_edges(parts)
    for s in merged:
        assert np.array_equal(again[s].start, merged[s].start)
