"""Shared plumbing of every command: options, JSON document, progress, outputs.

The contract (issue #2): ``lidarqa COMMAND ... [--json PATH]`` writes
``{"lidarqa_version", "command", "inputs", "parameters", "results"}``;
human-readable text goes to stdout, progress to stderr (silenced by ``-q``),
errors become one line on stderr and a non-zero exit.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from .._atomic import atomic_path, check_distinct, check_output
from .._json import to_jsonable
from .._version import __version__

__all__ = [
    "Settings",
    "common_options",
    "settings",
    "to_jsonable",
    "json_document",
    "write_json",
    "prepare_outputs",
    "Steps",
    "echo",
    "fmt_number",
    "parse_int_list",
    "INT_LIST",
    "crs_option",
    "output_option",
    "classes_option",
    "source_id_option",
    "input_crs",
    "target_options",
    "check_targets",
]

#: Suffixes of text outputs that get a ``.prj`` CRS sidecar.
_SIDECAR_SUFFIXES = {".csv", ".txt", ".xyz"}


@dataclass
class Settings:
    quiet: bool = False
    verbose: int = 0
    overwrite: bool = False
    json_path: str | None = None
    # accuracy targets given on the command line: metric -> (results key, limit)
    targets: dict[str, tuple[str, float]] | None = None


def settings(ctx: click.Context | None = None) -> Settings:
    """The merged global and per-command settings of the current invocation."""
    ctx = ctx or click.get_current_context()
    root = ctx.find_root()
    if root.obj is None:
        root.obj = Settings()
    return root.obj


def _merge_flag(name: str) -> Callable[[click.Context, click.Parameter, Any], Any]:
    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        s = settings(ctx)
        if name == "verbose":
            s.verbose = max(s.verbose, int(value or 0))
        elif name == "json_path":
            s.json_path = value
        elif value:
            setattr(s, name, True)
        return value

    return callback


def common_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """Add ``--json PATH``, ``--overwrite``, ``-q`` and ``-v`` to a command.

    The values land in :func:`settings`; the command function does not receive them.
    """

    def setting(*decls: str, name: str, **kwargs: Any) -> Callable[..., Any]:
        return click.option(*decls, expose_value=False, callback=_merge_flag(name), **kwargs)

    opts = [
        setting("--json", "json_path", name="json_path", type=click.Path(dir_okay=False),
                default=None, help="Also write the results as a JSON document to this path."),
        setting("--overwrite", name="overwrite", is_flag=True,
                help="Replace output files that already exist."),
        setting("-q", "--quiet", name="quiet", is_flag=True, help="No progress display."),
        setting("-v", "--verbose", name="verbose", count=True, help="Show tracebacks on errors."),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


CRS_HELP = (
    "CRS of inputs that declare none: an EPSG code (2154 or EPSG:2154), WKT, or a .prj "
    "file. CSV inputs also take it from a .prj file next to them; an input whose own "
    "CRS differs is an error."
)


def crs_option(func: Callable[..., Any]) -> Callable[..., Any]:
    """``--crs CRS``: the CRS of inputs that declare none (see :func:`input_crs`)."""
    return click.option("--crs", "crs", default=None, metavar="CRS", help=CRS_HELP)(func)


def output_option(help: str, *, required: bool = False) -> Callable[..., Any]:
    """``-o/--output FILE``: the file a command writes, with the command's own help text.

    Required, or None when not given.
    """
    given: dict[str, Any] = {"required": True} if required else {"default": None}
    return click.option("-o", "--output", type=click.Path(dir_okay=False), help=help, **given)


def classes_option(func: Callable[..., Any] | None = None, /, *, default: str | None = None,
                   help: str = "Use only points of these LAS classes (e.g. 6 for buildings, 2,6)."
                   ) -> Callable[..., Any]:
    """``--classes INT[,INT...]``: use only points of these LAS classes.

    ``@classes_option``, or ``@classes_option(help=..., default=...)`` with a command's own
    help text and default.
    """
    if func is None:
        return lambda f: classes_option(f, default=default, help=help)
    return click.option("--classes", type=INT_LIST, default=default,
                        show_default=default is not None, help=help)(func)


def source_id_option(func: Callable[..., Any]) -> Callable[..., Any]:
    """``--source-id INT[,INT...]``: use only points of these flight strips."""
    return click.option(
        "--source-id",
        "source_id",
        type=INT_LIST,
        default=None,
        help="Use only points of these flight strips / passes (LAS point_source_id).",
    )(func)


def input_crs(value: str | None) -> Any:
    """The pyproj CRS of ``--crs`` (None when not given); a bad value is an OptionError."""
    from ..io.crs import parse_crs

    return parse_crs(value)


def target_options(**metrics: tuple[str, str]) -> Callable[[Callable[..., Any]], Any]:
    """Add ``--target-METRIC LIMIT`` options (upper limits, in the results' units).

    ``metrics`` maps a metric name to ``(results key, description)``. The limits
    land in :func:`settings`; :func:`finish` checks them against the results,
    records the verdicts in the JSON document, and ends the command with
    :class:`~lidarqa.errors.TargetNotMetError` (exit status 4) when one is missed.
    """

    def store(metric: str, key: str) -> Callable[[click.Context, click.Parameter, Any], Any]:
        def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
            if value is not None:
                if not (value >= 0 and math.isfinite(value)):
                    raise click.BadParameter(f"must be a finite number >= 0, got {value}")
                s = settings(ctx)
                s.targets = {**(s.targets or {}), metric: (key, float(value))}
            return value

        return callback

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        for metric, (key, what) in reversed(list(metrics.items())):
            func = click.option(
                f"--target-{metric.replace('_', '-')}",
                type=float,
                default=None,
                expose_value=False,
                callback=store(metric, key),
                help=f"Pass only if {what} is at most this (exit status 4 otherwise).",
            )(func)
        return func

    return decorate


def check_targets(results: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Verdicts of the command-line targets against `results` (see :func:`target_options`)."""
    from ..errors import NothingToMeasureError

    out = []
    for metric, (key, limit) in (settings().targets or {}).items():
        value: Any = results.get(key)
        try:
            v = abs(float(value))
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v):
            raise NothingToMeasureError(f"target {metric}: {key} could not be computed")
        out.append({"metric": metric, "value": v, "target": limit, "passed": v <= limit})
    return out


def parse_int_list(value: str | None) -> list[int] | None:
    """Parse ``"1,7,9"`` into ``[1, 7, 9]`` (None stays None)."""
    if value is None or value == "":
        return None
    out = []
    for token in str(value).split(","):
        token = token.strip()
        if not token:
            continue
        try:
            out.append(int(token))
        except ValueError:
            raise click.BadParameter(f"expected comma-separated integers, got {value!r}") from None
    return out


class _IntList(click.ParamType):
    name = "INT[,INT...]"

    def convert(self, value: Any, param: Any, ctx: Any) -> list[int] | None:
        if isinstance(value, list):
            return value
        return parse_int_list(value)


INT_LIST = _IntList()


def json_document(command: str, inputs: Any, parameters: Mapping[str, Any], results: Any) -> dict:
    """The JSON document every command writes with ``--json``."""
    return {
        "lidarqa_version": __version__,
        "command": command,
        "inputs": to_jsonable(inputs),
        "parameters": to_jsonable(dict(parameters)),
        "results": to_jsonable(results),
    }


def write_json(doc: Any, path: str | Path, *, overwrite: bool = False) -> Path:
    """Write a JSON document atomically (strict JSON: no NaN)."""
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_text(
            json.dumps(to_jsonable(doc), indent=2, allow_nan=False) + "\n", encoding="utf-8"
        )
    return Path(path)


def prepare_outputs(*outputs: str | Path | None, inputs: tuple = ()) -> None:
    """Check every output (and the ``--json`` path) before any work starts.

    Refuses an existing output without ``--overwrite`` and an output that is an input.
    """
    from ..errors import OutputExistsError

    s = settings()
    for out in (*outputs, s.json_path):
        if out is None:
            continue
        paths = [Path(out)]
        if Path(out).suffix.lower() in _SIDECAR_SUFFIXES and not Path(out).exists():
            paths.append(Path(out).with_suffix(".prj"))  # its CRS sidecar
        for p in paths:
            try:
                check_output(p, overwrite=s.overwrite)
            except OutputExistsError:
                what = "" if p == Path(out) else f" (the CRS file of {Path(out).name})"
                raise OutputExistsError(
                    f"output {p}{what} exists; add --overwrite to replace it"
                ) from None
        check_distinct(out, *[i for i in inputs if i is not None])


def finish(command: str, *, inputs: Any, parameters: Mapping[str, Any], results: Any) -> dict:
    """Write the ``--json`` document if asked; return it."""
    s = settings()
    verdicts = check_targets(results) if s.targets and isinstance(results, Mapping) else []
    if verdicts:
        results = {**results, "targets": verdicts}
    doc = json_document(command, inputs, parameters, results)
    if s.json_path:
        write_json(doc, s.json_path, overwrite=s.overwrite)
    failed = [v for v in verdicts if not v["passed"]]
    for v in verdicts:
        echo(
            f"target {v['metric']:<8} {fmt_number(v['value'], 4)} <= {fmt_number(v['target'], 4)}"
            f"  {'PASS' if v['passed'] else 'FAIL'}"
        )
    if failed:
        from ..errors import TargetNotMetError

        raise TargetNotMetError(
            ", ".join(f"{v['metric']} {v['value']:.4g} > {v['target']:.4g}" for v in failed)
        )
    return doc


def fmt_number(value: Any, digits: int = 3, missing: str = "n/a") -> str:
    """Format a number for human output; None, NaN and inf become `missing`."""
    if value is None:
        return missing
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f"{v:.{digits}f}" if math.isfinite(v) else missing


def echo(text: str = "") -> None:
    """Human-readable output on stdout."""
    click.echo(text)


def echo_tables(*tables: Any) -> None:
    """Print report tables (:class:`lidarqa.report.html.Table`) as the command's summary.

    A command shows the figures its report section shows, built by the same function:
    chosen, labelled and formatted once.
    """
    from ..report.html import table_text

    for t in tables:
        echo(table_text(t))


def _no_progress(fraction: float) -> None:
    """The progress callback of a step that shows nothing."""


class Steps:
    """Progress display for the steps of a long command (rich, on stderr).

    ``with steps("Reading input") as progress:`` shows the step while it runs
    and a tick with its duration afterwards; nothing is shown with ``-q``.
    `progress` is a callback for the kernels' ``progress=`` keyword: once the
    kernel reports a fraction, the spinner becomes a bar with percentage,
    elapsed time and ETA. When stderr is not a terminal (piped, redirected,
    CI logs) there is no live display and no control code: one plain line per
    finished step, never wrapped.
    """

    def __init__(self, quiet: bool | None = None, console: Any = None) -> None:
        if quiet is None:
            try:
                quiet = settings().quiet
            except RuntimeError:
                quiet = True
        self.quiet = quiet
        self._console = None
        if not quiet:
            from rich.console import Console

            self._console = console or Console(stderr=True, soft_wrap=True, highlight=False)

    @property
    def live(self) -> bool:
        """True when progress is drawn live (stderr is an interactive terminal)."""
        c = self._console
        return c is not None and c.is_terminal and not c.is_dumb_terminal

    def _done(self, description: str, seconds: float) -> None:
        from rich.markup import escape
        from rich.text import Text

        assert self._console is not None
        if self.live:
            self._console.print(
                f"[green]✓[/green] {escape(description)} [dim]({seconds:.1f} s)[/dim]"
            )
        else:
            self._console.print(Text(f"✓ {description} ({seconds:.1f} s)"), soft_wrap=True)

    @contextlib.contextmanager
    def __call__(self, description: str) -> Iterator[Callable[[float], None]]:
        if self._console is None:
            yield _no_progress
            return
        t0 = time.perf_counter()
        if not self.live:
            yield _no_progress
            self._done(description, time.perf_counter() - t0)
            return
        from rich.progress import (
            BarColumn,
            Progress,
            SpinnerColumn,
            TaskProgressColumn,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        bar = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}", markup=False),
            BarColumn(bar_width=24),
            TaskProgressColumn(),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=self._console,
            transient=True,
        )
        with bar:
            task = bar.add_task(description, total=None)

            def update(fraction: float) -> None:
                f = min(1.0, max(0.0, float(fraction)))
                bar.update(task, total=1.0, completed=f, refresh=True)

            yield update
        self._done(description, time.perf_counter() - t0)
