"""The unit policy and the option set, walked over every command (issue #16).

Every command runs once on a small synthetic scene with ``--json``; every number
in every JSON document must have a unit in :mod:`lidarqa.units`. Every command's
``--help`` is read: shared options are present where they make sense, every
decimal option states its unit, and nothing speaks Python to a CLI user.
"""

from __future__ import annotations

import json
import re

import click
import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import COMMANDS, cli
from lidarqa.units import undefined_units

#: Commands that run a configured assessment (their inputs and CRS come from the config).
CONFIG_COMMANDS = {"assess", "demo"}
#: Commands without inputs (their JSON document is checked in their own test file).
NO_INPUTS = {"warmup"}
#: Commands that select points of a cloud by class and flight strip.
SELECTING = {"planes", "edges", "corners", "heights", "checkpoints", "repeatability", "lines"}
COMMON = {"--json", "--overwrite", "--quiet", "--verbose"}
UNIT_WORDS = re.compile(
    r"\((m|m²|degrees|1/m²?|dimensionless|0\.\.1|in --angle-unit)[),;]"
    r"|, (m|degrees|m²)\b|\b(metres|degrees)\b"
)


def _commands() -> dict[str, click.Command]:
    ctx = click.Context(cli)
    return {name: cli.get_command(ctx, name) for name in sorted(COMMANDS)}


def _long_opts(cmd: click.Command) -> set[str]:
    return {o for p in cmd.params if isinstance(p, click.Option) for o in p.opts if o[:2] == "--"}


@pytest.fixture(scope="module")
def documents(tmp_path_factory) -> dict[str, dict]:
    """One JSON document per command (and per mode of checkpoints)."""
    from lidarqa.io.crs import parse_crs
    from lidarqa.io.vector import PointSet, write_points
    from lidarqa.testing import make_scene

    d = tmp_path_factory.mktemp("units")
    scene = make_scene(
        seed=3, size=(40.0, 40.0), density=10.0, strips=2, n_buildings=2, n_trees=2, n_cars=1,
        origin=(770000.0, 6277000.0, 0.0),
    )  # fmt: skip
    cloud = scene.to_cloud()
    cloud.crs = parse_crs("EPSG:2154")
    laz = d / "scene.laz"
    lidarqa.write(cloud, laz)
    rng = np.random.default_rng(7)
    g = scene.points[scene.is_ground]
    lo, hi = g[:, :2].min(0) + 5, g[:, :2].max(0) - 5
    xy = rng.uniform(lo, hi, (30, 2))
    chk = np.column_stack([xy, scene.ground_z(xy)])
    ids = np.array([f"C{i}" for i in range(30)])
    write_points(PointSet(ids, chk), d / "check.csv")
    shifted = chk + [0.1, -0.05, 0.02] + rng.normal(0, 0.01, chk.shape)
    write_points(PointSet(ids, shifted), d / "measured.csv")
    write_points(PointSet(np.arange(30), np.column_stack([xy, np.zeros(30)])), d / "map.csv")
    (d / "obs.csv").write_text("id,distance,azimuth,elevation\n1,10,90,0\n2,10,0,30\n")
    import pyogrio
    import shapely

    road = shapely.box(lo[0], lo[1], lo[0] + 0.5 * (hi[0] - lo[0]), hi[1])
    pyogrio.raw.write(
        str(d / "roads.gpkg"), np.array([shapely.to_wkb(road)], dtype=object),
        geometry_type="Polygon", field_data=[np.array([1])], fields=["id"],
        crs="EPSG:2154", driver="GPKG",
    )  # fmt: skip
    runs = {
        "info": ["info", laz],
        "polar": ["polar", d / "obs.csv", "-o", d / "pol.csv", "--station", "1,2,3"],
        "ground": ["ground", laz, "-o", d / "g.laz", "--evaluate"],
        "planes": ["planes", laz, "-o", d / "planes.csv", "--classes", "6"],
        "edges": ["edges", laz, "-o", d / "edges.csv", "--classes", "6"],
        "corners": ["corners", laz, "-o", d / "corners.csv", "--classes", "6,2"],
        "lines": ["lines", laz, laz, "--classes", "6", "--test-source-id", "1",
                  "--model-source-id", "2"],
        "repeatability": ["repeatability", laz, "--by-source-id", "--classes", "6"],
        "checkpoints": ["checkpoints", d / "measured.csv", d / "check.csv", "--transform",
                        "helmert", "--control-ids", "C0,C1,C2,C3,C4"],
        "checkpoints-vertical": ["checkpoints", laz, d / "check.csv", "--vertical",
                                 "--source-id", "1"],
        "heights": ["heights", laz, d / "map.csv", d / "check.csv", "--classes", "2"],
        "swaths": ["swaths", laz, "--by-source-id", "-o", d / "swaths"],
        "roads": ["roads", laz, d / "roads.gpkg", "-o", d / "roads3d.gpkg", "--classes", "2"],
        "qc": ["qc", laz, "-o", d / "qc", "--checkpoints", d / "check.csv",
               "--relative-accuracy", "--ground-consistency"],
    }  # fmt: skip
    docs = {}
    for name, args in runs.items():
        js = d / f"{name}.json"
        r = CliRunner().invoke(cli, ["-q", *map(str, args), "--json", str(js)])
        # qc exits 4 when a tile fails the spec (this scene is no USGS delivery)
        assert r.exit_code == (4 if name == "qc" else 0), (name, r.output)
        docs[name] = json.loads(js.read_text())
    return docs


def _document_units(doc: dict) -> list[str]:
    return undefined_units({k: v for k, v in doc.items() if k != "lidarqa_version"})


def test_every_command_has_a_document(documents):
    covered = {name.split("-")[0] for name in documents}
    # a new command must be added here
    assert covered == set(COMMANDS) - CONFIG_COMMANDS - NO_INPUTS


@pytest.mark.parametrize(
    "name",
    ["info", "polar", "ground", "planes", "edges", "corners", "lines", "repeatability",
     "checkpoints", "checkpoints-vertical", "heights", "swaths", "roads", "qc"],
)  # fmt: skip
def test_every_number_in_every_document_has_a_unit(documents, name):
    doc = documents[name]
    assert set(doc) == {"lidarqa_version", "command", "inputs", "parameters", "results"}
    missing = _document_units(doc)
    assert missing == [], "\n".join(missing)


def test_the_walk_catches_a_number_without_unit():
    assert _document_units({"results": {"wobble": 1.0, "rmse_z": 0.1}}) == ["/results/wobble"]


def test_helmert_document_reports_the_centroid(documents):
    t = documents["checkpoints"]["results"]["transform"]
    assert set(t["origin"]) == {"x", "y", "z"}
    # about the centroid: the translation is the few-cm shift, not kilometres
    assert max(abs(t["params"][k]) for k in ("tx", "ty", "tz")) < 1.0
    assert max(t["sigmas"][k] for k in ("tx", "ty", "tz")) < 0.05


def test_help_of_every_command_and_the_option_set():
    for name, cmd in _commands().items():
        r = CliRunner().invoke(cli, [name, "--help"])
        assert r.exit_code == 0, name
        text = r.output
        opts = _long_opts(cmd)
        assert COMMON <= opts, (name, COMMON - opts)
        if name not in CONFIG_COMMANDS | NO_INPUTS:
            assert "--crs" in opts, name
        if name in SELECTING:
            assert "--classes" in opts, name
            assert "--source-id" in opts or {"--test-source-id", "--model-source-id"} <= opts, name
        # CLI terms, not Python
        assert not re.search(r"=True|=False|\bNone\b|overwrite=", text), (name, text)
        for p in cmd.params:
            if isinstance(p, click.Option) and isinstance(p.type, click.types.FloatParamType):
                assert p.help and UNIT_WORDS.search(p.help), (name, p.opts, p.help)


def test_same_option_same_meaning_everywhere():
    """An option name used by several commands has one help text (modulo command context)."""
    seen: dict[str, set[str]] = {}
    for cmd in _commands().values():
        for p in cmd.params:
            shared = ("--crs", "--source-id", "--overwrite")
            if isinstance(p, click.Option) and p.opts[-1] in shared:
                seen.setdefault(p.opts[-1], set()).add(p.type.name)
    assert all(len(types) == 1 for types in seen.values()), seen
