"""The automatic threshold between flight strips, bounded by the strips' sampling (#14)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

from lidarqa.accuracy.lines import (
    SAMPLING_BAND,
    SAMPLING_FACTOR,
    match_segments,
    match_strips,
    sampling_threshold_range,
)
from lidarqa.cli.main import cli
from lidarqa.errors import OptionError
from lidarqa.io.vector import Segments


def _strips(shift, n=40, far=0, seed=1234, spacing=(0.5, 0.6)):
    """Two edge sets: the same n edges, the second moved by `shift` m, plus `far` odd ones."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(0, 200, (n, 3))
    end = start + rng.normal(0, 6, (n, 3))
    b_start = start + shift * rng.normal(0, 1, (n, 3))
    b_end = end + shift * rng.normal(0, 1, (n, 3))
    if far:
        b_start = np.vstack([b_start, rng.uniform(300, 400, (far, 3))])
        b_end = np.vstack([b_end, b_start[-far:] + 5.0])
    a = Segments(np.arange(n), start, end,
                 attributes={"point_spacing": np.full(n, spacing[0])})
    m = len(b_start)
    b = Segments(np.arange(m), b_start, b_end,
                 attributes={"point_spacing": np.full(m, spacing[1])})
    return a, b


def test_band_follows_the_sparser_strip():
    a, b = _strips(0.05)
    lo, hi = sampling_threshold_range(a, b)
    assert lo == pytest.approx(SAMPLING_FACTOR * 0.6 / SAMPLING_BAND)
    assert hi == pytest.approx(SAMPLING_FACTOR * 0.6 * SAMPLING_BAND)
    assert hi / lo <= 2.0 / 1.1 + 1e-12  # room for 10 % spacing change between tiles
    assert sampling_threshold_range(a, Segments(b.ids, b.start, b.end)) is None


def test_a_knee_below_the_band_is_raised_and_one_inside_is_kept():
    # strips agree to ~1 cm, 10 odd edges far away: a knee far below the sampling (M -> T)
    a, b = _strips(0.01, far=10)
    knee = match_segments(a, b)
    lo, hi = sampling_threshold_range(a, b)
    assert knee.threshold_found_mt and knee.threshold_mt < lo
    row = match_strips(a, b)
    assert row["threshold_mt"] == pytest.approx(lo) and "raised" in row["threshold_rule_mt"]
    # T -> M has no knee (every edge has a twin): the ceiling, not the farthest edge
    assert not knee.threshold_found_tm and row["threshold_tm"] == pytest.approx(hi)
    assert (row["threshold_floor_m"], row["threshold_ceiling_m"]) == pytest.approx((lo, hi))
    # a knee inside the band is the knee
    mid = 0.5 * (lo + hi)
    r = match_segments(a, b, threshold_range=(0.0, 10.0))
    assert r.threshold_mt == knee.threshold_mt and r.auto_mt.reason == knee.auto_mt.reason
    r = match_segments(a, b, threshold_range=(mid, mid))
    assert r.threshold_tm == r.threshold_mt == pytest.approx(mid)
    # a fixed threshold wins over the band, and "knee" is the plain knee
    assert match_strips(a, b, threshold=0.3)["threshold_tm"] == 0.3
    assert match_strips(a, b, auto="knee")["threshold_mt"] == knee.threshold_mt


def test_no_knee_falls_back_to_the_ceiling_not_the_farthest_edge():
    a, b = _strips(0.0, n=2, far=1)  # too few segments for a knee
    r = match_segments(a, b, threshold_range=(0.5, 1.0))
    assert not r.threshold_found_tm and r.threshold_tm == 1.0
    assert "ceiling" in r.auto_tm.reason


def test_bad_band_is_an_option_error():
    a, b = _strips(0.05)
    with pytest.raises(OptionError, match="threshold_range"):
        match_segments(a, b, threshold_range=(1.0, 0.5))
    for bad in ("wide", (1.0,), ("a", "b"), (float("nan"), 1.0)):
        with pytest.raises(OptionError, match="threshold_range"):
            match_segments(a, b, threshold_range=bad)
    with pytest.raises(OptionError, match="auto"):
        match_strips(a, b, auto="median")


@needs_shared
@pytest.mark.slow  # ~6 s: edges of six real tiles
def test_six_ign_tiles_same_survey_same_threshold(tmp_path):
    """Per 50 m tile thresholds within a factor 2; the block as a catalog: >= 10 pairs <= 0.5 m."""
    tiles = sorted((SHARED / "ign-lidarhd").glob("test_data_770*_6277*_LA93_IGN69.laz"))
    assert len(tiles) == 6
    out = tmp_path / "tiles.json"
    r = CliRunner().invoke(cli, ["-q", "repeatability", *map(str, tiles), "--by-source-id",
                                 "--classes", "6", "--json", str(out)])
    assert r.exit_code == 0, r.output
    rows = json.loads(out.read_text())["results"]
    assert len(rows) == 6
    deltas = [d for row in rows for d in (row["threshold_tm"], row["threshold_mt"])]
    assert max(deltas) / min(deltas) <= 2.0
    # tiles where both strips hold roofs: >= 10 pairs agreeing to <= 0.5 m (one tile has only
    # 192 building points of strip 707, a handful of edges: no figure to expect there)
    full = [row for row in rows if min(row["p"], row["q"]) >= 10]
    assert len(full) == 5
    assert all(min(r_["n_pairs_tm"], r_["n_pairs_mt"]) >= 10 and r_["lhd"] <= 0.5 for r_ in full)
    folder = tmp_path / "block"
    folder.mkdir()
    for t in tiles:
        (folder / t.name).symlink_to(t)
    out = tmp_path / "block.json"
    r = CliRunner().invoke(cli, ["-q", "repeatability", str(folder), "--by-source-id",
                                 "--classes", "6", "--workers", "1", "--json", str(out)])
    assert r.exit_code == 0, r.output
    (row,) = json.loads(out.read_text())["results"]["pairs"]
    assert (row["test"], row["model"]) == ("706", "707")
    assert min(row["n_pairs_tm"], row["n_pairs_mt"]) >= 10 and row["lhd"] <= 0.5
