"""``lidarqa checkpoints``: accuracy at surveyed check points (ASPRS Ed. 2 2023, NSSDA)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from ..accuracy.transforms import TRANSFORMS
from ._catalog import (
    catalog_options,
    finish_run,
    open_catalog_source,
    reproducible_vectors,
    run_job,
    wants_catalog,
)
from ._common import (
    Steps,
    classes_option,
    common_options,
    crs_option,
    echo,
    echo_tables,
    input_crs,
    output_option,
    prepare_outputs,
    settings,
    source_id_option,
    target_options,
)


def _parse_ids(value: str | None) -> list[str] | None:
    if value is None:
        return None
    ids = [t.strip() for t in str(value).split(",") if t.strip()]
    return ids or None


def _read_control_file(path: str) -> list[str]:
    """Control ids from a point file (.gpkg/.geojson, a .csv with an ``id`` column) or a list."""
    from ..errors import ReadError
    from ..io.vector import read_points

    p = Path(path)
    if not p.is_file():
        raise ReadError(f"control file {p} does not exist")
    suffix = p.suffix.lower()
    if suffix in {".gpkg", ".geojson", ".json"}:
        return [str(v) for v in read_points(p, require_z=False).ids.tolist()]
    lines = [ln.strip() for ln in p.read_text(encoding="utf-8-sig").splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise ReadError(f"control file {p} lists no ids")
    delim = ";" if lines[0].count(";") > lines[0].count(",") else ","
    header = [h.strip().lower() for h in lines[0].split(delim)]
    col = header.index("id") if "id" in header else None
    body = lines[1:] if col is not None else lines
    col = col or 0
    ids = [ln.split(delim)[col].strip() for ln in body]
    ids = [i for i in ids if i]
    if not ids:
        raise ReadError(f"control file {p} lists no ids")
    return ids


def _units(measured: Any, check: Any, notes: list[str]) -> tuple[Any, float, float]:
    """The CRS both inputs are in and its factors to metres (notes added to `notes`)."""
    from ..accuracy.checkpoints import metric_units

    crs, fh, fv, more = metric_units(measured, check)
    notes.extend(more)
    return crs, fh, fv


@click.command()
@click.argument("measured", nargs=-1, required=True, type=click.Path())
@click.argument("check", type=click.Path(dir_okay=False))
@click.option(
    "--transform",
    type=click.Choice(TRANSFORMS),
    default="none",
    show_default=True,
    help="Least-squares transformation of MEASURED onto CHECK, estimated on the control points.",
)
@click.option(
    "--control-ids",
    default=None,
    metavar="ID[,ID...]",
    help="Check-point ids used as control (to estimate the transformation); the rest are checks.",
)
@click.option(
    "--control-file",
    type=click.Path(dir_okay=False),
    default=None,
    help="File listing control ids (one per line, a CSV with an id column, or a point file).",
)
@click.option(
    "--match",
    "match",
    type=click.Choice(["id", "nearest"]),
    default="id",
    show_default=True,
    help="Pair points by id, or by nearest neighbour (one-to-one) within --max-distance.",
)
@click.option(
    "--max-distance",
    type=float,
    default=None,
    help="Largest pair distance before transformation (m).",
)
@click.option(
    "--vertical",
    is_flag=True,
    help="MEASURED is a point cloud: compare CHECK heights with a TIN of its ground points.",
)
@classes_option(help="With --vertical: classes forming the ground TIN [default: 2].")
@source_id_option
@click.option(
    "--max-edge",
    type=float,
    default=None,
    help="With --vertical: flag check points in TIN triangles with a longer edge (m) "
    "[default: 5 x ground spacing].",
)
@click.option(
    "--checkpoint-rmse-h",
    type=float,
    default=0.0,
    show_default=True,
    help="Horizontal RMSE of the check-point survey (m), folded into the ASPRS Ed. 2 figures.",
)
@click.option(
    "--checkpoint-rmse-v",
    type=float,
    default=0.0,
    show_default=True,
    help="Vertical RMSE of the check-point survey (m), folded into the ASPRS Ed. 2 figures.",
)
@output_option("Write per-point residuals (.csv, .gpkg or .geojson); they carry the CRS of "
               "the inputs (a CSV in a .prj file next to it).")
@crs_option
@catalog_options
@target_options(
    rmse_z=("rmse_z", "the vertical RMSE (m)"),
    rmse_h=("rmse_h", "the horizontal RMSE (m)"),
    rmse_3d=("rmse_3d", "the 3D RMSE (m)"),
    mean_z=("mean_z", "the absolute mean vertical error (m)"),
)
@common_options
def checkpoints(
    measured: tuple[str, ...],
    check: str,
    transform: str,
    control_ids: str | None,
    control_file: str | None,
    match: str,
    max_distance: float | None,
    vertical: bool,
    classes: list[int] | None,
    source_id: list[int] | None,
    max_edge: float | None,
    checkpoint_rmse_h: float,
    checkpoint_rmse_v: float,
    output: str | None,
    crs: str | None,
    **cat_opts: Any,
) -> None:
    """Accuracy of MEASURED points against surveyed CHECK points.

    MEASURED is a point list (id,x,y,z; e.g. from `lidarqa corners`) or, with
    --vertical, a point cloud. Reports per-axis bias, standard deviation, RMSE
    and max |residual|, RMSE_H, RMSE_3D, the ASPRS Edition 2 (2023) accuracy
    with the check-point survey accuracy folded in, and NSSDA 95 % figures.
    Residuals are MEASURED (transformed) minus CHECK, in metres.

    With --vertical, MEASURED may be a catalog (several files, a folder, a
    glob, a .vpc): each check point is compared in the chunk whose core holds
    it, reading only those chunks; the figures equal one whole-area run.
    """
    from ..accuracy.checkpoints import scale_points
    from ..errors import OptionError
    from ..io.crs import crs_name
    from ..io.vector import VECTOR_SUFFIXES, PointSet, read_points, write_points

    if output is not None and Path(output).suffix.lower() not in VECTOR_SUFFIXES:
        raise OptionError(f"--output must end in .csv, .gpkg or .geojson, got {output}")
    if vertical and (transform != "none" or control_ids or control_file or match != "id"):
        raise OptionError(
            "--vertical compares heights only: --transform, --control-ids, --control-file "
            "and --match do not apply"
        )
    if not vertical and (classes is not None or max_edge is not None or source_id is not None):
        raise OptionError("--classes, --source-id and --max-edge apply only with --vertical")
    if control_ids and control_file:
        raise OptionError("give --control-ids or --control-file, not both")
    given = input_crs(crs)
    on_catalog = wants_catalog(measured, cat_opts)
    if on_catalog and not vertical:
        raise OptionError("a catalog of clouds (several files, a folder, a glob, a .vpc) "
                          "needs --vertical")
    measured_path = measured[0]
    prepare_outputs(output, inputs=(*measured, check, control_file))
    steps = Steps()
    notes: list[str] = []
    ctrl = _parse_ids(control_ids)
    if control_file:
        ctrl = _read_control_file(control_file)

    with steps("Reading check points"):
        chk = read_points(check, crs=given)

    run = None
    if vertical:
        from ..tiling.jobs_api import catalog_vertical_check

        # one job for a file (one region: the in-memory check) and a catalog (only the chunks
        # holding check points are read); heights in metres through the source
        source = open_catalog_source(measured, cat_opts, crs=given)
        if source.native_crs is None and chk.crs is not None:  # the check points' CRS for both
            source = open_catalog_source(measured, cat_opts, crs=chk.crs)
        crs_used, _, _ = _units(source.native_crs, chk.crs, notes)
        fh, fv = source.xy_factor, source.z_factor
        cls_arg: tuple[int, ...] | None = tuple(classes) if classes else (2,)
        if source.cloud is not None and source.cloud.classification is None:  # a point file
            if classes is not None:
                raise OptionError(f"{measured_path} has no classification, so --classes "
                                  "cannot select ground points")
            notes.append("the cloud has no classification: all its points form the TIN")
            cls_arg = None
        run = run_job(catalog_vertical_check, source, cat_opts, on_catalog, chk, classes=cls_arg,
                      source_id=source_id, max_edge=max_edge,
                      checkpoint_rmse_v=checkpoint_rmse_v)
        report: Any = run.value
    else:
        from ..accuracy.checkpoints import assess_checkpoints
        from ..io import CLOUD_SUFFIXES

        suffix = Path(measured_path).suffix.lower()
        if suffix in CLOUD_SUFFIXES and suffix not in VECTOR_SUFFIXES:
            raise OptionError(
                f"{measured_path} looks like a point cloud; add --vertical to check its heights, "
                "or give a point list (id,x,y,z) such as the output of `lidarqa corners`"
            )
        with steps("Reading measured points"):
            mea = read_points(measured_path, crs=given)
        crs_used, fh, fv = _units(mea.crs, chk.crs, notes)
        with steps("Matching and estimating"):
            report = assess_checkpoints(
                PointSet(mea.ids, scale_points(mea, fh, fv).xyz),
                PointSet(chk.ids, scale_points(chk, fh, fv).xyz),
                transform=transform,
                control_ids=ctrl,
                match=match,
                max_distance=max_distance,
                checkpoint_rmse_h=checkpoint_rmse_h,
                checkpoint_rmse_v=checkpoint_rmse_v,
            )

    if output is not None:
        res = report.residual_points()
        # write the check points in their own (unconverted) coordinates
        out = scale_points(res, 1.0 / fh, 1.0 / fv)
        out.crs = chk.crs or crs_used
        with steps("Writing " + output), reproducible_vectors():
            write_points(out, output, overwrite=settings().overwrite)

    results = report.to_dict()
    results["warnings"] = notes + results["warnings"]
    results["units"] = "m"
    _summary(results, vertical)
    finish_run(
        "checkpoints",
        run,
        on_catalog,
        inputs={"measured": list(measured) if on_catalog else measured_path, "check": check,
                "control_file": control_file},
        parameters={
            "transform": transform,
            "control_ids": ctrl,
            "match": match,
            "max_distance": max_distance,
            "vertical": vertical,
            "classes": (classes or [2]) if vertical else None,
            "source_id": source_id,
            "max_edge": results.get("vertical", {}).get("max_edge") if vertical else None,
            "checkpoint_rmse_h": checkpoint_rmse_h,
            "checkpoint_rmse_v": checkpoint_rmse_v,
            "output": output,
            "crs": crs_name(crs_used),
        },
        results=results,
        cat_opts=cat_opts,
    )


def _summary(r: dict, vertical: bool) -> None:
    from ..report.analyses.checkpoints import checkpoint_tables

    echo_tables(*checkpoint_tables(r, vertical))
    for w in r["warnings"]:
        echo(f"warning: {w}")
