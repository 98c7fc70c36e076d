"""lidarqa.open_source: one source for a file and a catalog (issue #26)."""

from __future__ import annotations

import numpy as np
import pytest

import lidarqa
from lidarqa.errors import CRSMismatchError, NothingToMeasureError
from lidarqa.io import PointCloud
from lidarqa.tiling.apply import apply
from lidarqa.tiling.source import Selection, is_catalog_input, open_source, sample_points


def _sorted(xyz: np.ndarray) -> np.ndarray:
    return xyz[np.lexsort(xyz.T[::-1])]


def test_a_folder_and_its_tiles_read_the_same_points_with_the_selection(scene_tiles):
    scene, paths = scene_tiles
    folder = paths[0].parent
    a = open_source(folder, classes=[2], source_id=[1]).read()
    b = open_source(paths, classes=[2], source_id=[1]).read()
    sel = (scene.classification == 2) & (scene.fields["point_source_id"] == 1)
    assert len(a) == len(b) == int(sel.sum()) > 100
    assert np.array_equal(_sorted(a.xyz), _sorted(b.xyz))
    assert set(np.unique(a.classification)) == {2}


def test_the_selection_is_applied_to_every_chunk(scene_tiles):
    _, paths = scene_tiles
    src = open_source(paths, classes=[6])
    run = apply(src, lambda d: (int(d.core.sum()), set(np.unique(d.cloud.classification))),
                lambda parts: parts, chunk_size=40.0, buffer=5.0)
    assert len(run.chunks) >= 9
    assert sum(n for n, _ in run.value) == len(src.read())  # each selected point once
    assert all(c <= {6} for _, c in run.value)


def test_a_single_file_is_one_region(scene_tiles, tmp_path):
    _, paths = scene_tiles
    src = open_source(paths[0])
    assert not src.is_catalog and is_catalog_input([str(p) for p in paths])
    run = apply(src, lambda d: int(d.core.sum()), sum)
    assert len(run.chunks) == 1 and run.value == len(lidarqa.read(paths[0]))


def test_heights_in_feet_are_read_in_metres(tmp_path):
    xyz = np.array([[0.0, 0.0, 100.0], [1.0, 0.0, 200.0], [0.0, 1.0, 300.0]])
    crs = lidarqa.io.crs.parse_crs("EPSG:26915+6360")  # NAVD88 height in US survey feet
    lidarqa.write(PointCloud(xyz, {"classification": np.full(3, 2, np.uint8)}, crs=crs),
                  tmp_path / "ft.laz")
    src = open_source(tmp_path / "ft.laz")
    assert src.z_factor == pytest.approx(1200 / 3937)
    got = src.read().xyz[:, 2]
    assert np.allclose(got, xyz[:, 2] * 1200 / 3937, atol=1e-3)
    assert open_source(tmp_path / "ft.laz", z_to_metres=False).read().xyz[0, 2] == 100.0


def test_a_crs_that_contradicts_the_files_is_refused(scene_tiles):
    _, paths = scene_tiles
    with pytest.raises(CRSMismatchError, match="--crs"):
        open_source(paths, crs="EPSG:32631")


def test_an_empty_selection_is_nothing_to_measure(scene_tiles):
    _, paths = scene_tiles
    with pytest.raises(NothingToMeasureError, match="source ids 999"):
        open_source(paths, source_id=[999]).read()


def test_the_sample_window_does_not_depend_on_the_tiling(scene_tiles):
    scene, paths = scene_tiles
    src = open_source(paths, classes=[6])
    got = src.sample(side=30.0).xyz
    whole = np.round(np.asarray(scene.points)[scene.classification == 6], 3)
    ref = sample_points(whole, src.area_bounds, side=30.0)
    assert len(got) == len(ref) > 0
    assert np.allclose(_sorted(got), _sorted(ref), atol=1e-6)


def test_selection_describes_itself():
    assert Selection([6, 2], 706).describe() == "classes 2,6 and source ids 706"
    assert Selection([6, 2], 706).label("a.laz") == "a.laz (classes 2,6 and source ids 706)"
    assert Selection().describe() == "" and Selection().label("a.laz") == "a.laz"
    assert not Selection() and Selection(classes=[2])


@pytest.mark.parametrize("command", ["planes", "lines", "report", "source"])
def test_every_selection_is_worded_by_the_selection(command, scene_tiles, tmp_path):
    """Regression (issue #26): the lines summary, the planes/edges/corners message, the
    source's message and the report's labels each worded a selection their own way."""
    from click.testing import CliRunner

    from lidarqa.cli.main import cli
    from lidarqa.report._context import selection_label

    _, paths = scene_tiles
    folder = paths[0].parent
    sel = Selection(classes=[6], source_id=[999])
    if command == "report":
        assert selection_label("block", [6], 999) == sel.label("block")
        return
    if command == "source":
        with pytest.raises(NothingToMeasureError) as err:
            open_source(paths, classes=[6], source_id=[999]).read()
        assert str(err.value).endswith(f"has no points with {sel.describe()}")
        return
    args = {"planes": ["planes", folder, "-o", tmp_path / "p.csv", "--source-id", "999"],
            "lines": ["lines", folder, folder, "--test-source-id", "999"]}[command]
    r = CliRunner().invoke(cli, ["-q", *map(str, args), "--classes", "6", "--workers", "1"])
    assert r.exit_code == 1, r.output
    said = {"planes": f"{folder}: 0 point(s) with {sel.describe()}; at least 3 are needed",
            "lines": f"test {sel.label(str(folder))}: no edges found"}[command]
    assert said in r.output, r.output
