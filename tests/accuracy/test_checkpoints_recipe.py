"""docs/recipes/corners-to-checkpoints.md end to end: cloud -> corners -> check points -> RMSE."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.accuracy.checkpoints import assess_checkpoints
from lidarqa.accuracy.transforms import rotation_matrix
from lidarqa.cli.main import cli
from lidarqa.io import PointCloud
from lidarqa.io.vector import PointSet, read_points, write_points
from lidarqa.testing import make_building_scene

corners_mod = pytest.importorskip("lidarqa.geometry.corners")
HAS_CORNERS_CLI = importlib.util.find_spec("lidarqa.cli.geometry") is not None


@pytest.fixture(scope="module")
def scene():
    return make_building_scene(seed=1)


@pytest.fixture(scope="module")
def survey(scene):
    """Total-station corners: the true corners with 5 mm survey noise, named like a survey."""
    rng = np.random.default_rng(21)
    xyz = scene.corners.xyz + rng.normal(0.0, 0.005, scene.corners.xyz.shape)
    ids = np.array([f"C{i:02d}" for i in range(len(xyz))])
    return PointSet(ids=ids, xyz=xyz)


def test_recipe_python_same_frame(scene, survey):
    corners = corners_mod.extract_corners(scene.points)
    report = assess_checkpoints(
        corners,
        survey,
        match="nearest",
        max_distance=0.5,
        checkpoint_rmse_h=0.007,
        checkpoint_rmse_v=0.005,
    )
    assert report.n_check == len(survey) == 18
    assert not report.match.unmatched_check
    # three-plane corners of a 2 cm-noise cloud at 20 pts/m²: sub-centimetre per axis
    assert np.all(report.stats.rmse < 0.02)
    assert report.stats.rmse_3d < 0.03
    assert report.asprs2023.rmse_h == pytest.approx(np.hypot(report.stats.rmse_h, 0.007))
    assert any("30" in w for w in report.warnings)  # 18 < 30 check points
    assert set(report.to_dict()) >= {"rmse_x", "rmse_3d", "nssda", "asprs2023", "residuals"}


def test_recipe_python_scanner_frame_similarity(scene, survey):
    """Fang & Huang: the scan is in a local frame; 5 control corners, the rest are checks."""
    r = rotation_matrix(0.0, 0.0, -35.0)
    origin = scene.corners.xyz.mean(axis=0)
    local = (scene.points - origin) @ r.T + [3.0, -2.0, 1.5]
    corners = corners_mod.extract_corners(local)
    # the user names the measured corners after the survey points (here with the known truth)
    back = (corners.xyz - [3.0, -2.0, 1.5]) @ r + origin
    nearest = np.argmin(np.linalg.norm(back[:, None] - survey.xyz[None], axis=2), axis=1)
    named = PointSet(ids=survey.ids[nearest], xyz=corners.xyz)
    control = ["C00", "C02", "C05", "C09", "C13"]
    report = assess_checkpoints(named, survey, transform="similarity2d", control_ids=control)
    assert report.n_control == 5 and report.n_check == 13
    assert report.transform.params["rotation_deg"] == pytest.approx(35.0, abs=0.1)
    assert report.transform.params["scale"] == pytest.approx(1.0, abs=1e-3)
    assert report.transform.sigmas["rotation_deg"] < 0.1
    assert report.stats.rmse_3d < 0.05
    without = assess_checkpoints(named, survey)  # no transformation: metres off
    assert without.stats.rmse_h > 1.0


@pytest.mark.skipif(not HAS_CORNERS_CLI, reason="lidarqa corners (cli/geometry.py) not there yet")
def test_recipe_cli(scene, survey, tmp_path):
    las = tmp_path / "building.las"
    lidarqa.write(PointCloud(scene.points, fields={"classification": scene.classification}), las)
    check = tmp_path / "check.csv"
    write_points(survey, check)
    corners = tmp_path / "corners.csv"
    runner = CliRunner()
    r = runner.invoke(cli, ["corners", str(las), "--classes", "6,2", "-o", str(corners), "-q"])
    assert r.exit_code == 0, r.output
    assert len(read_points(corners)) >= 18
    js = tmp_path / "accuracy.json"
    r = runner.invoke(
        cli,
        [
            "checkpoints",
            str(corners),
            str(check),
            "--match",
            "nearest",
            "--max-distance",
            "0.5",
            "--json",
            str(js),
            "-o",
            str(tmp_path / "residuals.gpkg"),
            "-q",
        ],
    )
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    assert res["n_check"] == 18 and res["rmse_3d"] < 0.03
