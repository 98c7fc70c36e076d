"""The ``lidarqa`` command group.

Commands are loaded lazily from ``COMMANDS`` (name -> "module:function"), so
``lidarqa --help`` stays fast and one broken optional dependency does not take
the whole CLI down.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import sys
import traceback
from collections.abc import Iterator
from typing import Any

import click

from .._version import __version__
from ..errors import LidarQAError, LidarQAWarning, MissingDependencyError, TargetNotMetError
from ._common import Settings, settings

# Exit statuses (documented in README.md and ``lidarqa --help``).
EXIT_OK = 0  # success; every target met
EXIT_ERROR = 1  # a clear error: bad input, bad option value, unwritable output, nothing to measure
EXIT_INTERNAL = 2  # a bug in lidarqa ("Internal error"), or a malformed command line (click)
EXIT_MISSING_DEPENDENCY = 3  # an optional dependency (extra) is not installed
EXIT_TARGET_FAILED = 4  # the run completed but an accuracy target was not met
EXIT_SIGINT = 130  # interrupted (Ctrl-C); 128 + signal number for SIGTERM (143), SIGHUP (129)

EXIT_STATUS_HELP = """\b
Exit status:
  0    success (every target met)
  1    error, explained in one line on stderr (bad input, option, output; nothing to measure)
  2    malformed command line, or an internal error (a bug: please report it)
  3    an optional dependency is missing (the message names the extra to install)
  4    completed, but an accuracy target was not met (assess, checkpoints --target-*,
       qc: a tile fails the spec)
  130  interrupted (SIGINT); 143 terminated (SIGTERM); no partial output is left behind
"""

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
    "swaths": "lidarqa.cli.swaths:swaths",
    "roads": "lidarqa.cli.roads:roads",
    "assess": "lidarqa.cli.assess:assess",
    "qc": "lidarqa.cli.qc:qc",
    "demo": "lidarqa.cli.assess:demo",
    "warmup": "lidarqa.cli.warmup:warmup",
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
        """Names of the commands whose module is importable, sorted."""
        return sorted(n for n in COMMANDS if _available(n))

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        """Import command `name` on first use (None when unknown or unavailable)."""
        if name not in COMMANDS or not _available(name):
            return None
        module, func = COMMANDS[name].split(":")
        return _bound_options(getattr(importlib.import_module(module), func))

    def invoke(self, ctx: click.Context) -> Any:
        """Run the command; turn every error into one line and its exit status."""
        from .._atomic import Terminated, install_signal_handlers, output_session

        saved = None if _STANDALONE else _save_signals()  # in-process callers get theirs back
        install_signal_handlers(exit_immediately=_STANDALONE)
        try:
            with output_session(), _one_line_warnings(settings(ctx).verbose):
                result = super().invoke(ctx)
                if _STANDALONE:
                    # The outputs are complete: a signal from now on must not undo them,
                    # nor kill the interpreter half-way through its exit.
                    _ignore_signals()
            return result
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            raise
        except KeyboardInterrupt:
            click.echo("Interrupted; no partial output was left behind.", err=True)
            sys.exit(EXIT_SIGINT)
        except Terminated as exc:
            click.echo(
                f"Terminated (signal {exc.signum}); no partial output was left behind.", err=True
            )
            sys.exit(128 + exc.signum)
        except MissingDependencyError as exc:
            _report(ctx, exc, prefix="Error")
            sys.exit(EXIT_MISSING_DEPENDENCY)
        except TargetNotMetError as exc:
            _report(ctx, exc, prefix="Target not met")
            sys.exit(EXIT_TARGET_FAILED)
        except LidarQAError as exc:
            _report(ctx, exc, prefix="Error")
            sys.exit(EXIT_ERROR)
        except Exception as exc:  # never a traceback unless -v
            known = _foreseeable(exc)
            if known is not None:
                _report(ctx, exc, prefix="Error", message=known)
                sys.exit(EXIT_ERROR)
            _report(ctx, exc, prefix=f"Internal error ({type(exc).__name__})", hint=True)
            sys.exit(EXIT_INTERNAL)
        finally:
            if saved:
                _restore_signals(saved)


_INT64 = 2**63 - 1
_MAX_FLOAT = 1e15  # as for coordinates: far beyond any real distance, size or tolerance


def _option_name(param: click.Parameter | None) -> str:
    if param is None:
        return "value"
    opts = getattr(param, "opts", None) or [param.name or "value"]
    return max(opts, key=len)


class _Wrapped:
    """A click type that checks the value of the type it wraps (name and metavar are its)."""

    def __init__(self, inner: click.ParamType) -> None:
        self.inner = inner
        self.name = inner.name

    def get_metavar(self, *args: Any, **kwargs: Any) -> str | None:
        return self.inner.get_metavar(*args, **kwargs)

    def __repr__(self) -> str:
        return repr(self.inner)


class _BoundedInt(_Wrapped, click.types.IntParamType):
    """An integer option that also fits a 64-bit integer (numeric kernels take int64)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        from ..errors import OptionError

        v = self.inner.convert(value, param, ctx)
        if isinstance(v, int) and not -_INT64 <= v <= _INT64:
            raise OptionError(f"{_option_name(param)} {value!s:.40} is too large")
        return v


class _BoundedFloat(_Wrapped, click.types.FloatParamType):
    """A number option that must be finite and within +-1e15 (no NaN, inf or 1e308)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        import math

        from ..errors import OptionError

        v = self.inner.convert(value, param, ctx)
        if isinstance(v, float):
            if not math.isfinite(v):
                raise OptionError(
                    f"{_option_name(param)} must be a finite number, got {value!s:.40}"
                )
            if abs(v) > _MAX_FLOAT:
                raise OptionError(
                    f"{_option_name(param)} {value!s:.40} is out of range (at most {_MAX_FLOAT:g})"
                )
        return v


def _bound_options(cmd: click.Command) -> click.Command:
    """Bound every integer (64 bits) and number (finite, +-1e15) option of `cmd`, once.

    Done here, where every command is loaded, so new commands get it for free.
    """
    if getattr(cmd, "_lidarqa_bounded", False):
        return cmd
    for p in cmd.params:
        if isinstance(p, click.Option) and p.count:
            continue
        t = p.type
        if isinstance(t, _BoundedInt | _BoundedFloat):
            continue
        if isinstance(t, click.types.IntParamType):
            p.type = _BoundedInt(t)
        elif isinstance(t, click.types.FloatParamType):
            p.type = _BoundedFloat(t)
    cmd._lidarqa_bounded = True  # type: ignore[attr-defined]
    return cmd


_STANDALONE = False  # set by main(): the process is ours (not a test runner's)


def _save_signals() -> dict:
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    return {
        getattr(signal, n): signal.getsignal(getattr(signal, n))
        for n in ("SIGINT", "SIGTERM", "SIGHUP")
        if hasattr(signal, n)
    }


def _restore_signals(saved: dict) -> None:
    import signal

    for sig, handler in saved.items():
        if handler is not None:
            try:
                signal.signal(sig, handler)
            except (ValueError, OSError, TypeError):
                pass


def _ignore_signals() -> None:
    import signal

    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            try:
                signal.signal(getattr(signal, name), signal.SIG_IGN)
            except (ValueError, OSError):  # not the main thread
                pass


@contextlib.contextmanager
def _one_line_warnings(verbose: int) -> Iterator[None]:
    """Show warnings as ``warning: MESSAGE`` lines on stderr, each message once.

    Warnings about the data (lidarqa's and its readers') are for the user; numeric
    RuntimeWarnings from inside a computation are noise to them and are shown only
    with ``-v`` (in Python's usual format, with the source line).
    """
    import warnings

    seen: set[str] = set()
    original = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, RuntimeWarning) and not issubclass(category, LidarQAWarning):
            if verbose:
                original(message, category, filename, lineno, file, line)
            return
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            click.echo(f"warning: {text}", err=True)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def _foreseeable(exc: BaseException) -> str | None:
    """A one-line message for exceptions the environment or the data cause, else None.

    These are not bugs in lidarqa: a file system refusing a write, the memory
    running out, an input too deeply nested for the parser, text that is not in
    the expected encoding. Everything else is reported as an internal error.
    """
    import errno

    if isinstance(exc, MemoryError):
        return "out of memory (the input is too large for this machine, or its header lies)"
    if isinstance(exc, RecursionError):
        return "input nested too deeply to be processed"
    if isinstance(exc, UnicodeError):
        return f"input is not valid text in the expected encoding (UTF-8): {exc}"
    if isinstance(exc, OSError):
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        if exc.errno == errno.ENOSPC:
            return f"no space left on the device{where and ' writing' + where}"
        if exc.strerror:
            return f"{exc.strerror}{':' + where if where else ''}"
        return str(exc) or type(exc).__name__
    return None


def _report(
    ctx: click.Context,
    exc: BaseException,
    *,
    prefix: str,
    hint: bool = False,
    message: str | None = None,
) -> None:
    s: Settings = settings(ctx)
    message = " ".join((message or str(exc)).split()) or type(exc).__name__
    if len(message) > 1000:
        message = message[:1000] + " ..."
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
    epilog=EXIT_STATUS_HELP,
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
    global _STANDALONE
    _STANDALONE = True
    from .._malloc import tune_process

    tune_process()
    cli.main(args=argv, prog_name="lidarqa")


if __name__ == "__main__":  # pragma: no cover
    main()
