"""Fixtures of the report tests: a small synthetic assessment, one demo run shared by the tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ORIGIN = np.array([770000.0, 6277000.0, 0.0])
CHECK_OFFSET = 0.05  # check points lie this far below the true ground: the cloud is 5 cm "too high"
SHIFT = np.array([0.03, -0.04, 0.0])  # test segments = true edges shifted by this
MEASURED_SHIFT = np.array([0.10, -0.05, 0.02])  # measured points = check points shifted by this


@pytest.fixture(scope="session")
def synthetic(tmp_path_factory) -> dict:
    """A synthetic scene as LAS (EPSG:2154) with check points, reference heights and segments."""
    import lidarqa
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, Segments, write_points, write_segments
    from lidarqa.testing import make_scene

    d = tmp_path_factory.mktemp("synthetic")
    scene = make_scene(
        seed=3,
        size=(40.0, 40.0),
        density=10.0,
        strips=2,
        n_buildings=2,
        n_trees=2,
        n_cars=1,
        origin=tuple(ORIGIN),
    )
    cloud = scene.to_cloud()
    cloud.crs = parse_crs("EPSG:2154")
    lidarqa.write(cloud, d / "scene.las")

    rng = np.random.default_rng(7)
    ground = scene.points[scene.is_ground]
    lo, hi = ground[:, :2].min(axis=0) + 5, ground[:, :2].max(axis=0) - 5
    # Check points on open ground (true terrain height minus the offset).
    xy = rng.uniform(lo, hi, size=(400, 2))
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(ground[:, :2]).query(xy)
    clear, _ = cKDTree(scene.points[~scene.is_ground, :2]).query(xy)
    xy = xy[(dist < 0.3) & (clear > 3.0)][:25]
    check = PointSet(
        ids=np.arange(1, len(xy) + 1), xyz=np.column_stack([xy, scene.ground_z(xy) - CHECK_OFFSET])
    )
    write_points(check, d / "check.csv")
    # "Measured" points (e.g. corners from the cloud): the check points shifted by MEASURED_SHIFT.
    write_points(PointSet(ids=check.ids, xyz=check.xyz + MEASURED_SHIFT), d / "measured.csv")
    # Reference heights for the height-quality analysis: true terrain at random ground locations.
    rxy = rng.uniform(lo, hi, size=(3000, 2))
    dist, _ = cKDTree(ground[:, :2]).query(rxy)
    rxy = rxy[dist < 0.3][:600]
    write_points(
        PointSet(ids=np.arange(len(rxy)), xyz=np.column_stack([rxy, scene.ground_z(rxy)])),
        d / "reference.csv",
    )
    # Map points: a 5 m grid over the ground.
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 5.0), np.arange(lo[1], hi[1], 5.0))
    mxy = np.column_stack([gx.ravel(), gy.ravel()])
    write_points(
        PointSet(ids=np.arange(len(mxy)), xyz=np.column_stack([mxy, np.zeros(len(mxy))])),
        d / "map.csv",
    )
    # Segments: true edges (model) and the same shifted (test).
    e = scene.edges
    write_segments(Segments(e.ids, e.start, e.end), d / "model.csv")
    write_segments(Segments(e.ids, e.start + SHIFT, e.end + SHIFT), d / "test.csv")
    return {"dir": d, "scene": scene, "n_check": len(xy)}


def write_config(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


SYNTHETIC_TOML = """
title = "Synthetic assessment"
crs = "EPSG:2154"

[inputs.clouds]
scene = "{d}/scene.las"
[inputs.points]
check = "{d}/check.csv"
reference = "{d}/reference.csv"
map = "{d}/map.csv"
[inputs.segments]
model = "{d}/model.csv"
test = "{d}/test.csv"

[info]
cloud = "scene"

[ground]
cloud = "scene"
target_total = 0.10

[edges]
cloud = "scene"
classes = [6]
source_ids = [1, 2]

[checkpoints]
measured = "scene"
vertical = true
check = "check"
target_rmse_z = 0.10

[heights]
cloud = "scene"
classes = [2]
map = "map"
reference = "reference"
sigma_ref = 0.02

[lines]
test = "test"
model = "model"
threshold = 0.5
target_lhd = 0.2
"""


#: A lighter config (two cheap analyses) for the tests of refusals, failures and Ctrl-C.
LIGHT_TOML = """
title = "Light assessment"
[inputs.clouds]
scene = "{d}/scene.las"
[inputs.points]
check = "{d}/check.csv"
[inputs.segments]
model = "{d}/model.csv"
test = "{d}/test.csv"

[checkpoints]
measured = "scene"
vertical = true
check = "check"
target_rmse_z = 0.10

[lines]
test = "test"
model = "model"
"""


@pytest.fixture
def synthetic_config(synthetic, tmp_path) -> Path:
    return write_config(tmp_path / "assess.toml", LIGHT_TOML.format(d=synthetic["dir"].as_posix()))


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """`lidarqa demo --out DIR` once per session (shared by the demo and browser tests)."""
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    out = tmp_path_factory.mktemp("demo") / "out"
    result = CliRunner().invoke(cli, ["-q", "demo", "--out", str(out)], catch_exceptions=False)
    return {"out": out, "result": result}
