"""``lidarqa heights``: predicted height precision of map points, tested against references."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any

import click
import numpy as np
from click.core import ParameterSource

from ..accuracy.heights import (
    CURVATURE,
    MAX_RADIUS,
    MIN_POINTS,
    RADIUS,
    SIGMA_GPS,
    SIGMA_INS,
    SIGMA_POINT,
    SIGMA_REF,
    SIGMA_STRIP,
)
from ._catalog import (
    catalog_engine,
    catalog_options,
    finish_run,
    job_options,
    open_catalog_source,
    reproducible_vectors,
    wants_catalog,
)
from ._common import (
    Steps,
    classes_option,
    common_options,
    crs_option,
    echo,
    echo_tables,
    finish,
    input_crs,
    output_option,
    prepare_outputs,
    settings,
    source_id_option,
)

OUT_SUFFIXES = (".csv", ".gpkg", ".geojson")  # GeoJSON: unfitted map points are written 2D


def _read_reference(path: str, crs: Any = None) -> Any:
    from ..io.vector import PointSet, read_points

    p = Path(path)
    if p.is_file() and p.stat().st_size == 0:  # an empty file: no reference points
        return PointSet(ids=np.empty(0, dtype=np.int64), xyz=np.empty((0, 3)), crs=crs)
    return read_points(p, require_z=True, crs=crs)


def _ids(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind in "iu" and b.dtype.kind in "iu":
        return np.concatenate([a.astype(np.int64), b.astype(np.int64)])
    return np.concatenate([a.astype(str), b.astype(str)]).astype(object)


_ZERO_PADDED = ("n_points", "failed", "outlier", "inside")  # counts and flags (0/1)


def _column(name: str, values: Any, before: int, after: int) -> np.ndarray:
    """`values` with empty rows before and after: NaN, 0 for counts and flags, '' for reasons."""
    v = np.asarray(values)
    if name == "reason":
        return np.concatenate([np.full(before, ""), v.astype(str), np.full(after, "")]).astype(
            object)
    if name in _ZERO_PADDED:
        v = v.astype(np.int64) if v.dtype == bool else v
        return np.concatenate([np.zeros(before, dtype=np.int64), v,
                               np.zeros(after, dtype=np.int64)])
    return np.concatenate([np.full(before, np.nan), v, np.full(after, np.nan)])


def _output_rows(mp: Any, map_xy: Any, ref_xyz: Any, ref_cols: dict[str, Any], ids: Any,
                 crs: Any, map_fields: tuple[str, ...], **first: Any) -> Any:
    """One row per map point (its fit) then per reference point (its test), as a PointSet."""
    from ..io.vector import PointSet

    m, r = len(mp), len(ref_xyz)
    attrs = {"kind": np.array(["map"] * m + ["reference"] * r, dtype=object), **first}
    attrs.update({k: _column(k, getattr(mp, k), 0, r) for k in map_fields})
    attrs.update({k: _column(k, v, m, 0) for k, v in ref_cols.items()})
    xyz = np.vstack([np.column_stack([map_xy, mp.height]), ref_xyz]).reshape(-1, 3)
    return PointSet(ids=ids, xyz=xyz, attributes=attrs, crs=crs)


_MAP_FIELDS = ("height", "sigma", "sigma_plane", "sigma_block", "sigma_model", "n_points")


class _SigmaStrip(click.ParamType):
    name = "FLOAT|auto"

    def convert(self, value: Any, param: Any, ctx: Any) -> float | str:
        if isinstance(value, float) or value == "auto":
            return value
        try:
            return float(value)
        except (TypeError, ValueError):
            self.fail(f"expected a number (m) or 'auto', got {value!r}", param, ctx)


def _measured_e4(source: Any, run_opts: dict[str, Any]) -> float:
    """E4 from the overlaps of the source's strips (ground and buildings, last returns).

    The ``lidarqa swaths --by-source-id`` job on the same source (a file or a catalog).
    """
    from ..errors import DegenerateGeometryError, EstimationError, InvalidPointsError
    from ..tiling.jobs_swaths import catalog_swaths

    try:
        rep = catalog_swaths(source.select(), by_source_id=True, return_grids=False,
                             **run_opts).value
    except (InvalidPointsError, DegenerateGeometryError) as exc:
        raise type(exc)(f"--sigma-strip auto: {exc}") from exc
    if not np.isfinite(rep.e4):
        raise EstimationError(
            "--sigma-strip auto: the strip offsets could not be estimated ("
            + "; ".join(rep.flags or ("too few matched planes",))
            + ")"
        )
    return float(rep.e4)


def laser_noise_options(func: Any) -> Any:
    """The options of the plane fits and the laser block, shared by ``heights`` and ``roads``.

    ``--radius --max-radius --min-points`` and the error budget ``--sigma-point
    --sigma-gps --sigma-ins`` (E1–E3 of Oude Elberink & Vosselman).
    """
    for opt in reversed(
        [
            click.option("--radius", type=float, default=RADIUS, show_default=True,
                         help="First search radius for laser points around a map point (m)."),
            click.option("--max-radius", type=float, default=MAX_RADIUS, show_default=True,
                         help="The radius grows (x2 per step) up to this until --min-points "
                              "are found (m)."),
            click.option("--min-points", type=int, default=MIN_POINTS, show_default=True,
                         help="Laser points needed for a plane fit; map points with fewer are "
                              "flagged."),
            click.option(
                "--sigma-point",
                type=float,
                default=SIGMA_POINT,
                show_default=True,
                help="E1: laser point height noise (m).",
            ),
            click.option(
                "--sigma-gps", type=float, default=SIGMA_GPS, show_default=True,
                help="E2: GPS noise (m).",
            ),
            click.option(
                "--sigma-ins", type=float, default=SIGMA_INS, show_default=True,
                help="E3: INS noise (m).",
            ),
        ]
    ):
        func = opt(func)
    return func


@click.command()
@click.argument("cloud", type=click.Path())
@click.argument("map_path", metavar="MAP", type=click.Path())
@click.argument("reference", type=click.Path())
@laser_noise_options
@click.option(
    "--sigma-strip",
    type=_SigmaStrip(),
    default=SIGMA_STRIP,
    show_default=True,
    help="E4: strip adjustment noise (m), or 'auto': measured from the CLOUD's overlapping "
    "strips (point_source_id), as in 'lidarqa swaths'.",
)
@click.option(
    "--sigma-ref",
    type=float,
    default=SIGMA_REF,
    show_default=True,
    help="Reference height noise (m).",
)
@click.option(
    "--curvature",
    type=float,
    default=CURVATURE,
    show_default=True,
    help="Maximum surface curvature (1/m) for the model term κ·s²/6; 0 = off.",
)
@click.option(
    "--correlation",
    type=float,
    default=0.0,
    show_default=True,
    help="Correlation between the heights of the three TIN vertices (0..1).",
)
@click.option(
    "--alpha",
    type=float,
    default=0.001,
    show_default=True,
    help="Significance level of the w-tests (0..1; 0.001 -> critical value 3.29).",
)
@classes_option(help="Use only laser points of these classes, e.g. 2 or 2,11.")
@source_id_option
@click.option(
    "--spacing",
    type=float,
    default=10.0,
    show_default=True,
    help="Distance between map points along polygon boundaries (m; polygon MAP).",
)
@click.option(
    "--eq8",
    "eq8_diagonal",
    is_flag=True,
    help="σ_plane by the paper's eq. 8 (no p1-p2 covariance) instead of the full form.",
)
@click.option(
    "--posterior",
    is_flag=True,
    help="Laser noise from each plane fit's residuals instead of --sigma-point.",
)
@click.option(
    "--estimate-offset",
    is_flag=True,
    help="Data snooping re-estimates a common height offset on each pass.",
)
@click.option(
    "--largest-segment",
    is_flag=True,
    help="Fit only the laser points of the largest surface-growing segment.",
)
@output_option("Per-point output (.csv, .gpkg or .geojson, layer 'heights'): a row per map "
               "point and per reference point, told apart by the 'kind' column.")
@crs_option
@catalog_options
@common_options
def heights(
    cloud: str,
    map_path: str,
    reference: str,
    radius: float,
    max_radius: float,
    min_points: int,
    sigma_point: float,
    sigma_gps: float,
    sigma_ins: float,
    sigma_strip: float | str,
    sigma_ref: float,
    curvature: float,
    correlation: float,
    alpha: float,
    classes: list[int] | None,
    source_id: list[int] | None,
    spacing: float,
    eq8_diagonal: bool,
    posterior: bool,
    estimate_offset: bool,
    largest_segment: bool,
    output: str | None,
    crs: str | None,
    **cat_opts: Any,
) -> None:
    """Height quality of map points by error propagation, tested with w-tests.

    Each map point (MAP: a point list id,x,y[,z], or polygons whose boundaries
    get a point every --spacing m) gets a height from a plane fitted to the
    CLOUD's laser points around it and a predicted σ (plane + laser block +
    model). Heights and σ are interpolated in a TIN of the map points to the
    REFERENCE points (id,x,y,z), and Δh/σ_Δh is w-tested (Oude Elberink &
    Vosselman). With road polygons as MAP the 3D roads are reconstructed first
    (as by ``lidarqa roads``): each polygon gets the laser points of its own
    height level, and each reference point is tested against the level it
    lies on, so a point on a road under a bridge is not compared with the deck
    (--correlation, --eq8, --posterior and --largest-segment apply to point maps
    only; the roads are reconstructed in one piece, in this process:
    --chunk-size, --buffer, --workers, --scheduler and --resume serve
    --sigma-strip auto only).

    CLOUD may be a catalog (a folder, a glob, a .vpc): each map point is
    fitted, and each reference point interpolated, in the chunk whose core
    holds it (the buffer must exceed --max-radius plus the map point spacing);
    the w-tests then run once over all reference points, as for one file.
    """
    from ..accuracy.heights import read_map_points
    from ..errors import OptionError
    from ..io.crs import require_metric_xy
    from ..tiling.jobs_api import catalog_heights

    if output is not None and Path(output).suffix.lower() not in OUT_SUFFIXES:
        raise OptionError(f"--output must end in {', '.join(OUT_SUFFIXES)}; got {output!r}")
    given = input_crs(crs)
    polygons = _is_polygon_map(map_path)
    source_of = click.get_current_context().get_parameter_source
    point_only = [o for o, on in (
        ("--correlation", source_of("correlation") not in (None, ParameterSource.DEFAULT)),
        ("--eq8", eq8_diagonal), ("--posterior", posterior),
        ("--largest-segment", largest_segment)) if on and polygons]
    if point_only:
        raise OptionError(f"{', '.join(point_only)}: for a point MAP only ({map_path} holds road "
                          "polygons)")
    prepare_outputs(output, inputs=(cloud, map_path, reference))
    steps = Steps()
    # one job for a file (one region: the in-memory run) and a catalog; heights in metres
    on_catalog = wants_catalog((cloud,), cat_opts)
    source = open_catalog_source([cloud], cat_opts, crs=given)
    native = source.native_crs
    require_metric_xy(native, cloud, "the search radius and the plane fits need")
    engine = catalog_engine(cat_opts) if on_catalog else contextlib.nullcontext()
    with engine as eng:
        run_opts = job_options(cat_opts, eng) if on_catalog else {}
        sigma_strip_source = "given"
        if sigma_strip == "auto":
            with steps("Measuring E4 from the strip overlaps"):
                sigma_strip = _measured_e4(source, run_opts)
            sigma_strip_source = "measured (strip offsets)"
            echo(f"E4 (σ_strip) measured from the strip overlaps: {sigma_strip:.3f} m")
        # options shared by the point-map and the road-level (polygon) paths
        common: dict[str, Any] = dict(
            radius=radius, max_radius=max_radius, min_points=min_points,
            sigma_point=sigma_point, sigma_gps=sigma_gps, sigma_ins=sigma_ins,
            sigma_strip=sigma_strip, sigma_ref=sigma_ref, curvature=curvature, alpha=alpha,
            estimate_offset=estimate_offset,
        )
        if polygons:  # the catalog options served the E4 job, if any; else the roads take them
            return _heights_by_levels(
                steps, source.select(classes=classes, source_id=source_id), cloud, map_path,
                _read_reference(reference, given), reference, output, classes=classes,
                source_id=source_id, spacing=spacing,
                run_opts=run_opts if sigma_strip_source == "given" else {}, **common,
            )  # fmt: skip
        with steps("Reading map and reference points"):
            mp = read_map_points(map_path, spacing=spacing, crs=given)
            ref = _read_reference(reference, given)
        options: dict[str, Any] = dict(
            common, correlation=correlation, eq8_diagonal=eq8_diagonal, posterior=posterior,
            largest_segment=largest_segment,
        )
        with steps(f"Fitting {len(mp):,} map points, testing {len(ref):,} reference points"):
            run = catalog_heights(source, mp, ref, classes=classes,
                                  source_id=source_id, options=options, **run_opts)
    report = run.value
    done = report.to_dict()
    n_fitted = done["map_points"]["n"] - done["map_points"]["n_failed"]
    if n_fitted == 0 or (len(ref) and done["comparison"]["n"] == 0):
        # Nothing to measure is an error (exit 1), never a table of n/a with exit 0. An
        # empty reference file is allowed: the map points' sigmas are then the result.
        from ..errors import NothingToMeasureError

        raise NothingToMeasureError(
            f"none of the {len(mp):,} map point(s) could be fitted"
            + (" (are there laser points with "
               + " ".join(f"--{k} {','.join(map(str, v))}" for k, v in
                          (("classes", classes), ("source-id", source_id)) if v) + "?)"
               if classes or source_id else "")
            if n_fitted == 0
            else f"none of the {len(ref):,} reference point(s) could be compared "
            f"({report.n_outside:,} outside the TIN of the fitted map points); do the map and "
            "reference points lie inside the cloud, in the same CRS?"
        )
    if output is not None:
        _write_output(steps, output, _output_rows(
            report.map_points, report.map_points.xy, report.reference_xyz,
            {"model_height": report.tin.height, "model_sigma": report.tin.sigma,
             "dh": report.dh, "sigma_dh": report.sigma_dh, "w": report.w_values,
             "outlier": report.outlier, "inside": report.inside},
            _ids(mp.ids, ref.ids), native or mp.crs or ref.crs,
            (*_MAP_FIELDS, "radius", "distance", "failed", "reason")))
    res = report.to_dict()
    from ..report.analyses.heights import heights_tables

    echo_tables(*heights_tables(res["map_points"], res["comparison"], res["w"],
                                n_reference=len(ref), n_outside=report.n_outside))
    if report.flags:
        echo("flags             " + ", ".join(report.flags))
    params = dict(report.parameters)
    params.update(
        classes=classes,
        source_id=source_id,
        spacing=spacing,
        crs=crs,
        sigma_strip_source=sigma_strip_source,
    )
    finish_run("heights", run, on_catalog, parameters=params, results=res, cat_opts=cat_opts,
               inputs={"cloud": cloud, "map": map_path, "reference": reference, "output": output})


def _write_output(steps: Any, output: str, rows: Any) -> None:
    """Write the --output of either path, the same bytes run to run (fixed GeoPackage time)."""
    from ..io.vector import write_points

    with steps("Writing " + output), reproducible_vectors():
        write_points(rows, output, overwrite=settings().overwrite, layer="heights")


def _is_polygon_map(path: str) -> bool:
    p = Path(path)
    if p.suffix.lower() not in (".gpkg", ".geojson", ".json") or not p.is_file():
        return False
    try:
        import pyogrio

        return "polygon" in str(pyogrio.read_info(str(p)).get("geometry_type") or "").lower()
    except Exception:
        return False


def _heights_by_levels(
    steps: Any,
    source: Any,
    cloud: str,
    map_path: str,
    ref: Any,
    reference: str,
    output: str | None,
    *,
    classes: Any,
    source_id: Any,
    spacing: float,
    alpha: float,
    sigma_ref: float,
    estimate_offset: bool,
    run_opts: dict[str, Any],
    **opts: Any,
) -> None:
    """``lidarqa heights`` with road polygons: test each reference point on its own level.

    `run_opts` are the catalog options (the roads job refuses those it cannot honour).
    """
    from ..tiling.jobs_api import catalog_roads

    with steps(f"Reconstructing the roads of {map_path} from {cloud}, testing "
               f"{len(ref):,} reference points on their levels"):
        run = catalog_roads(source, map_path, reference=ref, classes=classes,
                            source_id=source_id, options=dict(opts, spacing=spacing),
                            compare_options=dict(sigma_ref=sigma_ref, alpha=alpha,
                                                 estimate_offset=estimate_offset), **run_opts)
    extra: dict[str, Any] = run.extra
    rec, comp, ref_xyz = run.value, extra["comparison"], extra["reference_xyz"]
    mp = rec.map_points
    if output is not None:
        _write_output(steps, output, _output_rows(
            mp, mp.xy_laser, ref_xyz,
            {"model_height": comp.height, "model_sigma": comp.sigma, "dh": comp.comparison.dh,
             "sigma_dh": comp.comparison.sigma_dh, "w": comp.w.w, "outlier": comp.w.outlier},
            _ids(np.arange(len(mp)), ref.ids), run.extra["crs"] or ref.crs,
            (*_MAP_FIELDS, "failed", "reason"), road=np.concatenate([mp.road, comp.road])))
    res_roads = rec.to_dict()
    res = comp.to_dict()
    from ..report.analyses.heights import heights_tables

    dx, dy = res_roads["shift"]
    echo(
        f"road levels       {res_roads['n_roads']:,} road(s) from "
        f"{run.extra['n_polygons']:,} polygons; map shift dx {dx:+.3f} m, dy {dy:+.3f} m"
    )
    echo_tables(*heights_tables(
        {"n": res_roads["n_map_points"], "n_failed": res_roads["n_failed"],
         "sigma_mean": res_roads["sigma_mean"], "sigma_p95": res_roads["sigma_p95"]},
        res["comparison"], res["w"], n_reference=len(ref)))
    params = dict(rec.parameters)
    params.update(classes=classes, sigma_ref=sigma_ref, alpha=alpha, levels=True)
    finish(
        "heights",
        inputs={"cloud": cloud, "map": map_path, "reference": reference, "output": output},
        parameters=params,
        results={"roads": res_roads, **res},
    )
