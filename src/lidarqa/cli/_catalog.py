"""Catalog inputs of the command line: catalog or file, options, engine and summary.

Telling a catalog from one file, the catalog options every command takes, the
engine around a job and the catalog summary of its --json record.

A command calls its library job (:mod:`lidarqa.tiling.jobs_api`, through
:func:`~lidarqa.tiling.apply.apply`) with :func:`job_options` inside :func:`catalog_engine`.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import click

from ._common import Steps, echo, finish, settings

__all__ = ["bad_lines", "catalog_engine", "catalog_options", "catalog_options_given",
           "catalog_settings", "echo_run", "failed_exit", "finish_run", "job_options",
           "open_catalog_source", "option_given", "pop_catalog_options", "reproducible_vectors",
           "run_job", "run_settings", "run_summary", "sigterm_as_interrupt", "wants_catalog"]


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM into KeyboardInterrupt while a catalog job runs.

    So the same cleanup happens (atomic outputs removed, cluster shut down, work folder
    kept for --resume).
    """

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    try:
        old = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


_OPTION_NAMES = ("chunk_size", "buffer", "workers", "scheduler", "skip_bad", "resume")


def catalog_options(func: Callable[..., Any] | None = None, /,
                    **help_texts: str) -> Callable[..., Any]:
    """``--chunk-size --buffer --workers --scheduler --skip-bad --resume``.

    ``@catalog_options`` or ``@catalog_options(buffer="...")``, with a command's own help
    text for some of them.
    """
    if func is None:
        return lambda f: catalog_options(f, **help_texts)
    helps = {
        "chunk_size": "Catalog: chunk side, m (default: from the point density, aligned with "
                      "the tiles).",
        "buffer": "Catalog: margin read around each chunk, m (default: the margin the job "
                  "needs, see docs/catalogs.md).",
        "workers": "Catalog: local worker processes (default: one per core; 1 = serial, no "
                   "Dask).",
        "scheduler": "Catalog: Dask scheduler address (tcp://host:port) or 'serial'.",
        "skip_bad": "Catalog: leave out bad tiles (listed) instead of failing.",
        "resume": "Catalog: re-use the chunks finished by an interrupted or failed run (kept "
                  "in $LIDARQA_WORK_DIR, default ~/.cache/lidarqa/chunks, until a run ends "
                  "with no failed chunk).",
        **help_texts}
    opts = [click.option("--chunk-size", type=float, default=None, help=helps["chunk_size"]),
            click.option("--buffer", type=float, default=None, help=helps["buffer"]),
            click.option("--workers", type=int, default=None, help=helps["workers"]),
            click.option("--scheduler", default=None, help=helps["scheduler"]),
            click.option("--skip-bad", is_flag=True, help=helps["skip_bad"]),
            click.option("--resume", is_flag=True, help=helps["resume"])]
    for opt in reversed(opts):
        func = opt(func)
    return func


def option_given(value: Any) -> bool:
    """An option the user gave: not None and not an unset flag (``--buffer 0`` is given)."""
    return value is not None and value is not False


def catalog_options_given(opts: dict[str, Any]) -> bool:
    """Any catalog option given."""
    return any(option_given(opts.get(k)) for k in _OPTION_NAMES)


def wants_catalog(paths: Sequence[str], opts: dict[str, Any]) -> bool:
    """A catalog input (several paths, a folder, a glob, a ``.vpc``), or a catalog option given."""
    from ..tiling.source import is_catalog_input

    return is_catalog_input(list(paths)) or catalog_options_given(opts)


def pop_catalog_options(opts: dict[str, Any]) -> dict[str, Any]:
    """Remove the catalog options from a command's keyword arguments and return them."""
    return {k: opts.pop(k, None) for k in _OPTION_NAMES}


@contextlib.contextmanager
def catalog_engine(cat_opts: dict[str, Any]) -> Iterator[Any]:
    """The engine of ``--workers`` (default one per core; 1 = serial) or ``--scheduler``.

    SIGTERM stops the job as an interrupt does (outputs removed, finished chunks kept).
    """
    from ..tiling import Engine

    scheduler, workers = cat_opts.get("scheduler"), cat_opts.get("workers")
    eng = Engine("serial") if scheduler is None and workers == 1 else \
        Engine(scheduler, workers=workers)
    with sigterm_as_interrupt(), eng:  # the progress bar prints the dashboard's address
        yield eng


def open_catalog_source(paths: Sequence[str], cat_opts: dict[str, Any], *, crs: Any = None,
                        z_to_metres: bool = True, **selection: Any) -> Any:
    """The :class:`~lidarqa.tiling.source.Source` of `paths` (bad tiles listed or refused)."""
    from ..tiling.source import open_source

    with Steps()(f"Reading the headers of {', '.join(paths)}"):
        source = open_source(list(paths), skip_bad=bool(cat_opts.get("skip_bad")), crs=crs,
                             z_to_metres=z_to_metres, **selection)
    bad_lines(source.bad)
    return source


def job_options(cat_opts: dict[str, Any], engine: Any = None) -> dict[str, Any]:
    """The engine options every catalog job takes from the command's catalog options.

    Finished chunks are always kept in the work folder until the job ends with no
    failed chunk; ``--resume`` re-uses them.
    """
    from ..tiling.apply import default_work_dir

    return {"chunk_size": cat_opts.get("chunk_size"), "buffer": cat_opts.get("buffer"),
            "progress": not settings().quiet, "skip_failed": True,
            "work_dir": default_work_dir(), "resume": bool(cat_opts.get("resume")),
            **({"engine": engine} if engine is not None else {})}


def run_job(job: Callable[..., Any], source: Any, cat_opts: dict[str, Any], on_catalog: bool,
            *args: Any, **kwargs: Any) -> Any:
    """``job(source, *args, **kwargs)`` on the command's engine (one region: in this process).

    On a catalog the job gets the command's catalog options (:func:`job_options`).
    """
    with catalog_engine(cat_opts) if on_catalog else contextlib.nullcontext() as eng:
        return job(source, *args, **kwargs, **(job_options(cat_opts, eng) if on_catalog else {}))


def catalog_settings(cat_opts: dict[str, Any], chunk_size: float | None,
                     buffer: float | None) -> dict[str, Any]:
    """The catalog settings of a --json record, the same keys for every command.

    `chunk_size` and `buffer` are the ones the job ran with (its default or the
    user's), ``workers`` and ``scheduler`` the user's (None: the default).
    """
    return {"chunk_size": chunk_size, "buffer": buffer, "workers": cat_opts.get("workers"),
            "scheduler": cat_opts.get("scheduler")}


def run_settings(run: Any, cat_opts: dict[str, Any]) -> dict[str, Any]:
    """:func:`catalog_settings` of a job's `run`: its chunk grid's side and buffer."""
    c = run.chunks[0] if run.chunks else None
    return catalog_settings(cat_opts, c.size if c else cat_opts.get("chunk_size"),
                            (c.buffered[2] - c.core[2]) if c else cat_opts.get("buffer"))


def finish_run(command: str, run: Any, on_catalog: bool, *, inputs: dict[str, Any],
               parameters: dict[str, Any], results: dict[str, Any],
               cat_opts: dict[str, Any], record: bool = False) -> None:
    """Write the --json record of a job's `run` (None: no job); on a catalog its chunks too.

    On a catalog (or with `record`) the chunk counts are echoed first, the record gets
    the catalog settings the run used (:func:`run_settings`, in ``parameters``) and the
    run's summary (``results["catalog"]``), and a failed chunk fails the command after
    the record.
    """
    if run is not None and on_catalog:
        echo_run(run)
    if run is not None and (on_catalog or record):
        parameters = {**parameters, **run_settings(run, cat_opts)}
        results["catalog"] = run_summary(run)
    finish(command, inputs=inputs, parameters=parameters, results=results)
    if run is not None:
        failed_exit(run)


def run_summary(run: Any) -> dict[str, Any]:
    d = run.to_dict()
    d["chunks"] = run.chunk_status()
    d["bad_tiles"] = [{"path": str(p), "reason": str(r)} for p, r in run.catalog.bad]
    return d


def echo_run(run: Any) -> None:
    d = run.to_dict()
    c = d["chunk_status"]
    echo(f"  catalog         {d['n_tiles']} tile(s), {d['n_chunks']} chunk(s): "
         + ", ".join(f"{v} {k}" for k, v in c.items() if v))
    if run.failed:
        click.echo("Failed chunks (their area is missing from the results): "
                   + ", ".join(run.failed), err=True)


def failed_exit(run: Any) -> None:
    if run.failed:
        from ..errors import TilingError

        raise TilingError(f"{len(run.failed)} chunk(s) failed: {', '.join(run.failed)} "
                          "(the outputs hold every other chunk)")


# The GeoPackage driver stamps the writing time into the file (gpkg_contents.last_change); a
# catalog run's outputs must be byte-identical for any number of workers and any rerun, so its
# vector outputs carry this fixed time instead (the run's time is in the --json record).
FIXED_GPKG_TIME = "2000-01-01T00:00:00.000Z"


@contextlib.contextmanager
def reproducible_vectors() -> Iterator[None]:
    """Write GeoPackages with :data:`FIXED_GPKG_TIME` inside the block (restored after)."""
    try:
        import pyogrio
    except ImportError:  # no GIS extra: only CSV can be written, which has no time stamp
        yield
        return
    before = pyogrio.get_gdal_config_option("OGR_CURRENT_DATE")
    pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": FIXED_GPKG_TIME})
    try:
        yield
    finally:
        pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": before})


def bad_lines(bad: Sequence[tuple[str, str]]) -> None:
    if bad:
        click.echo(f"Skipped {len(bad)} bad input(s):", err=True)
        for p, r in bad:
            click.echo(f"  {p}: {r}", err=True)
