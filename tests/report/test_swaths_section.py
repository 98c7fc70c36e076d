"""The ``swaths`` analysis of an assessment on synthetic strips (issue #14)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pyproj import CRS

import lidarqa
from lidarqa.errors import ConfigError
from lidarqa.io import PointCloud
from lidarqa.report import run_assessment
from lidarqa.testing.strips import make_strip_scene

TOML = """
title = "Strips"
crs = "EPSG:2154"

[inputs.clouds]
block = "{path}"

[swaths]
cloud = "block"
quality_level = "QL1"
cell_size = 1.0
target_rmsdz = {target}
target_e4 = 0.05
"""


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    d = tmp_path_factory.mktemp("swaths_assess")
    scene = make_strip_scene(2, offsets=[[0, 0, 0], [0.03, 0.0, 0.04]], noise=0.02, seed=9)
    xyz = scene.points + [650_000.0, 6_860_000.0, 0.0]
    fields = {
        "classification": np.full(len(xyz), 2, dtype=np.uint8),
        "point_source_id": scene.strip.astype(np.uint16),
    }
    lidarqa.write(PointCloud(xyz=xyz, fields=fields, crs=CRS.from_epsg(2154)), d / "block.laz")
    return d / "block.laz"


@pytest.mark.parametrize(("target", "verdict"), [(0.08, "pass"), (0.02, "fail")])
def test_section_results_maps_and_verdict(block, tmp_path, target, verdict):
    cfg = tmp_path / "a.toml"
    cfg.write_text(TOML.format(path=block.as_posix(), target=target), encoding="utf-8")
    run = run_assessment(cfg, tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    res = doc["results"]["swaths"]
    (pair,) = res["pairs"]
    assert pair["mean"] == pytest.approx(0.04, abs=0.005)  # the strip's dz offset
    assert res["max_rmsdz"] == pytest.approx(pair["rmsdz"])
    assert doc["verdicts"]["swaths"]["verdict"] == verdict
    assert any(p.endswith("dz_1_2.tif") for p in run.document["outputs"]["swaths"])
    html = run.html_path.read_text(encoding="utf-8")
    assert "DZ map, strips 1 and 2" in html and "Swath overlap" in html


def test_config_rejects_bad_quality_level(block, tmp_path):
    from lidarqa.report._registry import library_params
    from lidarqa.report.config import load_config

    cfg = tmp_path / "a.toml"
    cfg.write_text(
        TOML.format(path=block.as_posix(), target=0.08).replace('"QL1"', '"QL7"'),
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match="quality_level"):
        load_config(cfg, library_params=library_params)
