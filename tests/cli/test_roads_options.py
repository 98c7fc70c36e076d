"""Roads are reconstructed in one piece: an option they cannot honour is refused in one line.

``lidarqa heights`` with a road-polygon MAP runs the roads job (``catalog_roads``); it used to
drop the catalog options (--workers, --scheduler, --resume, --chunk-size, --buffer) and the
options of point maps without a word (issue #26).
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.errors import OptionError


@pytest.fixture(scope="module")
def road_scene(tmp_path_factory):
    """A small cloud (EPSG:2154), one road polygon over it and reference points on the ground."""
    pyogrio = pytest.importorskip("pyogrio")
    shapely = pytest.importorskip("shapely")
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, write_points
    from lidarqa.testing import make_scene

    d = tmp_path_factory.mktemp("roads")
    scene = make_scene(seed=5, size=(40.0, 40.0), density=8.0, n_buildings=0, n_trees=0,
                       origin=(770000.0, 6277000.0, 0.0))
    cloud = scene.to_cloud()
    cloud.crs = parse_crs("EPSG:2154")
    lidarqa.write(cloud, d / "cloud.laz")
    xy = np.array([770000.0, 6277000.0]) + np.random.default_rng(5).uniform(10, 30, (10, 2))
    write_points(PointSet(np.arange(10), np.column_stack([xy, scene.ground_z(xy)])),
                 d / "ref.csv")
    road = shapely.box(770005.0, 6277005.0, 770035.0, 6277035.0)
    pyogrio.raw.write(str(d / "roads.gpkg"), np.array([shapely.to_wkb(road)], dtype=object),
                      geometry_type="Polygon", field_data=[np.array([1])], fields=["id"],
                      crs="EPSG:2154", driver="GPKG")
    return d


def _heights(d, *opts):
    args = ["-q", "heights", d / "cloud.laz", d / "roads.gpkg", d / "ref.csv", "--classes", "2",
            "--spacing", "15", *opts]
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.mark.parametrize("opts", [["--workers", "2"], ["--resume"], ["--chunk-size", "20"],
                                  ["--buffer", "5"], ["--workers", "2", "--resume"]])
def test_heights_with_road_polygons_refuses_the_catalog_options(road_scene, opts):
    res = _heights(road_scene, *opts)
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert "roads are reconstructed in one piece" in lines[0]
    assert all(o in lines[0] for o in opts if o.startswith("--")), lines[0]


def test_heights_with_road_polygons_runs_in_this_process_with_one_worker(road_scene, tmp_path):
    # --workers 1 is what the roads do (no Dask): taken, unlike --workers 2
    res = _heights(road_scene, "--workers", "1", "--json", tmp_path / "h.json")
    assert res.exit_code == 0, res.output
    assert _heights(road_scene, "--workers", "2").exit_code == 1


@pytest.mark.parametrize("opts", [["--correlation", "0.5"], ["--eq8"], ["--posterior"],
                                  ["--largest-segment"]])
def test_heights_with_road_polygons_refuses_the_point_map_options(road_scene, opts):
    res = _heights(road_scene, *opts)
    assert res.exit_code == 1, res.output
    assert res.output.strip().count("\n") == 0 and f"{opts[0]}: for a point MAP only" in \
        res.output, res.output


@pytest.mark.parametrize("engine, option", [
    (("tcp://127.0.0.1:9",), "--scheduler"), ((None, 3), "--workers")])
def test_the_roads_job_refuses_an_engine_of_several_workers(road_scene, engine, option):
    """Refused before any connection or work (the engine is not even started)."""
    from lidarqa.tiling import Engine
    from lidarqa.tiling.jobs_api import catalog_roads

    with pytest.raises(OptionError, match=f"in one piece, in this process: {option} cannot"):
        catalog_roads(road_scene / "cloud.laz", road_scene / "roads.gpkg",
                      engine=Engine(*engine))
