"""Catalog runs of planes/edges/corners, checkpoints --vertical and repeatability.

Each command keeps its single-file path unchanged; a catalog input (several
files, a folder, a glob pattern or a ``.vpc``) or any catalog option sends it
here. The figures are those of one in-memory run over the whole area (see
:mod:`lidarqa.tiling.jobs_api`).
"""

from __future__ import annotations

import contextlib
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import click
import numpy as np

from ._common import Steps, echo, finish, prepare_outputs, settings

__all__ = [
    "catalog_options",
    "features_on_catalog",
    "heights_on_catalog",
    "reproducible_vectors",
    "repeatability_on_catalog",
    "vertical_on_catalog",
    "wants_catalog",
]

_OPTION_NAMES = ("chunk_size", "buffer", "workers", "scheduler", "skip_bad", "resume")


def catalog_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """``--chunk-size --buffer --workers --scheduler --skip-bad --resume`` (as ``ground``)."""
    opts = [
        click.option("--chunk-size", type=float, default=None,
                     help="Catalog: chunk side, m (default: from the point density, aligned "
                          "with the tiles)."),
        click.option("--buffer", type=float, default=None,
                     help="Catalog: margin read around each chunk, m (default 60; wider than "
                          "the largest building)."),
        click.option("--workers", type=int, default=None,
                     help="Catalog: local worker processes (default: one per core; 1 = serial, "
                          "no Dask)."),
        click.option("--scheduler", default=None,
                     help="Catalog: Dask scheduler address (tcp://host:port) or 'serial'."),
        click.option("--skip-bad", is_flag=True,
                     help="Catalog: leave out bad tiles (listed) instead of failing."),
        click.option("--resume", is_flag=True,
                     help="Catalog: re-use the chunks finished by an interrupted or failed run "
                          "(kept in $LIDARQA_WORK_DIR, default ~/.cache/lidarqa/chunks, until "
                          "a run ends with no failed chunk)."),
    ]
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
    """A catalog input, or a catalog option given."""
    from ._catalog import is_catalog

    return is_catalog(paths) or catalog_options_given(opts)


def pop_catalog_options(opts: dict[str, Any]) -> dict[str, Any]:
    """Remove the catalog options from a command's keyword arguments and return them."""
    return {k: opts.pop(k, None) for k in _OPTION_NAMES}


@contextlib.contextmanager
def _engine(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    from ..tiling import Engine

    if scheduler is None and workers == 1:
        eng = Engine("serial")
    else:
        eng = Engine(scheduler, workers=workers)
    from ._catalog import sigterm_as_interrupt

    with sigterm_as_interrupt(), eng:
        if eng.dashboard_link and not settings().quiet:
            click.echo(f"Dask dashboard: {eng.dashboard_link}", err=True)
        yield eng


def _open(paths: Sequence[str], skip_bad: bool | None, steps: Steps, *, crs: Any = None,
          z_to_metres: bool = True) -> Any:
    from ..tiling.source import open_source
    from ._catalog import bad_lines

    with steps(f"Reading the headers of {', '.join(paths)}"):
        source = open_source(list(paths), skip_bad=bool(skip_bad), crs=crs,
                             z_to_metres=z_to_metres)
    bad_lines(source.bad)
    return source


def job_options(cat_opts: dict[str, Any]) -> dict[str, Any]:
    """The engine options every catalog job takes from the command's catalog options.

    Finished chunks are always kept in the work folder until the job ends with no
    failed chunk; ``--resume`` re-uses them.
    """
    from ..tiling.apply import default_work_dir

    return {"chunk_size": cat_opts.get("chunk_size"), "buffer": cat_opts.get("buffer"),
            "progress": not settings().quiet, "skip_failed": True,
            "work_dir": default_work_dir(), "resume": bool(cat_opts.get("resume"))}


def _common(cat_opts: dict[str, Any], eng: Any) -> dict[str, Any]:
    return {**job_options(cat_opts), "engine": eng}


def _run_summary(run: Any) -> dict[str, Any]:
    d = run.to_dict()
    d["chunks"] = run.chunk_status()
    d["bad_tiles"] = [{"path": str(p), "reason": str(r)} for p, r in run.catalog.bad]
    return d


def _echo_run(run: Any) -> None:
    d = run.to_dict()
    c = d["chunk_status"]
    echo(f"  catalog         {d['n_tiles']} tile(s), {d['n_chunks']} chunk(s): "
         + ", ".join(f"{v} {k}" for k, v in c.items() if v))
    if run.failed:
        click.echo("Failed chunks (their area is missing from the results): "
                   + ", ".join(run.failed), err=True)


def _failed_exit(run: Any) -> None:
    if run.failed:
        from ..errors import TilingError

        raise TilingError(f"{len(run.failed)} chunk(s) failed: {', '.join(run.failed)} "
                          "(the outputs hold every other chunk)")


# ------------------------------------------------------------------ planes / edges / corners


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


def features_on_catalog(
    kind: str,
    paths: Sequence[str],
    output: str,
    *,
    classes: Any,
    source_id: Any,
    segment_options: dict[str, Any],
    options: dict[str, Any],
    cat_opts: dict[str, Any],
    crs: Any = None,
) -> None:
    """``lidarqa planes|edges|corners CATALOG -o OUT``: each feature once (anchor-in-core)."""
    from ..io.vector import write_points, write_segments
    from ..tiling.jobs_api import catalog_features

    prepare_outputs(output, inputs=tuple(paths))
    steps = Steps()
    catalog = _open(paths, cat_opts.get("skip_bad"), steps, crs=crs, z_to_metres=False)
    with _engine(cat_opts.get("scheduler"), cat_opts.get("workers")) as eng:
        run = catalog_features(catalog, kind=kind, classes=classes, source_id=source_id,
                               segment_options=segment_options, options=options,
                               **_common(cat_opts, eng))
    f = run.value
    with steps(f"Writing {output}"), reproducible_vectors():
        if kind == "edges":
            write_segments(f, output, overwrite=settings().overwrite, layer=kind)
        else:
            write_points(f, output, overwrite=settings().overwrite, layer=kind)
    results: dict[str, Any] = {f"n_{kind}": len(f), "output": output, "catalog": _run_summary(run)}
    if kind == "edges":
        results["total_length_m"] = float(f.lengths.sum()) if len(f) else 0.0
    n_edge = int(np.sum(f.attributes["at_buffer_edge"])) if "at_buffer_edge" in f.attributes \
        else 0
    results["n_at_buffer_edge"] = n_edge
    if n_edge:
        click.echo(f"Warning: {n_edge} of {len(f)} {kind} come from planes that reach a chunk's "
                   "buffer edge (column at_buffer_edge): a roof wider than --buffer may be cut "
                   "there; widen --buffer", err=True)
    per_chunk = Counter(f.attributes["chunk"].tolist()) if len(f) else Counter()
    results["per_chunk"] = dict(sorted(per_chunk.items()))
    echo(f"{len(f)} {kind} from {len(run.catalog.tiles)} tile(s) -> {output}")
    _echo_run(run)
    finish(kind, inputs={"paths": list(paths), "classes": classes, "source_id": source_id},
           parameters={**run.extra.get("segment_options", {}), **run.extra.get("options", {}),
                       "chunk_size": run.chunks[0].size if run.chunks else None,
                       "buffer": (run.chunks[0].buffered[2] - run.chunks[0].core[2])
                       if run.chunks else None,
                       "workers": cat_opts.get("workers"), "scheduler": cat_opts.get("scheduler"),
                       "rule": "anchor-in-core (corner point, edge midpoint, plane centroid)"},
           results=results)
    _failed_exit(run)


# ------------------------------------------------------------------ checkpoints --vertical


def vertical_on_catalog(
    paths: Sequence[str],
    check_path: str,
    output: str | None,
    *,
    classes: Any,
    source_id: Any = None,
    crs: Any = None,
    max_edge: float | None,
    checkpoint_rmse_v: float,
    cat_opts: dict[str, Any],
    summary: Callable[[dict, bool], None],
) -> None:
    """``lidarqa checkpoints CATALOG CHECK --vertical`` (reads only chunks with check points)."""
    from ..io.crs import crs_name, ensure_same_crs
    from ..io.vector import PointSet, read_points, write_points
    from ..tiling.jobs_api import catalog_vertical_check

    prepare_outputs(output, inputs=(*paths, check_path))
    steps = Steps()
    with steps("Reading check points"):
        chk = read_points(check_path, crs=crs)
    source = _open(paths, cat_opts.get("skip_bad"), steps, crs=crs)
    ensure_same_crs(source.native_crs, chk.crs, what=("MEASURED", "CHECK"))
    crs_used = source.native_crs if source.native_crs is not None else chk.crs
    if source.native_crs is None and chk.crs is not None:  # the check points' CRS for both
        from ..tiling.source import open_source

        source = open_source(source.catalog, crs=chk.crs)
    from .checkpoints import _unit_factors

    _unit_factors(crs_used, "MEASURED")  # refuses a geographic CRS, as for one file
    notes: list[str] = []
    if source.z_factor != 1.0 or source.xy_factor != 1.0:
        from ..io.crs import horizontal_unit, vertical_unit

        notes.append(
            f"coordinates converted to metres (horizontal unit: "
            f"{horizontal_unit(crs_used)[0] or 'metre'}, vertical unit: "
            f"{vertical_unit(crs_used)[0] or 'metre'})")
    with _engine(cat_opts.get("scheduler"), cat_opts.get("workers")) as eng:
        run = catalog_vertical_check(source, chk, classes=tuple(classes) if classes else (2,),
                                     source_id=source_id, max_edge=max_edge,
                                     checkpoint_rmse_v=checkpoint_rmse_v,
                                     **_common(cat_opts, eng))
    report = run.value
    if output is not None:
        with steps("Writing " + output), reproducible_vectors():
            res = report.residual_points()
            # the check points in their own (unconverted) coordinates, as for one file
            xyz = res.xyz.copy()
            xyz[:, :2] /= source.xy_factor
            xyz[:, 2] /= source.z_factor
            out = PointSet(res.ids, xyz, res.attributes, crs=chk.crs or crs_used)
            write_points(out, output, overwrite=settings().overwrite)
    results = report.to_dict()
    results["warnings"] = notes + results["warnings"]
    results["units"] = "m"
    results["catalog"] = _run_summary(run)
    summary(results, True)
    _echo_run(run)
    finish("checkpoints",
           inputs={"measured": list(paths), "check": check_path},
           parameters={"vertical": True, "classes": classes or [2], "source_id": source_id,
                       "max_edge": results["vertical"]["max_edge"],
                       "checkpoint_rmse_v": checkpoint_rmse_v, "output": output,
                       "crs": crs_name(crs_used), "chunk_size": cat_opts.get("chunk_size"),
                       "buffer": cat_opts.get("buffer"), "workers": cat_opts.get("workers"),
                       "scheduler": cat_opts.get("scheduler")},
           results=results)
    _failed_exit(run)


# ------------------------------------------------------------------ heights


def heights_on_catalog(
    catalog: Any,
    map_xy: Any,
    reference_xyz: Any,
    *,
    classes: Any,
    source_id: Any = None,
    options: dict[str, Any],
    cat_opts: dict[str, Any],
) -> tuple[Any, Any]:
    """``lidarqa heights CATALOG MAP REFERENCE``: (HeightReport, CatalogRun)."""
    from ..tiling.jobs_api import catalog_heights

    with _engine(cat_opts.get("scheduler"), cat_opts.get("workers")) as eng:
        run = catalog_heights(catalog, map_xy, reference_xyz, classes=classes,
                              source_id=source_id, options=options, **_common(cat_opts, eng))
    return run.value, run


# ------------------------------------------------------------------ repeatability


def repeatability_on_catalog(
    paths: Sequence[str],
    *,
    classes: Any,
    source_id: Any,
    match_options: dict[str, Any],
    cat_opts: dict[str, Any],
    print_rows: Callable[[list[dict]], None],
    edge_options: dict[str, Any] | None = None,
    crs: Any = None,
) -> None:
    """``lidarqa repeatability CATALOG --by-source-id``: every strip pair over the whole block."""
    from ..tiling.jobs_api import catalog_repeatability

    prepare_outputs(inputs=tuple(paths))
    steps = Steps()
    catalog = _open(paths, cat_opts.get("skip_bad"), steps, crs=crs, z_to_metres=False)
    with _engine(cat_opts.get("scheduler"), cat_opts.get("workers")) as eng:
        run = catalog_repeatability(catalog, classes=classes, source_id=source_id,
                                    match_options=match_options, edge_options=edge_options,
                                    **_common(cat_opts, eng))
    rows = run.value
    if not rows:
        from ..errors import OptionError

        raise OptionError(f"repeatability needs at least two strips with edges, got "
                          f"{len(run.extra['strips'])}")
    print_rows(rows)
    _echo_run(run)
    strips = {str(k): len(v) for k, v in run.extra["strips"].items()}
    echo("  strips          " + ", ".join(f"{k} ({n} edges)" for k, n in strips.items()))
    finish("repeatability", inputs={"files": list(paths)},
           parameters={"by_source_id": True, "source_id": source_id, "classes": classes,
                       **match_options, **run.extra["segment_options"],
                       **run.extra["edge_options"], "chunk_size": cat_opts.get("chunk_size"),
                       "buffer": cat_opts.get("buffer"), "workers": cat_opts.get("workers"),
                       "scheduler": cat_opts.get("scheduler")},
           results={"pairs": rows, "strips": strips, "catalog": _run_summary(run)})
    _failed_exit(run)
