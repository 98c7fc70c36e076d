"""``lidarqa swaths`` and ``lidarqa heights --sigma-strip auto`` through CliRunner (issue #14)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.io import PointCloud
from lidarqa.testing.strips import make_strip_scene

X0, Y0 = 650_000.0, 6_860_000.0
TRUTH = [[0.0, 0.0, 0.0], [0.04, -0.03, 0.05], [-0.02, 0.05, -0.03]]


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _cloud(points, strip=None, **fields):
    from pyproj import CRS

    xyz = points + [X0, Y0, 0.0]
    f = {"classification": np.full(len(xyz), 2, dtype=np.uint8), **fields}
    if strip is not None:
        f["point_source_id"] = strip.astype(np.uint16)
    return PointCloud(xyz=xyz, fields=f, crs=CRS.from_epsg(2154))


@pytest.fixture(scope="module")
def strips(tmp_path_factory):
    d = tmp_path_factory.mktemp("swaths")
    scene = make_strip_scene(3, offsets=TRUTH, noise=0.02, seed=3, first_id=52)
    lidarqa.write(_cloud(scene.points, scene.strip), d / "block.laz")
    for s in scene.strip_ids:
        m = scene.strip == s
        lidarqa.write(_cloud(scene.points[m]), d / f"strip{s}.laz")
    one = scene.strip == 52
    lidarqa.write(_cloud(scene.points[one], scene.strip[one]), d / "one.laz")
    apart = scene.points.copy()
    apart[scene.strip == 53, 1] += 500.0  # strip 53 moved away: no overlap at all
    keep = scene.strip != 54
    lidarqa.write(_cloud(apart[keep], scene.strip[keep]), d / "apart.laz")
    np.savetxt(
        d / "noid.csv", scene.points + [X0, Y0, 0], delimiter=",", header="x,y,z", comments=""
    )
    return d, scene


def test_by_source_id_writes_tables_rasters_json(strips, tmp_path):
    rasterio = pytest.importorskip("rasterio")
    d, scene = strips
    out = tmp_path / "out"
    r = run(
        "swaths",
        d / "block.laz",
        "--by-source-id",
        "-o",
        out,
        "--json",
        tmp_path / "s.json",
        "-q",
        "--cell-size",
        "1",
        "--reference-strip",
        "52",
    )
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "s.json").read_text())
    res = doc["results"]
    assert [(p["strip_a"], p["strip_b"]) for p in res["pairs"]] == [(52, 53), (53, 54)]
    net = {o["strip_b"]: o for o in res["network_offsets"]}
    for s in (53, 54):
        true = scene.offset(52, s)
        got = [net[s]["dx"], net[s]["dy"], net[s]["dz"]]
        assert np.allclose(got, true, atol=0.01)
    assert {"dz_52_53.tif", "dz_53_54.tif", "pairs.csv", "offsets.csv"} <= set(res["outputs"])
    with rasterio.open(out / "dz_52_53.tif") as ds:
        assert ds.crs.to_epsg() == 2154
        band = ds.read(1, masked=True)
        assert ds.nodata == -9999.0 and band.count() == res["pairs"][0]["n_cells"]
        assert float(band.mean()) == pytest.approx(res["pairs"][0]["mean"], abs=1e-5)
        left, bottom, right, top = ds.bounds
        assert left <= X0 + 1 and top >= Y0 + 60  # georeferenced where the strips are
    with (out / "pairs.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[0]["rmsdz"]) == pytest.approx(res["pairs"][0]["rmsdz"])
    assert "E4" in r.output
    # refuses to write into a non-empty folder without --overwrite
    again = run("swaths", d / "block.laz", "--by-source-id", "-o", out, "-q")
    assert again.exit_code == 1 and "not empty" in again.output


def test_one_file_per_strip(strips, tmp_path):
    d, scene = strips
    files = [d / f"strip{s}.laz" for s in scene.strip_ids]
    r = run("swaths", *files, "-o", tmp_path / "o", "-q", "--no-maps", "--cell-size", "1")
    assert r.exit_code == 0, r.output
    assert "1–2" in r.output.replace(" ", "") and "2–3" in r.output.replace(" ", "")  # en dash


@pytest.mark.parametrize(
    ("name", "extra", "message"),
    [
        ("one.laz", ["--by-source-id"], "one flight strip"),
        ("apart.laz", ["--by-source-id"], "overlap"),
        ("noid.csv", ["--by-source-id"], "point_source_id"),
        ("strip52.laz", ["--by-source-id"], "point_source_id is 0 for every point"),
        ("block.laz", [], "one file is one flight strip"),
    ],
)
def test_bad_input_clear_message_no_output(strips, tmp_path, name, extra, message):
    d, _ = strips
    out = tmp_path / "out"
    r = run("swaths", d / name, *extra, "-o", out, "--json", tmp_path / "x.json")
    assert r.exit_code == 1
    assert message in r.output and "Traceback" not in r.output
    assert not out.exists() and not (tmp_path / "x.json").exists()


def test_no_smooth_surface(tmp_path):
    scene = make_strip_scene(2, noise=0.4, seed=2)
    lidarqa.write(_cloud(scene.points, scene.strip), tmp_path / "rough.laz")
    r = run("swaths", tmp_path / "rough.laz", "--by-source-id", "-o", tmp_path / "o")
    assert r.exit_code == 1 and "no smooth surface" in r.output
    assert not (tmp_path / "o").exists()


def test_heights_sigma_strip_auto_uses_measured_e4(strips, tmp_path):
    d, scene = strips
    rng = np.random.default_rng(5)
    pts = rng.uniform([5, 5], [95, 115], (40, 2))
    with (tmp_path / "map.csv").open("w") as fh:
        fh.write("id,x,y\n")
        for i, (x, y) in enumerate(pts):
            fh.write(f"{i},{x + X0},{y + Y0}\n")
    ref = rng.uniform([20, 20], [80, 100], (30, 2))
    with (tmp_path / "ref.csv").open("w") as fh:
        fh.write("id,x,y,z\n")
        for i, (x, y) in enumerate(ref):
            fh.write(f"r{i},{x + X0},{y + Y0},{100.0 + 0.01 * x}\n")
    sw = run(
        "swaths",
        d / "block.laz",
        "--by-source-id",
        "-o",
        tmp_path / "sw",
        "--no-maps",
        "-q",
        "--json",
        tmp_path / "sw.json",
    )
    assert sw.exit_code == 0, sw.output
    e4 = json.loads((tmp_path / "sw.json").read_text())["results"]["e4"]
    r = run(
        "heights",
        d / "block.laz",
        tmp_path / "map.csv",
        tmp_path / "ref.csv",
        "--sigma-strip",
        "auto",
        "--classes",
        "2",
        "-q",
        "--json",
        tmp_path / "h.json",
    )
    assert r.exit_code == 0, r.output
    params = json.loads((tmp_path / "h.json").read_text())["parameters"]
    assert params["sigma_strip"] == pytest.approx(e4, rel=1e-9)
    assert params["sigma_strip_source"].startswith("measured")
    assert e4 == pytest.approx(np.std(np.array(TRUTH)[:, 2], ddof=1), abs=0.01)
    bad = run(
        "heights",
        d / "one.laz",
        tmp_path / "map.csv",
        tmp_path / "ref.csv",
        "--sigma-strip",
        "auto",
        "-q",
    )
    assert bad.exit_code == 1 and "one flight strip" in bad.output
    typo = run(
        "heights",
        d / "block.laz",
        tmp_path / "map.csv",
        tmp_path / "ref.csv",
        "--sigma-strip",
        "automatic",
    )
    assert typo.exit_code == 2 and "auto" in typo.output


@needs_shared
def test_real_ign_block_every_pair_and_epsg(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    f = SHARED / "ign-lidarhd" / "test_semis_2023_0299_6802_LA93_IGN69.laz"
    out = tmp_path / "o"
    r = run(
        "swaths", f, "--by-source-id", "-o", out, "--no-maps", "-q", "--json", tmp_path / "s.json"
    )
    assert r.exit_code == 0, r.output
    res = json.loads((tmp_path / "s.json").read_text())["results"]
    pairs = {(p["strip_a"], p["strip_b"]): p for p in res["pairs"]}
    # the five strip pairs that share ground in this tile (4 strips of 52..55 overlap)
    assert {(52, 53), (52, 54), (53, 54), (53, 55), (54, 55)} <= set(pairs)
    for p in pairs.values():
        assert p["overlap_area"] > 10_000 and p["area"] > 0 and p["rmsdz"] < 0.08
        with rasterio.open(out / f"dz_{p['strip_a']}_{p['strip_b']}.tif") as ds:
            assert ds.crs.to_epsg() == 2154


def test_crs_option_for_files_without_one(strips, tmp_path):
    rasterio = pytest.importorskip("rasterio")
    d, scene = strips
    from lidarqa.io import read

    pc = read(d / "block.laz")
    bare = tmp_path / "bare.laz"
    lidarqa.write(PointCloud(xyz=pc.xyz, fields=pc.fields, crs=None), bare)
    r = run("swaths", bare, "--by-source-id", "-o", tmp_path / "a", "--no-maps", "-q")
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "a" / "dz_52_53.tif") as src:
        assert src.crs is None
    r = run(
        "swaths",
        bare,
        "--by-source-id",
        "-o",
        tmp_path / "b",
        "--no-maps",
        "-q",
        "--crs",
        "EPSG:5490",
    )
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "b" / "dz_52_53.tif") as src:
        assert src.crs.to_epsg() == 5490
    # a file that has a CRS: a different --crs is an error, raised before any output
    r = run("swaths", d / "block.laz", "--by-source-id", "-o", tmp_path / "c", "--crs", "32632")
    assert r.exit_code == 1 and "differs" in r.output and not (tmp_path / "c").exists()
