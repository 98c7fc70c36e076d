"""Regression guards on the ISPRS filter-test samples (Sithole & Vosselman 2004), ALS preset.

These are regression guards, not a validation: the ALS preset's constants were chosen
on these same 15 samples (``lidarqa.ground.ALS_SEGMENT_PARAMS``), so a pass says that
the filter still does what it did, not that it generalises (for that, see the
leave-one-site-out figure of ``benchmarks/ground_isprs.py --loso`` and the other data
families of ``benchmarks/ground_dtm.py``). Per-sample bounds are the totals measured
with ``benchmarks/ground_isprs.py`` plus a margin; the 15-sample means must reproduce
the measured values and meet issue #3's goals.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

import lidarqa
from lidarqa.ground import PRESETS, PTD, SegmentPTD, classify_ground, filter_errors

SAMPLES = ["11", "12", "21", "22", "23", "24", "31", "41", "42", "51", "52", "53", "54", "61", "71"]

# measured total error (%) with PRESETS["als"], 2026-11-22; segment-PTD re-measured
# 2026-11-23 after the perched-surface test joined the preset (was 15.00 / 4.30 / 4.44),
# again after the façade trial joined it (`facade_distance`; was 13.22 / 3.99 / 4.30), and
# after the final roof check (`roof_ratio`; was 12.18 / 3.98 / 4.09), and after the
# perched test judged the segments it cuts into whole (was 11.27 / 3.98 / 4.03), and
# after the façade trial took the points under the ground surface of the façade
# segments that surface passes through (was 10.41 / 3.98 / 3.95), and after the
# unsegmented points were judged again once the raised test rejects segments (was
# 10.04 / 3.94 / 3.91), and after the gap test joined the sparse preset (`gap_step`;
# was 9.72 / 3.94 / 3.87: samp11 and samp24 unchanged)
MEASURED_BUNDLED = {
    ("segment-ptd", "samp11"): 9.72,
    ("segment-ptd", "samp24"): 3.94,
    ("ptd", "samp11"): 16.91,
    ("ptd", "samp24"): 8.22,
}
MEASURED_MEAN = {"segment-ptd": 3.84, "ptd": 5.90}
# issue #3: mean total error with one parameter set, segment-PTD <= 4.5 %, PTD <= 6 %
GOAL_MEAN = {"segment-ptd": 4.5, "ptd": 6.0}


def _filter(method):
    cls = SegmentPTD if method == "segment-ptd" else PTD
    return cls(**PRESETS["als"][method])


_RESULTS: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}


def _ground(method: str, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(reference ground, filtered ground) of one sample file with the ALS preset.

    Cached by file content: the bundled samp11/samp24 are the shared ones byte for byte, so
    the bundled-sample tests and the 15-sample mean run the (deterministic) filter once each.
    """
    key = (method, hashlib.sha256(Path(path).read_bytes()).hexdigest())
    if key not in _RESULTS:
        cloud = lidarqa.read(path)
        _RESULTS[key] = (cloud.classification == 2, _filter(method).ground_mask(cloud.xyz))
    return _RESULTS[key]


@pytest.mark.parametrize("method", ["segment-ptd", "ptd"])
@pytest.mark.parametrize("sample", ["samp11", "samp24"])
def test_bundled_samples(data_dir, method, sample):
    """Regression guard: the bundled samples stay within 2 points of their measured totals."""
    ref, g = _ground(method, data_dir / f"{sample}-utm.laz")
    e = filter_errors(ref, g)
    assert 100 * e.total <= MEASURED_BUNDLED[(method, sample)] + 2.0
    assert e.kappa > 0.5


def test_classify_ground_preset_matches_kernel(data_dir):
    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    r = classify_ground(cloud, method="ptd", preset="als", evaluate=True)
    _, g = _ground("ptd", data_dir / "samp24-utm.laz")
    np.testing.assert_array_equal(r.ground_mask, g)
    assert r.evaluation.total == filter_errors(cloud.classification == 2, g).total


@pytest.mark.shared
@pytest.mark.slow
@pytest.mark.parametrize("method", ["segment-ptd", "ptd"])
def test_all_fifteen_samples(shared_data, method):
    """Regression guard: the 15-sample mean is reproduced (the preset was chosen on it)."""
    folder = shared_data / "isprs-filtertest-pdal"
    totals = []
    for s in SAMPLES:
        e = filter_errors(*_ground(method, folder / f"samp{s}-utm.laz"))
        assert e.kappa > 0.3, s
        totals.append(100 * e.total)
    # the filters are deterministic: the measured means are reproduced to the
    # rounding, and they meet the goal (the thin margin is the result's)
    assert np.mean(totals) == pytest.approx(MEASURED_MEAN[method], abs=0.005)
    assert np.mean(totals) <= GOAL_MEAN[method]


@pytest.mark.parametrize(("method", "bound"), [("segment-ptd", 0.015), ("ptd", 0.02)])
def test_ign_demo_tile_default_parameters(demo_tile, method, bound):
    # IGN LiDAR HD 50×50 m urban tile; its classification as reference, ignoring
    # unclassified / noise / water / IGN special classes. Measured: 0.81 % / 1.20 %.
    cloud = lidarqa.read(demo_tile)
    r = classify_ground(cloud, method=method, evaluate=True, ignore_classes=[1, 7, 9, 64, 65, 66])
    assert r.return_handling == "last_only"
    assert r.evaluation.total <= bound and r.evaluation.kappa > 0.95
