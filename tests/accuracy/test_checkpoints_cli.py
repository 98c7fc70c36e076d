"""``lidarqa checkpoints``: JSON document, outputs, units and clear errors."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner
from pyproj import CRS

import lidarqa
from lidarqa.accuracy.transforms import rotation_matrix
from lidarqa.cli.main import cli
from lidarqa.io import PointCloud
from lidarqa.io.vector import PointSet, read_points, write_points


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _write_csv(path, ids, xyz):
    lines = ["id,x,y,z"] + [
        f"{i},{x!r},{y!r},{z!r}" for i, (x, y, z) in zip(ids, xyz.tolist(), strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def survey(tmp_path):
    rng = np.random.default_rng(4)
    chk = rng.uniform(0, 100, (35, 3)) + [600000.0, 4500000.0, 100.0]
    ids = [f"C{i}" for i in range(35)]
    mea = chk + [0.04, -0.02, 0.08] + rng.normal(0, 0.01, chk.shape)
    return (
        _write_csv(tmp_path / "measured.csv", ids, mea),
        _write_csv(tmp_path / "check.csv", ids, chk),
        ids,
        mea,
        chk,
    )


def test_json_document_and_residual_csv(survey, tmp_path):
    mea_p, chk_p, ids, mea, chk = survey
    js, out = tmp_path / "r.json", tmp_path / "res.csv"
    r = run(
        "checkpoints", mea_p, chk_p, "--json", js, "-o", out, "--checkpoint-rmse-v", "0.02", "-q"
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(js.read_text())
    assert doc["command"] == "checkpoints"
    res = doc["results"]
    assert res["n_check"] == 35 and res["n_control"] == 0
    assert res["transform"]["name"] == "none"
    assert res["mean_z"] == pytest.approx(0.08, abs=0.005)
    assert res["rmse_z"] == pytest.approx(np.sqrt(np.mean((mea[:, 2] - chk[:, 2]) ** 2)), rel=1e-9)
    assert res["asprs2023"]["rmse_v"] == pytest.approx(np.hypot(res["rmse_z"], 0.02))
    assert res["asprs2023"]["n_check"] == 35
    assert "accuracy_r" in res["nssda"] and "formula" in res["nssda"]
    assert len(res["residuals"]) == 35 and res["residuals"][0]["role"] == "check"
    pts = read_points(out)
    assert len(pts) == 35 and {"dx", "dy", "dz", "role"} <= set(pts.attributes)
    assert pts.ids.tolist() == ids  # natural id order: C0, C1, ..., C10
    np.testing.assert_allclose(pts.xyz, chk, atol=5.1e-5)  # CSV coordinates, dx/dy/dz to 0.1 mm
    np.testing.assert_allclose(pts.attributes["dz"], mea[:, 2] - chk[:, 2], atol=5.1e-5)
    r2 = run("checkpoints", mea_p, chk_p, "-q")
    assert "ASPRS Ed. 2" in r2.output and "NSSDA" in r2.output


def test_transform_with_control_ids_and_file(tmp_path):
    rng = np.random.default_rng(8)
    chk = rng.uniform(0, 80, (30, 3)) + [512000.0, 5403000.0, 250.0]
    ids = list(range(1, 31))
    local = (chk - [512040.0, 5403040.0, 250.0]) @ rotation_matrix(0.0, 0.0, 40.0) + [5.0, 5.0, 0.0]
    mea = local + rng.normal(0, 0.01, chk.shape)
    mea_p, chk_p = (
        _write_csv(tmp_path / "m.csv", ids, mea),
        _write_csv(tmp_path / "c.csv", ids, chk),
    )
    js = tmp_path / "t.json"
    r = run(
        "checkpoints",
        mea_p,
        chk_p,
        "--transform",
        "similarity2d",
        "--control-ids",
        "1,2,3,4,5,6",
        "--json",
        js,
        "-q",
    )
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    assert res["n_control"] == 6 and res["n_check"] == 24
    assert res["transform"]["params"]["rotation_deg"] == pytest.approx(40.0, abs=0.05)
    assert res["transform"]["sigmas"]["rotation_deg"] > 0 and res["transform"]["sigma0"] > 0
    assert res["rmse_3d"] < 0.05
    roles = {d["id"]: d["role"] for d in res["residuals"]}
    assert roles[1] == "control" and roles[30] == "check"
    cf = tmp_path / "control.txt"
    cf.write_text("# control points\n1\n2\n3\n4\n5\n6\n")
    js2 = tmp_path / "t2.json"
    r = run(
        "checkpoints",
        mea_p,
        chk_p,
        "--transform",
        "helmert",
        "--control-file",
        cf,
        "--json",
        js2,
        "-q",
    )
    assert r.exit_code == 0, r.output
    res2 = json.loads(js2.read_text())["results"]
    assert res2["n_control"] == 6
    assert res2["transform"]["params"]["kappa_deg"] == pytest.approx(40.0, abs=0.05)
    # a CSV point file with an id column works as a control file too
    cf_csv = _write_csv(tmp_path / "control.csv", [2, 4, 6, 8], chk[[1, 3, 5, 7]])
    js3 = tmp_path / "t3.json"
    r = run(
        "checkpoints",
        mea_p,
        chk_p,
        "--transform",
        "helmert-fixed-scale",
        "--control-file",
        cf_csv,
        "--json",
        js3,
        "-q",
    )
    assert r.exit_code == 0, r.output
    res3 = json.loads(js3.read_text())["results"]
    assert res3["n_control"] == 4 and res3["transform"]["params"]["scale"] == 1.0
    # the text reads like a surveyor's adjustment report: about the centroid, degrees, ppm
    text = run("checkpoints", mea_p, chk_p, "--transform", "helmert", "--control-file", cf).output
    assert "about the control-point centroid" in text and "kappa_deg" not in text
    assert re.search(r"kappa\s+40\.0\d* ± [\d.]+ °", text) and "ppm)" in text
    text = run("checkpoints", mea_p, chk_p, "--transform", "helmert-fixed-scale",
               "--control-file", cf).output  # fmt: skip
    assert "1 (fixed)" in text and "ppm" not in text
    assert {d["id"] for d in res3["residuals"] if d["role"] == "control"} == {2, 4, 6, 8}


def test_nearest_matching_reports_unmatched(tmp_path):
    rng = np.random.default_rng(2)
    chk = rng.uniform(0, 100, (25, 3))
    mea = chk[:20] + rng.normal(0, 0.02, (20, 3))
    mea_p = _write_csv(tmp_path / "m.csv", [f"corner{i}" for i in range(20)], mea)
    chk_p = _write_csv(tmp_path / "c.csv", list(range(25)), chk)
    js = tmp_path / "n.json"
    r = run(
        "checkpoints",
        mea_p,
        chk_p,
        "--match",
        "nearest",
        "--max-distance",
        "0.5",
        "--json",
        js,
        "-q",
    )
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    assert res["n_check"] == 20 and sorted(res["match"]["unmatched_check"]) == [20, 21, 22, 23, 24]
    assert all(d["measured_id"] == f"corner{d['id']}" for d in res["residuals"])


def test_vertical_cloud_in_feet_is_converted(tmp_path):
    rng = np.random.default_rng(6)
    xy = rng.uniform(0, 60, (20000, 2)) + [500000.0, 5000000.0]
    z_m = 100 + 0.02 * (xy[:, 0] - 500000)
    ft = 0.30480060960121924
    cls = np.where(rng.random(20000) < 0.8, 2, 5).astype(np.uint8)
    z_cloud = (
        np.where(cls == 2, z_m, z_m + 10) / ft + 1.0
    )  # cloud 1 ftUS too high, vegetation class 5
    cloud = PointCloud(
        np.column_stack([xy, z_cloud]), fields={"classification": cls}, crs=CRS("EPSG:32632+6360")
    )
    las = tmp_path / "cloud.las"
    lidarqa.write(cloud, las)
    cxy = rng.uniform(10, 50, (30, 2)) + [500000.0, 5000000.0]
    cz = (100 + 0.02 * (cxy[:, 0] - 500000)) / ft
    chk_p = _write_csv(tmp_path / "c.csv", list(range(30)), np.column_stack([cxy, cz]))
    js = tmp_path / "v.json"
    r = run("checkpoints", las, chk_p, "--vertical", "--json", js, "-o", tmp_path / "v.gpkg", "-q")
    assert r.exit_code == 0, r.output
    res = json.loads(js.read_text())["results"]
    assert res["n_check"] == 30
    assert res["mean_z"] == pytest.approx(ft, abs=0.01)  # reported in metres
    assert any("metres" in w for w in res["warnings"])
    assert res["nssda"]["accuracy_z"] == pytest.approx(1.96 * res["rmse_z"])
    out = read_points(tmp_path / "v.gpkg")
    assert len(out) == 30 and "dz" in out.attributes
    np.testing.assert_allclose(
        np.sort(out.xyz[:, 2]), np.sort(cz), atol=1e-6
    )  # check points unconverted


# ------------------------------------------------------------------ bad input


def _bad_case(tmp_path, case):
    """(MEASURED, CHECK, extra args) for each bad-input case."""
    good = np.array([[0, 0, 0], [10, 0, 1], [0, 10, 2], [10, 10, 3.0]])
    c = _write_csv(tmp_path / "check.csv", [1, 2, 3, 4], good)
    if case == "one-point":
        return _write_csv(tmp_path / "m.csv", [1], good[:1]), c, ["--transform", "similarity2d"]
    if case == "duplicate-ids":
        return _write_csv(tmp_path / "m.csv", [1, 1, 2, 3], good), c, []
    if case == "ids-do-not-match":
        return _write_csv(tmp_path / "m.csv", ["a", "b", "c", "d"], good), c, []
    if case == "unknown-control-id":
        return (
            _write_csv(tmp_path / "m.csv", [1, 2, 3, 4], good),
            c,
            ["--transform", "helmert", "--control-ids", "1,2,99"],
        )
    if case == "collinear-control":
        line = np.column_stack([np.arange(5.0), np.arange(5.0), np.arange(5.0)])
        c = _write_csv(tmp_path / "check.csv", [1, 2, 3, 4, 5], line + 0.01)
        return (
            _write_csv(tmp_path / "m.csv", [1, 2, 3, 4, 5], line),
            c,
            ["--transform", "helmert", "--control-ids", "1,2,3,4"],
        )
    if case == "nan":
        m = tmp_path / "m.csv"
        m.write_text("id,x,y,z\n1,0,0,nan\n2,10,0,1\n")
        return m, c, []
    if case == "crs-mismatch":
        m, cc = tmp_path / "m.gpkg", tmp_path / "c.gpkg"
        write_points(PointSet(np.array([1, 2]), good[:2], crs=CRS("EPSG:2154")), m)
        write_points(PointSet(np.array([1, 2]), good[:2], crs=CRS("EPSG:32632")), cc)
        return m, cc, []
    if case == "cloud-without-vertical":
        las = tmp_path / "cloud.las"
        lidarqa.write(PointCloud(good.copy()), las)
        return las, c, []
    if case == "vertical-crs-mismatch":
        las = tmp_path / "cloud.las"
        lidarqa.write(
            PointCloud(
                good.copy(),
                fields={"classification": np.full(4, 2, np.uint8)},
                crs=CRS("EPSG:2154"),
            ),
            las,
        )
        cc = tmp_path / "c.gpkg"
        write_points(
            PointSet(np.array([1]), np.array([[5.0, 5.0, 1.0]]), crs=CRS("EPSG:32632")), cc
        )
        return las, cc, ["--vertical"]
    raise AssertionError(case)


BAD = [
    "one-point",
    "duplicate-ids",
    "ids-do-not-match",
    "unknown-control-id",
    "collinear-control",
    "nan",
    "crs-mismatch",
    "cloud-without-vertical",
    "vertical-crs-mismatch",
]


@pytest.mark.parametrize("case", BAD)
def test_bad_input_clear_error(tmp_path, case):
    m, c, extra = _bad_case(tmp_path, case)
    js, out = tmp_path / "out.json", tmp_path / "out.csv"
    r = run("checkpoints", m, c, *extra, "--json", js, "-o", out, "-q")
    assert r.exit_code == 1, (case, r.output)
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), r.output
    assert "Traceback" not in r.output
    assert not js.exists() and not out.exists()


def test_bad_input_messages_say_why(tmp_path):
    expect = {
        "one-point": "at least 2",
        "duplicate-ids": "duplicate",
        "ids-do-not-match": "no ids in common",
        "collinear-control": "collinear",
        "nan": "NaN",
        "crs-mismatch": "CRS",
        "cloud-without-vertical": "--vertical",
    }
    for case, text in expect.items():
        d = tmp_path / case
        d.mkdir()
        m, c, extra = _bad_case(d, case)
        r = run("checkpoints", m, c, *extra, "-q")
        assert text in r.output, (case, r.output)


def test_option_errors(survey, tmp_path):
    mea_p, chk_p, *_ = survey
    r = run("checkpoints", mea_p, chk_p, "--transform", "affine")
    assert r.exit_code == 2 and "Traceback" not in r.output
    r = run("checkpoints", mea_p, chk_p, "--vertical", "--transform", "helmert", "-q")
    assert r.exit_code == 1 and "--vertical" in r.output
    r = run("checkpoints", mea_p, chk_p, "-o", tmp_path / "x.txt", "-q")
    assert r.exit_code == 1 and ".gpkg" in r.output
