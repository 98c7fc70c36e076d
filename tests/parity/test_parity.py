"""File vs catalog parity (issue #26): the same data as one merged file and as a folder of
tiles, with the same options, give the same JSON results.

Real data: the six adjacent IGN LiDAR HD 50 m tiles (merged with laspy for the file side).
Feet: a synthetic scene written with a compound CRS whose heights are US survey feet.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, ign_block, needs_shared

from lidarqa.cli.main import cli

IGN = SHARED / "ign-lidarhd"
FT = 1200.0 / 3937.0  # US survey foot, m


def run(*args: object) -> object:
    args = [str(a) for a in args]
    if Path(args[1]).is_dir() and args[0] not in ("info", "roads"):  # catalog: serial
        args += ["--workers", "1"]
    return CliRunner().invoke(cli, ["-q", *args])


def results(tmp: Path, *args: object) -> dict:
    out = tmp / f"r{len(list(tmp.glob('r*.json')))}.json"
    res = run(*args, "--json", out)
    assert res.exit_code == 0, res.output
    return json.loads(out.read_text())["results"]


# ------------------------------------------------------------------ fixtures


@pytest.fixture(scope="module")
def ign(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The six IGN tiles as a folder, and merged into one file."""
    if not IGN.is_dir():
        pytest.skip("../shared/lidar-data is not present")
    base = tmp_path_factory.mktemp("ign")
    folder, _, merged = ign_block(base)
    # check points: on the ground of strip 706 and 707 alike, on a 12 m grid (z = local median
    # of the ground points + a seeded offset), written as id,x,y,z
    xyz = np.column_stack([merged.x, merged.y, merged.z])
    ground = xyz[np.asarray(merged.classification) == 2]
    from scipy.spatial import cKDTree

    tree = cKDTree(ground[:, :2])
    x0, y0 = ground[:, :2].min(0) + 4.0
    x1, y1 = ground[:, :2].max(0) - 4.0
    gx, gy = np.meshgrid(np.arange(x0, x1, 12.0), np.arange(y0, y1, 12.0))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    rng = np.random.default_rng(26)
    rows = []
    for i, p in enumerate(grid):
        near = tree.query_ball_point(p, 1.0)
        if len(near) >= 4:
            z = float(np.median(ground[near, 2])) + rng.normal(0.0, 0.03)
            rows.append(f"CP{i:04d},{p[0]:.3f},{p[1]:.3f},{z:.3f}")
    chk = base / "chk.csv"
    chk.write_text("id,x,y,z\n" + "\n".join(rows) + "\n")
    far = base / "far.csv"
    far.write_text("id,x,y,z\nA,0.0,0.0,0.0\nB,10.0,10.0,0.0\n")
    # map points for heights: a jittered 20 m grid (a regular grid has co-circular points,
    # whose Delaunay triangulation is not unique)
    mp = base / "map.csv"
    mgx, mgy = np.meshgrid(np.arange(x0 + 6, x1, 20.0), np.arange(y0 + 6, y1, 20.0))
    mgx = mgx + rng.uniform(-3, 3, mgx.shape)
    mgy = mgy + rng.uniform(-3, 3, mgy.shape)
    mp.write_text("id,x,y\n" + "\n".join(
        f"M{i},{x:.3f},{y:.3f}" for i, (x, y) in enumerate(zip(mgx.ravel(), mgy.ravel(),
                                                               strict=True))) + "\n")
    return {"folder": folder, "file": base / "merged.laz", "chk": chk, "far": far, "map": mp}


# ------------------------------------------------------------------ info


@needs_shared
def test_info_counts_points_the_same_on_the_file_and_the_folder(ign, tmp_path):
    a = results(tmp_path, "info", ign["file"])
    b = results(tmp_path, "info", ign["folder"])
    n_file = a.get("n_points", a.get("point_count"))
    assert n_file == b["n_points"] == 405937


# ------------------------------------------------------------------ checkpoints --vertical


@needs_shared
@pytest.mark.slow
@pytest.mark.parametrize("sid", [None, "706"], ids=["all", "source-id"])
def test_checkpoints_vertical_parity(ign, tmp_path, sid):
    opts = ("--source-id", sid) if sid else ()
    a = results(tmp_path, "checkpoints", ign["file"], ign["chk"], "--vertical", *opts)
    b = results(tmp_path, "checkpoints", ign["folder"], ign["chk"], "--vertical", *opts)
    assert a["n_check"] == b["n_check"] > 20
    for k in ("rmse_z", "mean_z", "std_z"):
        assert abs(a[k] - b[k]) < 1e-3, k
    assert b["units"] == "m"


@needs_shared
@pytest.mark.slow
def test_checkpoints_vertical_source_id_changes_the_catalog_answer(ign, tmp_path):
    """Regression: the catalog path used to drop --source-id and measure every strip."""
    a = results(tmp_path, "checkpoints", ign["folder"], ign["chk"], "--vertical")
    b = results(tmp_path, "checkpoints", ign["folder"], ign["chk"], "--vertical",
                "--source-id", "706")
    assert a["vertical"]["n_ground"] > b["vertical"]["n_ground"]


@needs_shared
@pytest.mark.slow
def test_checkpoints_with_nothing_to_measure_fail_alike(ign, tmp_path):
    """Regression: zero usable check points gave NaN figures on a catalog."""
    for src in (ign["file"], ign["folder"]):
        res = run("checkpoints", src, ign["far"], "--vertical")
        assert res.exit_code == 1, res.output
        assert "could be compared" in res.output


def test_checkpoints_vertical_in_feet_parity_and_metres(feet, tmp_path):
    """Heights in US survey feet: converted to metres on a file and on a catalog alike."""
    a = results(tmp_path, "checkpoints", feet["file"], feet["chk"], "--vertical")
    b = results(tmp_path, "checkpoints", feet["folder"], feet["chk"], "--vertical")
    m = results(tmp_path, "checkpoints", feet["metres"], feet["chk_m"], "--vertical")
    assert a["n_check"] == b["n_check"] == m["n_check"] > 10
    for k in ("rmse_z", "mean_z", "std_z"):
        assert abs(a[k] - b[k]) < 1e-3, k
        assert abs(b[k] - m[k]) < 1e-3, k  # metres, not feet
    assert any("converted to metres" in w for w in b["warnings"])


def test_checkpoints_vertical_crs_is_honoured_on_a_catalog(feet, tmp_path):
    """--crs that contradicts the files is refused on a file and on a catalog alike."""
    for src in (feet["file"], feet["folder"]):
        res = run("checkpoints", src, feet["chk"], "--vertical", "--crs", "EPSG:2154")
        assert res.exit_code == 1 and "--crs" in res.output, res.output


# ------------------------------------------------------------------ heights


@needs_shared
@pytest.mark.slow
def test_heights_parity_with_source_id(ign, tmp_path):
    opts = ("--classes", "2", "--source-id", "706", "--max-radius", "5")
    a = results(tmp_path, "heights", ign["file"], ign["map"], ign["chk"], *opts)
    b = results(tmp_path, "heights", ign["folder"], ign["map"], ign["chk"], *opts)
    assert a["comparison"]["n"] == b["comparison"]["n"] > 10
    assert a["map_points"]["n_failed"] == b["map_points"]["n_failed"]
    for k in ("rms", "mean", "std"):
        assert abs(a["comparison"][k] - b["comparison"][k]) < 1e-3, k
    c = results(tmp_path, "heights", ign["folder"], ign["map"], ign["chk"],
                "--classes", "2", "--max-radius", "5")
    assert c["comparison"]["rms"] != b["comparison"]["rms"]  # --source-id is not dropped


def test_heights_in_feet_parity(feet, tmp_path):
    """Regression: catalog heights converted the reference z to metres but not the laser z."""
    mp = tmp_path / "map.csv"
    g = np.meshgrid(np.arange(500_005.0, 500_080.0, 9.0), np.arange(4_000_005.0, 4_000_080.0, 9.0))
    rng = np.random.default_rng(9)  # jittered: a regular grid's Delaunay TIN is not unique
    g = [g[0] + rng.uniform(-2, 2, g[0].shape), g[1] + rng.uniform(-2, 2, g[1].shape)]
    mp.write_text("id,x,y\n" + "\n".join(f"M{i},{x:.3f},{y:.3f}" for i, (x, y) in
                                         enumerate(zip(g[0].ravel(), g[1].ravel(), strict=True))))
    opts = ("--classes", "2", "--max-radius", "4")
    a = results(tmp_path, "heights", feet["file"], mp, feet["chk"], *opts)
    b = results(tmp_path, "heights", feet["folder"], mp, feet["chk"], *opts)
    assert a["comparison"]["n"] == b["comparison"]["n"] > 5
    assert abs(a["comparison"]["rms"] - b["comparison"]["rms"]) < 1e-3
    assert b["comparison"]["rms"] < 0.5  # metres against metres, not feet against metres


# ------------------------------------------------------------------ lines


@needs_shared
@pytest.mark.slow
def test_lines_on_the_ign_catalog_and_file(ign, tmp_path):
    opts = ("--classes", "6", "--test-source-id", "707", "--model-source-id", "706")
    b = results(tmp_path, "lines", ign["folder"], ign["folder"], *opts)
    assert b["n_pairs_tm"] >= 15 and b["lhd"] <= 0.5
    a = results(tmp_path, "lines", ign["file"], ign["file"], *opts)
    assert abs(a["lhd"] - b["lhd"]) < 1e-3
    assert abs(a["p"] - b["p"]) <= 0.02 * a["p"] + 1 and abs(a["q"] - b["q"]) <= 0.02 * a["q"] + 1


# ------------------------------------------------------------------ options honoured
# every option of every command: tests/parity/test_catalog_options.py


# ------------------------------------------------------------------ roads


@pytest.fixture(scope="module")
def semis_quadrants(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The IGN 1 km tile with a road bridge, cut into four quadrant files."""
    path = IGN / "test_semis_2023_0299_6802_LA93_IGN69.laz"
    if not path.is_file():
        pytest.skip("../shared/lidar-data is not present")
    import laspy

    las = laspy.read(path)
    folder = tmp_path_factory.mktemp("semis")
    x, y = np.asarray(las.x), np.asarray(las.y)
    for i, mx in enumerate((x < 299500.0, x >= 299500.0)):
        for j, my in enumerate((y < 6801500.0, y >= 6801500.0)):
            out = laspy.LasData(las.header)
            out.points = las.points[mx & my]
            out.update_header()
            out.write(folder / f"q{i}{j}.laz")
    return folder


@needs_shared
@pytest.mark.slow
def test_roads_on_a_folder_equals_the_file(semis_quadrants, tmp_path):
    """Regression: roads refused folders."""
    roads = Path(__file__).parents[1] / "data" / "ign-bridge-roads.geojson"
    a = results(tmp_path, "roads", IGN / "test_semis_2023_0299_6802_LA93_IGN69.laz", roads,
                "-o", tmp_path / "a.gpkg")
    b = results(tmp_path, "roads", semis_quadrants, roads, "-o", tmp_path / "b.gpkg")
    assert a["n_roads"] == b["n_roads"] == 2
    assert a["n_map_points"] == b["n_map_points"] and a["n_failed"] == b["n_failed"] == 0
    assert abs(a["sigma_mean"] - b["sigma_mean"]) < 1e-3


# ------------------------------------------------------------------ planes, edges, corners
# and repeatability: tests/parity/test_parity_geometry.py (a chunked folder, >= 98 % matched)


# ------------------------------------------------------------------ strips


@needs_shared
@pytest.mark.slow
def test_swaths_of_the_file_and_the_folder_agree(ign, tmp_path):
    opts = ("--by-source-id", "--no-maps", "--classes", "2")
    a = results(tmp_path, "swaths", ign["file"], *opts, "-o", tmp_path / "a")
    b = results(tmp_path, "swaths", ign["folder"], *opts, "-o", tmp_path / "b")
    pa = {(p["strip_a"], p["strip_b"]): p for p in a["pairs"]}
    pb = {(p["strip_a"], p["strip_b"]): p for p in b["pairs"]}
    assert pa.keys() == pb.keys() and pa
    for k in pa:
        assert pa[k]["n_cells"] == pb[k]["n_cells"], k
        assert abs(pa[k]["rmsdz"] - pb[k]["rmsdz"]) < 1e-3, k
