"""The CRS travels with CSV files (issue #16): .prj sidecars, --crs, mismatches."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner
from pyproj import CRS

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.errors import CRSMismatchError, OutputExistsError
from lidarqa.io.vector import PointSet, read_points, write_points

pyogrio = pytest.importorskip("pyogrio")

L93 = CRS.from_epsg(2154)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _survey(tmp_path, measured_xyz, ids, *, seed=5):
    """A check-point survey of `measured_xyz` (1 cm noise), CSV without CRS."""
    rng = np.random.default_rng(seed)
    chk = measured_xyz + rng.normal(0, 0.01, measured_xyz.shape)
    p = tmp_path / "survey.csv"
    write_points(PointSet(ids=np.asarray(ids), xyz=chk), p)
    assert not p.with_suffix(".prj").exists()
    return p


def test_csv_sidecar_roundtrip_and_gdal_reads_it(tmp_path):
    p = tmp_path / "pts.csv"
    xyz = np.array([[770500.05000000005, 6277500.1, 20.123456789], [770510.0, 6277510.0, 21.0]])
    write_points(PointSet(ids=np.array(["A", "B"]), xyz=xyz, crs=L93), p)
    assert p.with_suffix(".prj").is_file()
    back = read_points(p)
    assert back.crs is not None and back.crs.to_epsg() == 2154
    # coordinates to 0.1 mm, never float noise
    assert "770500.0500," in p.read_text() and "0000000" not in p.read_text()
    # GDAL's CSV driver (so QGIS) reads the sidecar
    info = pyogrio.read_info(p, X_POSSIBLE_NAMES="x", Y_POSSIBLE_NAMES="y", Z_POSSIBLE_NAMES="z")
    assert info["crs"] == "EPSG:2154"
    # rewriting without a CRS removes the stale sidecar
    write_points(PointSet(ids=np.array(["A"]), xyz=xyz[:1]), p, overwrite=True)
    assert not p.with_suffix(".prj").exists() and read_points(p).crs is None


def test_reader_crs_argument_and_mismatch(tmp_path):
    p = tmp_path / "pts.csv"
    write_points(PointSet(ids=np.array([1]), xyz=[[1.0, 2.0, 3.0]], crs=L93), p)
    assert read_points(p, crs=CRS.from_epsg(2154)).crs.to_epsg() == 2154
    with pytest.raises(CRSMismatchError) as err:
        read_points(p, crs=CRS.from_epsg(32632))
    assert "Lambert-93" in str(err.value) and "UTM zone 32N" in str(err.value)
    q = tmp_path / "bare.csv"
    q.write_text("id,x,y,z\n1,1,2,3\n")
    assert read_points(q).crs is None
    assert read_points(q, crs=L93).crs.to_epsg() == 2154


def test_existing_sidecar_is_not_clobbered(tmp_path):
    (tmp_path / "a.prj").write_text("keep")
    with pytest.raises(OutputExistsError):
        write_points(PointSet(np.array([1]), [[1.0, 2.0, 3.0]], crs=L93), tmp_path / "a.csv")
    assert (tmp_path / "a.prj").read_text() == "keep" and not (tmp_path / "a.csv").exists()


def test_checkpoints_from_csv_with_crs_option_writes_gpkg_in_that_crs(tmp_path):
    ids = [f"P{i}" for i in range(12)]
    rng = np.random.default_rng(1)
    mea = rng.uniform(0, 150, (12, 3)) + [770400.0, 6277500.0, 20.0]
    m = tmp_path / "measured.csv"
    write_points(PointSet(ids=np.array(ids), xyz=mea), m)
    s = _survey(tmp_path, mea, ids)
    out = tmp_path / "resid.gpkg"
    js = tmp_path / "c.json"
    r = run("checkpoints", m, s, "--crs", "EPSG:2154", "-o", out, "-q", "--json", js)
    assert r.exit_code == 0, r.output
    assert pyogrio.read_info(out)["crs"] == "EPSG:2154"
    doc = json.loads(js.read_text())
    assert doc["parameters"]["crs"] == "RGF93 v1 / Lambert-93"
    # a CSV output carries it in its sidecar
    out_csv = tmp_path / "resid.csv"
    assert run("checkpoints", m, s, "--crs", "2154", "-o", out_csv, "-q").exit_code == 0
    assert read_points(out_csv).crs.to_epsg() == 2154
    # without --crs (and no sidecar) nothing is invented
    out2 = tmp_path / "resid2.gpkg"
    assert run("checkpoints", m, s, "-o", out2, "-q").exit_code == 0
    assert pyogrio.read_info(out2)["crs"] is None


@pytest.fixture(scope="module")
def building_laz(tmp_path_factory):
    from lidarqa.testing import make_building_scene

    sc = make_building_scene(seed=3, roofs=("gable", "flat"))
    cloud = sc.to_cloud()
    cloud.crs = L93
    path = tmp_path_factory.mktemp("crs") / "scene.laz"
    lidarqa.write(cloud, path)
    return path


def test_corners_csv_roundtrips_its_crs_into_checkpoints(building_laz, tmp_path):
    corners = tmp_path / "corners.csv"
    r = run("-q", "corners", building_laz, "-o", corners)
    assert r.exit_code == 0, r.output
    assert corners.with_suffix(".prj").is_file()
    c = read_points(corners)
    assert c.crs.to_epsg() == 2154 and len(c) >= 4
    survey = _survey(tmp_path, c.xyz, c.ids.tolist())
    out = tmp_path / "resid.gpkg"
    r = run("checkpoints", corners, survey, "-o", out, "-q")  # no --crs
    assert r.exit_code == 0, r.output
    assert pyogrio.read_info(out)["crs"] == "EPSG:2154"
    # a --crs that contradicts the sidecar is an error naming both CRSs
    r = run("checkpoints", corners, survey, "--crs", "EPSG:32632", "-q")
    assert r.exit_code == 1
    assert "Lambert-93" in r.output and "UTM zone 32N" in r.output and "--crs" in r.output


def test_info_suggests_crs(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z\n0,0,0\n1,1,1\n")
    r = run("info", p, "-q")
    assert r.exit_code == 0 and "--crs" in r.output
    r = run("info", p, "-q", "--crs", "2154")
    assert "Lambert-93" in r.output and "pass --crs" not in r.output


def test_ground_text_output_keeps_las_precision_and_crs(data_dir, tmp_path):
    out = tmp_path / "g.txt"
    r = run("ground", data_dir / "samp24-utm.laz", "-o", out, "--preset", "als", "-q")
    assert r.exit_code == 0, r.output
    first = out.read_text().splitlines()[1].split(",")
    src = lidarqa.read(data_dir / "samp24-utm.laz")
    decimals = int(round(-np.log10(src.source.scales[0])))
    assert len(first[0].split(".")[1]) == decimals
    back = lidarqa.read(out)
    assert back.crs is not None and back.crs.to_epsg() == 32632
    np.testing.assert_allclose(back.xyz, src.xyz, atol=0.5 * 10.0**-decimals + 1e-9)


def test_assess_reads_csv_sidecars_and_refuses_a_contradicting_config(tmp_path):
    from lidarqa.report.config import ConfigCRSMismatchError, load_config

    p = tmp_path / "check.csv"
    write_points(PointSet(np.array([1, 2]), [[1.0, 2.0, 3.0], [2.0, 3.0, 4.0]], crs=L93), p)
    cfg = tmp_path / "a.toml"
    cfg.write_text(
        'crs = "EPSG:32632"\n[inputs.points]\ncheck = "check.csv"\nmeasured = "check.csv"\n'
        '[checkpoints]\nmeasured = "measured"\ncheck = "check"\n'
    )
    with pytest.raises(ConfigCRSMismatchError, match="Lambert-93"):
        load_config(cfg)


def test_las_without_crs_gets_the_given_one_on_write(tmp_path):
    from lidarqa.io import PointCloud

    xyz = np.random.default_rng(0).uniform(0, 100, (500, 3)) + [770000.0, 6277000.0, 0.0]
    bare = tmp_path / "bare.laz"
    lidarqa.write(PointCloud(xyz=xyz), bare)
    assert lidarqa.read(bare).crs is None
    cloud = lidarqa.read(bare, crs=L93)  # what --crs does
    out = tmp_path / "out.laz"
    lidarqa.write(cloud, out)
    back = lidarqa.read(out)
    assert back.crs.to_epsg() == 2154
    np.testing.assert_array_equal(back.xyz, lidarqa.read(bare).xyz)  # points untouched


def test_csv_residuals_are_written_to_a_tenth_of_a_millimetre(tmp_path):
    p = tmp_path / "r.csv"
    pts = PointSet(
        ids=np.array(["A"]), xyz=[[1.0, 2.0, 3.0]],
        attributes={"dx": np.array([-0.0002972952789]), "sigma": np.array([8.82e-07])},
    )  # fmt: skip
    write_points(pts, p)
    row = p.read_text().splitlines()[1].split(",")
    assert row[-2:] == ["-0.0003", "8.82e-07"]  # metres to 0.1 mm; other decimals keep their digits


def test_text_output_keeps_gps_time_microseconds(tmp_path):
    from lidarqa.data import demo_tile

    src = lidarqa.read(demo_tile())
    src = src.subset(np.arange(len(src)) < 3000)
    assert src.fields["gps_time"].max() > 1e8  # adjusted GPS time: 15 significant digits needed
    out = tmp_path / "demo.txt"
    lidarqa.write(src, out)
    back = lidarqa.read(out)
    assert back.crs is not None and back.crs.equals(src.crs)
    np.testing.assert_allclose(back.fields["gps_time"], src.fields["gps_time"], rtol=0, atol=1e-6)


def test_info_describes_point_lists_with_text_ids(tmp_path):
    p = tmp_path / "check.csv"
    write_points(PointSet(np.array(["C1", "C2"]), [[1.0, 2.0, 3.0], [2.0, 3.0, 4.5]], crs=L93), p)
    gpkg = tmp_path / "check.gpkg"
    write_points(read_points(p), gpkg)
    for path in (p, gpkg):
        r = run("info", path)
        assert r.exit_code == 0, r.output
        assert re.search(r"^  points +2$", r.output, re.M) and "Lambert-93 (EPSG:2154)" in r.output
        assert "3.000 .. 4.500" in r.output


@pytest.mark.parametrize("epsg", [2227, 4326])  # California zone 3 (US survey feet), WGS 84
def test_geometry_commands_refuse_x_y_not_in_metres(tmp_path, epsg):
    from lidarqa.io import PointCloud

    xyz = np.random.default_rng(0).uniform(0, 30, (300, 3)) + [6_000_000.0, 2_000_000.0, 0.0]
    if epsg == 4326:
        xyz = xyz / [1e5, 1e5, 1.0]
    path = tmp_path / "c.laz"
    lidarqa.write(PointCloud(xyz=xyz, crs=CRS.from_epsg(epsg)), path)
    r = run("planes", path, "-o", tmp_path / "p.csv")
    assert r.exit_code == 1 and "metres" in r.output and "reproject" in r.output, r.output
    assert not (tmp_path / "p.csv").exists()
    pts = tmp_path / "m.csv"
    write_points(PointSet(np.array([1]), xyz[:1], crs=CRS.from_epsg(epsg)), pts)
    r = run("heights", path, pts, pts)
    assert r.exit_code == 1 and "x, y unit" in r.output and "metres" in r.output, r.output
