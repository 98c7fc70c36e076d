"""``lidarqa repeatability --shared-threshold``: one threshold for all passes of a survey (#14)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

from lidarqa.accuracy.lines import match_segments
from lidarqa.cli.main import cli
from lidarqa.io.vector import Segments, read_segments, write_segments


def _passes(tmp_path, n_files=3, seed=0):
    rng = np.random.default_rng(seed)
    start = rng.uniform(0, 200, (40, 3))
    end = start + rng.normal(0, 6, (40, 3))
    paths = []
    for k in range(n_files):
        keep = rng.random(40) < 0.8  # each pass misses a few edges
        noise = rng.normal(0, 0.05, (2, int(keep.sum()), 3))
        seg = Segments(np.flatnonzero(keep), start[keep] + noise[0], end[keep] + noise[1])
        p = tmp_path / f"pass{k}.csv"
        write_segments(seg, p)
        paths.append(p)
    return paths


def test_shared_threshold_is_the_median_of_pair_thresholds(tmp_path):
    paths = _passes(tmp_path)
    r = CliRunner().invoke(
        cli,
        [
            "repeatability",
            *map(str, paths),
            "--shared-threshold",
            "-q",
            "--json",
            str(tmp_path / "r.json"),
        ],
    )
    assert r.exit_code == 0, r.output
    rows = json.loads((tmp_path / "r.json").read_text())["results"]
    assert len(rows) == 3
    segs = [read_segments(p) for p in paths]
    knees = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        m = match_segments(segs[i], segs[j])
        knees += [
            t
            for t, ok in (
                (m.threshold_tm, m.threshold_found_tm),
                (m.threshold_mt, m.threshold_found_mt),
            )
            if ok
        ]
    assert knees
    delta = float(np.median(knees))
    for row in rows:
        assert row["threshold_tm"] == pytest.approx(delta)
        assert row["threshold_mt"] == pytest.approx(delta)
    assert "shared threshold" in r.output


def test_shared_threshold_conflicts_with_a_fixed_one(tmp_path):
    paths = _passes(tmp_path, n_files=2)
    r = CliRunner().invoke(
        cli, ["repeatability", *map(str, paths), "--shared-threshold", "--threshold", "0.5"]
    )
    assert r.exit_code == 1 and "--shared-threshold" in r.output


@needs_shared
def test_outlines_raise_strip_pairs_on_an_ign_tile(tmp_path):
    f = SHARED / "ign-lidarhd" / "test_data_77055_627755_LA93_IGN69.laz"
    counts = []
    for extra in (["--no-steps"], ["--no-steps", "--outlines"]):
        out = tmp_path / f"r{len(extra)}.json"
        r = CliRunner().invoke(
            cli,
            [
                "repeatability",
                str(f),
                "--by-source-id",
                "--classes",
                "6",
                "--threshold",
                "0.5",
                "-q",
                "--json",
                str(out),
                *extra,
            ],
        )
        assert r.exit_code == 0, r.output
        (row,) = json.loads(out.read_text())["results"]["pairs"]
        counts.append(row["n_pairs_tm"])
        assert row["lhd"] < 0.5
    assert counts[1] >= 10 > counts[0]
