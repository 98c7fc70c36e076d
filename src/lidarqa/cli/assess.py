"""``lidarqa assess CONFIG.toml --out DIR`` and ``lidarqa demo --out DIR``."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import Steps, common_options, echo, finish, prepare_outputs, settings


def _run(
    config_path: str | Path, out: str, command: str, *, skip_unavailable: bool = False
) -> None:
    from ..errors import OutputExistsError
    from ..report.config import load_config
    from ..report.run import check_out_dir, run_assessment

    s = settings()
    steps = Steps()
    # Everything is checked before any work: config (keys, types, inputs, CRSs) and outputs.
    with steps("Checking the configuration"):
        cfg = load_config(config_path, skip_unavailable=skip_unavailable)
    prepare_outputs(inputs=tuple(str(p) for p in cfg.input_paths()))
    try:
        check_out_dir(out, overwrite=s.overwrite)
    except OutputExistsError as exc:  # the library's message also names the Python keyword
        raise OutputExistsError(str(exc).replace(" (overwrite=True)", "")) from None
    if command == "demo" and not s.quiet and not _demo_kernels_cached():
        click.echo(
            "First run: compiling the numeric kernels (about 30-60 s, once; "
            "they are cached for later runs)",
            err=True,
        )
    run = run_assessment(cfg, out, overwrite=s.overwrite, steps=steps, command=command)
    echo(f"{cfg.title}")
    width = max((len(r.analysis) for r in run.summary), default=10)
    for r in run.summary:
        verdict = {"pass": "PASS", "fail": "FAIL", "error": "ERROR", "skipped": "SKIP"}.get(
            r.verdict, ""
        )
        echo(f"  {r.analysis:<{width}}  {verdict:<5}  {r.headline}")
        for caveat in r.caveats:  # what qualifies the verdict goes right under it
            echo(f"  {'':<{width}}  {'':<5}  warning: {caveat}")
    echo(f"Report: {run.html_path}")
    echo(f"JSON:   {run.json_path}")
    doc = run.document
    finish(
        command,
        inputs=doc["inputs"],
        parameters=doc["parameters"],
        results={
            "report_html": str(run.html_path),
            "report_json": str(run.json_path),
            "verdicts": doc["verdicts"],
            "errors": doc["errors"],
            "analyses": doc["results"],
        },
    )
    if run.errors:
        # The report and JSON are complete (they show the failures); scripts still need to know.
        from ..errors import AnalysisError

        raise AnalysisError(
            f"{len(run.errors)} analysis(es) failed: "
            + "; ".join(f"{k}: {v}" for k, v in run.errors.items())
            + f" (details in {run.html_path})"
        )
    failed = [r.analysis for r in run.summary if r.verdict == "fail"]
    if failed:
        # Complete run, report written: exit status 4 lets CI pipelines gate on the targets.
        from ..errors import TargetNotMetError

        raise TargetNotMetError(
            f"{len(failed)} analysis(es) missed their target: {', '.join(failed)} "
            f"(details in {run.html_path})"
        )


def _demo_kernels_cached() -> bool:
    """Whether the compiled kernels the demo needs (ground TIN, kNN, surface growing) are cached."""
    from ..geometry import kernels_cached as geometry_cached
    from ..ground import kernels_cached as ground_cached

    return ground_cached() and geometry_cached()


#: ``-o/--out DIR`` of ``assess`` and ``demo``
_out_option = click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
                           help="Output folder: report.html, report.json and outputs/.")


@click.command()
@click.argument("config", type=click.Path(dir_okay=False))
@_out_option
@common_options
def assess(config: str, out: str) -> None:
    """Run the accuracy assessment described by CONFIG (TOML) and write an HTML report.

    The config names the inputs, the analyses (info, ground, edges, lines,
    checkpoints, heights) and their parameters (same names as the commands'
    options). It is validated completely before any work starts. A minimal
    config:

    \b
        [inputs.clouds]
        tile = "tile.laz"
        [ground]
        cloud = "tile"
        target_total = 0.05

    Every key is listed in the documentation (Reference > Assessment config).
    `lidarqa demo` runs a config that uses every analysis; its report shows
    that config.
    """
    _run(config, out, "assess")


@click.command()
@_out_option
@common_options
def demo(out: str) -> None:
    """Assess the bundled IGN LiDAR HD tile (IGN – LiDAR HD, Licence Ouverte 2.0).

    Runs a bundled config (shown in the report): ground filtering scored
    against IGN's classes, building edges per flight strip and their
    repeatability, height quality against held-apart ground points, and a
    vertical check against points of the other strip.
    """
    from ..report.run import demo_config_path

    _run(demo_config_path(), out, "demo", skip_unavailable=True)
