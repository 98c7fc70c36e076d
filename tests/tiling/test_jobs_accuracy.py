"""checkpoints --vertical and heights run chunk by chunk give the in-memory figures."""

from __future__ import annotations

import json

import numpy as np
import pytest
from chunkgrid import grid_chunks, run_fake

from lidarqa.accuracy.checkpoints import vertical_check
from lidarqa.accuracy.heights import assess_heights
from lidarqa.io import PointCloud
from lidarqa.testing import make_scene, sample_checkpoints
from lidarqa.tiling.jobs_accuracy import (
    CheckSpacingTask,
    HeightsTask,
    VerticalCheckTask,
    chunks_with_points,
    max_edge_from_spacing,
    merge_heights,
    merge_vertical,
)


@pytest.fixture(scope="module")
def scene():
    # at projected-coordinate magnitudes, as real deliveries are: differences of nearby
    # coordinates are then exact, and the chunked figures equal the in-memory ones bit for bit
    return make_scene(seed=3, size=(130.0, 90.0), density=6.0, origin=(651000.0, 6862000.0, 80.0))


@pytest.fixture(scope="module")
def cloud(scene):
    return PointCloud(scene.points, {"classification": scene.classification})


def _vertical_chunked(cloud, check, chunks, order=None):
    todo = chunks_with_points(chunks, check.xyz)
    spacing = run_fake(cloud, todo, CheckSpacingTask(check.xyz, classes=(2,)))
    max_edge = max_edge_from_spacing(spacing)
    parts = run_fake(cloud, todo, VerticalCheckTask(check, max_edge=max_edge))
    if order is not None:
        parts = [parts[i] for i in order]
    return merge_vertical(parts, check, max_edge=max_edge), parts, todo


def test_vertical_check_by_chunks_equals_the_in_memory_check(scene, cloud):
    check = sample_checkpoints(scene, 60, seed=4)
    assert len(check) >= 40
    whole = vertical_check(scene.points, check, classification=scene.classification)
    chunks = grid_chunks(cloud, 40.0, 12.0, origin=(3.0, -7.0))
    merged, parts, todo = _vertical_chunked(cloud, check, chunks)
    assert len(todo) >= 4  # check points really spread over several chunks
    assert sum(len(p.index) for p in parts) == len(check)  # each check point owned once
    assert merged.max_edge == whole.max_edge
    assert np.array_equal(merged.ids, whole.ids)
    assert np.array_equal(merged.flag, whole.flag)
    assert 0 < merged.n_ground < whole.n_ground  # only the chunks holding check points are read
    # per point: same triangle, same arithmetic (vertices in XY order), so the same bits
    assert np.array_equal(merged.dz, whole.dz, equal_nan=True)
    a, b = merged.to_dict(), whole.to_dict()
    for k in ("n_check", "rmse_z", "mean_z", "std_z", "max_abs_z"):
        assert a[k] == b[k], k


def test_vertical_merge_is_independent_of_completion_order(scene, cloud):
    check = sample_checkpoints(scene, 30, seed=5)
    chunks = chunks_with_points(grid_chunks(cloud, 40.0, 12.0), check.xyz)
    parts = run_fake(cloud, chunks, VerticalCheckTask(check, max_edge=3.0))
    a = merge_vertical(parts, check, max_edge=3.0)
    shuffled = [parts[i] for i in np.random.default_rng(0).permutation(len(parts))]
    b = merge_vertical(shuffled, check, max_edge=3.0)
    assert len(parts) >= 4
    assert json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)


def test_a_check_point_outside_every_chunk_is_flagged_not_lost(scene, cloud):
    check = sample_checkpoints(scene, 10, seed=6)
    chunks = grid_chunks(cloud, 40.0, 12.0)
    parts = run_fake(cloud, chunks, VerticalCheckTask(check, max_edge=3.0))
    whole = vertical_check(scene.points, check, classification=scene.classification, max_edge=3.0)
    assert merge_vertical(parts, check, max_edge=3.0).n_ground == whole.n_ground  # every chunk
    parts[[i for i, p in enumerate(parts) if len(p.index)][0]] = None  # a failed chunk
    rep = merge_vertical(parts, check, max_edge=3.0)
    assert (rep.flag == "outside_tin").sum() >= 1
    assert len(rep.ids) == len(check)


def test_heights_by_chunks_equal_the_in_memory_run(scene, cloud):
    rng = np.random.default_rng(7)
    lo, hi = scene.points[:, :2].min(0) + 5, scene.points[:, :2].max(0) - 5
    map_xy = lo + rng.random((80, 2)) * (hi - lo)
    gsel = scene.classification == 2
    ref = sample_checkpoints(scene, 40, seed=8).xyz
    ref = ref + np.c_[np.zeros((len(ref), 2)), rng.normal(0, 0.05, len(ref))]
    ref[3, 2] += 1.5  # one gross error for data snooping
    pts = scene.points[gsel]
    opts = {"max_radius": 3.0}
    whole = assess_heights(pts, map_xy, ref, **opts)
    chunks = grid_chunks(cloud, 50.0, 30.0, origin=(1.0, 2.0))
    parts = run_fake(cloud, chunks, HeightsTask(map_xy, ref, options=opts, classes=(2,)))
    assert sum(len(p.ref_index) for p in parts) == len(ref)
    assert sum(len(p.map_index) for p in parts) == len(map_xy)
    merged = merge_heights(parts[::-1], map_xy, ref, options=opts)
    # bit for bit: each fit sums its laser points in (x, y, z) order whatever the chunk
    assert np.array_equal(merged.map_points.height, whole.map_points.height, equal_nan=True)
    assert np.array_equal(merged.map_points.failed, whole.map_points.failed)
    assert np.array_equal(merged.dh, whole.dh, equal_nan=True)
    assert np.array_equal(merged.outlier, whole.outlier)
    assert merged.outlier[3]
    a, b = merged.to_dict(), whole.to_dict()
    for part in ("comparison", "w"):
        for k, v in b[part].items():
            assert a[part][k] == pytest.approx(v, rel=0, abs=0, nan_ok=True), (part, k)


def test_heights_options_that_need_the_whole_set_are_refused():
    from lidarqa.errors import OptionError

    with pytest.raises(OptionError, match="covariance"):
        HeightsTask(np.zeros((1, 2)), np.zeros((1, 3)), options={"covariance": np.eye(1)})


def test_heights_chunk_with_a_too_narrow_buffer_fails_loudly(scene, cloud):
    from lidarqa.errors import TilingError

    rng = np.random.default_rng(7)
    lo, hi = scene.points[:, :2].min(0) + 5, scene.points[:, :2].max(0) - 5
    map_xy = lo + rng.random((40, 2)) * (hi - lo)  # sparse map points: long triangles
    ref = sample_checkpoints(scene, 30, seed=8).xyz
    chunks = grid_chunks(cloud, 50.0, 3.0)
    with pytest.raises(TilingError, match="larger buffer"):
        run_fake(cloud, chunks, HeightsTask(map_xy, ref, options={"max_radius": 3.0},
                                            classes=(2,)))
