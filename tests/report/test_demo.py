"""`lidarqa demo --out DIR`: the bundled config on the bundled IGN tile, end to end."""

from __future__ import annotations

import json

import pytest

from lidarqa.report.config import ANALYSIS_KINDS, load_config
from lidarqa.report.run import demo_config_path


@pytest.mark.slow  # ~7 s: the whole demo assessment
def test_demo_writes_report_json_and_outputs(demo_run):
    r = demo_run["result"]
    out = demo_run["out"]
    assert r.exit_code == 0, r.output
    assert (out / "report.html").is_file() and (out / "report.json").is_file()
    doc = json.loads((out / "report.json").read_text())
    assert doc["command"] == "demo"
    assert doc["attribution"].startswith("IGN – LiDAR HD")
    html = (out / "report.html").read_text()
    assert "IGN – LiDAR HD" in html
    # Every analysis of the bundled config ran, or is listed as not available in this build.
    planned = {a.kind for a in load_config(demo_config_path(), skip_unavailable=True).analyses}
    skipped = {s["kind"] for s in doc["skipped"]}
    assert planned | skipped == {
        "info",
        "ground",
        "edges",
        "lines",
        "checkpoints",
        "heights",
        "swaths",
    }
    params = doc["parameters"]
    for pid, p in params.items():
        assert p["kind"] in ANALYSIS_KINDS
        if pid not in doc["errors"]:
            assert doc["results"][pid], pid
    # Inputs are hashed; the tile is the bundled one.
    (tile,) = doc["inputs"].values()
    assert tile["sha256"].startswith("152177670d187233")
    assert tile["crs_epsg"] == 2154
    # The held-apart split and the sampled check points are deterministic.
    res = doc["results"]
    if "heights" in res and res["heights"]:
        assert res["heights"]["n_reference"] == 5000
        assert 0.0 < res["heights"]["comparison"]["rms"] < 0.2
    if "checkpoints" in res and res["checkpoints"]:
        assert res["checkpoints"]["n_check"] >= 15
        assert abs(res["checkpoints"]["mean_z"]) < 0.1  # two strips of one survey agree
    if res.get("swaths"):
        assert [(p["strip_a"], p["strip_b"]) for p in res["swaths"]["pairs"]] == [(706, 707)]


def test_demo_report_is_self_contained(demo_run):
    import re

    html = (demo_run["out"] / "report.html").read_text()
    assert '<meta name="viewport"' in html
    # No resource is fetched: every src is inline data; links are in-page anchors or the
    # relative output files beside the report.
    for attr in re.findall(r'src\s*=\s*"([^"]*)"', html):
        assert attr.startswith("data:image/png;base64,"), attr[:80]
    for attr in re.findall(r'href\s*=\s*"([^"]*)"', html):
        assert attr.startswith(("#", "outputs/")), attr[:80]
        if attr.startswith("outputs/"):
            assert (demo_run["out"] / attr).is_file(), attr
    assert not re.search(r"url\(\s*['\"]?https?:", html)
    assert "@import" not in html and "<script" not in html and "<link" not in html
    assert html.count("<img ") >= 5


def test_demo_refuses_to_overwrite(demo_run):
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    r = CliRunner().invoke(cli, ["demo", "--out", str(demo_run["out"]), "-q"])
    assert r.exit_code == 1 and "--overwrite" in r.stderr
