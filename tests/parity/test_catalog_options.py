"""Every option of every command has a catalog path (issue #26): a new option fails here until
its catalog path honours it (or refuses it with one clear line) and it is listed below.

A command's options are what its file path takes; a catalog input (a folder, several files, a
glob, a ``.vpc``) must give them the same meaning. ``HONOURED`` lists the options the catalog
path takes (checked by the parity tests of tests/parity, tests/tiling and below), ``REFUSED``
those it refuses with an error (they need the whole set in memory), ``NO_CATALOG`` the commands
that take no cloud input.
"""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from lidarqa.cli.main import COMMANDS, cli

# shared by every command: the --json record, outputs, verbosity, the catalog engine
COMMON = {"json_path", "overwrite", "quiet", "verbose", "chunk_size", "buffer", "workers",
          "scheduler", "skip_bad", "resume", "crs"}
_SEGMENT = {"paths", "output", "classes", "source_id", "grow_radius", "grow_dist", "seed_method",
            "min_segment_size", "max_rmse"}
_MATCH = {"weight", "sensitivity", "threshold", "rotate", "denominator", "classes"}
_HEIGHTS = {"map_path", "output", "classes", "spacing", "radius", "max_radius", "min_points",
            "sigma_point", "sigma_gps", "sigma_ins", "sigma_strip", "curvature"}
HONOURED: dict[str, set[str]] = {
    "info": {"paths", "strips", "headers"},
    "ground": {"paths", "output", "method", "preset", "sensor", "cell_size", "max_terrain_angle",
               "iter_angle", "iter_distance", "min_edge_length", "no_mirror", "accept_ratio",
               "orientation_thr", "scatter_thr", "grow_radius", "filter_density", "all_returns",
               "exclude_classes", "evaluate", "ignore_classes"},
    "planes": _SEGMENT,
    "edges": _SEGMENT | {"near_dist", "min_angle", "min_length"},
    "corners": _SEGMENT | {"max_dist", "min_angle", "min_det"},
    "checkpoints": {"measured", "check", "vertical", "classes", "source_id", "max_edge",
                    "checkpoint_rmse_v", "output"},
    "heights": _HEIGHTS | {"cloud", "reference", "source_id", "sigma_ref", "alpha",
                           "estimate_offset", "correlation", "eq8_diagonal", "posterior"},
    "roads": _HEIGHTS | {"cloud", "max_shift", "min_area", "shift", "tolerance"},
    "lines": _MATCH | {"test", "model", "test_source_id", "model_source_id", "ground_truth",
                       "matrix", "pairs_out"},
    "repeatability": _MATCH | {"files", "by_source_id", "source_id", "pool", "step_edges",
                               "auto"},
    "swaths": {"files", "by_source_id", "classes", "all_returns", "cell_size", "min_points",
               "range_cell", "max_roughness", "max_slope", "quality_level", "no_offsets",
               "rotations", "reference_strip", "out_dir", "no_maps", "crs_option"},
    "assess": {"config", "out"},  # every analysis runs on a catalog (tests/report)
    "qc": {"paths", "out", "spec", "checkpoints", "checkpoint_rmse_v", "reference",
           "reference_tolerance", "land_cover", "exclude", "relative_accuracy",
           "ground_consistency"},  # qc reads deliveries: a catalog is its input
}
# options a catalog refuses with a one-line error
REFUSED: dict[str, set[str]] = {
    "checkpoints": {"transform", "control_ids", "control_file", "match", "max_distance",
                    "checkpoint_rmse_h"},
    "heights": {"largest_segment"},
    "repeatability": {"outlines", "shared_threshold"},
}
NO_CATALOG = {"demo", "polar", "warmup"}


def test_every_command_is_listed():
    assert set(COMMANDS) == set(HONOURED) | NO_CATALOG


@pytest.mark.parametrize("name", sorted(HONOURED))
def test_every_option_of_a_command_has_a_catalog_path(name):
    cmd = cli.get_command(None, name)
    params = {p.name for p in cmd.params}
    target = {p for p in params if p.startswith("target_")}  # checked by finish() on both
    unknown = params - HONOURED[name] - REFUSED.get(name, set()) - COMMON - target
    assert not unknown, f"{name}: options with no catalog path: {sorted(unknown)}"
    stale = (HONOURED[name] | REFUSED.get(name, set())) - params
    assert not stale, f"{name}: listed options it no longer has: {sorted(stale)}"


def _run(*args: object) -> object:
    return CliRunner().invoke(cli, ["-q", *[str(a) for a in args]])


@pytest.fixture(scope="module")
def no_crs_tiles(tmp_path_factory: pytest.TempPathFactory):
    """Two tiles that declare no CRS, and one that declares EPSG:2154."""
    from lidarqa.testing import make_scene, write_tiles

    scene = make_scene(seed=1, size=(40.0, 20.0), density=1.0, origin=(0.0, 0.0, 10.0))
    folder = tmp_path_factory.mktemp("nocrs")
    write_tiles(scene, folder / "none", tile_size=20.0, crs=None)
    write_tiles(scene, folder / "l93", tile_size=20.0, crs="EPSG:2154")
    return folder


@pytest.mark.parametrize("command", ["info", "ground"])
def test_crs_is_honoured_on_a_catalog(command, no_crs_tiles, tmp_path):
    """Regression: info and ground on a catalog dropped --crs (a contradicting --crs passed
    silently; tiles without a CRS were reported without the given one)."""
    import json

    args = ["-o", tmp_path / "out", "--workers", "1"] if command == "ground" else []
    res = _run(command, no_crs_tiles / "l93", *args, "--crs", "EPSG:32631")
    assert res.exit_code == 1 and "--crs" in res.output, res.output
    if command == "info":
        res = _run("info", no_crs_tiles / "none", "--crs", "EPSG:2154", "--json",
                   tmp_path / "i.json")
        assert res.exit_code == 0, res.output
        assert json.loads((tmp_path / "i.json").read_text())["results"]["crs_epsg"] == 2154
