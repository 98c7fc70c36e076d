"""Every command, with one input replaced by a hostile file: one clean line, no hang, no debris."""

from __future__ import annotations

import shutil

import pytest
from hostile import (
    SPECIAL_KINDS,
    TIME_LIMIT,
    make_special,
    run_cli,
    text_cases,
    toml_cases,
)

pytestmark = pytest.mark.fuzz

COMMANDS = [
    "info", "polar", "ground", "planes", "edges", "corners", "lines", "repeatability",
    "checkpoints", "heights", "assess", "swaths", "roads", "qc",
]


def test_every_command_is_covered(world, baseline, tmp_path):
    """New commands must get a baseline here (and so enter the fuzz suite)."""
    import click

    from lidarqa.cli.main import cli

    # demo has no inputs; its outputs: test_fuzz_outputs.py::test_demo_hostile_outputs
    listed = set(cli.list_commands(click.Context(cli))) - {"demo"}
    assert listed <= set(baseline(tmp_path)), listed - set(baseline(tmp_path))


@pytest.mark.parametrize("command", COMMANDS)
def test_baseline_works(command, baseline, tmp_path):
    r = run_cli(["-q", *baseline(tmp_path)[command]], out_dir=tmp_path)
    # the scene is no USGS delivery (no return numbers, no WKT): qc's documented exit 4
    assert r.exit_code == (4 if command == "qc" else 0), r.output


def _input_slots(argv):
    """Indices of the input files of an invocation (existing paths before any option)."""
    from pathlib import Path

    return [i for i, a in enumerate(argv) if isinstance(a, Path) and a.exists()]


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("kind", SPECIAL_KINDS)
def test_special_files_as_inputs(command, kind, baseline, tmp_path):
    out = tmp_path / "out"
    argv = baseline(out)[command]
    for slot in _input_slots(argv):
        bad = make_special(kind, tmp_path / f"in{slot}", argv[slot])
        case = list(argv)
        case[slot] = bad
        r = run_cli(["-q", *case], out_dir=out)
        # a cut text table may still be a valid one; an empty reference file is documented
        # for `heights` (precision only, no test)
        if kind not in ("truncated", "header-only", "empty"):
            assert r.exit_code != 0, r.output


@pytest.mark.parametrize("name", sorted(text_cases()))
@pytest.mark.parametrize("command", ["polar", "lines", "checkpoints", "heights", "info"])
def test_bad_tables(command, name, baseline, tmp_path):
    out = tmp_path / "out"
    argv = baseline(out)[command]
    data = text_cases()[name]
    for slot in _input_slots(argv):
        p = tmp_path / f"in{slot}" / ("t" + (argv[slot].suffix if argv[slot].suffix != ".las"
                                             else ".csv"))
        p.parent.mkdir()
        p.write_bytes(data)
        case = list(argv)
        case[slot] = p
        run_cli(["-q", *case], out_dir=out)


@pytest.mark.parametrize("name", sorted(toml_cases()))
def test_bad_configs(name, world, tmp_path):
    for f in ("scene.las", "check.csv"):
        shutil.copy(world["dir"] / f, tmp_path / f)
    cfg = tmp_path / "config.toml"
    cfg.write_bytes(toml_cases()[name])
    r = run_cli(["-q", "assess", cfg, "-o", tmp_path / "out" / "report"], out_dir=tmp_path / "out")
    assert r.exit_code == 1, r.output


@pytest.mark.parametrize(
    "target,expected",
    [("target_rmse_z = 10.0", 0), ("target_rmse_z = 0.0001", 4), ("", 0)],
)
def test_assess_exit_status_follows_targets(target, expected, world, tmp_path):
    for f in ("scene.las", "check.csv"):
        shutil.copy(world["dir"] / f, tmp_path / f)
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        '[inputs.clouds]\ntile = "scene.las"\n[inputs.points]\ncheck = "check.csv"\n'
        f'[checkpoints]\nmeasured = "tile"\ncheck = "check"\nvertical = true\n{target}\n'
    )
    out = tmp_path / "out"
    r = run_cli(["-q", "assess", cfg, "-o", out / "r"], out_dir=out)
    assert r.exit_code == expected, r.output
    assert (out / "r" / "report.html").is_file()


def test_assess_nothing_to_measure_is_an_error_verdict(world, tmp_path):
    shutil.copy(world["dir"] / "scene.las", tmp_path / "scene.las")
    (tmp_path / "far.csv").write_text("id,x,y,z\n1,0,0,0\n2,1,1,1\n3,2,0,1\n")
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        '[inputs.clouds]\ntile = "scene.las"\n[inputs.points]\ncheck = "far.csv"\n'
        '[checkpoints]\nmeasured = "tile"\ncheck = "check"\nvertical = true\n'
        "target_rmse_z = 0.1\n"
    )
    out = tmp_path / "out"
    r = run_cli(["-q", "assess", cfg, "-o", out / "r"], out_dir=out)
    assert r.exit_code == 1 and "none of the 3 check point(s)" in r.stderr, r.output
    assert "nan" not in r.output.lower()


def _numeric_options(command: str) -> list[str]:
    import click

    from lidarqa.cli.main import cli

    cmd = cli.get_command(click.Context(cli), command)
    return sorted(
        p.opts[-1] for p in cmd.params
        if isinstance(p, click.Option) and not p.is_flag and not p.count
        and isinstance(p.type, click.types.FloatParamType | click.types.IntParamType)
    )


BAD_NUMBERS = ["nan", "inf", "-inf", "-1", "0", "1e308", "1e-300", "99999999999999999999", "x"]
# A valid catalog option (e.g. --buffer 0 or 1e-300) runs the job on a local Dask cluster: starting
# its worker processes takes seconds, more on a loaded machine. That is not a hang.
CATALOG_OPTIONS = {"--chunk-size", "--buffer", "--workers"}
CLUSTER_TIME_LIMIT = 60.0
# every numeric option of every command with an input, each bad value: ~860 cases, ~1 min on
# two processes. Exhaustive rather than sampled: a sample of 120 let `--min-edge-length
# 1e-300` (an int64 overflow, then a segfault) through for several runs.
NUMERIC_CASES = [
    (command, opt, value)
    for command in COMMANDS
    for opt in _numeric_options(command)
    for value in BAD_NUMBERS
]


@pytest.mark.parametrize("command,opt,value", NUMERIC_CASES)
def test_bad_numeric_options(command, opt, value, baseline, tmp_path):
    """Any numeric option of any command set to NaN, inf, 0, negative, huge or tiny."""
    out = tmp_path / "opt"
    limit = CLUSTER_TIME_LIMIT if opt in CATALOG_OPTIONS else TIME_LIMIT
    run_cli(["-q", *baseline(out)[command], opt, value], out_dir=out, limit=limit)
