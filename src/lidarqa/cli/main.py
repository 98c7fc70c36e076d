"""The ``lidarqa`` command group.

Commands are loaded lazily from ``COMMANDS`` (name -> "module:function"), so
``lidarqa --help`` stays fast and one broken optional dependency does not take
the whole CLI down.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import traceback
from typing import Any

import click

from .._version import __version__
from ..errors import LidarQAError, MissingDependencyError
from ._common import Settings, settings

COMMANDS: dict[str, str] = {
    "info": "lidarqa.cli.info:info",
    "polar": "lidarqa.cli.info:polar",
    "ground": "lidarqa.cli.ground:ground",
    "planes": "lidarqa.cli.geometry:planes",
    "edges": "lidarqa.cli.geometry:edges",
    "corners": "lidarqa.cli.geometry:corners",
    "lines": "lidarqa.cli.lines:lines",
    "repeatability": "lidarqa.cli.lines:repeatability",
    "checkpoints": "lidarqa.cli.checkpoints:checkpoints",
    "heights": "lidarqa.cli.heights:heights",
    "roads": "lidarqa.cli.roads:roads",
    "assess": "lidarqa.cli.assess:assess",
    "demo": "lidarqa.cli.assess:demo",
}


def _available(name: str) -> bool:
    module = COMMANDS[name].split(":")[0]
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


class LazyGroup(click.Group):
    """A click group that imports each command on first use and owns error reporting."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(n for n in COMMANDS if _available(n))

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS or not _available(name):
            return None
        module, func = COMMANDS[name].split(":")
        return getattr(importlib.import_module(module), func)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            raise
        except KeyboardInterrupt:
            click.echo("Interrupted; no partial output was left behind.", err=True)
            sys.exit(130)
        except MissingDependencyError as exc:
            _report(ctx, exc, prefix="Error")
            sys.exit(3)
        except LidarQAError as exc:
            _report(ctx, exc, prefix="Error")
            sys.exit(1)
        except MemoryError as exc:
            _report(ctx, exc, prefix="Error: out of memory")
            sys.exit(1)
        except Exception as exc:  # never a traceback unless -v
            _report(ctx, exc, prefix=f"Internal error ({type(exc).__name__})", hint=True)
            sys.exit(2)


def _report(ctx: click.Context, exc: BaseException, *, prefix: str, hint: bool = False) -> None:
    s: Settings = settings(ctx)
    message = " ".join(str(exc).split()) or type(exc).__name__
    line = f"{prefix}: {message}"
    if hint and not s.verbose:
        line += " (run with -v for the traceback; please report it)"
    if s.verbose:
        traceback.print_exception(exc, file=sys.stderr)
    click.echo(line, err=True)


def _show_versions(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    from .. import show_versions

    for k, v in show_versions().items():
        click.echo(f"{k:>12}: {v}")
    ctx.exit()


@click.group(
    cls=LazyGroup,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
)
@click.version_option(__version__, "--version", prog_name="lidarqa")
@click.option(
    "--show-versions",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_show_versions,
    help="Show versions of lidarqa and its dependencies.",
)
@click.option("-q", "--quiet", is_flag=True, help="No progress display.")
@click.option("-v", "--verbose", count=True, help="Show tracebacks on errors.")
@click.pass_context
def cli(ctx: click.Context, quiet: bool, verbose: int) -> None:
    """How accurate is this LiDAR point cloud?

    Ground filtering, planes/edges/corners and accuracy assessment (line
    matching, check points, height quality) for LAS/LAZ point clouds.
    """
    s = settings(ctx)
    s.quiet = s.quiet or quiet
    s.verbose = max(s.verbose, verbose)


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point."""
    cli.main(args=argv, prog_name="lidarqa")


if __name__ == "__main__":  # pragma: no cover
    main()
