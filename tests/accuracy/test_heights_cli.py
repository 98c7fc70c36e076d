"""``lidarqa heights`` through click's CliRunner (issue #7)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.io import PointCloud


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A tilted plane with 5 cm noise, a grid of map points and reference points."""
    from pyproj import CRS

    d = tmp_path_factory.mktemp("heights")
    rng = np.random.default_rng(1234)
    x0, y0 = 650_000.0, 6_860_000.0
    xy = rng.uniform(0, 100, (20_000, 2))
    z = 40.0 + 0.02 * xy[:, 0] + rng.normal(0, 0.05, len(xy))
    line = np.column_stack([np.linspace(150, 160, 30), np.full(30, 50.0)])  # a collinear scan line
    xyz = np.vstack([np.column_stack([xy, z]), np.column_stack([line, np.full(30, 43.0)])])
    xyz[:, 0] += x0
    xyz[:, 1] += y0
    cls = np.full(len(xyz), 2, dtype=np.uint8)
    cls[:100] = 6  # a few non-ground points
    cloud = PointCloud(xyz=xyz, fields={"classification": cls}, crs=CRS.from_epsg(2154))
    lidarqa.write(cloud, d / "cloud.las")
    g = np.arange(5.0, 100.0, 10.0)
    mx, my = np.meshgrid(g, g)
    mxy = np.column_stack([mx.ravel(), my.ravel()])
    mxy = np.vstack([mxy, [[300.0, 300.0], [155.0, 50.0]]])  # no laser points; collinear points
    with (d / "map.csv").open("w") as fh:
        fh.write("id,x,y\n")
        for i, (x, y) in enumerate(mxy):
            fh.write(f"{i},{x + x0},{y + y0}\n")
    rxy = np.vstack([rng.uniform(10, 90, (200, 2)), [[500.0, 500.0]]])  # last one outside the TIN
    rz = 40.0 + 0.02 * rxy[:, 0] + rng.normal(0, 0.09, len(rxy))
    with (d / "ref.csv").open("w") as fh:
        fh.write("id,x,y,z\n")
        for i, (x, y, zz) in enumerate(zip(rxy[:, 0], rxy[:, 1], rz, strict=True)):
            fh.write(f"r{i},{x + x0},{y + y0},{zz}\n")
    (d / "empty.csv").write_text("")
    (d / "header_only.csv").write_text("id,x,y,z\n")
    return d


def test_cli_json_and_csv(scene, tmp_path):
    out_json, out_csv = tmp_path / "h.json", tmp_path / "h.csv"
    r = run(
        "heights",
        scene / "cloud.las",
        scene / "map.csv",
        scene / "ref.csv",
        "--json",
        out_json,
        "-o",
        out_csv,
        "-q",
        "--classes",
        "2",
        "--radius",
        "3",
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(out_json.read_text())
    assert doc["command"] == "heights"
    res = doc["results"]
    assert set(res) == {"map_points", "comparison", "w"}
    assert res["map_points"]["n"] == 102 and res["map_points"]["n_failed"] == 2
    assert res["comparison"]["n"] == 200
    assert res["w"]["critical"] == pytest.approx(3.290527, abs=1e-6)
    assert abs(res["comparison"]["mean"]) < 0.03
    assert 0.05 < res["comparison"]["std"] < 0.2
    assert doc["parameters"]["radius"] == 3 and doc["parameters"]["classes"] == [2]
    rows = list(csv.DictReader(out_csv.open()))
    kinds = [row["kind"] for row in rows]
    assert kinds.count("map") == 102 and kinds.count("reference") == 201
    by_id = {(row["kind"], row["id"]): row for row in rows}
    assert by_id[("map", "100")]["reason"] == "too_few_points"
    assert by_id[("map", "101")]["reason"] == "collinear"
    assert by_id[("map", "0")]["failed"] == "0" and float(by_id[("map", "0")]["sigma"]) > 0.058
    assert (
        by_id[("reference", "r200")]["inside"] == "0" and by_id[("reference", "r200")]["dh"] == ""
    )
    assert by_id[("reference", "r0")]["inside"] == "1" and by_id[("reference", "r0")]["w"] != ""
    assert "map points" in r.output


def test_cli_gpkg_output(scene, tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    out = tmp_path / "h.gpkg"
    r = run("heights", scene / "cloud.las", scene / "map.csv", scene / "ref.csv", "-o", out, "-q")
    assert r.exit_code == 0, r.output
    meta, _, geoms, fields = pyogrio.raw.read(str(out))
    kind = fields[list(meta["fields"]).index("kind")]
    assert (kind == "map").sum() == 102 and (kind == "reference").sum() == 201
    assert pyogrio.list_layers(str(out))[:, 0].tolist() == ["heights"]


@pytest.mark.parametrize("name", ["empty.csv", "header_only.csv"])
def test_cli_empty_reference(scene, tmp_path, name):
    out = tmp_path / "h.json"
    r = run("heights", scene / "cloud.las", scene / "map.csv", scene / name, "--json", out, "-q")
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())["results"]
    assert res["comparison"]["n"] == 0 and res["comparison"]["mean"] is None
    assert res["w"]["std"] is None and res["w"]["n_outliers"] == 0
    assert res["map_points"]["n"] == 102


def test_cli_crs_mismatch(scene, tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    shapely = pytest.importorskip("shapely")
    path = tmp_path / "map_rd.gpkg"
    geoms = shapely.to_wkb(shapely.points([[650_010.0, 6_860_010.0], [650_050.0, 6_860_050.0]]))
    pyogrio.raw.write(
        str(path),
        geoms,
        geometry_type="Point",
        field_data=[np.array([1, 2])],
        fields=["id"],
        crs="EPSG:28992",
        driver="GPKG",
    )
    r = run("heights", scene / "cloud.las", path, scene / "ref.csv", "-q")
    assert r.exit_code == 1
    assert "Error" in r.output and "Traceback" not in r.output and "CRS" in r.output


def _roads_map(tmp_path):
    """One road polygon over the scene (a GeoJSON file)."""
    pyogrio = pytest.importorskip("pyogrio")
    shapely = pytest.importorskip("shapely")
    x0, y0 = 650_000.0, 6_860_000.0
    poly = shapely.box(x0 + 5, y0 + 5, x0 + 95, y0 + 95)
    path = tmp_path / "roads.geojson"
    pyogrio.raw.write(
        str(path),
        shapely.to_wkb(np.array([poly], dtype=object)),
        geometry_type="Polygon",
        field_data=[np.array([1])],
        fields=["id"],
        crs="EPSG:2154",
        driver="GeoJSON",
    )
    return path


@pytest.mark.parametrize("kind", ["points", "road polygons"])
def test_cli_gpkg_output_is_the_same_bytes_run_to_run(kind, scene, tmp_path):
    """Regression (issue #26): with road polygons the GeoPackage carried its writing time."""
    import sqlite3

    from lidarqa.cli._catalog import FIXED_GPKG_TIME

    pytest.importorskip("pyogrio")
    mp = scene / "map.csv" if kind == "points" else _roads_map(tmp_path)
    outs = [tmp_path / "a.gpkg", tmp_path / "b.gpkg"]
    for out in outs:
        r = run("heights", scene / "cloud.las", mp, scene / "ref.csv", "--spacing", "15",
                "-o", out, "-q")
        assert r.exit_code == 0, r.output
    with sqlite3.connect(outs[0]) as db:
        assert db.execute("SELECT last_change FROM gpkg_contents").fetchall() == \
            [(FIXED_GPKG_TIME,)]
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_cli_polygon_map(scene, tmp_path):
    path = _roads_map(tmp_path)
    out = tmp_path / "h.json"
    r = run(
        "heights",
        scene / "cloud.las",
        path,
        scene / "ref.csv",
        "--spacing",
        "15",
        "--json",
        out,
        "-q",
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    res = doc["results"]
    # road polygons go through the level-aware reconstruction (issue #15)
    assert doc["parameters"]["levels"] is True
    assert res["roads"]["n_map_points"] == 4 * 6 and res["roads"]["n_failed"] == 0
    assert res["comparison"]["n"] == 200


def test_cli_bad_options(scene, tmp_path):
    r = run(
        "heights", scene / "cloud.las", scene / "map.csv", scene / "ref.csv", "--correlation", "2"
    )
    assert r.exit_code == 1 and "correlation" in r.output
    r = run(
        "heights",
        scene / "cloud.las",
        scene / "map.csv",
        scene / "ref.csv",
        "-o",
        tmp_path / "x.txt",
    )
    assert r.exit_code == 1 and "--output" in r.output
    gj = tmp_path / "x.geojson"  # GeoJSON is an output format like the others (issue #16)
    r = run("heights", scene / "cloud.las", scene / "map.csv", scene / "ref.csv", "-o", gj, "-q")
    assert r.exit_code == 0, r.output
    from lidarqa.io.vector import read_points

    rows = read_points(gj, require_z=False)
    assert set(rows.attributes["kind"].tolist()) == {"map", "reference"}
    r = run("heights", scene / "cloud.las", scene / "map.csv", scene / "ref.csv", "--alpha", "0")
    assert r.exit_code == 1 and "alpha" in r.output and "Traceback" not in r.output
    r = run("heights", scene / "cloud.las", scene / "missing.csv", scene / "ref.csv")
    assert r.exit_code == 1 and "does not exist" in r.output
    out = tmp_path / "exists.csv"
    out.write_text("x")
    r = run("heights", scene / "cloud.las", scene / "map.csv", scene / "ref.csv", "-o", out)
    assert r.exit_code == 1 and "exists" in r.output
