"""``lidarqa swaths``: relative accuracy of overlapping flight strips."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Any, cast

import click
import numpy as np

from ..accuracy.swaths import DEFAULT_QUALITY_LEVEL, QUALITY_LEVELS
from ._catalog import (
    catalog_options,
    catalog_options_given,
    finish_run,
    open_catalog_source,
    pop_catalog_options,
    run_job,
    wants_catalog,
)
from ._common import (
    Steps,
    classes_option,
    common_options,
    echo,
    echo_tables,
    prepare_outputs,
    settings,
)


def _csv(rows: list[dict[str, Any]]) -> str:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o",
    "--output",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False),
    help="Output folder (created; must be empty unless --overwrite).",
)
@click.option(
    "--by-source-id",
    is_flag=True,
    help="Strips are the point_source_id values (default: one strip per file).",
)
@click.option(
    "--quality-level",
    type=click.Choice(tuple(QUALITY_LEVELS)),
    default=DEFAULT_QUALITY_LEVEL,
    show_default=True,
    help="USGS LBS / ASPRS relative accuracy thresholds for pass/fail.",
)
@click.option(
    "--cell-size", type=float, default=None, help="Grid cell (m); default: ~16 points per strip."
)
@click.option("--min-points", type=int, default=8, show_default=True, help="Points per cell plane.")
@click.option(
    "--range-cell",
    type=float,
    default=None,
    help="Cells (m) for the smooth-surface max − min; default: ~2 point spacings (USGS).",
)
@click.option(
    "--max-roughness",
    type=float,
    default=0.05,
    show_default=True,
    help="Smooth surface: plane residual RMS at most this (m).",
)
@click.option(
    "--max-slope",
    type=float,
    default=10.0,
    show_default=True,
    help="Smooth surface for dz: slope at most this (degrees).",
)
@classes_option(help="Compare these classes [default: 2,6 (ground, buildings); all but noise "
                     "if absent].")
@click.option("--all-returns", is_flag=True, help="Use every return, not only last/single.")
@click.option("--rotations", is_flag=True, help="Also estimate small rotations per strip.")
@click.option("--no-offsets", is_flag=True, help="Skip the strip offsets.")
@click.option("--reference-strip", type=int, default=None, help="Strip held fixed in the network.")
@click.option("--no-maps", is_flag=True, help="Do not write PNG maps (no matplotlib needed).")
@click.option(
    "--crs",
    "crs_option",
    default=None,
    help="CRS of the DZ rasters for files that declare none (EPSG code or WKT); a file's own "
    "CRS must agree with it.",
)
@catalog_options
@common_options
def swaths(
    files: tuple[str, ...],
    out_dir: str,
    by_source_id: bool,
    quality_level: str,
    cell_size: float | None,
    min_points: int,
    range_cell: float | None,
    max_roughness: float,
    max_slope: float,
    classes: list[int] | None,
    all_returns: bool,
    rotations: bool,
    no_offsets: bool,
    reference_strip: int | None,
    no_maps: bool,
    crs_option: str | None,
    **cat: Any,
) -> None:
    """Relative accuracy of overlapping flight strips (swaths).

    Per pair of overlapping strips: dz between local planes fitted in each strip
    on smooth surfaces (RMSDz, mean, median, max, 95th percentile, area), a DZ
    GeoTIFF and map; per strip: smooth-surface repeatability; strip offsets
    (dx, dy, dz with σ) by least squares on matched planes, adjusted as a
    network for more than two strips, and the measured strip noise E4 (use it
    with ``lidarqa heights --sigma-strip``). Pass/fail follows the USGS Lidar
    Base Specification / ASPRS Ed. 2 (2023) relative accuracy of the quality level.

    FILES may be a catalog (a folder, a glob, a .vpc, or several files with any
    catalog option): the strips are then compared over the whole block, chunk by
    chunk, with the figures of one in-memory run.
    """
    from .._atomic import atomic_path
    from ..errors import InvalidPointsError, OutputExistsError, WriteError
    from ..io.crs import ensure_same_crs, parse_crs
    from ..io.raster import write_geotiff

    s = settings()
    given_crs = parse_crs(crs_option)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise WriteError(f"output {out} exists and is not a folder")
    if out.exists() and any(out.iterdir()) and not s.overwrite:
        raise OutputExistsError(
            f"output folder {out} is not empty; pass --overwrite to write into it"
        )
    if not out.parent.exists():
        raise WriteError(f"output folder {out.parent} does not exist")
    # realpath, not Path.resolve: a symlink loop among the inputs is reported by the reader
    resolved = {os.path.realpath(f) for f in files}
    if os.path.realpath(out) in resolved:
        raise WriteError(f"output {out} is also an input")
    prepare_outputs(inputs=tuple(files))  # the --json path
    cat_opts = pop_catalog_options(cat)
    # several named files without catalog options: one strip per file, in memory (as before);
    # a folder, a glob, a .vpc or any catalog option: the whole block, chunk by chunk
    named_files = len(files) > 1 and not catalog_options_given(cat_opts)
    on_catalog = wants_catalog(files, cat_opts) and not named_files
    if not by_source_id and len(files) == 1 and not on_catalog:
        raise InvalidPointsError(
            "one file is one flight strip: give one file per strip, or --by-source-id to split "
            "the file by point_source_id"
        )
    from .._validate import require

    if not no_maps:
        require("matplotlib", "report")
    require("rasterio", "raster")
    steps = Steps()
    options: dict[str, Any] = dict(
        cell_size=cell_size,
        min_points=min_points,
        range_cell=range_cell,
        max_roughness=max_roughness,
        max_slope=max_slope,
        quality_level=quality_level,
        estimate_offsets=not no_offsets,
        rotations=rotations,
        reference_strip=reference_strip,
    )
    from ..tiling.jobs_swaths import catalog_swaths

    # one job for every input: one file (--by-source-id) or named strip files are one region
    # (read once, as in memory); a folder, a glob, a .vpc or any catalog option the whole block,
    # chunk by chunk. Heights are converted to metres by the task.
    source = open_catalog_source(files, cat_opts, z_to_metres=False)
    crs = source.crs
    with steps(f"Comparing strips of {', '.join(Path(f).name for f in files)}"):
        run = run_job(catalog_swaths, source, cat_opts, on_catalog, by_source_id=by_source_id,
                      classes=classes, all_returns=all_returns,
                      one_region=True if named_files else None, **options)
    rep = run.value
    strip_labels = cast("dict[int, str]", run.extra["labels"])
    labels = {k: v if by_source_id else Path(v).name for k, v in strip_labels.items()}
    if given_crs is not None:
        if crs is not None:  # the rasters are horizontal: compare horizontal parts
            ensure_same_crs(_horizontal(crs), _horizontal(given_crs), what=(files[0], "--crs"))
        else:
            crs = given_crs
    written: list[str] = []
    out.mkdir(exist_ok=True)
    with steps(f"Writing {out}"):
        for g in rep.grids:
            tif = out / f"dz_{g.strip_a}_{g.strip_b}.tif"
            write_geotiff(
                tif, g.dz, x0=g.x0, y1=g.y1, cell_size=g.cell_size, crs=crs, overwrite=s.overwrite
            )
            written.append(tif.name)
            if not no_maps:
                from ..report.analyses.swaths import plot_dz_map

                png = out / f"dz_{g.strip_a}_{g.strip_b}.png"
                data = plot_dz_map(g, vmax=rep.thresholds["max_abs"])
                with atomic_path(png, overwrite=s.overwrite) as tmp:
                    tmp.write_bytes(data)
                written.append(png.name)
        tables = {
            "pairs.csv": [p.to_dict() for p in rep.pairs],
            "repeatability.csv": [r.to_dict() for r in rep.repeatability],
            "offsets.csv": [
                {
                    k: v
                    for k, v in o.to_dict().items()
                    if k not in ("rotations", "sigma_rotations", "sigma_robust")
                }
                | _rot_cols(o)
                for o in (*rep.pair_offsets, *rep.network_offsets)
            ],
        }
        for name, rows in tables.items():
            if not rows:
                continue
            with atomic_path(out / name, overwrite=s.overwrite) as tmp:
                tmp.write_text(_csv(rows), encoding="utf-8")
            written.append(name)

    from ..report.analyses.swaths import swaths_tables

    echo_tables(*swaths_tables(rep))
    if np.isfinite(rep.e4):
        echo(
            f"E4 (strip height noise) {rep.e4:.3f} m; use: lidarqa heights ... "
            f"--sigma-strip {rep.e4:.3f}"
        )
    for f in rep.flags:
        echo("note: " + f)
    echo(f"{'PASS' if rep.passed else 'FAIL'}; wrote {len(written)} file(s) to {out}")
    results = dict(rep.to_dict(), outputs=written)
    finish_run(
        "swaths",
        run,
        on_catalog,
        inputs={"files": list(files), "strips": labels},
        parameters=dict(
            rep.parameters,
            by_source_id=by_source_id,
            classes=classes,
            all_returns=all_returns,
            crs=crs_option,
        ),
        results=results,
        cat_opts=cat_opts,
    )


def _horizontal(crs: Any) -> Any:
    if getattr(crs, "is_compound", False) and crs.sub_crs_list:
        return crs.sub_crs_list[0]
    return crs


def _rot_cols(o: Any) -> dict[str, Any]:
    r = o.rotations or (None, None, None)
    sr = o.sigma_rotations or (None, None, None)
    rb = o.sigma_robust or (None, None, None)
    return {
        "sigma_robust_dx": rb[0],
        "sigma_robust_dy": rb[1],
        "sigma_robust_dz": rb[2],
        "rot_x_deg": r[0],
        "rot_y_deg": r[1],
        "rot_z_deg": r[2],
        "sigma_rot_x_deg": sr[0],
        "sigma_rot_y_deg": sr[1],
        "sigma_rot_z_deg": sr[2],
    }
