"""Real data: flight strips of IGN LiDAR HD tiles matched with each other (repeatability)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

pytestmark = pytest.mark.shared

TILE = "ign-lidarhd/test_data_77055_627755_LA93_IGN69.laz"


@pytest.fixture(scope="module")
def strips(shared_data):
    pytest.importorskip("lidarqa.geometry.edges", reason="edge extraction is not available yet")
    from lidarqa.accuracy.lines_io import load_segments

    path = shared_data / TILE
    a = load_segments(path, classes=[6], source_id=[706])
    b = load_segments(path, classes=[6], source_id=[707])
    return path, a, b


def test_two_strips_of_an_ign_tile_agree(strips):
    from lidarqa.accuracy.lines import match_segments

    _, a, b = strips
    assert len(a) >= 5 and len(b) >= 5
    r = match_segments(a, b)
    assert r.n_pairs_tm >= 3 and r.n_pairs_mt >= 3
    # strips of one survey agree to a few decimetres (edges extracted from ~25 pts/m²)
    assert 0.0 < r.lhd < 1.0
    assert r.lhd == max(r.olhd_tm, r.olhd_mt)
    # symmetric distance: swapping the strips swaps the directions
    s = match_segments(b, a)
    np.testing.assert_allclose(s.nearest_tm, r.nearest_mt, rtol=0, atol=1e-12)
    assert s.lhd == pytest.approx(r.lhd, rel=1e-12)


def test_repeatability_cli_on_an_ign_tile(strips, tmp_path):
    from lidarqa.cli.main import cli

    path, a, b = strips
    out = tmp_path / "rep.json"
    res = CliRunner().invoke(
        cli,
        ["-q", "repeatability", str(path), "--by-source-id", "--classes", "6", "--no-steps",
         "--json", str(out)],
    )
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())["results"]["pairs"]
    assert len(rows) == 1
    assert (rows[0]["test"], rows[0]["model"], rows[0]["p"], rows[0]["q"]) == (
        "706",
        "707",
        len(a),
        len(b),
    )
    assert "*" in res.output


def test_st_barthelemy_strips(shared_data):
    pytest.importorskip("lidarqa.geometry.edges", reason="edge extraction is not available yet")
    from lidarqa.accuracy.lines import match_segments
    from lidarqa.accuracy.lines_io import load_segments

    path = shared_data / "ign-lidarhd/St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz"
    a = load_segments(path, classes=[6], source_id=[4320])
    b = load_segments(path, classes=[6], source_id=[4330])
    assert len(a) >= 50 and len(b) >= 50  # a 100 m × 100 m built-up subset: many roof edges
    r = match_segments(a, b)
    # most edges of one strip find a counterpart in the other, and they agree to < 1 m
    assert r.n_pairs_tm >= 0.5 * len(a) and r.n_pairs_mt >= 0.5 * len(b)
    assert 0.0 < r.lhd < 1.0
    # a fixed, tighter threshold gives fewer pairs and a smaller OLHD (monotone in δ)
    tight = match_segments(a, b, threshold=0.3)
    assert tight.n_pairs_tm < r.n_pairs_tm and tight.olhd_tm < r.olhd_tm
    assert np.all(tight.pairs_tm()[2] <= 0.3)
