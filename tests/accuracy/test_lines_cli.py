"""``lidarqa lines`` and ``lidarqa repeatability`` (CliRunner)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from lidarqa.accuracy._lines_synthetic import make_segment_sets
from lidarqa.cli.main import cli
from lidarqa.io.vector import Segments, write_segments

T_CSV = """id,x1,y1,z1,x2,y2,z2
1,0,0.2,0,10,0.2,0
2,0,5,0,0,5,3
3,20,20,0,25,20,0
"""
M_CSV = """id,x1,y1,z1,x2,y2,z2
a,0,0,0,10,0,0
b,0,5.3,0,0,5.3,4
c,0,10,0,4,10,0
"""

KEYS = {
    "p",
    "q",
    "threshold_tm",
    "threshold_mt",
    "olhd_tm",
    "olhd_mt",
    "lhd",
    "n_pairs_tm",
    "n_pairs_mt",
    "threshold_found_tm",
    "threshold_found_mt",
}
GT_KEYS = {f"{k}_{s}" for k in ("tp", "fp", "fn", "tn", "detection_rate") for s in ("tm", "mt")}


@pytest.fixture
def toy(tmp_path):
    (tmp_path / "T.csv").write_text(T_CSV)
    (tmp_path / "M.csv").write_text(M_CSV)
    (tmp_path / "G.csv").write_text("test_id,model_id\n1,a\n2,b\n")
    return tmp_path


def run(*args):
    return CliRunner().invoke(cli, ["-q", *[str(a) for a in args]], catch_exceptions=False)


def test_lines_toy_json_matrix_pairs(toy):
    out = toy / "r.json"
    res = run(
        "lines",
        toy / "T.csv",
        toy / "M.csv",
        "--ground-truth",
        toy / "G.csv",
        "--matrix",
        toy / "S.csv",
        "--pairs",
        toy / "P.csv",
        "--json",
        out,
    )
    assert res.exit_code == 0, res.output
    assert "LHD 0.2286 m" in res.output  # the report's 4 significant digits
    doc = json.loads(out.read_text())
    assert doc["command"] == "lines"
    r = doc["results"]
    assert set(r) == KEYS | GT_KEYS
    assert (r["p"], r["q"], r["n_pairs_tm"], r["n_pairs_mt"]) == (3, 3, 2, 2)
    assert r["threshold_tm"] == pytest.approx(0.3) and r["olhd_tm"] == pytest.approx(
        0.228571, abs=1e-6
    )
    assert r["olhd_mt"] == pytest.approx(0.223077, abs=1e-6) and r["lhd"] == pytest.approx(
        0.228571, abs=1e-6
    )
    assert r["detection_rate_tm"] == 1.0 and r["tp_mt"] == 2 and r["tn_tm"] == 7
    rows = list(csv.reader((toy / "S.csv").open()))
    assert rows[0] == ["test_id", "a", "b", "c"]
    assert [r[0] for r in rows[1:]] == ["1", "2", "3"]
    assert float(rows[1][1]) == pytest.approx(0.2) and rows[1][2] == ""  # pruned pair: empty
    pairs = list(csv.DictReader((toy / "P.csv").open()))
    assert [(p["test_id"], p["model_id"]) for p in pairs] == [("1", "a"), ("2", "b")]
    assert float(pairs[1]["d_tm"]) == pytest.approx(0.3)
    # the pairs file is itself a ground-truth file
    res = run(
        "lines",
        toy / "T.csv",
        toy / "M.csv",
        "--ground-truth",
        toy / "P.csv",
        "--json",
        toy / "r2.json",
    )
    assert res.exit_code == 0
    assert json.loads((toy / "r2.json").read_text())["results"]["detection_rate_mt"] == 1.0


def test_lines_fixed_threshold_and_options(toy):
    res = run(
        "lines",
        toy / "T.csv",
        toy / "M.csv",
        "--threshold",
        "10",
        "--weight",
        "1",
        "--denominator",
        "all",
        "--json",
        toy / "r.json",
    )
    assert res.exit_code == 0, res.output
    doc = json.loads((toy / "r.json").read_text())
    assert doc["parameters"]["threshold"] == 10.0 and doc["parameters"]["weight"] == 1.0
    r = doc["results"]
    from lidarqa.accuracy.lines import segment_distances
    from lidarqa.io.vector import read_segments

    d = segment_distances(read_segments(toy / "T.csv"), read_segments(toy / "M.csv"), weight=1)[3]
    assert r["threshold_tm"] == 10.0 and r["threshold_found_tm"] is False
    assert r["n_pairs_tm"] == int((d <= 10).sum()) == 6
    assert "fixed" in res.output


def test_lines_refuses_existing_output_before_work(toy):
    (toy / "S.csv").write_text("x")
    res = CliRunner().invoke(
        cli, ["lines", str(toy / "T.csv"), str(toy / "M.csv"), "--matrix", str(toy / "S.csv")]
    )
    assert res.exit_code == 1 and "exists" in res.output
    assert (toy / "S.csv").read_text() == "x"


def test_lines_bad_inputs(toy):
    (toy / "Z.csv").write_text("id,x1,y1,z1,x2,y2,z2\n1,0,0,0,0,0,0\n2,0,0,0,1,0,0\n")
    res = CliRunner().invoke(cli, ["lines", str(toy / "Z.csv"), str(toy / "M.csv")])
    assert res.exit_code == 1 and "zero-length" in res.output and "Traceback" not in res.output
    (toy / "E.csv").write_text("id,x1,y1,z1,x2,y2,z2\n")
    res = CliRunner().invoke(cli, ["lines", str(toy / "E.csv"), str(toy / "M.csv")])
    assert res.exit_code == 1 and "empty" in res.output
    (toy / "G2.csv").write_text("test_id,model_id\n1,zz\n")
    res = CliRunner().invoke(
        cli,
        ["lines", str(toy / "T.csv"), str(toy / "M.csv"), "--ground-truth", str(toy / "G2.csv")],
    )
    assert res.exit_code == 1 and "zz" in res.output
    res = CliRunner().invoke(
        cli, ["lines", str(toy / "T.csv"), str(toy / "M.csv"), "--classes", "6"]
    )
    assert res.exit_code == 1 and "segment file" in res.output


def test_lines_crs_mismatch_geojson(tmp_path):
    from pyproj import CRS

    s = make_segment_sets(n_model=20, seed=0)
    write_segments(
        Segments(s.test.ids, s.test.start, s.test.end, crs=CRS.from_epsg(2154)),
        tmp_path / "t.geojson",
    )
    write_segments(
        Segments(s.model.ids, s.model.start, s.model.end, crs=CRS.from_epsg(32632)),
        tmp_path / "m.gpkg",
    )
    res = CliRunner().invoke(cli, ["lines", str(tmp_path / "t.geojson"), str(tmp_path / "m.gpkg")])
    assert res.exit_code == 1 and "CRS" in res.output


def test_lines_gpkg_synthetic_detection(tmp_path):
    s = make_segment_sets(n_model=200, seed=5)
    write_segments(s.test, tmp_path / "t.gpkg")
    write_segments(s.model, tmp_path / "m.csv")
    with (tmp_path / "gt.csv").open("w") as fh:
        fh.write("test_id,model_id\n" + "".join(f"{a},{b}\n" for a, b in s.truth_ids()))
    res = run(
        "lines",
        tmp_path / "t.gpkg",
        tmp_path / "m.csv",
        "--ground-truth",
        tmp_path / "gt.csv",
        "--json",
        tmp_path / "r.json",
    )
    assert res.exit_code == 0, res.output
    r = json.loads((tmp_path / "r.json").read_text())["results"]
    assert r["detection_rate_tm"] >= 0.995 and r["detection_rate_mt"] >= 0.995
    assert r["tp_tm"] >= 0.98 * len(s.truth)


def test_repeatability_table_of_segment_files(tmp_path):
    s1 = make_segment_sets(n_model=150, seed=7)
    s2 = make_segment_sets(n_model=150, seed=7, translation=(0.3, 0.0, 0.0))
    write_segments(s1.model, tmp_path / "c1.csv")
    write_segments(s1.test, tmp_path / "c2.csv")
    write_segments(s2.test, tmp_path / "c3.csv")
    res = run(
        "repeatability",
        tmp_path / "c1.csv",
        tmp_path / "c2.csv",
        tmp_path / "c3.csv",
        "--json",
        tmp_path / "rep.json",
    )
    assert res.exit_code == 0, res.output
    assert "c1.csv - c2.csv" in res.output and "c2.csv - c3.csv" in res.output
    assert res.output.count("*") >= 3
    rows = json.loads((tmp_path / "rep.json").read_text())["results"]
    assert isinstance(rows, list) and len(rows) == 3
    assert [(r["test"], r["model"]) for r in rows] == [
        ("c1.csv", "c2.csv"),
        ("c1.csv", "c3.csv"),
        ("c2.csv", "c3.csv"),
    ]
    for r in rows:
        assert KEYS <= set(r)
        assert r["lhd"] == max(r["olhd_tm"], r["olhd_mt"])
    # c1–c3 is offset by 0.3 m more than c1–c2: a larger LHD
    assert rows[1]["lhd"] > rows[0]["lhd"] + 0.1


def test_repeatability_needs_two_passes(tmp_path):
    (tmp_path / "T.csv").write_text(T_CSV)
    res = CliRunner().invoke(cli, ["repeatability", str(tmp_path / "T.csv")])
    assert res.exit_code == 1 and "two passes" in res.output


def test_point_cloud_input_without_edges_is_a_clear_error(demo_tile, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "lidarqa.geometry.edges", None)  # import fails
    res = CliRunner().invoke(cli, ["lines", str(demo_tile), str(demo_tile), "--classes", "6"])
    assert res.exit_code == 3 and "extract_edges" in res.output and "Traceback" not in res.output


def test_synthetic_pairs_ids_roundtrip():
    s = make_segment_sets(n_model=30, seed=0)
    ids = s.truth_ids()
    assert len(ids) == len(s.truth) and all(isinstance(a, np.integer | int) for a, _ in ids)


@pytest.fixture
def strips_laz(tmp_path, monkeypatch):
    """A LAZ with two strips whose points are segment end points, and a stand-in edge extractor.

    The stand-in (consecutive point pairs are segments) isolates the CLI plumbing from
    lidarqa.geometry.edges: strip selection, classes, names, pairs and the table.
    """
    import lidarqa
    from lidarqa.accuracy import lines_io
    from lidarqa.io import PointCloud

    s = make_segment_sets(n_model=60, seed=11)
    model = np.stack([s.model.start, s.model.end], axis=1).reshape(-1, 3)
    test = np.stack([s.test.start, s.test.end], axis=1).reshape(-1, 3)
    noise = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0]])  # class 1: must be filtered out
    xyz = np.concatenate([model, test, noise])
    sid = np.concatenate([np.full(len(model), 706), np.full(len(test), 707), [706, 707]]).astype(
        np.uint16
    )
    cls = np.concatenate([np.full(len(model) + len(test), 6), [1, 1]]).astype(np.uint8)
    cloud = PointCloud(xyz, {"classification": cls, "point_source_id": sid})
    path = tmp_path / "strips.laz"
    lidarqa.write(cloud, path)

    def fake_extract(points, *, crs=None, **options):
        pts = np.asarray(points).reshape(-1, 2, 3)
        return Segments(np.arange(len(pts)), pts[:, 0], pts[:, 1], crs=crs)

    monkeypatch.setattr(lines_io, "extract_segments", fake_extract)

    # a cloud's edges go through the area engine (one region for one file); jobs_lines is
    # imported before jobs_vector is patched (it binds vector_features at import)
    from lidarqa.tiling import jobs_lines, jobs_vector

    def fake_features(points, *, kind, core=None, crs=None, box=None, **options):
        seg = fake_extract(points, crs=crs)
        seg.attributes["at_buffer_edge"] = np.zeros(len(seg), dtype=np.int64)
        return seg if core is None else jobs_vector.keep_anchored(seg, core)

    monkeypatch.setattr(jobs_vector, "vector_features", fake_features)
    monkeypatch.setattr(jobs_lines, "vector_features", fake_features)  # strips of one cloud
    return path, s


def test_lines_two_strips_of_one_cloud(strips_laz, tmp_path):
    path, s = strips_laz
    res = run(
        "lines",
        path,
        path,
        "--classes",
        "6",
        "--test-source-id",
        "707",
        "--model-source-id",
        "706",
        "--json",
        tmp_path / "r.json",
    )
    assert res.exit_code == 0, res.output
    r = json.loads((tmp_path / "r.json").read_text())["results"]
    assert (r["p"], r["q"]) == (len(s.test), len(s.model))
    assert r["n_pairs_tm"] >= 0.98 * len(s.truth) and r["lhd"] < 0.3


def test_repeatability_by_source_id(strips_laz, tmp_path):
    path, s = strips_laz
    # the stand-in edges are not sampled from the strips: the plain knee, not the sampling band
    res = run("repeatability", path, "--by-source-id", "--classes", "6", "--auto-threshold",
              "knee", "--json", tmp_path / "rep.json")
    assert res.exit_code == 0, res.output
    assert "706 - 707" in res.output
    # one cloud goes through the catalog job (one region): the catalog's JSON shape
    res_json = json.loads((tmp_path / "rep.json").read_text())["results"]
    rows = res_json["pairs"]
    assert len(rows) == 1
    row = rows[0]
    assert (row["test"], row["model"]) == ("706", "707")
    assert res_json["strips"] == {"706": len(s.model), "707": len(s.test)}
    assert res_json["catalog"]["n_chunks"] == 1
    assert (row["p"], row["q"]) == (len(s.model), len(s.test))
    assert row["lhd"] == max(row["olhd_tm"], row["olhd_mt"]) < 0.3
    res = CliRunner().invoke(
        cli, ["repeatability", str(path), "--by-source-id", "--source-id", "706", "--classes", "6"]
    )
    assert res.exit_code == 1 and "two strips" in res.output, res.output
