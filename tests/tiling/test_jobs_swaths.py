"""``lidarqa swaths`` on a catalog: chunked strip comparison = one in-memory run (issue #14)."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

import lidarqa
from lidarqa.accuracy.swaths import assess_swaths
from lidarqa.cli.main import cli
from lidarqa.errors import InvalidPointsError, OptionError
from lidarqa.io.crs import parse_crs
from lidarqa.testing import write_tiles
from lidarqa.testing.strips import make_strip_scene
from lidarqa.tiling.jobs_swaths import catalog_swaths


def load_strips(files, *, by_source_id, classes, all_returns):
    """The in-memory oracle: every file read whole, strips by point_source_id or by file."""
    from lidarqa.accuracy.swaths import select_surface
    from lidarqa.io.crs import z_to_metres_factor

    xyz, ids = [], []
    for k, path in enumerate(files):
        pc = lidarqa.read(path)
        keep = select_surface(pc, classes=classes, all_returns=all_returns, where=str(path))
        sid = (np.asarray(pc.point_source_id).astype(np.int64) if by_source_id
               else np.full(len(pc), k + 1, dtype=np.int64))
        p = pc.xyz[keep].copy()
        p[:, 2] *= z_to_metres_factor(pc.crs)
        xyz.append(p)
        ids.append(sid[keep])
    return np.vstack(xyz), np.concatenate(ids), None, None


ORIGIN = np.array([600_000.0, 6_800_000.0, 0.0])
OFFSETS = [[0.0, 0.0, 0.0], [0.06, -0.04, 0.03], [-0.03, 0.05, -0.02]]


def _scene_as_tiles(folder, *, tile_size=40.0, n_strips=3, seed=5):
    scene = make_strip_scene(n_strips, offsets=OFFSETS[:n_strips], noise=0.02, length=120.0,
                             seed=seed)
    n = len(scene.points)
    obj = SimpleNamespace(
        points=scene.points + ORIGIN,
        classification=np.full(n, 2, dtype=np.uint8),
        fields={"point_source_id": scene.strip.astype(np.uint16)},
    )
    return write_tiles(obj, folder, tile_size=tile_size, origin=tuple(ORIGIN[:2]))


def _close(a, b, path=""):
    """Recursive comparison of two report dicts (floats to 1e-9 relative)."""
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (u, v) in enumerate(zip(a, b, strict=True)):
            _close(u, v, f"{path}[{i}]")
    elif isinstance(a, float) and (math.isnan(a) or isinstance(b, float) and math.isnan(b)):
        assert math.isnan(a) and math.isnan(b), path
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=1e-9, abs=1e-9), path
    else:
        assert a == b, path


def _same_report(whole, run):
    _close(whole.to_dict(), run.to_dict())
    assert len(whole.grids) == len(run.grids) > 0
    for g, h in zip(whole.grids, run.grids, strict=True):
        assert (g.strip_a, g.strip_b, g.x0, g.y1, g.cell_size) == (
            h.strip_a, h.strip_b, h.x0, h.y1, h.cell_size)
        np.testing.assert_allclose(g.dz, h.dz, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def strip_tiles(tmp_path_factory):
    return _scene_as_tiles(tmp_path_factory.mktemp("strips") / "tiles")


def test_catalog_equals_one_run_with_default_cell(strip_tiles):
    xyz, sid, _, _ = load_strips(tuple(map(str, strip_tiles)), by_source_id=True, classes=None,
                                 all_returns=False)
    whole = assess_swaths(xyz, sid)
    run = catalog_swaths(strip_tiles, by_source_id=True, chunk_size=25.0)
    assert len(run.chunks) >= 12
    assert run.extra["cell_size"] == whole.cell_size
    assert [(p.strip_a, p.strip_b) for p in run.value.pairs] == [(1, 2), (2, 3)]
    _same_report(whole, run.value)
    # the offsets are the known ones (the scene's own check, through the catalog path)
    net = {o.strip_b: o for o in run.value.network_offsets}
    for s in (2, 3):
        assert net[s].dz - net[1].dz == pytest.approx(OFFSETS[s - 1][2], abs=0.01)


def test_catalog_does_not_depend_on_chunks_or_order(strip_tiles):
    a = catalog_swaths(strip_tiles, by_source_id=True, cell_size=1.25, chunk_size=25.0,
                       rotations=True).value
    b = catalog_swaths(strip_tiles, by_source_id=True, cell_size=1.25, chunk_size=70.0,
                       origin=(3.0, 7.0), order_seed=4, rotations=True).value
    _same_report(a, b)


def test_catalog_strip_files(tmp_path):
    """A delivery of strip files (one strip per file) compared chunk by chunk."""
    scene = make_strip_scene(2, offsets=OFFSETS[:2], noise=0.02, length=100.0, seed=8)
    paths = []
    for s in (1, 2):
        sel = scene.strip == s
        cloud = lidarqa.io.PointCloud(
            np.round(scene.points[sel] + ORIGIN, 3),
            {"classification": np.full(int(sel.sum()), 2, dtype=np.uint8)},
            crs=parse_crs("EPSG:2154"),
        )
        paths.append(lidarqa.write(cloud, tmp_path / f"strip{s}.laz"))
    xyz, sid, _, labels = load_strips(tuple(map(str, paths)), by_source_id=False, classes=None,
                                      all_returns=False)
    whole = assess_swaths(xyz, sid)
    run = catalog_swaths(paths, chunk_size=30.0)
    _same_report(whole, run.value)
    assert sorted(run.extra["labels"].values()) == sorted(str(p) for p in paths)


def test_catalog_refuses_one_strip_and_bad_options(tmp_path, strip_tiles):
    scene = make_strip_scene(1, noise=0.02, length=60.0, seed=1)
    obj = SimpleNamespace(points=scene.points + ORIGIN,
                          classification=np.full(len(scene.points), 2, dtype=np.uint8),
                          fields={"point_source_id": np.full(len(scene.points), 9, np.uint16)})
    one = write_tiles(obj, tmp_path / "one", tile_size=40.0, origin=tuple(ORIGIN[:2]))
    with pytest.raises(InvalidPointsError, match="one flight strip only"):
        catalog_swaths(one, by_source_id=True)
    with pytest.raises(OptionError, match="buffer must be at least the cell size"):
        catalog_swaths(strip_tiles, by_source_id=True, cell_size=2.0, buffer=1.0)
    with pytest.raises(OptionError, match="unknown option"):
        catalog_swaths(strip_tiles, by_source_id=True, cell_sise=2.0)
    # a range cell far below the cell size: a clear error on both paths, not an overflow
    with pytest.raises(OptionError, match="too small"):
        catalog_swaths(strip_tiles, by_source_id=True, cell_size=1.0, range_cell=1e-300)
    scene = make_strip_scene(2, noise=0.02, length=60.0, seed=1)
    with pytest.raises(OptionError, match="too small"):
        assess_swaths(scene.points, scene.strip, cell_size=1.0, range_cell=1e-300)


@pytest.mark.slow  # ~5 s: a chunked swaths job through the CLI
def test_cli_swaths_on_a_folder(tmp_path, strip_tiles):
    pytest.importorskip("rasterio")
    out, doc = tmp_path / "out", tmp_path / "swaths.json"
    folder = str(strip_tiles[0].parent)
    r = CliRunner().invoke(cli, ["swaths", folder, "--by-source-id", "-o", str(out),
                                 "--chunk-size", "30", "--workers", "1", "--no-maps",
                                 "--json", str(doc), "-q"])
    assert r.exit_code == 0, r.output
    res = json.loads(doc.read_text())["results"]
    assert res["catalog"]["n_chunks"] > 1 and res["catalog"]["failed_chunks"] == []
    assert {(p["strip_a"], p["strip_b"]) for p in res["pairs"]} == {(1, 2), (2, 3)}
    import rasterio

    with rasterio.open(out / "dz_1_2.tif") as ds:
        assert ds.crs.to_epsg() == 2154
        assert np.isfinite(ds.read(1, masked=True).compressed()).all()
    # the same figures as the in-memory command on the same tiles named one by one
    xyz, sid, _, _ = load_strips(tuple(map(str, strip_tiles)), by_source_id=True, classes=None,
                                 all_returns=False)
    whole = assess_swaths(xyz, sid)
    for p, q in zip(res["pairs"], whole.to_dict()["pairs"], strict=True):
        assert p["rmsdz"] == pytest.approx(q["rmsdz"], rel=1e-9)
    # without --by-source-id every tile is a strip, and tiles do not overlap: one line, exit 1
    r = CliRunner().invoke(cli, ["swaths", folder, "-o", str(tmp_path / "o2"), "--workers", "1"])
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert not (tmp_path / "o2").exists() or not any((tmp_path / "o2").iterdir())
    # --buffer 0 is a given catalog option (0 is not "unset"): refused, one line
    r = CliRunner().invoke(cli, ["swaths", str(strip_tiles[0]), "--by-source-id", "-o",
                                 str(tmp_path / "o3"), "--buffer", "0", "--cell-size", "1"])
    assert r.exit_code == 1 and "buffer must be at least the cell size" in r.output


@needs_shared
@pytest.mark.shared
def test_six_ign_tiles_in_chunks_equal_one_run():
    paths = sorted((SHARED / "ign-lidarhd").glob("test_data_770*_6277*_LA93_IGN69.laz"))
    assert len(paths) == 6
    xyz, sid, _, _ = load_strips(tuple(map(str, paths)), by_source_id=True, classes=None,
                                 all_returns=False)
    whole = assess_swaths(xyz, sid)
    run = catalog_swaths(paths, by_source_id=True, chunk_size=50.0)
    assert len(run.chunks) == 6
    assert [(p.strip_a, p.strip_b) for p in run.value.pairs] == [(706, 707)]
    _same_report(whole, run.value)


@needs_shared
@pytest.mark.shared
def test_semis_tile_in_four_chunks_equals_one_run():
    """The 1 km² tile with 4–5 strips, cut into 4 chunks of 500 m."""
    path = SHARED / "ign-lidarhd" / "test_semis_2023_0299_6802_LA93_IGN69.laz"
    xyz, sid, _, _ = load_strips((str(path),), by_source_id=True, classes=None,
                                 all_returns=False)
    whole = assess_swaths(xyz, sid)
    run = catalog_swaths([path], by_source_id=True, chunk_size=500.0)
    assert len(run.chunks) == 4
    assert len(run.value.pairs) == len(whole.pairs) >= 5
    _same_report(whole, run.value)


def test_assess_swaths_on_a_catalog_input(tmp_path, strip_tiles):
    pytest.importorskip("matplotlib")
    pytest.importorskip("rasterio")
    from lidarqa.report import run_assessment

    folder = strip_tiles[0].parent
    cfg = tmp_path / "a.toml"
    cfg.write_text(f"""
title = "strips"
[inputs.clouds]
block = "{folder.as_posix()}"
[swaths]
cloud = "block"
""")
    run_assessment(cfg, tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    assert "swaths" not in doc.get("errors", {}), doc.get("errors")
    res = doc["results"]["swaths"]
    xyz, sid, _, _ = load_strips(tuple(map(str, strip_tiles)), by_source_id=True, classes=None,
                                 all_returns=False)
    whole = assess_swaths(xyz, sid)
    assert res["max_rmsdz"] == pytest.approx(max(p.rmsdz for p in whole.pairs), rel=1e-9)
    assert res["catalog"]["chunk_status"]["failed"] == 0
    assert list((tmp_path / "out").glob("**/dz_1_2.tif"))
    assert "Flight strips" in (tmp_path / "out" / "report.html").read_text()
