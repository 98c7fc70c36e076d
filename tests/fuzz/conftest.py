"""A small valid world for the fuzz suite: every command has a baseline invocation that works.

Each fuzz case replaces ONE input of a baseline invocation by a hostile one, or
points an output somewhere hostile, so the corruption reaches the code that
reads that input (and not only the first argument check).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(scope="session")
def world(tmp_path_factory) -> dict:
    import lidarqa
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, Segments, write_points, write_segments
    from lidarqa.testing import make_scene

    d = tmp_path_factory.mktemp("fuzzworld")
    scene = make_scene(
        seed=5,
        size=(30.0, 30.0),
        density=6.0,
        strips=2,
        n_buildings=1,
        n_trees=1,
        n_cars=0,
        origin=(770000.0, 6277000.0, 0.0),
    )
    cloud = scene.to_cloud()
    cloud.crs = parse_crs("EPSG:2154")
    lidarqa.write(cloud, d / "scene.las")
    lidarqa.write(cloud, d / "scene.laz")
    rng = np.random.default_rng(1)
    ground = scene.points[scene.is_ground]
    lo, hi = ground[:, :2].min(axis=0) + 4, ground[:, :2].max(axis=0) - 4
    xy = rng.uniform(lo, hi, size=(25, 2))
    check = PointSet(ids=np.arange(1, 26), xyz=np.column_stack([xy, scene.ground_z(xy)]))
    write_points(check, d / "check.csv")
    write_points(PointSet(ids=check.ids, xyz=check.xyz + 0.05), d / "measured.csv")
    rxy = rng.uniform(lo, hi, size=(200, 2))
    write_points(
        PointSet(ids=np.arange(200), xyz=np.column_stack([rxy, scene.ground_z(rxy)])),
        d / "reference.csv",
    )
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 4.0), np.arange(lo[1], hi[1], 4.0))
    mxy = np.column_stack([gx.ravel(), gy.ravel()])
    write_points(
        PointSet(ids=np.arange(len(mxy)), xyz=np.column_stack([mxy, np.zeros(len(mxy))])),
        d / "map.csv",
    )
    a = rng.uniform(lo, hi, size=(12, 2))
    start = np.column_stack([a, rng.uniform(3, 9, 12)])
    end = start + np.column_stack([rng.uniform(-6, 6, (12, 2)), rng.uniform(-1, 1, 12)])
    write_segments(Segments(np.arange(12), start, end), d / "model.csv")
    write_segments(Segments(np.arange(12), start + 0.03, end + 0.03), d / "test.csv")
    import pyogrio
    import shapely

    (x0, y0), (x1, y1) = lo, hi
    road = shapely.box(x0, y0, x0 + 0.5 * (x1 - x0), y1)
    pyogrio.raw.write(
        str(d / "roads.gpkg"),
        np.array([shapely.to_wkb(road)], dtype=object),
        geometry_type="Polygon",
        field_data=[np.array([1])],
        fields=["id"],
        crs="EPSG:2154",
        driver="GPKG",
    )
    (d / "obs.csv").write_text("id,distance,azimuth,elevation\n1,10,90,0\n2,10,0,30\n3,5,45,10\n")
    (d / "config.toml").write_text(
        '[inputs.clouds]\ntile = "scene.las"\n'
        '[inputs.points]\ncheck = "check.csv"\n'
        '[info]\ncloud = "tile"\n'
        '[checkpoints]\nmeasured = "tile"\ncheck = "check"\nvertical = true\n',
        encoding="utf-8",
    )
    return {"dir": d, "scene": scene}


@pytest.fixture(scope="session")
def baseline(world):
    """``baseline(out)``: a working invocation of every command (outputs in `out`), by name."""
    return lambda out: _baseline(world, Path(out))


def _baseline(world: dict, out: Path) -> dict[str, list]:
    d = world["dir"]
    return {
        "info": ["info", d / "scene.las"],
        "polar": ["polar", d / "obs.csv", "-o", out / "pts.csv"],
        "ground": ["ground", d / "scene.las", "-o", out / "g.laz"],
        "planes": ["planes", d / "scene.las", "-o", out / "p.csv"],
        "edges": ["edges", d / "scene.las", "-o", out / "e.csv"],
        "corners": ["corners", d / "scene.las", "-o", out / "c.csv"],
        "lines": ["lines", d / "test.csv", d / "model.csv", "--pairs", out / "pairs.csv"],
        "repeatability": ["repeatability", d / "test.csv", d / "model.csv"],
        "checkpoints": ["checkpoints", d / "measured.csv", d / "check.csv", "-o", out / "r.csv"],
        "heights": ["heights", d / "scene.las", d / "map.csv", d / "reference.csv",
                    "-o", out / "h.csv"],
        "assess": ["assess", d / "config.toml", "-o", out / "report"],
        "swaths": ["swaths", d / "scene.las", "--by-source-id", "-o", out / "swaths"],
        "roads": ["roads", d / "scene.las", d / "roads.gpkg", "-o", out / "roads.gpkg"],
        # no input; runs the demo (seconds when warm): its --json output is fuzzed in
        # test_fuzz_outputs.py::test_demo_hostile_outputs, refused before any work
        "warmup": ["warmup", "--json", out / "warmup.json"],
        "qc": ["qc", d / "scene.las", "-o", out / "qc", "--checkpoints", d / "check.csv"],
    }


@pytest.fixture(scope="session", autouse=True)
def _warm_kernels(world) -> None:
    """Compile (or load) the numba kernels once, outside the per-case time limits.

    On a fresh checkout numba's cache is empty and the first ground or segmentation
    call spends 10-30 s compiling: that is not a hang, and must not eat the 10 s
    bound that a hostile case gets.
    """
    import warnings

    import lidarqa.geometry as geo
    import lidarqa.ground as gnd

    pts = world["scene"].points
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method in ("segment-ptd", "ptd"):
            gnd.classify_ground(pts, method=method)
        geo.extract_edges(pts)
