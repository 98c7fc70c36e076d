"""``lidarqa repeatability --by-source-id --pool``: one pass per strip across tiles (#14)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

from lidarqa.accuracy._lines_synthetic import make_segment_sets
from lidarqa.accuracy.lines_io import pool_passes
from lidarqa.cli.main import cli
from lidarqa.errors import InvalidPointsError
from lidarqa.io.vector import Segments


def _seg(n, x0, attrs=True):
    start = np.column_stack([np.arange(n) + x0, np.zeros(n), np.zeros(n)])
    extra = {"length": np.ones(n), "kind": np.array(["a"] * n, dtype=object)} if attrs else {}
    return Segments(np.arange(n), start, start + [1.0, 0, 0], {**extra} if attrs else {})


def test_pool_passes_joins_strips_across_files():
    err = InvalidPointsError("no edges")
    passes = [
        ("t1.laz", "706", _seg(3, 0.0)),
        ("t1.laz", "707", _seg(2, 0.0, attrs=False)),
        ("t2.laz", "706", _seg(4, 100.0)),
        ("t2.laz", "707", err),
        ("t2.laz", "708", err),
        ("t3.laz", "707", _seg(5, 200.0)),
    ]
    out = {name: (group, seg) for group, name, seg in pool_passes(passes)}
    assert set(out) == {"706", "707", "708"}
    assert all(group == "" for group, _ in out.values())
    s706, s707 = out["706"][1], out["707"][1]
    assert len(s706) == 7 and len(s707) == 7  # the failed part of 707 is skipped
    assert len(set(s706.ids.tolist())) == 7 and s706.ids[0] == "t1.laz:0"
    assert s706.ids[-1] == "t2.laz:3"
    np.testing.assert_array_equal(s706.start[3:, 0], 100.0 + np.arange(4))
    assert set(s706.attributes) == {"length", "kind"}
    assert s707.attributes == {}  # only attributes that every part has
    assert out["708"][1] is err  # failed everywhere: the error is reported


def _write_tiles(tmp_path, monkeypatch, n_model=60):
    """Two strips' segments (end points as points) split into a west and an east tile."""
    import lidarqa
    from lidarqa.accuracy import lines_io
    from lidarqa.io import PointCloud

    s = make_segment_sets(n_model=n_model, seed=5)
    cut = float(np.median(0.5 * (s.model.start[:, 0] + s.model.end[:, 0])))
    paths = []
    for name, west in (("west.laz", True), ("east.laz", False)):
        xyz, sid = [], []
        for seg, strip in ((s.model, 706), (s.test, 707)):
            mid = 0.5 * (seg.start[:, 0] + seg.end[:, 0])
            k = (mid < cut) == west
            xyz.append(np.stack([seg.start[k], seg.end[k]], axis=1).reshape(-1, 3))
            sid.append(np.full(2 * int(k.sum()), strip))
        xyz, sid = np.concatenate(xyz), np.concatenate(sid).astype(np.uint16)
        cloud = PointCloud(
            xyz,
            {"classification": np.full(len(xyz), 6, np.uint8), "point_source_id": sid},
        )
        paths.append(tmp_path / name)
        lidarqa.write(cloud, paths[-1])

    def fake_extract(points, *, crs=None, **options):
        pts = np.asarray(points).reshape(-1, 2, 3)
        return Segments(np.arange(len(pts)), pts[:, 0], pts[:, 1], crs=crs)

    monkeypatch.setattr(lines_io, "extract_segments", fake_extract)
    return paths, s


def test_pooled_tiles_give_the_whole_block_answer(tmp_path, monkeypatch):
    from lidarqa.accuracy.lines import match_segments

    paths, s = _write_tiles(tmp_path, monkeypatch)
    out = tmp_path / "r.json"
    r = CliRunner().invoke(
        cli,
        ["repeatability", *map(str, paths), "--by-source-id", "--pool", "-q", "--json", str(out)],
    )
    assert r.exit_code == 0, r.output
    (row,) = json.loads(out.read_text())["results"]
    assert (row["test"], row["model"]) == ("706", "707")
    # oracle: the same segments as stored in the tiles (LAZ rounds coordinates), unsplit
    from lidarqa.io import read

    clouds = [read(p) for p in paths]
    whole_sets = []
    for strip in (706, 707):
        pts = np.concatenate([c.xyz[np.asarray(c.point_source_id) == strip] for c in clouds])
        pts = pts.reshape(-1, 2, 3)
        whole_sets.append(Segments(np.arange(len(pts)), pts[:, 0], pts[:, 1]))
    whole = match_segments(*whole_sets)
    assert (row["p"], row["q"]) == (len(s.model), len(s.test))
    assert row["n_pairs_tm"] == whole.n_pairs_tm
    assert row["threshold_tm"] == pytest.approx(whole.threshold_tm)
    assert row["lhd"] == pytest.approx(whole.lhd)
    # per tile: one row per file, each with only its share of the segments
    r = CliRunner().invoke(
        cli,
        [
            "repeatability",
            *map(str, paths),
            "--by-source-id",
            "-q",
            "--json",
            str(out),
            "--overwrite",
        ],
    )
    rows = json.loads(out.read_text())["results"]
    assert len(rows) == 2 and sum(x["p"] for x in rows) == len(s.model)


def test_pool_needs_by_source_id(tmp_path):
    r = CliRunner().invoke(cli, ["repeatability", "a.csv", "b.csv", "--pool"])
    assert r.exit_code == 1 and "--by-source-id" in r.output


@needs_shared
def test_six_ign_tiles_pooled_give_ten_line_pairs_within_half_a_metre(tmp_path):
    # Per tile the two strips share only 1,000-2,500 m² and 2-5 matched edges; the
    # six tiles of the same two strips together are one usable strip pair.
    files = sorted((SHARED / "ign-lidarhd").glob("test_data_*.laz"))
    assert len(files) == 6
    out = tmp_path / "r.json"
    r = CliRunner().invoke(
        cli,
        [
            "repeatability",
            *map(str, files),
            "--by-source-id",
            "--pool",
            "--classes",
            "6",
            "-q",
            "--json",
            str(out),
        ],
    )
    assert r.exit_code == 0, r.output
    (row,) = json.loads(out.read_text())["results"]
    assert row["threshold_found_tm"] and row["threshold_found_mt"]
    assert min(row["n_pairs_tm"], row["n_pairs_mt"]) >= 10
    assert row["lhd"] <= 0.5


def test_small_tiles_get_a_note_about_unstable_thresholds(tmp_path, monkeypatch):
    paths, _ = _write_tiles(tmp_path, monkeypatch, n_model=40)
    base = ["repeatability", *map(str, paths), "--by-source-id", "-q"]
    r = CliRunner().invoke(cli, base)  # each tile holds about 20 segments per strip
    assert r.exit_code == 0, r.output
    assert "automatic thresholds are unstable" in r.output
    for extra in (["--pool"], ["--threshold", "0.5"]):
        r = CliRunner().invoke(cli, base + extra)
        assert r.exit_code == 0 and "unstable" not in r.output, r.output
