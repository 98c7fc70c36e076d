"""Automatic filter parameters: measurements on clouds of known density, sensor and slope."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from lidarqa.cli.main import cli
from lidarqa.errors import OptionError
from lidarqa.ground import (
    ALS_SEGMENT_PARAMS,
    DENSE_ALS,
    auto_parameters,
    classify_ground,
    measure_cloud,
)
from lidarqa.io import PointCloud


def _flat(density: float, size: float = 120.0, seed: int = 0, slope_deg: float = 0.0):
    rng = np.random.default_rng(seed)
    n = int(density * size * size)
    xy = rng.uniform(0, size, (n, 2))
    z = xy[:, 0] * math.tan(math.radians(slope_deg)) + rng.normal(0, 0.02, n)
    return np.column_stack([xy, z])


@pytest.mark.parametrize("density", [0.5, 2.0, 15.0])
def test_density_and_spacing_measured(density):
    m = measure_cloud(_flat(density))
    assert m.density == pytest.approx(density, rel=0.15)
    assert m.spacing == pytest.approx(1 / math.sqrt(density), rel=0.1)
    assert m.sensor == "als"


def test_density_robust_to_gaps_and_overlaps():
    p = _flat(4.0, seed=1)
    gap = p[(p[:, 0] < 40) | (p[:, 0] > 80)]  # a 40 m wide hole: same density per occupied m²
    overlap = np.vstack([p, _flat(4.0, seed=2)[:, :] + [0, 0, 0]])  # a second strip everywhere
    full = measure_cloud(p)
    assert measure_cloud(gap).density == pytest.approx(full.density, rel=0.1)
    assert measure_cloud(gap).occupied_area < 0.8 * full.occupied_area
    assert measure_cloud(overlap).density == pytest.approx(2 * full.density, rel=0.15)


def test_return_structure_and_scan_angle():
    p = _flat(2.0)
    n = len(p)
    rng = np.random.default_rng(3)
    nr = np.where(rng.random(n) < 0.3, 2, 1).astype(np.uint8)
    rn = nr.copy()
    m = measure_cloud(p, fields={"return_number": rn, "number_of_returns": nr})
    assert m.has_returns
    assert m.multi_return_share == pytest.approx(0.3, abs=0.03)
    wide = measure_cloud(p, fields={"scan_angle_rank": rng.integers(-90, 91, n)})
    narrow = measure_cloud(p, fields={"scan_angle_rank": rng.integers(-20, 21, n)})
    assert wide.sensor == "mls" and narrow.sensor == "als"
    assert not measure_cloud(p).has_returns
    # the reason for a regime names the measured figures and the thresholds
    from lidarqa.ground.auto import parameter_notes, regime_reason

    why = regime_reason(wide, "mls")
    assert why.startswith("mobile scan") and "> 60°" in why
    assert "<= 60°" in regime_reason(narrow, "als-sparse") and "< 4" in regime_reason(
        narrow, "als-sparse"
    )
    assert "sensor given as als" in regime_reason(wide, "als-sparse", sensor="als")
    notes = parameter_notes(narrow, {"a": "preset", "b": "given", "filter_density": "preset"}, "x")
    assert set(notes) == {"a", "filter_density"} and "1.5 × 4 = 6" in notes["filter_density"]


def test_slope_measured():
    m = measure_cloud(_flat(1.0, size=200.0, slope_deg=30.0))
    assert m.slope_median == pytest.approx(30.0, abs=3.0)
    flat = measure_cloud(_flat(1.0, size=200.0))
    assert flat.slope_p90 < 3.0


def test_largest_object_footprint():
    p = _flat(2.0, size=200.0, seed=4)
    inside = (np.abs(p[:, 0] - 100) < 20) & (np.abs(p[:, 1] - 100) < 15)  # 40 m x 30 m roof
    p[inside, 2] += 10.0
    m = measure_cloud(p)
    assert 20.0 <= m.largest_object_diameter <= 34.0  # inscribed disc of a 30 m wide roof
    assert m.largest_object_area == pytest.approx(1200.0, rel=0.3)
    assert measure_cloud(_flat(2.0, size=200.0, seed=4)).largest_object_diameter < 5.0


def test_regimes_follow_density_and_sensor_hint():
    sparse = measure_cloud(_flat(0.8))
    dense = measure_cloud(_flat(2 * DENSE_ALS))
    p, src, regime = auto_parameters(sparse, "segment-ptd")
    assert regime == "als-sparse"
    # the preset's constants are labelled as such, not "measured" (issue #28)
    assert p == ALS_SEGMENT_PARAMS and set(src.values()) == {"preset"}
    _, dsrc, _ = auto_parameters(dense, "segment-ptd")
    assert set(dsrc.values()) == {"preset"}
    assert auto_parameters(dense, "segment-ptd")[2] == "als-dense"
    assert auto_parameters(sparse, "segment-ptd", sensor="mls") == ({}, {}, "mls")
    with pytest.raises(OptionError):
        auto_parameters(sparse, "segment-ptd", sensor="tls")


def test_classify_ground_records_provenance_and_explicit_options_win():
    pts = _flat(1.0, size=80.0)
    r = classify_ground(pts, method="ptd")
    assert r.preset == "auto" and r.regime == "als-sparse"
    assert r.parameter_sources["iter_angle"] == "preset"
    assert r.parameter_sources["cell_size"] == "default"
    # the note says which preset and which measured figures chose the regime
    note = r.parameter_notes["iter_angle"]
    assert "als-sparse" in note and "measured density" in note and "< 4" in note
    assert set(r.parameter_notes) == {k for k, v in r.parameter_sources.items() if v == "preset"}
    assert "measured density" in r.regime_reason
    assert set(r.parameter_sources) == set(r.parameters)
    g = classify_ground(pts, method="ptd", iter_angle=9.0)
    assert g.parameters["iter_angle"] == 9.0 and g.parameter_sources["iter_angle"] == "given"
    assert "iter_angle" not in g.parameter_notes
    a = classify_ground(pts, method="ptd", preset="als")
    assert a.parameter_sources["iter_angle"] == "preset" and a.regime_reason is None
    assert a.parameter_notes["iter_angle"] == "constant of the als preset"
    m = classify_ground(pts, method="ptd", preset="mls")
    assert m.measures is None and m.parameters["iter_angle"] == 6.0
    d = json.loads(json.dumps(r.to_dict()))
    assert d["measured"]["density"] == pytest.approx(1.0, rel=0.15)
    assert d["parameter_sources"]["iter_angle"] == "preset"
    assert "measured" not in d["parameter_sources"].values()


def test_auto_is_independent_of_input_order():
    pts = _flat(1.0, size=80.0, seed=5)
    perm = np.random.default_rng(0).permutation(len(pts))
    a = classify_ground(pts, method="ptd")
    b = classify_ground(pts[perm], method="ptd")
    assert a.parameters == b.parameters
    np.testing.assert_array_equal(a.ground_mask[perm], b.ground_mask)


def test_cli_prints_and_records_measured_figures(tmp_path):
    from lidarqa.io import write

    src = tmp_path / "in.laz"
    write(PointCloud(_flat(1.0, size=80.0) + [500000.0, 5400000.0, 100.0]), src)
    js = tmp_path / "out.json"
    res = CliRunner().invoke(
        cli,
        [
            "ground",
            str(src),
            "-o",
            str(tmp_path / "out.laz"),
            "--method",
            "ptd",
            "--iter-distance",
            "0.6",
            "--json",
            str(js),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "pts/m2" in res.output and "als-sparse" in res.output
    doc = json.loads(js.read_text())["parameters"]
    assert doc["preset"] == "auto" and doc["regime"] == "als-sparse"
    assert doc["parameter_sources"]["iter_distance"] == "given" and doc["iter_distance"] == 0.6
    assert doc["parameter_sources"]["iter_angle"] == "preset"
    assert "als-sparse" in doc["parameter_notes"]["iter_angle"]
    assert "iter_distance" not in doc["parameter_notes"]
    assert "(preset)" in res.output and "(measured)" not in res.output
    assert doc["measured"]["density"] == pytest.approx(1.0, rel=0.15)


def test_default_is_independent_of_thread_count():
    """The parallel kernels (TIN setup, judging) give the same ground with 1 or 2 threads."""
    import numba

    from lidarqa.testing import make_scene

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba limited to one thread (NUMBA_NUM_THREADS)")
    sc = make_scene(seed=3, size=(60.0, 60.0), density=5.0)
    before = numba.get_num_threads()
    try:
        masks = []
        for t in (1, 2):
            numba.set_num_threads(t)
            masks.append(classify_ground(sc.points).ground_mask)
    finally:
        numba.set_num_threads(before)
    assert masks[0].any() and not masks[0].all()
    np.testing.assert_array_equal(masks[0], masks[1])
