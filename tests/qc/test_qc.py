"""lidarqa qc: planted defects found by the right check, ANPD and void area against the
synthetic truth, no false alarm on clean tiles, the output contract and bad input."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
from click.testing import CliRunner

from lidarqa.cli.main import cli
from lidarqa.qc import get_spec, run_qc
from lidarqa.testing import make_delivery
from lidarqa.testing.delivery import DEFECTS

ALL = tuple(DEFECTS)


@pytest.fixture(scope="module")
def delivery(tmp_path_factory):
    d = tmp_path_factory.mktemp("delivery")
    return make_delivery(d / "tiles", nx=3, ny=3, density=4.0, defects=ALL, seed=11)


@pytest.fixture(scope="module")
def result(delivery, tmp_path_factory):
    out = tmp_path_factory.mktemp("qcout") / "out"
    return run_qc(delivery.paths[0].parent, "usgs-ql2", out=out)


def _tile(result, path):
    return next(t for t in result.tiles if t.path == str(path))


@pytest.mark.parametrize("defect", ALL)
def test_each_planted_defect_is_found_by_its_check_in_its_tile(result, delivery, defect):
    t = _tile(result, delivery.defects[defect])
    assert t.checks[DEFECTS[defect]].status == "fail", t.checks[DEFECTS[defect]]
    assert t.status == "fail"
    # the check stays quiet on every clean tile
    for p in delivery.clean:
        assert _tile(result, p).checks[DEFECTS[defect]].status == "pass"


def test_clean_tiles_pass_and_anpd_is_within_5_percent(result, delivery):
    assert len(delivery.clean) == 2
    for p in delivery.clean:
        t = _tile(result, p)
        assert t.status == "pass", {k: c for k, c in t.checks.items() if c.status != "pass"}
        assert t.checks["density"].value == pytest.approx(delivery.density, rel=0.05)
    sparse = _tile(result, delivery.defects["sparse"])
    assert sparse.checks["density"].value == pytest.approx(delivery.sparse_density, rel=0.05)


def test_void_area_within_20_percent_and_where_it_was_planted(result, delivery):
    t = _tile(result, delivery.defects["void"])
    assert t.checks["voids"].value == pytest.approx(delivery.void_area, rel=0.20)
    polys = [g for p, g, _ in result.voids if p == str(delivery.defects["void"])]
    assert len(polys) == 1
    c = polys[0].centroid
    x0, y0, x1, y1 = delivery.void
    assert abs(c.x - (x0 + x1) / 2) < 1.0 and abs(c.y - (y0 + y1) / 2) < 1.0


def test_overlap_flag_and_unflagged_overlap_give_the_single_swath_density(tmp_path):
    # the middle column holds both swaths over 20 m: flagged or not, ANPD is one swath's
    for flag in (True, False):
        d = make_delivery(tmp_path / str(flag), nx=3, ny=1, density=3.0, flag_overlap=flag,
                          seed=2, suffix=".las")
        r = run_qc(d.paths, "usgs-ql2")
        for t in r.tiles:
            assert t.checks["density"].value == pytest.approx(3.0, rel=0.05), (flag, t.path)


def test_no_false_alarm_over_20_clean_tiles_near_the_minimum_density(tmp_path):
    d = make_delivery(tmp_path / "clean", nx=5, ny=4, density=2.6, seed=5, suffix=".las")
    r = run_qc(d.paths[0].parent, "usgs-ql2")
    assert len(r.tiles) == 20
    bad = {t.path: {k: c.message for k, c in t.checks.items() if c.status != "pass"}
           for t in r.tiles if t.status != "pass"}
    assert bad == {}
    assert r.voids == ()


def test_output_contract(result):
    out = result.outputs
    doc = json.loads(open(out["json"]).read())
    res = doc["results"]
    assert res["spec"]["name"] == "usgs-ql2"
    assert set(res["summary"]) >= {"n_tiles", "n_pass", "n_warn", "n_fail", "status"}
    for t in res["tiles"]:
        assert set(t) >= {"path", "status", "checks"}
        for name in ("density", "spatial_distribution", "voids"):
            assert set(t["checks"][name]) == {"status", "value", "limit", "message"}
            assert t["checks"][name]["status"] in ("pass", "warn", "fail")
    import pyogrio

    layers = [layer for layer, _ in pyogrio.list_layers(out["gpkg"])]
    assert layers == ["tiles", "voids"]
    info = pyogrio.read_info(out["gpkg"], layer="tiles")
    assert info["features"] == 9 and {"status", "density", "voids"} <= set(info["fields"])
    assert pyogrio.read_info(out["gpkg"], layer="voids")["features"] >= 1
    import rasterio

    with rasterio.open(out["density"]) as ds:
        arr = ds.read(1, masked=True)
        assert np.ma.median(arr) == pytest.approx(4.0, rel=0.1)
    html = open(out["html"], encoding="utf-8").read()
    assert html.index("Block map") < html.index('id="summary"')
    assert "check-voids" in html


def test_cli_exits_4_and_writes_everything(delivery, tmp_path):
    out = tmp_path / "o"
    r = CliRunner().invoke(cli, ["-q", "qc", str(delivery.paths[0].parent), "-o", str(out),
                                 "--json", str(tmp_path / "doc.json")])
    assert r.exit_code == 4, r.output
    assert "7 of 9 tile(s) fail" in r.output
    assert sorted(p.name for p in out.iterdir()) == ["density.tif", "qc.gpkg", "qc.html",
                                                     "qc.json"]
    clean = CliRunner().invoke(cli, ["-q", "qc", *map(str, delivery.clean), "-o",
                                     str(tmp_path / "c")])
    assert clean.exit_code == 0, clean.output


def test_a_corrupt_tile_and_a_tile_in_another_crs_fail_but_the_run_goes_on(tmp_path):
    from lidarqa.io import read, write

    d = make_delivery(tmp_path / "t", nx=3, ny=1, density=2.5, seed=3, suffix=".las")
    data = d.paths[1].read_bytes()
    d.paths[1].write_bytes(data[: len(data) // 2])  # truncated
    c = read(d.paths[2])
    from lidarqa.io.crs import parse_crs

    c.crs = parse_crs("EPSG:32615+5703")
    c.source = None
    write(c, d.paths[2], overwrite=True)
    r = run_qc(d.paths[0].parent, "usgs-ql2")
    assert _tile(r, d.paths[0]).status == "pass"
    assert _tile(r, d.paths[1]).checks["readable"].status == "fail"
    crs = _tile(r, d.paths[2]).checks["crs"]
    assert crs.status == "fail" and "differs" in crs.message


def test_no_return_numbers_is_a_return_numbers_failure_and_density_cannot_pass(tmp_path):
    from lidarqa.io import read, write

    d = make_delivery(tmp_path / "t", nx=1, ny=1, density=3.0, seed=4, suffix=".las")
    c = read(d.paths[0])
    c.fields["return_number"] = np.zeros(len(c), np.uint8)
    c.fields["number_of_returns"] = np.zeros(len(c), np.uint8)
    write(c, d.paths[0], overwrite=True)
    t = run_qc(d.paths, "usgs-ql2").tiles[0]
    assert t.checks["return_numbers"].status == "fail"
    assert t.checks["density"].status == "warn"


def test_toml_spec_of_ones_own_limits(tmp_path, delivery):
    p = tmp_path / "county.toml"
    p.write_text('base = "usgs-ql2"\nmin_anpd = 5.0\nallowed_classes = [1, 2]\n'
                 '[sources]\nmin_anpd = "County RFP 3.2"\n')
    spec = get_spec(p)
    assert spec.min_anpd == 5.0 and spec.source("min_anpd") == "County RFP 3.2"
    assert spec.source("allowed_classes") == "county.toml (own limit)"
    assert spec.max_nva_rmse_m == get_spec("usgs-ql2").max_nva_rmse_m
    r = run_qc(delivery.clean[:1], spec)
    assert r.tiles[0].checks["density"].status == "fail"  # 4 < 5 per m²


def test_profiles_cite_a_source_for_every_limit():
    for name in ("usgs-ql0", "usgs-ql1", "usgs-ql2", "usgs-ql3"):
        s = get_spec(name)
        for key in ("min_anpd", "min_spatial_distribution", "void_factor", "allowed_classes",
                    "point_formats", "las_versions", "gps_time_type", "max_nva_rmse_m",
                    "max_swath_rmsdz_m", "max_intraswath_m"):
            assert "Lidar Base Specification" in s.source(key) or "ASPRS" in s.source(key)
    assert get_spec("usgs-ql1").min_anpd == 8.0 and get_spec("usgs-ql3").min_anpd == 0.5


def test_confusion_matrix_equals_an_independent_count(tmp_path):
    from lidarqa.io import read, write

    d = make_delivery(tmp_path / "t", nx=2, ny=1, density=2.0, seed=6, suffix=".las")
    ref_dir = tmp_path / "ref"
    ref_dir.mkdir()
    rng = np.random.default_rng(0)
    truth = Counter()
    for p in d.paths:
        c = read(p)
        cls = np.asarray(c.classification).copy()
        flip = rng.random(len(cls)) < 0.1
        ref = cls.copy()
        ref[flip] = rng.choice([1, 2, 6], int(flip.sum()))
        c.fields["classification"] = ref
        write(c, ref_dir / p.name)
        truth.update(zip(ref.tolist(), cls.tolist(), strict=True))
    r = run_qc(d.paths[0].parent, "usgs-ql2", reference=ref_dir)
    conf = r.block["confusion"]
    got = Counter()
    for i, a in enumerate(conf["codes"]):
        for j, b in enumerate(conf["codes"]):
            if conf["matrix"][i][j]:
                got[(a, b)] = conf["matrix"][i][j]
    assert got == truth
    n = sum(truth.values())
    po = sum(v for (a, b), v in truth.items() if a == b) / n
    rows = Counter()
    cols = Counter()
    for (a, b), v in truth.items():
        rows[a] += v
        cols[b] += v
    pe = sum(rows[k] * cols[k] for k in rows) / n**2
    assert conf["kappa_coefficient"] == pytest.approx((po - pe) / (1 - pe), rel=1e-12)
    assert conf["n_unmatched"] == 0


def test_nva_and_vva_equal_checkpoints_vertical(tmp_path):
    from lidarqa.io.vector import PointSet, write_points
    from lidarqa.testing.delivery import _terrain

    d = make_delivery(tmp_path / "t", nx=2, ny=1, density=4.0, seed=8, suffix=".las")
    rng = np.random.default_rng(1)
    xy = rng.uniform([500_005, 4_000_005], [500_195, 4_000_095], (40, 2))
    z = _terrain(xy) + rng.normal(0, 0.05, 40)
    lc = np.where(np.arange(40) < 32, "open", "forest")
    write_points(PointSet(np.arange(40), np.column_stack([xy, z]), {"land_cover": lc}),
                 tmp_path / "cp.csv")
    r = run_qc(d.paths[0].parent, "usgs-ql2", checkpoints=tmp_path / "cp.csv",
               land_cover="land_cover")
    for name, sel in (("nva", lc == "open"), ("vva", lc == "forest")):
        write_points(PointSet(np.arange(40)[sel], np.column_stack([xy, z])[sel]),
                     tmp_path / f"{name}.csv")
        js = tmp_path / f"{name}.json"
        out = CliRunner().invoke(cli, ["-q", "checkpoints", *map(str, d.paths),
                                       str(tmp_path / f"{name}.csv"), "--vertical", "--json",
                                       str(js)])
        assert out.exit_code == 0, out.output
        ref = json.loads(js.read_text())["results"]
        assert r.block[name]["value"] == ref["rmse_z"]
        assert r.block[name]["n_check"] == ref["n_check"]
    assert r.block["nva"]["status"] == "pass"  # 32 points, RMSEz about 5 cm < 10 cm


@pytest.mark.parametrize("case", ["not_las", "empty_folder", "no_land_cover", "unknown_spec"])
def test_bad_input_is_one_clear_line(tmp_path, delivery, case):
    args = [str(delivery.clean[0])]
    extra: list[str] = []
    if case == "not_las":
        bad = tmp_path / "x.laz"
        bad.write_text("not a point cloud\n")
        args = [str(bad)]
    elif case == "empty_folder":
        (tmp_path / "empty").mkdir()
        args = [str(tmp_path / "empty")]
    elif case == "no_land_cover":
        (tmp_path / "cp.csv").write_text("id,x,y,z\n1,500010,4000010,120\n")
        extra = ["--checkpoints", str(tmp_path / "cp.csv"), "--land-cover", "land_cover"]
    else:
        extra = ["--spec", "usgs-ql9"]
    r = CliRunner().invoke(cli, ["-q", "qc", *args, "-o", str(tmp_path / "o"), *extra])
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), r.output
    assert not (tmp_path / "o" / "qc.json").exists()


def test_a_delivery_in_feet_gets_the_verdicts_of_its_metres_copy(tmp_path):
    # regression: the grids were laid in feet with the metric spec: ANPD per square foot
    # (0.9 for 9.9 pts/m²) and every gap a void. Densities and void areas are per m² now,
    # the void polygons stay in the tiles' units.
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs

    ft = 1200.0 / 3937.0
    d = make_delivery(tmp_path / "m", nx=2, ny=1, density=4.0, defects=("void",), seed=3)
    src = d.defects["void"]
    (tmp_path / "m1").mkdir()
    (tmp_path / "m1" / src.name).symlink_to(src)
    cloud = lidarqa.read(src)
    (tmp_path / "ft").mkdir()
    lidarqa.write(PointCloud(np.round(cloud.xyz / ft, 3), dict(cloud.fields),
                             crs=parse_crs("EPSG:2263+6360")), tmp_path / "ft" / src.name)
    m = run_qc(tmp_path / "m1", "usgs-ql2", out=tmp_path / "qm").tiles[0]
    f = run_qc(tmp_path / "ft", "usgs-ql2", out=tmp_path / "qf").tiles[0]
    for check in ("density", "spatial_distribution", "voids"):
        assert f.checks[check].status == m.checks[check].status, check
    assert f.checks["density"].value == pytest.approx(m.checks["density"].value, rel=0.02)
    assert f.checks["voids"].value == pytest.approx(m.checks["voids"].value, rel=0.05)
    assert m.checks["voids"].value == pytest.approx(d.void_area, rel=0.20)
