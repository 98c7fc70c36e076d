"""Progress with percentage and ETA from pure kernels; clean output when piped (issue #16)."""

from __future__ import annotations

import io
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli._common import Steps
from lidarqa.cli.main import cli


def _check_fractions(seen: list[float]) -> None:
    assert seen, "the kernel never reported progress"
    assert all(0.0 <= f <= 1.0 for f in seen)
    assert all(b >= a for a, b in zip(seen, seen[1:], strict=False)), seen
    assert seen[-1] == 1.0 and len(set(seen)) >= 3


@pytest.mark.parametrize("method", ["ptd", "segment-ptd"])
def test_ground_filter_reports_monotone_progress_and_stays_pure(data_dir, method):
    from lidarqa.ground import classify_ground

    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    seen: list[float] = []
    with_cb = classify_ground(cloud, method=method, preset="als", progress=seen.append)
    without = classify_ground(cloud, method=method, preset="als")
    _check_fractions(seen)
    np.testing.assert_array_equal(with_cb.ground_mask, without.ground_mask)
    assert "progress" not in with_cb.parameters


def test_segmentation_and_matching_report_progress():
    from lidarqa.accuracy import match_segments
    from lidarqa.accuracy._lines_synthetic import make_segment_sets
    from lidarqa.geometry import segment_planes
    from lidarqa.testing import make_building_scene

    scene = make_building_scene(seed=2, roofs=("gable",))
    seen: list[float] = []
    segment_planes(scene.points, progress=seen.append)
    _check_fractions(seen)
    s = make_segment_sets(n_model=40, seed=3)
    seen = []
    match_segments(s.test, s.model, progress=seen.append)
    _check_fractions(seen)


def test_edge_extraction_of_passes_reports_progress(tmp_path):
    """lines/repeatability read clouds and segment them: the longest step of both."""
    from lidarqa.accuracy.lines_io import load_passes, load_segments
    from lidarqa.testing import make_scene

    scene = make_scene(seed=3, size=(40.0, 40.0), density=10.0, strips=2, n_buildings=2,
                       n_trees=0, n_cars=0)  # fmt: skip
    path = tmp_path / "scene.laz"
    lidarqa.write(scene.to_cloud(), path)
    seen: list[float] = []
    passes = load_passes([str(path)], by_source_id=True, classes=[6], progress=seen.append)
    assert len(passes) == 2
    _check_fractions(seen)
    assert any(0.0 < f < 0.5 for f in seen) and any(0.5 < f < 1.0 for f in seen)  # per strip
    seen = []
    load_segments(path, classes=[6], source_id=1, progress=seen.append)
    _check_fractions(seen)


def test_live_bar_shows_percentage_and_eta():
    from rich.console import Console

    buf = io.StringIO()
    steps = Steps(quiet=False, console=Console(file=buf, force_terminal=True, width=120))
    assert steps.live
    with steps("Filtering") as progress:
        progress(0.25)
        progress(0.5)
    out = buf.getvalue()
    assert "50%" in out and "ETA" in out and "Filtering" in out


def test_piped_output_has_no_control_codes_and_unwrapped_paths(data_dir, tmp_path):
    import os
    import shutil

    deep = tmp_path / ("a_rather_long_folder_name_" * 4) / "and_another_level_of_folders"
    deep.mkdir(parents=True)
    src = deep / "a_point_cloud_with_a_long_file_name.laz"
    shutil.copy(data_dir / "samp24-utm.laz", src)
    proc = subprocess.run(
        [sys.executable, "-m", "lidarqa.cli.main", "info", str(src)],
        capture_output=True, text=True, env={**os.environ, "COLUMNS": "40"},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "\x1b" not in proc.stderr and "\r" not in proc.stderr
    assert any(f"Reading {src}" in line for line in proc.stderr.splitlines()), proc.stderr
    assert any(str(src) in line for line in proc.stdout.splitlines())


def test_quiet_shows_nothing(data_dir, tmp_path):
    r = CliRunner().invoke(cli, ["-q", "info", str(data_dir / "samp24-utm.laz")])
    assert r.exit_code == 0 and "✓" not in r.output
