"""Tiled = untiled on real IGN LiDAR HD data (needs ../shared/lidar-data; slow)."""

from __future__ import annotations

import numpy as np
import pytest
from datapaths import SHARED, needs_shared

import lidarqa
from lidarqa.ground import classify_ground
from lidarqa.tiling import make_chunks, open_catalog
from lidarqa.tiling.ground import ground_catalog

pytestmark = [needs_shared, pytest.mark.shared, pytest.mark.slow]

IGN = SHARED / "ign-lidarhd"


def _whole_and_tiled(sources, tmp_path, **opts):
    cat = open_catalog(sources)
    clouds = [lidarqa.read(t.path) for t in cat.tiles]
    whole = lidarqa.io.PointCloud(
        np.concatenate([c.xyz for c in clouds]),
        {k: np.concatenate([c.fields[k] for c in clouds]) for k in clouds[0].fields},
    )
    untiled = classify_ground(whole).ground_mask
    res = ground_catalog(cat, tmp_path / "out", workers=1, **opts)
    tiled = np.concatenate([lidarqa.read(p).fields["classification"] == 2 for p in res.outputs])
    return cat, res, whole, untiled, tiled


@pytest.fixture(scope="module")
def ign_six(tmp_path_factory):
    """The six adjacent 50 m IGN tiles as one catalog, in 50 m chunks (= the tiles)."""
    paths = sorted(IGN.glob("test_data_770*_6277*_LA93_IGN69.laz"))
    assert len(paths) == 6
    return _whole_and_tiled(paths, tmp_path_factory.mktemp("ign"), chunk_size=50.0, evaluate=True)


def test_six_ign_tiles_tiled_equals_untiled(ign_six):
    cat, res, whole, untiled, tiled = ign_six
    assert res.n_chunks >= 6 and res.buffer == 60.0
    agree = float(np.mean(tiled == untiled))
    assert agree >= 0.999, f"agreement {agree:.5f}"
    # ISPRS counts summed over chunks = counts of the assembled labels over the whole area
    from lidarqa.ground import filter_errors

    ref = np.asarray(whole.fields["classification"]) == 2
    e, w = res.evaluation, filter_errors(ref, tiled)
    assert (e.a, e.b, e.c, e.d) == (w.a, w.b, w.c, w.d)


def test_six_ign_tiles_no_roof_as_ground_at_tile_borders(ign_six):
    cat, res, whole, untiled, tiled = ign_six
    roof = np.asarray(whole.fields["classification"]) == 6
    assert roof.sum() > 10_000
    frac = float(np.mean(tiled[roof]))
    assert frac <= 0.01, f"{100 * frac:.2f} % of building points labelled ground"


def test_semis_tile_cut_into_four_chunks_equals_untiled(tmp_path):
    """The 1 km2 sparse tile (0.28 pts/m2) in 500 m chunks, default buffer."""
    path = IGN / "test_semis_2023_0299_6802_LA93_IGN69.laz"
    cat = open_catalog(path)
    assert len(make_chunks(cat, chunk_size=500.0)) >= 4
    _, res, _, untiled, tiled = _whole_and_tiled(path, tmp_path, chunk_size=500.0)
    assert res.n_chunks >= 4
    agree = float(np.mean(tiled == untiled))
    print(f"semis tile, 4 chunks: agreement {agree:.5f}")
    assert agree >= 0.999, f"agreement {agree:.5f}"
