"""Assessment runs on a synthetic scene: report files, JSON contents, verdicts, refusals, Ctrl-C."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

from lidarqa.errors import OutputExistsError
from lidarqa.report import _registry, run_assessment

from .conftest import CHECK_OFFSET, LIGHT_TOML, SHIFT, SYNTHETIC_TOML, write_config

_registry.specs()  # the built-in analyses registered, so that the tests' patches hold


@pytest.fixture(scope="module")
def synthetic_run(synthetic, tmp_path_factory):
    cfg = write_config(
        tmp_path_factory.mktemp("cfg") / "assess.toml",
        SYNTHETIC_TOML.format(d=synthetic["dir"].as_posix()),
    )
    out = tmp_path_factory.mktemp("run") / "out"
    run = run_assessment(cfg, out)
    return run, cfg, out


def test_writes_report_json_and_outputs(synthetic_run):
    run, cfg, out = synthetic_run
    assert run.html_path == out / "report.html" and run.html_path.is_file()
    doc = json.loads((out / "report.json").read_text())
    assert set(doc["results"]) == {"info", "ground", "edges", "checkpoints", "heights", "lines"}
    assert doc["errors"] == {}
    # Provenance: hashes of every input, the config itself, versions.
    for name, rec in doc["inputs"].items():
        assert rec["sha256"] == hashlib.sha256(Path(rec["path"]).read_bytes()).hexdigest(), name
    assert doc["config"]["sha256"] == hashlib.sha256(cfg.read_bytes()).hexdigest()
    assert doc["versions"]["lidarqa"] == doc["lidarqa_version"]
    assert doc["versions"]["numpy"] == np.__version__
    # Parameters are recorded with library defaults filled in.
    assert doc["parameters"]["heights"]["params"]["sigma_ref"] == 0.02
    assert "radius" in doc["parameters"]["heights"]["params"]
    assert doc["parameters"]["lines"]["params"]["weight"] == 10.0
    # Per-item outputs exist where the JSON says.
    for files in doc["outputs"].values():
        for rel in files:
            assert (out / rel).is_file(), rel
    assert any(f.endswith("residuals.csv") for f in doc["outputs"]["checkpoints"])
    # No temporary folder is left behind.
    assert not [p for p in out.iterdir() if p.name.startswith(".lidarqa-run-")]


def test_results_match_synthetic_truth(synthetic_run, synthetic):
    run, _, _ = synthetic_run
    r = run.results
    # Vertical check: the check points lie CHECK_OFFSET below the true ground.
    assert r["checkpoints"]["mean_z"] == pytest.approx(CHECK_OFFSET, abs=0.01)
    assert r["checkpoints"]["n_check"] >= synthetic["n_check"] // 2  # the rest flagged (sparse TIN)
    # Lines: test = model shifted by SHIFT; every segment pairs with its original.
    shift = float(np.linalg.norm(SHIFT[:2]))
    assert r["lines"]["lhd"] == pytest.approx(shift, abs=0.01)
    assert r["lines"]["p"] == r["lines"]["q"] == len(synthetic["scene"].edges)
    # Heights: the reference is the true terrain; the cloud has 2 cm noise.
    assert abs(r["heights"]["comparison"]["mean"]) < 0.02
    assert r["heights"]["comparison"]["rms"] < 0.10
    assert r["info"]["n_points"] == len(synthetic["scene"].points)
    # Ground filter scored against the scene's true classes; classified cloud written.
    assert r["ground"]["n_evaluated"] == len(synthetic["scene"].points)
    assert r["ground"]["total"] < 0.10
    # the terrain model is scored too; the synthetic reference ground is complete
    t = r["ground"]["terrain"]
    assert t["reason"] == "" and t["rmse_m"] < 0.5 and t["n_cells"] > 0
    assert t["reference_thinned"] is False
    # Edges of the buildings in each strip.
    assert set(r["edges"]["by_source_id"]) == {"1", "2"}
    assert all(v["n_edges"] > 0 for v in r["edges"]["by_source_id"].values())


def test_classified_cloud_follows_the_relabelling_rule(synthetic_run, synthetic):
    import lidarqa

    run, _, out = synthetic_run
    (rel,) = [f for f in run.document["outputs"]["ground"] if f.endswith((".laz", ".las"))]
    cloud = lidarqa.read(out / rel)
    scene = synthetic["scene"]
    assert len(cloud) == len(scene.points)
    np.testing.assert_allclose(cloud.xyz, scene.points, atol=1e-3)  # input order kept
    cls = cloud.classification
    orig = scene.classification
    assert run.results["ground"]["n_ground"] == int((cls == 2).sum())
    # Former ground points that are no longer ground became 1; other classes kept unless ground.
    assert set(np.unique(orig[cls == 1])) <= {1, 2}
    kept = (cls != 2) & (orig != 2)
    np.testing.assert_array_equal(cls[kept], orig[kept])


def test_verdicts_against_targets(synthetic_run):
    run, _, _ = synthetic_run
    v = run.document["verdicts"]
    assert v["checkpoints"]["verdict"] == "pass"
    assert v["checkpoints"]["targets"][0]["metric"] == "rmse_z"
    assert v["lines"]["verdict"] == "pass"
    assert v["info"]["verdict"] == "n/a"


def test_failed_target_is_reported(synthetic, tmp_path):
    text = LIGHT_TOML.format(d=synthetic["dir"].as_posix()).replace(
        "target_rmse_z = 0.10", "target_rmse_z = 0.01"
    )
    run = run_assessment(write_config(tmp_path / "a.toml", text), tmp_path / "out")
    assert run.document["verdicts"]["checkpoints"]["verdict"] == "fail"
    html = run.html_path.read_text()
    assert "verdict fail" in html


def test_refuses_existing_report_without_overwrite(synthetic_config, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.html").write_text("old")
    with pytest.raises(OutputExistsError, match="report.html"):
        run_assessment(synthetic_config, out)
    assert (out / "report.html").read_text() == "old"
    run = run_assessment(synthetic_config, out, overwrite=True)
    assert "Light assessment" in run.html_path.read_text()


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def test_ctrl_c_leaves_no_partial_report(synthetic_config, tmp_path, monkeypatch):
    monkeypatch.setitem(_registry.ANALYSES, "lines", _interrupt)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_assessment(synthetic_config, out)
    assert not (out / "report.html").exists()
    assert not (out / "report.json").exists()
    assert not (out / "outputs").exists()
    assert not out.exists()  # the folder was created by the run: not even it is left


def test_ctrl_c_keeps_the_previous_report(synthetic_config, tmp_path, monkeypatch):
    out = tmp_path / "out"
    first = run_assessment(synthetic_config, out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    monkeypatch.setitem(_registry.ANALYSES, "lines", _interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_assessment(synthetic_config, out, overwrite=True)
    after = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert first.html_path.is_file()


def test_failing_analysis_is_reported_and_others_still_run(synthetic_config, tmp_path, monkeypatch):
    from lidarqa.errors import DegenerateGeometryError

    def boom(ctx, item):
        raise DegenerateGeometryError("all points collinear")

    monkeypatch.setitem(_registry.ANALYSES, "lines", boom)
    run = run_assessment(synthetic_config, tmp_path / "out")
    assert run.errors == {"lines": "all points collinear"}
    assert run.document["verdicts"]["lines"]["verdict"] == "error"
    assert run.results["checkpoints"]["n_check"] > 0
    assert "This analysis failed: all points collinear" in run.html_path.read_text()


def test_cli_exits_nonzero_when_an_analysis_fails(synthetic_config, tmp_path, monkeypatch):
    from click.testing import CliRunner

    from lidarqa.cli.main import cli
    from lidarqa.errors import DegenerateGeometryError

    def boom(ctx, item):
        raise DegenerateGeometryError("all points collinear")

    monkeypatch.setitem(_registry.ANALYSES, "lines", boom)
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["assess", str(synthetic_config), "--out", str(out), "-q"])
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "lines: all points collinear" in lines[0]
    assert "Traceback" not in r.output
    assert (out / "report.html").is_file() and (out / "report.json").is_file()


def test_cli_assess_and_refusal(synthetic_config, tmp_path):
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    out = tmp_path / "out"
    js = tmp_path / "doc.json"
    r = CliRunner().invoke(
        cli, ["assess", str(synthetic_config), "--out", str(out), "-q", "--json", str(js)]
    )
    assert r.exit_code == 0, r.output
    assert "Report:" in r.stdout and "PASS" in r.stdout
    doc = json.loads(js.read_text())
    assert (
        doc["command"] == "assess"
        and doc["results"]["verdicts"]["checkpoints"]["verdict"] == "pass"
    )
    r2 = CliRunner().invoke(cli, ["assess", str(synthetic_config), "--out", str(out), "-q"])
    assert r2.exit_code == 1
    assert "exists" in r2.stderr and "--overwrite" in r2.stderr
    assert "overwrite=True" not in r2.stderr  # CLI terms, not Python
    assert len(r2.stderr.strip().splitlines()) == 1


def test_cli_ctrl_c_exits_130_without_report(synthetic_config, tmp_path, monkeypatch):
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    monkeypatch.setitem(_registry.ANALYSES, "lines", _interrupt)
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["assess", str(synthetic_config), "--out", str(out), "-q"])
    assert r.exit_code == 130
    assert "Interrupted" in r.stderr
    assert not (out / "report.html").exists() and not (out / "report.json").exists()


def test_heights_with_map_polygons_and_held_apart_reference(synthetic, tmp_path):
    """Map points from polygon boundaries; the reference split from the cloud by seed."""
    pyogrio = pytest.importorskip("pyogrio")
    shapely = pytest.importorskip("shapely")
    from .conftest import ORIGIN

    x0, y0 = ORIGIN[:2]
    polys = [shapely.box(x0 + 5, y0 + 5, x0 + 35, y0 + 35)]
    pyogrio.raw.write(str(tmp_path / "roads.gpkg"), shapely.to_wkb(polys), geometry_type="Polygon",
                      field_data=[np.array([7])], fields=["id"], crs="EPSG:2154", driver="GPKG")
    d = synthetic["dir"].as_posix()
    text = f"""
[inputs.clouds]
scene = "{d}/scene.las"
[inputs.polygons]
roads = "{(tmp_path / 'roads.gpkg').as_posix()}"
[heights]
cloud = "scene"
map = "roads"
map_spacing = 5.0
reference = {{ from_cloud = true, fraction = 0.3, seed = 4, max_points = 400 }}
"""
    runs = [run_assessment(write_config(tmp_path / "h.toml", text), tmp_path / f"out{k}")
            for k in range(2)]
    r = runs[0].results["heights"]
    assert r["map_points"]["n"] == 24  # a 30 m square, a point every 5 m
    assert r["n_reference"] == 400
    assert r["comparison"]["rms"] < 0.2
    # Deterministic split: the same seed gives the same numbers.
    docs = [json.loads(run.json_path.read_text())["results"]["heights"] for run in runs]
    assert docs[0] == docs[1]


def test_checkpoints_from_a_point_list(synthetic, tmp_path):
    from .conftest import MEASURED_SHIFT

    d = synthetic["dir"].as_posix()
    text = f"""
[inputs.points]
check = "{d}/check.csv"
measured = "{d}/measured.csv"
[[checkpoints]]
name = "raw"
measured = "measured"
check = "check"
target_rmse_h = 0.05
[[checkpoints]]
name = "helmert"
measured = "measured"
check = "check"
transform = "helmert"
"""
    run = run_assessment(write_config(tmp_path / "c.toml", text), tmp_path / "out")
    raw = run.results["raw"]
    assert raw["mean_x"] == pytest.approx(MEASURED_SHIFT[0], abs=1e-6)
    assert raw["rmse_z"] == pytest.approx(MEASURED_SHIFT[2], abs=1e-6)
    assert run.document["verdicts"]["raw"]["verdict"] == "fail"  # RMSE h 0.11 m > 0.05 m
    # A 3D Helmert absorbs a pure shift: residuals vanish.
    assert run.results["helmert"]["rmse_3d"] < 1e-6
    assert run.document["parameters"]["helmert"]["params"]["transform"] == "helmert"
    # about the control-point centroid, the translation is the shift itself (issue #16)
    t = run.results["helmert"]["transform"]
    assert [t["params"][k] for k in ("tx", "ty", "tz")] == pytest.approx(-MEASURED_SHIFT, abs=1e-6)
    html = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    # as `lidarqa checkpoints` prints it: value ± σ with its unit
    assert re.search(r"<td>tx</td><td>-?[\d.]+ ± [\d.]+ m</td>", html)
    assert "control-point centroid" in html
