"""``lidarqa ground`` command line."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.errors import DataQualityWarning
from lidarqa.ground import classify_ground, ground_candidates, relabel_classification
from lidarqa.io import PointCloud


def _run(*args):
    return CliRunner().invoke(cli, ["-q", "ground", *map(str, args)])


@pytest.mark.parametrize("method", ["segment-ptd", "ptd"])
def test_cli_writes_every_point_and_evaluates(data_dir, tmp_path, method):
    src = data_dir / "samp24-utm.laz"
    out = tmp_path / "out.laz"
    js = tmp_path / "out.json"
    res = _run(src, "-o", out, "--method", method, "--evaluate", "--json", js)
    assert res.exit_code == 0, res.output
    a, b = lidarqa.read(src), lidarqa.read(out)
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    assert set(a.fields) <= set(b.fields)
    for name in a.fields:
        if name != "classification":
            np.testing.assert_array_equal(a.fields[name], b.fields[name])
    doc = json.loads(js.read_text())
    r = doc["results"]
    assert doc["command"] == "ground" and doc["parameters"]["method"] == method
    for key in ("type_i", "type_ii", "total", "kappa", "n_evaluated", "confusion"):
        assert key in r
    assert r["n_evaluated"] == len(a)
    # the written classes are exactly the relabelled input
    cls_out = np.asarray(b.classification)
    assert set(np.unique(cls_out)) <= {0, 1, 2}
    assert (cls_out == 2).sum() == r["n_ground"]
    e = r["confusion"]
    assert e["ref_ground_pred_ground"] + e["ref_object_pred_ground"] == r["n_ground"]
    assert 0 <= r["total"] < 0.35
    # the terrain model: the kernel on the written ground against the input's
    from lidarqa.ground import terrain_scores

    want = terrain_scores(a.xyz, cls_out == 2, np.asarray(a.classification) == 2).to_dict()
    assert r["terrain"] == pytest.approx(want, nan_ok=True)
    assert r["terrain"]["reference_thinned"] is False and 0 <= r["terrain"]["rmse_m"] < 1.0


def test_cli_says_when_the_reference_looks_thinned(tmp_path):
    """A vendor ground that kept a third of the ground points: the CLI says so."""
    from lidarqa.testing import make_scene

    sc = make_scene(seed=2, size=(40.0, 40.0), density=4.0)
    keep = np.random.default_rng(0).random(len(sc)) < 0.33
    cls = np.where(sc.is_ground & ~keep, 1, sc.classification).astype(np.uint8)
    src = tmp_path / "thin.laz"
    lidarqa.write(PointCloud(sc.points, fields={"classification": cls}), src)
    res = CliRunner().invoke(
        cli, ["ground", str(src), "-o", str(tmp_path / "o.laz"), "--evaluate"]
    )
    assert res.exit_code == 0, res.output
    assert "terrain model RMSE (filter − reference TIN) (m)" in res.output  # the report's label
    assert "the reference ground looks thinned" in res.output
    assert "judge by the terrain model" in res.output


def test_relabel_rules():
    cls = np.array([2, 2, 6, 0, 7, 5], dtype=np.uint8)
    g = np.array([True, False, True, False, False, False])
    out = relabel_classification(cls, g)
    assert out.tolist() == [2, 1, 2, 0, 7, 5] and out.dtype == np.uint8


def test_existing_ground_labels_are_not_used():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0, 40, (800, 2)), rng.normal(0, 0.02, 800)])
    a = PointCloud(pts, fields={"classification": np.full(800, 2, dtype=np.uint8)})
    b = PointCloud(pts, fields={"classification": np.zeros(800, dtype=np.uint8)})
    ga = classify_ground(a, method="ptd").ground_mask
    gb = classify_ground(b, method="ptd").ground_mask
    np.testing.assert_array_equal(ga, gb)


def test_return_handling_and_noise():
    n = 6
    cloud = PointCloud(
        np.zeros((n, 3)),
        fields={
            "return_number": np.array([1, 1, 2, 1, 0, 1], dtype=np.uint8),
            "number_of_returns": np.array([1, 2, 2, 3, 0, 1], dtype=np.uint8),
            "classification": np.array([1, 1, 1, 1, 1, 7], dtype=np.uint8),
        },
    )
    with pytest.warns(DataQualityWarning):
        mask, handling, n_noise, _ = ground_candidates(cloud)
    assert mask.tolist() == [True, False, True, False, True, False]
    assert handling == "last_only_partial" and n_noise == 1
    mask, handling, _, _ = ground_candidates(cloud, last_returns_only=False, exclude_classes=())
    assert mask.all() and handling == "all"


def test_cli_warns_on_partly_zero_returns(tmp_path):
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0, 30, (500, 2)), rng.normal(0, 0.02, 500)]) + [
        1000,
        2000,
        50,
    ]
    rn = np.ones(500, dtype=np.uint8)
    rn[:50] = 0
    cloud = PointCloud(
        pts,
        fields={
            "return_number": rn,
            "number_of_returns": np.ones(500, dtype=np.uint8),
            "classification": np.zeros(500, dtype=np.uint8),
        },
    )
    src = tmp_path / "in.las"
    lidarqa.write(cloud, src)
    res = CliRunner().invoke(
        cli, ["ground", str(src), "-o", str(tmp_path / "o.las"), "--method", "ptd"]
    )
    assert res.exit_code == 0, res.output
    assert "return number" in res.output  # the warning is shown (stderr is mixed in)


def test_cli_refuses_existing_output(data_dir, tmp_path):
    out = tmp_path / "o.laz"
    out.write_bytes(b"x")
    res = _run(data_dir / "samp24-utm.laz", "-o", out)
    assert res.exit_code == 1 and "Traceback" not in res.output


def test_cli_option_errors(data_dir, tmp_path):
    res = _run(data_dir / "samp24-utm.laz", "-o", tmp_path / "o.laz", "--iter-angle", "95")
    assert res.exit_code == 1 and "iter_angle" in res.output
    res = _run(
        data_dir / "samp24-utm.laz",
        "-o",
        tmp_path / "o.laz",
        "--method",
        "ptd",
        "--accept-ratio",
        "0.3",
    )
    assert res.exit_code == 1 and "segment-ptd" in res.output


def _write_csv(path, pts):
    lines = ["x,y,z"] + [f"{x},{y},{z}" for x, y, z in pts]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("case", ["empty", "one", "two", "vertical", "flat", "nan"])
def test_cli_bad_input_never_tracebacks(tmp_path, case):
    rng = np.random.default_rng(0)
    pts = {
        "empty": np.zeros((0, 3)),
        "one": np.array([[1.0, 2.0, 3.0]]),
        "two": np.array([[1.0, 2.0, 3.0], [2.0, 2.0, 3.5]]),
        "vertical": np.column_stack([np.ones(20), np.ones(20), np.linspace(0, 5, 20)]),
        "flat": np.column_stack([rng.uniform(0, 20, (300, 2)), np.full(300, 4.0)]),
        "nan": np.array([[0.0, 0.0, 0.0], [1.0, np.nan, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]),
    }[case]
    if case == "nan":  # LAS cannot hold NaN: use a text file
        src = tmp_path / "in.csv"
        _write_csv(src, pts)
    else:
        src = tmp_path / "in.las"
        lidarqa.write(PointCloud(pts + [500000.0, 5000000.0, 0.0]), src)
    for method in ("segment-ptd", "ptd"):
        out = tmp_path / f"o-{method}.las"
        res = _run(src, "-o", out, "--method", method)
        assert "Traceback" not in res.output
        assert res.exit_code in (0, 1), res.output
        if case == "nan":
            assert res.exit_code == 1 and "NaN" in res.output
        elif case == "flat":
            assert res.exit_code == 0
            assert (lidarqa.read(out).classification == 2).all()
        else:
            assert res.exit_code == 0, res.output


def test_cli_keeps_input_order_on_las(data_dir, tmp_path):
    src = tmp_path / "samp24.laz"
    shutil.copy(data_dir / "samp24-utm.laz", src)
    out = tmp_path / "o.laz"
    assert _run(src, "-o", out, "--method", "ptd").exit_code == 0
    np.testing.assert_array_equal(lidarqa.read(src).xyz, lidarqa.read(out).xyz)


def test_cli_preset_als(data_dir, tmp_path):
    js = tmp_path / "o.json"
    res = _run(
        data_dir / "samp24-utm.laz",
        "-o",
        tmp_path / "o.laz",
        "--preset",
        "als",
        "--iter-distance",
        "0.75",
        "--evaluate",
        "--json",
        js,
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(js.read_text())
    assert doc["parameters"]["preset"] == "als"
    assert doc["parameters"]["iter_angle"] == 16.0  # from the preset
    assert doc["parameters"]["iter_distance"] == 0.75  # explicit option wins
    assert doc["results"]["total"] < 0.10
