"""Area jobs on a real catalog of tiles (files on disk, serial engine) equal the in-memory runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from datapaths import SHARED, needs_shared

from lidarqa.accuracy.checkpoints import vertical_check
from lidarqa.io import PointCloud, read, write
from lidarqa.testing import make_building_scene, sample_checkpoints
from lidarqa.tiling import open_catalog
from lidarqa.tiling.jobs_api import (
    catalog_features,
    catalog_repeatability,
    catalog_vertical_check,
)
from lidarqa.tiling.jobs_lines import strip_pairs
from lidarqa.tiling.jobs_vector import dedupe_segments, vector_features

TILE = 50.0


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    """A synthetic building block with two strips as 50 m tiles, and its points read back."""
    scene = make_building_scene(seed=1, roofs=("gable", "flat", "gable", "flat"), density=8,
                                strips=2, strip_offset=(0.04, -0.03, 0.03),
                                origin=(651000.0, 6862000.0, 80.0))  # projected magnitudes
    folder = tmp_path_factory.mktemp("tiles")
    xy = scene.points[:, :2]
    key = np.floor(xy / TILE).astype(int)
    for i, j in sorted({tuple(k) for k in key.tolist()}):
        sel = (key[:, 0] == i) & (key[:, 1] == j)
        cloud = PointCloud(scene.points[sel], {
            "classification": scene.classification[sel],
            "point_source_id": scene.fields["point_source_id"][sel]})
        write(cloud, folder / f"tile_{i:+03d}_{j:+03d}.las")
    clouds = [read(p) for p in sorted(folder.glob("*.las"))]
    whole = PointCloud(np.concatenate([c.xyz for c in clouds]), {
        k: np.concatenate([c.fields[k] for c in clouds])
        for k in ("classification", "point_source_id")})
    assert len(clouds) >= 4
    return scene, folder, whole


def _match_once(whole, merged, tol=0.05):
    """How often each whole-area segment is found in `merged` (endpoints within tol)."""
    out = []
    for s, e in zip(whole.start, whole.end, strict=True):
        same = np.maximum(np.linalg.norm(merged.start - s, axis=1),
                          np.linalg.norm(merged.end - e, axis=1))
        flip = np.maximum(np.linalg.norm(merged.start - e, axis=1),
                          np.linalg.norm(merged.end - s, axis=1))
        out.append(int((np.minimum(same, flip) < tol).sum()))
    return np.array(out)


def _chunk_of(run, xy):
    out = np.full(len(xy), -1)
    for k, c in enumerate(run.chunks):
        out[c.core_mask(xy)] = k
    return out


@pytest.fixture(scope="module")
def edges_run(tiles):
    """Edges of the tiled block by catalog chunks (30 m, buffer 20 m), as the CLI test runs them."""
    _, folder, _ = tiles
    return catalog_features(folder, kind="edges", classes=(6,), chunk_size=30.0, buffer=20.0)


def test_edges_of_a_tiled_block_equal_the_in_memory_run(tiles, edges_run):
    _, _, whole = tiles
    b = whole.classification == 6
    run = edges_run
    assert run.failed == [] and len(run.chunks) >= 9
    ref = vector_features(whole.xyz[b], kind="edges", segment_options=run.extra["segment_options"],
                          options=run.extra["options"])
    m = run.value
    assert len(m) == len(ref)
    assert (_match_once(ref, m) == 1).all()  # every in-memory edge exactly once
    crossing = _chunk_of(run, m.start) != _chunk_of(run, m.end)
    assert crossing.sum() >= 3  # chunk borders really cut edges
    assert m.attributes["at_buffer_edge"].sum() == 0
    # (corners chunk by chunk vs in memory: tests/tiling/test_jobs_vector.py)


def test_vertical_check_on_the_tiles_equals_the_in_memory_check(tiles):
    scene, folder, whole = tiles
    check = sample_checkpoints(scene, 40, seed=2)
    ref = vertical_check(whole.xyz, check, classification=whole.classification)
    run = catalog_vertical_check(folder, check, chunk_size=30.0, buffer=15.0)
    rep = run.value
    assert np.array_equal(rep.flag, ref.flag) and rep.n_check == ref.n_check > 20
    assert np.array_equal(rep.dz, ref.dz, equal_nan=True)  # bit for bit
    assert rep.to_dict()["rmse_z"] == ref.to_dict()["rmse_z"]
    assert len(run.chunks) < 20  # only chunks holding check points were read


def test_strip_pairs_over_the_tiled_block_equal_the_in_memory_pairs(tiles):
    _, folder, whole = tiles
    run = catalog_repeatability(folder, classes=(6,), chunk_size=30.0, buffer=20.0)
    b = whole.classification == 6
    sid = whole.point_source_id
    fixed = run.extra["strip_options"]  # each strip's defaults, fixed from the sample window
    ref = {int(s): vector_features(whole.xyz[b & (sid == s)], kind="edges",
                                   segment_options=fixed[int(s)]["segment_options"],
                                   options=fixed[int(s)]["edge_options"])
           for s in np.unique(sid[b])}
    for s, e in ref.items():
        e.attributes["point_spacing"] = np.full(len(e), fixed[s]["point_spacing"])
    assert sorted(run.extra["strips"]) == sorted(ref)
    rows, ref_rows = run.value, strip_pairs(ref)
    assert len(rows) == len(ref_rows) == 1
    for k in ("olhd_tm", "olhd_mt", "lhd", "n_pairs_tm", "n_pairs_mt"):
        # plane fits centre on the points' box middle, which a chunk moves: round-off only
        assert rows[0][k] == pytest.approx(ref_rows[0][k], abs=1e-9), k


@needs_shared
@pytest.mark.slow
def test_ign_edges_crossing_chunk_borders_are_reported_once():
    files = sorted((SHARED / "ign-lidarhd").glob("test_data_770*.laz"))
    assert len(files) == 6
    cat = open_catalog(files)
    # tolerance 0: no near-duplicate removal, so only the anchor-in-core rule is tested
    # the data-driven defaults measured on the chunk the test was written with (the source's
    # central sample window now gives 0.80 / 0.48, where one edge near a border comes out of
    # two chunks 0.1-0.3 m apart; the default 5 cm merge tolerance keeps both: issue #26 notes)
    run = catalog_features(cat, kind="edges", classes=(6,), chunk_size=50.0, buffer=30.0,
                           tolerance=0.0, segment_options={"grow_radius": 0.772},
                           options={"near_dist": 0.4632})
    m = run.value
    crossing = _chunk_of(run, m.start) != _chunk_of(run, m.end)
    assert crossing.sum() >= 5
    assert len(m) > 80
    assert m.attributes["at_buffer_edge"].sum() == 0  # a 30 m buffer holds these roofs whole
    # no edge was kept by two chunks: no other edge has both endpoints within 30 cm
    assert len(dedupe_segments(m, tolerance=0.3)) == len(m)
    counts = _match_once(m.subset(np.flatnonzero(crossing)), m, tol=0.3)
    assert (counts == 1).all()


@needs_shared
@pytest.mark.slow
def test_ign_corners_on_a_catalog_are_reported_once():
    from scipy.spatial import cKDTree

    from lidarqa.tiling.jobs_vector import dedupe_points

    files = sorted((SHARED / "ign-lidarhd").glob("test_data_770*.laz"))
    cat = open_catalog(files)
    run = catalog_features(cat, kind="corners", classes=(6,), chunk_size=50.0, buffer=30.0,
                           tolerance=0.0)  # no near-duplicate removal: the anchor rule alone
    m = run.value
    assert not run.failed and len(run.chunks) >= 6
    assert len(dedupe_points(m, tolerance=0.3)) == len(m) > 10  # no corner kept twice
    assert len(np.unique(_chunk_of(run, m.xyz))) >= 3  # corners kept by several chunks
    pts = np.concatenate([c.xyz[c.classification == 6] for c in map(read, files)])
    ref = vector_features(pts, kind="corners", segment_options=run.extra["segment_options"],
                          options=run.extra["options"])
    found = np.array([len(n) for n in cKDTree(m.xyz).query_ball_point(ref.xyz, r=0.05)])
    assert (found <= 1).all()  # no in-memory corner found twice
    # nearly all: a chunk may segment a roof by a point differently
    assert (found == 1).mean() >= 0.9


# ------------------------------------------------------------------ command line


def _cli(args):
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_cli_edges_on_a_folder_writes_each_edge_once(tiles, edges_run, tmp_path):
    import json

    from lidarqa.io.vector import read_segments

    _, folder, _ = tiles
    out, js = tmp_path / "edges.gpkg", tmp_path / "edges.json"
    args = ["-q", "edges", folder, "-o", out, "--classes", "6", "--chunk-size", "30",
            "--buffer", "20", "--scheduler", "serial", "--json", js]
    r = _cli(args)
    assert r.exit_code == 0, r.output
    api = edges_run
    seg = read_segments(out)
    assert len(seg) == len(api.value) > 10
    assert np.allclose(seg.start, api.value.start)
    doc = json.loads(js.read_text())
    cat = doc["results"]["catalog"]
    assert cat["chunk_status"]["ok"] == cat["n_chunks"] == len(api.chunks)
    # an existing output is refused before any work
    r2 = _cli(args)
    assert r2.exit_code == 1
    # a rerun gives the same bytes (the GeoPackage carries no writing time)
    again = tmp_path / "again.gpkg"
    r3 = _cli([again if a == out else a for a in args if a not in ("--json", js)])
    assert r3.exit_code == 0, r3.output
    assert again.read_bytes() == out.read_bytes()


@pytest.mark.slow  # ~5 s: two catalog jobs through the CLI
def test_cli_vertical_check_and_repeatability_on_a_catalog(tiles, tmp_path):
    import json

    from lidarqa.io.vector import read_points, write_points

    scene, folder, whole = tiles
    check = sample_checkpoints(scene, 25, seed=9)
    cpath = tmp_path / "check.csv"
    write_points(check, cpath)
    check = read_points(cpath)  # as the command reads it: CSV coordinates to 0.1 mm
    js = tmp_path / "cp.json"
    r = _cli(["-q", "checkpoints", *sorted(folder.glob("*.las")), cpath, "--vertical",
              "--scheduler", "serial", "--chunk-size", "30", "--buffer", "15", "--json", js])
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    ref = vertical_check(whole.xyz, check, classification=whole.classification).to_dict()
    assert res["n_check"] == ref["n_check"]
    assert res["rmse_z"] == ref["rmse_z"]
    js2 = tmp_path / "rep.json"
    r = _cli(["-q", "repeatability", folder, "--by-source-id", "--classes", "6",
              "--scheduler", "serial", "--chunk-size", "30", "--buffer", "20", "--json", js2])
    assert r.exit_code == 0, r.output
    rep = json.loads(js2.read_text())["results"]
    assert len(rep["pairs"]) == 1 and rep["pairs"][0]["lhd"] > 0
    assert len(rep["strips"]) == 2  # both strips of the scene, pooled over every tile


def test_cli_heights_on_a_catalog_equals_the_in_memory_run(tiles, tmp_path):
    import json

    from lidarqa.accuracy.heights import assess_heights
    from lidarqa.io.vector import PointSet, read_points, write_points

    scene, folder, whole = tiles
    rng = np.random.default_rng(4)
    lo, hi = whole.xyz[:, :2].min(0) + 3, whole.xyz[:, :2].max(0) - 3
    mxy = lo + rng.random((60, 2)) * (hi - lo)
    ref = sample_checkpoints(scene, 30, seed=11)
    write_points(PointSet(np.arange(60), np.c_[mxy, np.zeros(60)]), tmp_path / "map.csv")
    write_points(ref, tmp_path / "ref.csv")
    # as the command reads them: CSV coordinates to 0.1 mm
    mxy, ref = read_points(tmp_path / "map.csv").xyz[:, :2], read_points(tmp_path / "ref.csv")
    js = tmp_path / "h.json"
    r = _cli(["-q", "heights", folder, tmp_path / "map.csv", tmp_path / "ref.csv", "--classes",
              "2", "--scheduler", "serial", "--chunk-size", "30", "--buffer", "30", "--json", js])
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    g = whole.classification == 2
    mem = assess_heights(whole.xyz[g], mxy, ref.xyz).to_dict()
    assert res["map_points"]["n_failed"] == mem["map_points"]["n_failed"]
    assert res["comparison"]["n"] == mem["comparison"]["n"] > 10
    for k in ("rms", "mean", "std"):
        assert res["comparison"][k] == mem["comparison"][k], k
    assert res["w"]["n_outliers"] == mem["w"]["n_outliers"]
    assert res["w"]["std"] == mem["w"]["std"]
    assert res["catalog"]["chunk_status"]["failed"] == 0


def test_vector_output_is_byte_identical_for_any_completion_order(tiles, tmp_path):
    # The same with a 2-worker LocalCluster (Engine(workers=2)) was checked once by hand: it
    # costs ~30 s here (worker start-up and imports), too much for the routine suite.
    from lidarqa.io.vector import write_points

    _, folder, _ = tiles
    # one tile (a small catalog: fast), the one with the most building points
    one = [str(max(sorted(folder.glob("*.las")),
                   key=lambda p: int((read(p).classification == 6).sum())))]
    outs = []
    for k, seed in enumerate((None, 5)):
        run = catalog_features(one, kind="corners", classes=(6,), chunk_size=15.0,
                               buffer=15.0, order_seed=seed)
        assert len(run.chunks) >= 4 and not run.failed
        out = tmp_path / f"corners{k}.csv"
        write_points(run.value, out)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] and len(outs[0]) > 100


@pytest.mark.slow  # ~8 s: a whole assess run on a catalog
def test_assess_with_a_catalog_input_shows_the_overview_and_chunk_status(tiles, tmp_path):
    import json

    pytest.importorskip("matplotlib")
    from lidarqa.accuracy.heights import assess_heights
    from lidarqa.io.vector import PointSet, write_points
    from lidarqa.report import run_assessment

    scene, folder, whole = tiles
    from lidarqa.io.vector import read_points

    check = sample_checkpoints(scene, 20, seed=12)
    write_points(check, tmp_path / "check.csv")
    rng = np.random.default_rng(4)
    lo, hi = whole.xyz[:, :2].min(0) + 3, whole.xyz[:, :2].max(0) - 3
    mxy = lo + rng.random((40, 2)) * (hi - lo)
    write_points(PointSet(np.arange(40), np.c_[mxy, np.zeros(40)]), tmp_path / "map.csv")
    href = sample_checkpoints(scene, 25, seed=13)
    write_points(href, tmp_path / "href.csv")
    # as the run reads them: CSV coordinates to 0.1 mm
    check, href = read_points(tmp_path / "check.csv"), read_points(tmp_path / "href.csv")
    mxy = read_points(tmp_path / "map.csv").xyz[:, :2]
    cfg = tmp_path / "a.toml"
    cfg.write_text(f"""
title = "catalog"
[inputs.clouds]
block = "{folder.as_posix()}"
[inputs.points]
check = "check.csv"
map = "map.csv"
href = "href.csv"
[info]
cloud = "block"
[checkpoints]
measured = "block"
vertical = true
check = "check"
[ground]
cloud = "block"
[heights]
cloud = "block"
map = "map"
reference = "href"
[lines]
test = {{ cloud = "block", classes = [6], source_id = [1] }}
model = {{ cloud = "block", classes = [6], source_id = [2] }}
""")
    run = run_assessment(cfg, tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    info = doc["results"]["info"]
    assert info["n_tiles"] == len(list(folder.glob("*.las"))) and info["n_chunks"] >= 1
    cp = doc["results"]["checkpoints"]
    ref = vertical_check(whole.xyz, check, classification=whole.classification).to_dict()
    assert cp["rmse_z"] == ref["rmse_z"]
    assert cp["catalog"]["chunk_status"]["ok"] >= 1
    assert cp["catalog"]["chunk_status"]["failed"] == 0
    h = doc["results"]["heights"]
    g = whole.classification == 2
    mem = assess_heights(whole.xyz[g], mxy, href.xyz).to_dict()
    assert h["comparison"]["n"] == mem["comparison"]["n"] > 10
    assert h["comparison"]["rms"] == mem["comparison"]["rms"]  # bit for bit
    assert h["w"]["n_outliers"] == mem["w"]["n_outliers"]
    assert h["catalog"]["chunk_status"]["failed"] == 0
    # ground on a catalog: the catalog ground job, ISPRS counts summed over its chunks
    assert not doc.get("errors"), doc.get("errors")
    from lidarqa.ground import classify_ground

    g, mem = doc["results"]["ground"], classify_ground(whole, evaluate=True).evaluation
    assert g["n_points"] == len(whole) and g["catalog"]["n_chunks"] >= 1
    assert g["kappa"] == pytest.approx(mem.kappa, abs=0.01)  # tiled = untiled (>= 99.9 %)
    assert list((tmp_path / "out").glob("**/block_ground/*.vpc"))
    # lines between two strips of the catalog: edges extracted chunk by chunk
    ln = doc["results"]["lines"]
    assert ln["p"] > 0 and ln["q"] > 0
    assert run.results["info"]["n_tiles"] == info["n_tiles"]
    html = (tmp_path / "out" / "report.html").read_text()
    assert "tiles, chunks" in html and "Chunks" in html
    assert "cannot run on the catalog input" not in html


@needs_shared
@pytest.mark.slow
def test_semis_tile_in_4_chunks_gives_the_whole_tile_rmse_and_w_statistics():
    from lidarqa.accuracy.heights import assess_heights
    from lidarqa.io.vector import PointSet
    from lidarqa.tiling.jobs_api import catalog_heights

    path = SHARED / "ign-lidarhd" / "test_semis_2023_0299_6802_LA93_IGN69.laz"
    cloud = read(path)
    g = cloud.classification == 2
    gxyz = cloud.xyz[g]
    rng = np.random.default_rng(0)
    pick = rng.choice(len(gxyz), 300, replace=False)
    # check points: real ground heights moved 0.37 m sideways, so the TIN is really interpolated
    check = PointSet(np.arange(300), gxyz[pick] + [0.37, 0.0, 0.0])
    ref = vertical_check(cloud.xyz, check, classification=cloud.classification, max_edge=6.0)
    run = catalog_vertical_check(path, check, chunk_size=500.0, buffer=30.0, max_edge=6.0)
    assert len(run.chunks) >= 4 and not run.failed
    rep = run.value
    assert np.array_equal(rep.flag, ref.flag) and rep.n_check > 200
    # exactly: a triangle's arithmetic does not depend on the subset that was triangulated
    assert np.array_equal(rep.dz, ref.dz, equal_nan=True)
    a, b = rep.to_dict(), ref.to_dict()
    for k in ("rmse_z", "mean_z", "std_z", "max_abs_z"):
        assert a[k] == b[k], k
    # heights: map points jittered on a 40 m grid (a regular grid has co-circular squares whose
    # diagonal the triangulator picks freely), reference = other ground points
    xs = np.arange(299020.0, 300000.0, 40.0)
    mxy = np.array([(x, y) for x in xs for y in xs - 299000.0 + 6801000.0])
    mxy = mxy + rng.uniform(-8, 8, mxy.shape)
    refz = np.delete(gxyz, pick, axis=0)[rng.choice(len(gxyz) - 300, 400, replace=False)]
    # away from the hull of the map points, where the TIN has slivers hundreds of metres long
    # (a chunk refuses those with a "larger buffer" error rather than guessing)
    inner = np.all((refz[:, :2] > [299050, 6801050]) & (refz[:, :2] < [299950, 6801950]), axis=1)
    refz = refz[inner]
    mem = assess_heights(gxyz, mxy, refz)
    hrun = catalog_heights(path, mxy, refz, classes=(2,), chunk_size=500.0)
    assert len(hrun.chunks) >= 4 and not hrun.failed
    h = hrun.value
    assert np.array_equal(h.outlier, mem.outlier)
    assert np.array_equal(h.dh, mem.dh, equal_nan=True)  # bit for bit
    for part in ("comparison", "w"):
        for k, v in mem.to_dict()[part].items():
            assert h.to_dict()[part][k] == pytest.approx(v, rel=0, abs=0, nan_ok=True), (part, k)


def test_an_analysis_without_a_catalog_version_runs_on_the_catalog_in_memory(tiles, tmp_path):
    """roads has no chunked version: its file analysis runs on the catalog read through its
    source as one region (issue #26: a catalog input is never refused)."""
    from types import SimpleNamespace

    from lidarqa.report._context import RunContext

    _, folder, whole = tiles
    spec = SimpleNamespace(kind="clouds", path=folder, effective_crs=None)
    cfg = SimpleNamespace(inputs={"block": spec}, crs=None)
    ctx = RunContext(cfg, tmp_path)
    assert ctx.is_catalog("block")
    cloud = ctx.cloud("block")
    assert len(cloud) == len(whole)
    assert np.array_equal(np.sort(cloud.xyz[:, 2]), np.sort(whole.xyz[:, 2]))


# ------------------------------------------------------------------ every catalog command alike


def _catalog_commands(folder, chk, out):
    """Every command with catalog options, on the folder `folder` (serial, one worker)."""
    return {
        "ground": ["ground", folder, "-o", out / "g"],
        "planes": ["planes", folder, "--classes", "6", "-o", out / "p.csv"],
        "edges": ["edges", folder, "--classes", "6", "-o", out / "e.csv"],
        "corners": ["corners", folder, "--classes", "6", "-o", out / "c.csv"],
        "checkpoints": ["checkpoints", folder, chk, "--vertical"],
        "heights": ["heights", folder, chk, chk, "--classes", "2", "--max-radius", "4"],
        "repeatability": ["repeatability", folder, "--by-source-id", "--classes", "6"],
        "swaths": ["swaths", folder, "--by-source-id", "-o", out / "s", "--no-maps"],
    }


CATALOG_COMMANDS = sorted(_catalog_commands("", "", Path()))


@pytest.fixture(scope="module")
def tiles_check(tiles, tmp_path_factory):
    from lidarqa.io.vector import write_points

    scene, _, _ = tiles
    path = tmp_path_factory.mktemp("chk") / "check.csv"
    write_points(sample_checkpoints(scene, 25, seed=9), path)
    return path


@pytest.mark.slow  # ~30 s over the commands: one catalog run each
@pytest.mark.parametrize("name", CATALOG_COMMANDS)
def test_every_catalog_command_records_the_same_catalog_settings(name, tiles, tiles_check,
                                                                 tmp_path):
    """Regression (issue #26): each command recorded its own subset of the catalog settings
    (the ones given, or None for the defaults); every one records the chunk size and buffer
    the job ran with, the workers and the scheduler."""
    import json

    if name == "swaths":
        pytest.importorskip("rasterio")
    _, folder, _ = tiles
    js = tmp_path / "r.json"
    r = _cli(["-q", *_catalog_commands(folder, tiles_check, tmp_path)[name], "--workers", "1",
              "--json", js])
    assert r.exit_code == 0, r.output
    params = json.loads(js.read_text())["parameters"]
    got = {k: params.get(k, "missing") for k in ("chunk_size", "buffer", "workers", "scheduler")}
    assert all(isinstance(got[k], float) for k in ("chunk_size", "buffer")), got
    assert (got["workers"], got["scheduler"]) == (1, None), got


@pytest.mark.parametrize("name", CATALOG_COMMANDS)
def test_every_catalog_command_refuses_an_existing_json_alike(name, tiles, tiles_check, tmp_path):
    """Regression (issue #26): ground on a catalog and swaths checked the --json path with the
    library's message ("pass --overwrite (overwrite=True)"); every command says the same."""
    _, folder, _ = tiles
    js = tmp_path / "r.json"
    js.write_text("{}")
    r = _cli(["-q", *_catalog_commands(folder, tiles_check, tmp_path)[name], "--workers", "1",
              "--json", js])
    assert r.exit_code == 1, r.output
    assert r.output.strip().endswith(f"output {js} exists; add --overwrite to replace it"), \
        r.output
    assert js.read_text() == "{}"
