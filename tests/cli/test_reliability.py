"""Issue #13: each reported failure gives one clear line and a documented exit status."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from hostile import run_cli

from lidarqa.cli.main import cli


def _points_csv(path, xyz, extra=""):
    rows = "".join(f"{i},{x},{y},{z}{extra}\n" for i, (x, y, z) in enumerate(xyz.tolist()))
    path.write_bytes(("id,x,y,z" + (",comment" if extra else "") + "\n").encode() + rows.encode(
        "latin-1"))
    return path


@pytest.fixture
def survey(tmp_path):
    rng = np.random.default_rng(0)
    chk = rng.uniform(0, 100, (30, 3))
    mea = chk + rng.normal(0, 0.05, chk.shape)
    return _points_csv(tmp_path / "mea.csv", mea), _points_csv(tmp_path / "chk.csv", chk)


def test_help_documents_exit_statuses():
    r = CliRunner().invoke(cli, ["--help"])
    assert "Exit status" in r.output
    for code in ("0 ", "1 ", "2 ", "3 ", "4 ", "130"):
        assert f"\n  {code}" in r.output or f"  {code}" in r.output


def test_checkpoint_targets_exit_4_and_keep_outputs(survey, tmp_path):
    mea, chk = survey
    out = tmp_path / "out"
    r = run_cli(["-q", "checkpoints", mea, chk, "--target-rmse-h", "0.001",
                 "--json", out / "r.json"], out_dir=out)
    assert r.exit_code == 4 and "Target not met: rmse_h" in r.stderr
    assert (out / "r.json").is_file()  # complete results, for the record
    r = run_cli(["-q", "checkpoints", mea, chk, "--target-rmse-h", "1"], out_dir=out)
    assert r.exit_code == 0 and "PASS" in r.output


def test_latin1_comment_is_read(tmp_path):
    rng = np.random.default_rng(1)
    chk = rng.uniform(0, 100, (10, 3))
    c = _points_csv(tmp_path / "c.csv", chk, extra=",caf\xe9")
    m = _points_csv(tmp_path / "m.csv", chk + 0.01)
    r = run_cli(["-q", "checkpoints", m, c], out_dir=tmp_path / "out")
    assert r.exit_code == 0, r.output
    # the encoding is reported as one warning line, not Python's two-line warning format
    assert "c.csv is not UTF-8" in r.stderr and r.stderr.startswith("warning: ")
    assert "read_points(" not in r.stderr and "DataQualityWarning" not in r.stderr


def test_no_check_point_inside_the_cloud_is_an_error(tmp_path):
    import lidarqa
    from lidarqa.io import PointCloud

    rng = np.random.default_rng(2)
    xyz = np.column_stack([rng.uniform(0, 50, (2000, 2)), rng.normal(0, 0.01, 2000)])
    cls = np.full(2000, 2, dtype=np.uint8)
    lidarqa.write(PointCloud(xyz=xyz, fields={"classification": cls}), tmp_path / "c.las")
    far = _points_csv(tmp_path / "g.csv", np.array([[500.0, 500, 0], [600, 600, 0]]))
    r = run_cli(["-q", "checkpoints", tmp_path / "c.las", far, "--vertical"],
                out_dir=tmp_path / "out")
    assert r.exit_code == 1 and "none of the 2 check point(s)" in r.stderr, r.output


def test_output_under_a_file(tmp_path, survey):
    mea, chk = survey
    (tmp_path / "notadir").write_text("x")
    r = run_cli(["-q", "checkpoints", mea, chk, "-o", tmp_path / "notadir" / "out.csv"],
                out_dir=tmp_path)
    assert r.exit_code == 1 and "is a file, not a folder" in r.stderr


def test_polygons_given_to_lines(tmp_path):
    shapely = pytest.importorskip("shapely")
    pyogrio = pytest.importorskip("pyogrio")
    poly = shapely.Polygon([(0, 0, 0), (1, 0, 0), (1, 1, 0)])
    pyogrio.raw.write(str(tmp_path / "poly.gpkg"), np.array([shapely.to_wkb(poly)], dtype=object),
                      geometry_type="Polygon Z", field_data=[np.array([1])], fields=["id"],
                      driver="GPKG")
    r = run_cli(["-q", "lines", tmp_path / "poly.gpkg", tmp_path / "poly.gpkg"],
                out_dir=tmp_path / "out")
    assert r.exit_code == 1 and "Polygon" in r.stderr


def test_heights_with_no_reference_point_compared_is_an_error(tmp_path):
    import lidarqa
    from lidarqa.io import PointCloud

    rng = np.random.default_rng(3)
    xyz = np.column_stack([rng.uniform(0, 50, (3000, 2)), rng.normal(0, 0.01, 3000)])
    lidarqa.write(PointCloud(xyz=xyz), tmp_path / "c.las")
    far = _points_csv(tmp_path / "far.csv", np.array([[900.0, 900, 0], [950, 950, 0]]))
    inside = _points_csv(tmp_path / "map.csv", np.array([[10.0, 10, 0], [40, 10, 0], [25, 40, 0]]))
    out = tmp_path / "out"
    r = run_cli(["-q", "heights", tmp_path / "c.las", inside, far, "-o", out / "h.csv"],
                out_dir=out)
    assert r.exit_code == 1 and "none of the 2 reference point(s)" in r.stderr, r.output
    r = run_cli(["-q", "heights", tmp_path / "c.las", far, inside], out_dir=out)
    assert r.exit_code == 1 and "none of the 2 map point(s) could be fitted" in r.stderr, r.output


def test_repeatability_with_no_comparable_pair_is_an_error(tmp_path):
    seg = tmp_path / "s.csv"
    seg.write_text("id,x1,y1,z1,x2,y2,z2\n1,0,0,0,0,0,0\n2,5,5,0,5,5,0\n")
    r = run_cli(["-q", "repeatability", seg, seg], out_dir=tmp_path / "out")
    assert r.exit_code == 1 and "none of the 1 pair(s)" in r.stderr, r.output
