"""``lidarqa planes``, ``lidarqa edges`` and ``lidarqa corners``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.io.vector import read_points, read_segments
from lidarqa.testing import make_building_scene


@pytest.fixture(scope="module")
def scene_las(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    sc = make_building_scene(seed=3, roofs=("gable", "flat"))
    path = tmp_path_factory.mktemp("geo") / "scene.laz"
    cloud = sc.to_cloud()
    cloud.crs = None
    from pyproj import CRS

    cloud.crs = CRS.from_epsg(2154)
    lidarqa.write(cloud, path)
    return path, sc


def run(args: list[str]) -> object:
    return CliRunner().invoke(cli, args, catch_exceptions=False)


def test_edges_csv_and_json(scene_las: tuple, tmp_path: Path) -> None:
    path, sc = scene_las
    out, js = tmp_path / "edges.csv", tmp_path / "edges.json"
    r = run(["-q", "edges", str(path), "-o", str(out), "--classes", "6,2", "--json", str(js)])
    assert r.exit_code == 0, r.output
    assert out.read_text().splitlines()[0].startswith("id,x1,y1,z1,x2,y2,z2,plane_a,plane_b")
    segs = read_segments(out)
    doc = json.loads(js.read_text())
    assert doc["command"] == "edges"
    assert doc["results"]["n_edges"] == len(segs) >= 20
    assert doc["inputs"]["classes"] == [6, 2]
    from lidarqa.testing import score_edges

    # LAS stores 1 cm / 1 mm coordinates: still within 3 cm
    assert score_edges(segs, sc.edges).recall >= 0.9


def test_corners_gpkg_keeps_crs(scene_las: tuple, tmp_path: Path) -> None:
    path, sc = scene_las
    out = tmp_path / "corners.gpkg"
    r = run(["-q", "corners", str(path), "-o", str(out)])
    assert r.exit_code == 0, r.output
    c = read_points(out)
    assert len(c) >= 10
    assert c.crs is not None and c.crs.to_epsg() == 2154
    for k in ("plane_a", "plane_b", "plane_c", "sigma_x", "sigma_y", "sigma_z"):
        assert k in c.attributes
    csv_out = tmp_path / "corners.csv"
    assert run(["-q", "corners", str(path), "-o", str(csv_out)]).exit_code == 0
    assert csv_out.read_text().startswith("id,x,y,z,")


def test_planes_geojson(scene_las: tuple, tmp_path: Path) -> None:
    path, sc = scene_las
    out, js = tmp_path / "planes.geojson", tmp_path / "p.json"
    r = run(["-q", "planes", str(path), "-o", str(out), "--json", str(js)])
    assert r.exit_code == 0, r.output
    p = read_points(out)
    assert len(p) == json.loads(js.read_text())["results"]["n_segments"] == len(sc.planes)
    n = np.column_stack([p.attributes[k] for k in ("nx", "ny", "nz")]).astype(float)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)


def test_source_id_selection_on_demo_tile(demo_tile: Path, tmp_path: Path) -> None:
    out, js = tmp_path / "e706.csv", tmp_path / "e.json"
    r = run(["-q", "edges", str(demo_tile), "-o", str(out), "--classes", "6", "--source-id", "706",
             "--json", str(js)])
    assert r.exit_code == 0, r.output
    doc = json.loads(js.read_text())
    cloud = lidarqa.read(demo_tile).select(classes=6, source_id=706)
    assert doc["inputs"]["n_points_selected"] == len(cloud)
    assert doc["results"]["n_edges"] >= 5
    assert doc["inputs"]["crs"]


def test_bad_inputs(tmp_path: Path, demo_tile: Path) -> None:
    missing = str(tmp_path / "missing.laz")
    r = CliRunner().invoke(cli, ["edges", missing, "-o", str(tmp_path / "e.csv")])
    assert r.exit_code == 1 and "Traceback" not in r.output
    r = CliRunner().invoke(cli, ["edges", str(demo_tile), "-o", str(tmp_path / "e.csv"),
                                 "--classes", "99"])
    assert r.exit_code == 1 and "0 point(s)" in r.output
    r = CliRunner().invoke(cli, ["corners", str(demo_tile), "-o", str(tmp_path / "c.txt")])
    assert r.exit_code == 1 and ".csv" in r.output
    r = CliRunner().invoke(cli, ["planes", str(demo_tile), "-o", str(tmp_path / "p.csv"),
                                 "--classes", "x"])
    assert r.exit_code == 2
    r = CliRunner().invoke(cli, ["edges", str(demo_tile), "-o", str(tmp_path / "e.csv"),
                                 "--min-angle", "120"])
    assert r.exit_code == 1 and "--min-angle" in r.output
    r = CliRunner().invoke(cli, ["corners", str(demo_tile), "-o", str(tmp_path / "c.csv"),
                                 "--grow-radius", "-1"])
    assert r.exit_code == 1 and "grow_radius" in r.output
    existing = tmp_path / "exists.csv"
    existing.write_text("x")
    r = CliRunner().invoke(cli, ["edges", str(demo_tile), "-o", str(existing)])
    assert r.exit_code == 1 and existing.read_text() == "x"


@pytest.mark.parametrize("kind", ["planes", "edges", "corners"])
def test_the_output_suffix_is_checked_once(kind: str, tmp_path: Path, demo_tile: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """Regression (issue #26): edges and corners checked it in the command and in the job."""
    from lidarqa.cli import geometry

    calls = []
    check = geometry._check_suffix
    monkeypatch.setattr(geometry, "_check_suffix", lambda out: (calls.append(out), check(out)))
    r = CliRunner().invoke(cli, [kind, str(demo_tile), "-o", str(tmp_path / "o.txt")])
    assert r.exit_code == 1 and "use a .csv, .gpkg or .geojson file name" in r.output
    calls.clear()
    out = str(tmp_path / "o.csv")
    r = CliRunner().invoke(cli, [kind, str(tmp_path / "missing.laz"), "-o", out])
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert calls == [out]


def test_degenerate_cloud_writes_no_nan(tmp_path: Path) -> None:
    t = np.linspace(0, 10, 200)
    line = lidarqa.io.PointCloud(xyz=np.column_stack([t, t, t]),
                                 fields={"classification": np.full(200, 6, np.uint8)})
    path = tmp_path / "line.laz"
    lidarqa.write(line, path)
    for cmd, name in (("edges", "e.csv"), ("corners", "c.csv"), ("planes", "p.csv")):
        out = tmp_path / name
        r = CliRunner().invoke(cli, ["-q", cmd, str(path), "-o", str(out)])
        assert r.exit_code == 0, r.output
        text = out.read_text()
        assert "nan" not in text.lower()
        assert len(text.splitlines()) == 1  # header only
