"""The CLI command and the ``assess`` analysis of one job give one answer (issue #26).

Each job applies the CRS, the conversion to metres and the selection through one library
function, so the CLI and the report cannot drift apart: the same feet-unit data through
``lidarqa roads`` / ``heights`` / ``checkpoints`` and through ``lidarqa assess`` give the same
figures (and the figures of the same data in metres), and a map or reference in another CRS
is refused by both.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from lidarqa.cli.main import cli

FT = 1200.0 / 3937.0  # US survey foot, m
CRS_FT = "EPSG:26915+6360"  # UTM 15N (m) + NAVD88 height (US survey feet)
OFF = np.array([500_000.0, 4_000_000.0, 100.0])

pyogrio = pytest.importorskip("pyogrio")
shapely = pytest.importorskip("shapely")


def cli_results(tmp: Path, *args: object) -> dict:
    out = tmp / f"c{len(list(tmp.glob('c*.json')))}.json"
    r = CliRunner().invoke(cli, ["-q", *map(str, args), "--json", str(out)])
    assert r.exit_code == 0, r.output
    return json.loads(out.read_text())["results"]


def cli_fails(*args: object) -> str:
    r = CliRunner().invoke(cli, ["-q", *map(str, args)])
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    return r.output


def assess(tmp: Path, body: str) -> dict:
    from lidarqa.report import run_assessment

    n = len(list(tmp.glob("a*.toml")))
    cfg = tmp / f"a{n}.toml"
    cfg.write_text(body)
    run_assessment(cfg, tmp / f"out{n}")
    return json.loads((tmp / f"out{n}" / "report.json").read_text())


def assess_refusal(tmp: Path, body: str, kind: str) -> str:
    """The reason `assess` refuses the analysis `kind`: the run's refusal or its error entry."""
    from lidarqa.errors import LidarQAError

    try:
        doc = assess(tmp, body)
    except LidarQAError as exc:  # refused before any analysis ran (the config's CRS check)
        return str(exc)
    assert kind in doc["errors"], doc["errors"]
    return json.dumps(doc["errors"][kind])


def _write_polygons(path: Path, polys: list, ids: np.ndarray, crs: str) -> None:
    pyogrio.raw.write(str(path), shapely.to_wkb(np.array(polys, dtype=object)),
                      geometry_type="Polygon", field_data=[ids.astype(str).astype(object)],
                      fields=["id"], crs=crs, driver="GPKG")


# ------------------------------------------------------------------ roads


@pytest.fixture(scope="module")
def interchange(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The synthetic interchange with heights in feet and in metres, its map and references."""
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs
    from lidarqa.testing.interchange import make_interchange

    d = tmp_path_factory.mktemp("interchange")
    s = make_interchange(seed=3, density=2.0)
    xyz = np.round(s.points + OFF, 3)
    ft = xyz.copy()
    ft[:, 2] = np.round(xyz[:, 2] / FT, 3)
    fields = {"classification": s.classification}
    lidarqa.write(PointCloud(xyz, dict(fields), crs=parse_crs("EPSG:26915")), d / "m.las")
    lidarqa.write(PointCloud(ft, dict(fields), crs=parse_crs(CRS_FT)), d / "ft.las")
    moved = [shapely.transform(g, lambda c: c + OFF[:2]) for g in s.polygons]
    _write_polygons(d / "map.gpkg", moved, s.polygon_ids, "EPSG:26915")
    _write_polygons(d / "map_2154.gpkg", moved, s.polygon_ids, "EPSG:2154")  # same numbers
    ref = s.reference_xyz + OFF
    (d / "ref_m.csv").write_text("id,x,y,z\n" + "\n".join(
        f"{i},{x:.3f},{y:.3f},{z:.4f}" for i, (x, y, z) in enumerate(ref)) + "\n")
    (d / "ref_ft.csv").write_text("id,x,y,z\n" + "\n".join(
        f"{i},{x:.3f},{y:.3f},{z / FT:.4f}" for i, (x, y, z) in enumerate(ref)) + "\n")
    return {"dir": d, "m": d / "m.las", "ft": d / "ft.las", "map": d / "map.gpkg",
            "map_2154": d / "map_2154.gpkg", "ref_m": d / "ref_m.csv", "ref_ft": d / "ref_ft.csv"}


_ROADS_KEYS = ("n_roads", "n_map_points", "n_failed", "sigma_mean", "sigma_p95")


def _same_roads(a: dict, b: dict) -> None:
    for k in _ROADS_KEYS:
        assert a[k] == pytest.approx(b[k], abs=1e-3), (k, a[k], b[k])
    assert np.allclose(a["shift"], b["shift"], atol=1e-3)


def _roads_toml(cloud: Path, map_path: Path, ref: Path) -> str:
    return f"""
title = "roads"
[inputs.clouds]
cloud = "{cloud.as_posix()}"
[inputs.polygons]
roads = "{map_path.as_posix()}"
[inputs.points]
ref = "{ref.as_posix()}"
[roads]
cloud = "cloud"
map = "roads"
reference = "ref"
"""


def test_roads_in_feet_give_the_same_answer_through_the_cli_and_assess(interchange, tmp_path):
    """Regression: the report's roads fitted planes to heights in feet (n/a conversion)."""
    d = interchange
    m = cli_results(tmp_path, "roads", d["m"], d["map"], "-o", tmp_path / "m.gpkg")
    f = cli_results(tmp_path, "roads", d["ft"], d["map"], "-o", tmp_path / "f.gpkg")
    _same_roads(m, f)
    doc = assess(tmp_path, _roads_toml(d["ft"], d["map"], d["ref_ft"]))
    assert not doc["errors"], doc["errors"]
    rep = doc["results"]["roads"]
    _same_roads(m, rep)
    # the reference points on their levels: the report and `lidarqa heights` with polygons
    h = cli_results(tmp_path, "heights", d["ft"], d["map"], d["ref_ft"], "--classes", "2,17")
    hm = cli_results(tmp_path, "heights", d["m"], d["map"], d["ref_m"], "--classes", "2,17")
    _same_roads(m, h["roads"])
    for k in ("n", "rms", "mean", "std"):
        assert rep["reference"]["comparison"][k] == pytest.approx(h["comparison"][k], abs=1e-3)
        assert h["comparison"][k] == pytest.approx(hm["comparison"][k], abs=1e-3)
    assert rep["reference"]["comparison"]["rms"] < 0.5  # metres against metres


def test_a_map_in_another_crs_is_refused_by_the_cli_and_assess(interchange, tmp_path):
    """Regression: the report's roads did not check the map's CRS."""
    d = interchange
    out = cli_fails("roads", d["m"], d["map_2154"], "-o", tmp_path / "x.gpkg")
    assert "CRS" in out or "EPSG" in out
    out = cli_fails("heights", d["m"], d["map_2154"], d["ref_m"], "--classes", "2,17")
    assert "CRS" in out or "EPSG" in out
    why = assess_refusal(tmp_path, _roads_toml(d["m"], d["map_2154"], d["ref_m"]), "roads")
    assert "CRS" in why and ("2154" in why or "Lambert" in why), why


def test_heights_with_polygons_honours_crs_for_the_map(interchange, tmp_path):
    """--crs is the CRS of every input that declares none: the map too, as for `roads`."""
    import lidarqa
    from lidarqa.io import PointCloud

    d = interchange
    pc = lidarqa.read(d["m"])
    lidarqa.write(PointCloud(pc.xyz, dict(pc.fields), crs=None), tmp_path / "nocrs.las")
    nocrs = tmp_path / "map_nocrs.gpkg"
    polys, ids, _ = __import__("lidarqa.accuracy.roads", fromlist=["x"]).read_road_polygons(
        d["map"])
    _write_polygons(nocrs, list(polys), ids, None)
    a = cli_results(tmp_path, "roads", tmp_path / "nocrs.las", nocrs, "--crs", "EPSG:26915",
                    "-o", tmp_path / "a.gpkg")
    b = cli_results(tmp_path, "heights", tmp_path / "nocrs.las", nocrs, d["ref_m"],
                    "--classes", "2,17", "--crs", "EPSG:26915", "-o", tmp_path / "b.gpkg")
    _same_roads(a, b["roads"])
    from pyproj import CRS

    assert CRS(pyogrio.read_info(str(tmp_path / "b.gpkg"), layer="heights")["crs"]).to_epsg() \
        == 26915


# ------------------------------------------------------------------ heights, checkpoints


def _heights_toml(cloud: Path, map_path: Path, ref: Path) -> str:
    return f"""
title = "heights"
[inputs.clouds]
cloud = "{cloud.as_posix()}"
[inputs.points]
map = "{map_path.as_posix()}"
ref = "{ref.as_posix()}"
[heights]
cloud = "cloud"
classes = [2]
map = "map"
reference = "ref"
max_radius = 4.0
"""


@pytest.mark.parametrize("side", ["file", "folder"])
def test_heights_in_feet_give_the_same_answer_through_the_cli_and_assess(feet, tmp_path, side):
    """Regression: the report's heights compared laser and reference heights in feet."""
    opts = ("--classes", "2", "--max-radius", "4")
    m = cli_results(tmp_path, "heights", feet["metres"], feet["map"], feet["chk_m"], *opts)
    c = cli_results(tmp_path, "heights", feet[side], feet["map"], feet["chk"], *opts,
                    *(("--workers", "1") if side == "folder" else ()))
    doc = assess(tmp_path, _heights_toml(feet[side], feet["map"], feet["chk"]))
    assert not doc["errors"], doc["errors"]
    r = doc["results"]["heights"]
    assert r["comparison"]["n"] == c["comparison"]["n"] == m["comparison"]["n"] > 5
    for k in ("rms", "mean", "std", "max_abs"):
        assert r["comparison"][k] == pytest.approx(c["comparison"][k], abs=1e-3), k
        assert c["comparison"][k] == pytest.approx(m["comparison"][k], abs=1e-3), k
    assert r["map_points"]["sigma_mean"] == pytest.approx(c["map_points"]["sigma_mean"],
                                                          abs=1e-3)


@pytest.mark.parametrize("side", ["file", "folder"])
def test_heights_reference_in_another_crs_is_refused_alike(feet, tmp_path, side):
    """Regression: the report's heights on a catalog checked neither the map's nor the
    reference's CRS."""
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, read_points, write_points

    ref = read_points(feet["chk"], require_z=True)
    bad = tmp_path / "ref_2154.gpkg"
    write_points(PointSet(ref.ids, ref.xyz, crs=parse_crs("EPSG:2154")), bad)
    out = cli_fails("heights", feet[side], feet["map"], bad, "--classes", "2")
    assert "2154" in out or "CRS" in out
    why = assess_refusal(tmp_path, _heights_toml(feet[side], feet["map"], bad), "heights")
    assert "CRS" in why and ("2154" in why or "Lambert" in why), why


def test_checkpoints_in_feet_give_the_same_answer_through_the_cli_and_assess(tmp_path):
    """Regression: the report's (non-vertical) check points compared coordinates in feet."""
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, write_points

    rng = np.random.default_rng(4)
    n = 30
    chk = np.column_stack([rng.uniform(0, 3000, n) + 1_000_000.0,
                           rng.uniform(0, 3000, n) + 200_000.0, rng.uniform(10, 100, n)])
    mea = chk + rng.normal(0.0, [0.3, 0.3, 0.2], chk.shape)  # feet
    ids = np.array([f"P{i}" for i in range(n)], dtype=object)
    crs = parse_crs("EPSG:2263+6360")  # NY Long Island (US ft) + NAVD88 height (US ft)
    write_points(PointSet(ids, chk, crs=crs), tmp_path / "chk.gpkg")
    write_points(PointSet(ids, mea, crs=crs), tmp_path / "mea.gpkg")
    c = cli_results(tmp_path, "checkpoints", tmp_path / "mea.gpkg", tmp_path / "chk.gpkg",
                    "-o", tmp_path / "res.csv")
    doc = assess(tmp_path, f"""
title = "checkpoints"
[inputs.points]
mea = "{(tmp_path / 'mea.gpkg').as_posix()}"
chk = "{(tmp_path / 'chk.gpkg').as_posix()}"
[checkpoints]
measured = "mea"
check = "chk"
""")
    assert not doc["errors"], doc["errors"]
    r = doc["results"]["checkpoints"]
    d = mea - chk
    assert c["rmse_z"] == pytest.approx(np.sqrt(np.mean(d[:, 2] ** 2)) * FT, rel=1e-6)
    for k in ("n_check", "rmse_x", "rmse_y", "rmse_z", "rmse_h", "rmse_3d", "mean_z"):
        assert r[k] == pytest.approx(c[k], abs=1e-6), (k, r[k], c[k])
    # the residual files: check points at their own coordinates (feet, as their CRS says)
    # and residuals in metres, from the CLI and from the report alike
    from lidarqa.io.vector import read_points

    cli_res = read_points(tmp_path / "res.csv")
    rep_csv = sorted((tmp_path / "out0").rglob("*residuals*.csv"))
    assert rep_csv, list((tmp_path / "out0").rglob("*"))
    rep_res = read_points(rep_csv[0])
    order = np.argsort(np.asarray(rep_res.ids, dtype=str))
    cli_order = np.argsort(np.asarray(cli_res.ids, dtype=str))
    np.testing.assert_allclose(rep_res.xyz[order], cli_res.xyz[cli_order], atol=1e-3)
    np.testing.assert_allclose(cli_res.xyz[cli_order], chk[np.argsort(ids.astype(str))], atol=1e-3)


@pytest.mark.parametrize("side", ["file", "folder"])
def test_vertical_check_in_feet_gives_the_same_answer_through_the_cli_and_assess(feet, tmp_path,
                                                                                 side):
    """Regression: the report's vertical check compared TIN and check heights in feet."""
    c = cli_results(tmp_path, "checkpoints", feet[side], feet["chk"], "--vertical",
                    *(("--workers", "1") if side == "folder" else ()))
    m = cli_results(tmp_path, "checkpoints", feet["metres"], feet["chk_m"], "--vertical")
    doc = assess(tmp_path, f"""
title = "vertical"
[inputs.clouds]
cloud = "{feet[side].as_posix()}"
[inputs.points]
chk = "{feet['chk'].as_posix()}"
[checkpoints]
measured = "cloud"
check = "chk"
vertical = true
""")
    assert not doc["errors"], doc["errors"]
    r = doc["results"]["checkpoints"]
    assert r["n_check"] == c["n_check"] == m["n_check"] > 10
    for k in ("rmse_z", "mean_z", "std_z"):
        assert r[k] == pytest.approx(c[k], abs=1e-3), (k, r[k], c[k])
        assert c[k] == pytest.approx(m[k], abs=1e-3), k


def _ground_labels(tmp: Path, src: Path, *opts: object) -> np.ndarray:
    """Ground flags of `lidarqa ground SRC` (a file, or a folder: tiles in name order)."""
    import lidarqa

    out = tmp / f"g{len(list(tmp.glob('g*')))}"
    target = out if src.is_dir() else out.with_suffix(".laz")
    cli_results(tmp, "ground", src, "-o", target, *opts)
    files = sorted(target.glob("*.laz")) if src.is_dir() else [target]
    return np.concatenate([np.asarray(lidarqa.read(f).classification) == 2 for f in files])


def test_ground_filters_a_cloud_in_feet_in_metres(feet, tmp_path):
    """Regression: the filter ran its metric thresholds on heights in feet (and on x, y in
    feet): slopes 3.28 times too steep, the density per square foot, another regime."""
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs

    m = _ground_labels(tmp_path, feet["metres"])
    z_ft = _ground_labels(tmp_path, feet["file"])  # x, y in metres, z in US survey feet
    assert np.mean(z_ft == m) >= 0.999
    cloud = lidarqa.read(feet["metres"])  # every axis in feet (NY Long Island + NAVD88, ftUS)
    all_ft = PointCloud(np.round(cloud.xyz / FT, 3), dict(cloud.fields),
                        crs=parse_crs("EPSG:2263+6360"))
    lidarqa.write(all_ft, tmp_path / "all_ft.laz")
    assert np.mean(_ground_labels(tmp_path, tmp_path / "all_ft.laz") == m) >= 0.999
    # a folder in feet, several chunks: the same labels as the file (tiles in name order)
    tiles = _ground_labels(tmp_path, feet["folder"], "--workers", "1", "--chunk-size", "40")
    whole = lidarqa.read(feet["file"]).xyz
    order = []
    for f in sorted(feet["folder"].glob("*.laz")):
        t = lidarqa.read(f).xyz
        idx = {tuple(p): i for i, p in enumerate(np.round(whole, 3).tolist())}
        order.extend(idx[tuple(p)] for p in np.round(t, 3).tolist())
    assert np.mean(tiles == z_ft[np.asarray(order)]) >= 0.999


def test_edges_of_a_cloud_in_feet_match_its_metres_copy(feet, tmp_path):
    """Regression: with heights in feet, the default radii were measured on feet heights
    (other planes) and the lengths summed on feet heights (921 m for 479 m of edges)."""
    m = cli_results(tmp_path, "edges", feet["metres"], "-o", tmp_path / "em.csv", "--classes", 6)
    f = cli_results(tmp_path, "edges", feet["file"], "-o", tmp_path / "ef.csv", "--classes", 6)
    assert f["n_edges"] == m["n_edges"] > 5
    assert f["total_length_m"] == pytest.approx(m["total_length_m"], abs=0.05)


@pytest.mark.slow
def test_lines_and_repeatability_of_a_cloud_in_feet_match_its_metres_copy(tmp_path):
    """Regression: edges of a cloud with heights in feet were matched with feet heights
    (IGN block, strip 707 against 706, class 6: LHD 0.294 m against 0.240 m in metres;
    repeatability 0.484 against 0.383 m). Heights are quantised differently in the two
    copies (1 mm of feet against 1 cm), so the edges differ by a few: 1 cm is allowed."""
    from datapaths import SHARED, ign_block

    if not SHARED.is_dir():
        pytest.skip("needs ../shared")
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs

    _, merged, _ = ign_block(tmp_path)
    c = lidarqa.read(merged)
    ft = c.xyz.copy()
    ft[:, 2] = np.round(ft[:, 2] / FT, 3)
    lidarqa.write(PointCloud(ft, dict(c.fields), crs=parse_crs("EPSG:2154+6360")),
                  tmp_path / "ft.laz")
    sides = ("--test-source-id", 707, "--model-source-id", 706, "--classes", 6)
    m = cli_results(tmp_path, "lines", merged, merged, *sides)
    f = cli_results(tmp_path, "lines", tmp_path / "ft.laz", tmp_path / "ft.laz", *sides)
    assert f["lhd"] == pytest.approx(m["lhd"], abs=0.01)
    doc = assess(tmp_path, f"""
title = "lines in feet"
[inputs.clouds]
c = "{(tmp_path / 'ft.laz').as_posix()}"
[lines]
test = {{ cloud = "c", classes = [6], source_id = [707] }}
model = {{ cloud = "c", classes = [6], source_id = [706] }}
""")
    assert not doc["errors"], doc["errors"]
    assert doc["results"]["lines"]["lhd"] == pytest.approx(f["lhd"], abs=1e-6)
    rm = cli_results(tmp_path, "repeatability", merged, "--by-source-id", "--classes", 6)
    rf = cli_results(tmp_path, "repeatability", tmp_path / "ft.laz", "--by-source-id",
                     "--classes", 6)
    assert rf["pairs"][0]["lhd"] == pytest.approx(rm["pairs"][0]["lhd"], abs=0.01)


def test_info_density_of_a_cloud_in_feet_is_per_square_metre(feet, tmp_path):
    """Regression: x, y in feet gave the density per square foot, labelled pts/m²."""
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs

    cloud = lidarqa.read(feet["metres"])
    lidarqa.write(PointCloud(np.round(cloud.xyz / FT, 3), dict(cloud.fields),
                             crs=parse_crs("EPSG:2263+6360")), tmp_path / "all_ft.laz")
    m = cli_results(tmp_path, "info", feet["metres"])
    f = cli_results(tmp_path, "info", tmp_path / "all_ft.laz")
    assert f["density_per_m2"] == pytest.approx(m["density_per_m2"], rel=0.05)
