"""The command-line contract shared by every command (issue #2)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_version():
    r = run("--version")
    assert r.exit_code == 0 and lidarqa.__version__ in r.output


def test_show_versions():
    r = run("--show-versions")
    assert r.exit_code == 0 and "laspy" in r.output and "numpy" in r.output


def test_info_json_document(data_dir, tmp_path):
    out = tmp_path / "i.json"
    r = run("info", data_dir / "samp11-utm.laz", "--json", out, "-q")
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert set(doc) == {"lidarqa_version", "command", "inputs", "parameters", "results"}
    res = doc["results"]
    assert doc["command"] == "info"
    assert res["n_points"] == 38010
    assert res["crs_epsg"] == 32632
    assert res["classes"] == {"0": 16224, "2": 21786}
    assert res["point_source_ids"] == {"0": 38010}
    assert set(res["bounds"]) == {"min_x", "min_y", "min_z", "max_x", "max_y", "max_z"}
    assert res["bounds"]["min_x"] == pytest.approx(512700.87)
    # about 1 pt/m² in the ISPRS reference samples
    assert 0.5 < res["density_per_m2"] < 2.5
    assert res["returns"]["present"] is True


@pytest.mark.parametrize("as_folder", [False, True])
def test_info_headers_only_agrees_with_the_points_and_reads_none(data_dir, tmp_path, as_folder):
    src = data_dir / "samp11-utm.laz"
    if as_folder:
        (tmp_path / "f").mkdir()
        (tmp_path / "f" / src.name).write_bytes(src.read_bytes())
        src = tmp_path / "f"
    full, head = tmp_path / "full.json", tmp_path / "head.json"
    assert run("info", src, "--json", full, "-q").exit_code == 0
    r = run("info", src, "--headers", "--json", head)
    assert r.exit_code == 0, r.output
    a, b = json.loads(full.read_text())["results"], json.loads(head.read_text())["results"]
    assert b["n_points"] == a["n_points"] == 38010
    assert b["crs_epsg"] == a["crs_epsg"]
    # header bounds are the points' extent, to the header's scale (a catalog lists them)
    assert b["bounds"] == pytest.approx(a["bounds"], abs=0.01)
    assert b["points_read"] is False and a["points_read"] is True
    assert b["classes"] == {} and b["density_per_m2"] is None and b["returns"] == {}
    assert "not read (--headers)" in r.output


def test_info_headers_refuses_a_point_list_in_one_line(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z\n0,0,0\n1,1,1\n")
    r = run("info", p, "--headers")
    assert r.exit_code != 0 and "--headers" in r.output and "Traceback" not in r.output


def test_info_demo_tile_strips_and_returns(demo_tile):
    r = run("info", demo_tile, "-q")
    assert r.exit_code == 0
    assert "706" in r.output and "707" in r.output and "Lambert-93" in r.output


def test_info_text_cloud(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z,classification\n0,0,0,2\n1,1,1,6\n")
    out = tmp_path / "i.json"
    assert run("info", p, "--json", out).exit_code == 0
    assert json.loads(out.read_text())["results"]["classes"] == {"2": 1, "6": 1}


def _bad_inputs(tmp_path, data_dir):
    rng = np.random.default_rng(7)
    cases = {}
    cases["missing"] = tmp_path / "nope.laz"
    d = tmp_path / "adir.laz"
    d.mkdir()
    cases["directory"] = d
    e = tmp_path / "empty.laz"
    e.write_bytes(b"")
    cases["empty"] = e
    rb = tmp_path / "random.laz"
    rb.write_bytes(rng.bytes(4096))
    cases["random-bytes"] = rb
    raw = (data_dir / "samp11-utm.laz").read_bytes()
    tr = tmp_path / "trunc.laz"
    tr.write_bytes(raw[: len(raw) // 3])
    cases["truncated-laz"] = tr
    las = bytearray((data_dir / "autzen-bmx-2010.las").read_bytes())
    n = int.from_bytes(las[247:255], "little")
    las[247:255] = (n + 5).to_bytes(8, "little")
    las[107:111] = (n + 5).to_bytes(4, "little")
    hc = tmp_path / "count.las"
    hc.write_bytes(bytes(las))
    cases["header-count"] = hc
    nx = tmp_path / "noxyz.csv"
    nx.write_text("a,b,c\n1,2,3\n")
    cases["csv-no-xyz"] = nx
    nan = tmp_path / "nan.csv"
    nan.write_text("x,y,z\n1,2,3\nnan,2,3\n")
    cases["nan"] = nan
    return cases


@pytest.mark.parametrize(
    "case",
    [
        "missing",
        "directory",
        "empty",
        "random-bytes",
        "truncated-laz",
        "header-count",
        "csv-no-xyz",
        "nan",
    ],
)
def test_bad_input_one_line_no_traceback_no_output(tmp_path, data_dir, case):
    path = _bad_inputs(tmp_path, data_dir)[case]
    out = tmp_path / "out.json"
    r = run("info", path, "--json", out)
    assert r.exit_code == 1, (case, r.output)
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), r.output
    assert "Traceback" not in r.output
    assert not out.exists()


def test_existing_output_needs_overwrite(data_dir, tmp_path):
    out = tmp_path / "i.json"
    out.write_text("keep")
    r = run("info", data_dir / "samp24-utm.laz", "--json", out)
    assert r.exit_code == 1 and "--overwrite" in r.output
    assert out.read_text() == "keep"
    r = run("info", data_dir / "samp24-utm.laz", "--json", out, "--overwrite")
    assert r.exit_code == 0 and json.loads(out.read_text())["results"]["n_points"] == 7492


def test_verbose_shows_traceback(tmp_path):
    r = run("-v", "info", tmp_path / "missing.laz")
    assert r.exit_code == 1 and "Traceback" in r.output


def test_console_script_subprocess(data_dir):
    """The installed entry point: errors go to stderr, exit code is non-zero."""
    proc = subprocess.run(
        [sys.executable, "-m", "lidarqa.cli.main", "info", str(data_dir / "missing.laz")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 1
    assert proc.stderr.strip().startswith("Error:") and proc.stdout == ""


def test_polar_command(tmp_path):
    obs = tmp_path / "obs.csv"
    obs.write_text("id,distance,azimuth,elevation\n1,10,90,0\n2,10,0,30\n")
    out = tmp_path / "pts.csv"
    r = run("polar", obs, "-o", out, "--station", "100,200,50", "--json", tmp_path / "p.json")
    assert r.exit_code == 0, r.output
    from lidarqa.io.vector import read_points

    pts = read_points(out)
    np.testing.assert_allclose(pts.xyz, [[110, 200, 50], [100, 208.660254, 55]], atol=5.1e-5)
    bad = run("polar", obs, "-o", out)
    assert bad.exit_code == 1 and "exists" in bad.output
