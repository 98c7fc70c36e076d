"""``lidarqa planes``, ``lidarqa edges`` and ``lidarqa corners``: plane segmentation products."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from ._catalog import (
    catalog_options,
    finish_run,
    open_catalog_source,
    pop_catalog_options,
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
    input_crs,
    output_option,
    prepare_outputs,
    settings,
    source_id_option,
)

_OUT_SUFFIXES = (".csv", ".gpkg", ".geojson", ".json")


def _selection_options(func: Callable[..., Any]) -> Callable[..., Any]:
    opts: list[Callable[..., Any]] = [
        click.argument("paths", nargs=-1, required=True, type=click.Path()),
        output_option("Output file: .csv, .gpkg or .geojson (by extension).", required=True),
        classes_option,
        source_id_option,
        click.option("--grow-radius", type=float, default=None,
                     help="Surface growing: neighbourhood radius (m) [default: 2x the point "
                          "spacing, 0.5-3 m]."),
        click.option("--grow-dist", type=float, default=0.2, show_default=True,
                     help="Surface growing: largest distance of a point to the segment plane (m)."),
        click.option("--seed-method", type=click.Choice(["pca", "hough", "ransac"]), default="pca",
                     show_default=True, help="How seed planes are found."),
        click.option("--min-segment-size", type=int, default=30, show_default=True,
                     help="Smallest planar segment kept (points)."),
        click.option("--max-rmse", type=float, default=0.15, show_default=True,
                     help="Drop segments whose plane RMS residual exceeds this (m)."),
        crs_option,
    ]
    for opt in reversed(opts):
        func = opt(func)
    return catalog_options(func)


def _run(kind: str, paths: tuple[str, ...], output: str, classes: Any, source_id: Any,
         opts: dict[str, Any], options: dict[str, Any]) -> None:
    """One job for one file (one region) and a catalog (chunks with buffers).

    Each feature is kept once, by the chunk whose core holds its anchor.
    """
    from ..errors import InvalidPointsError
    from ..io.crs import crs_name, require_metric_xy
    from ..io.vector import metric_lengths, write_points, write_segments
    from ..tiling.jobs_api import catalog_features
    from ..tiling.source import Selection

    cat = pop_catalog_options(opts)
    on_catalog = wants_catalog(paths, cat)
    _check_suffix(output)
    prepare_outputs(output, inputs=tuple(paths))
    crs = input_crs(opts.pop("crs", None))
    source = open_catalog_source(paths, cat, crs=crs, z_to_metres=False)
    # fitted in metres: x, y in feet or degrees mixed with z in metres would distort them
    require_metric_xy(source.crs, source.label, "planes, edges and corners need")
    run = run_job(catalog_features, source, cat, on_catalog, kind=kind, classes=classes,
                  source_id=source_id, options={**opts, **options})
    extra: dict[str, Any] = run.extra  # the job's details
    f, s = run.value, extra["summary"]
    if s["n_points"] < 3:
        what = Selection.of(classes, source_id).describe()
        raise InvalidPointsError(f"{source.label}: {s['n_points']} point(s)"
                                 + (f" with {what}" if what else "") + "; at least 3 are needed")
    with Steps()(f"Writing {output}"), reproducible_vectors():
        write = write_segments if kind == "edges" else write_points
        write(f, output, overwrite=settings().overwrite, layer=kind)
    n_edge = int(np.sum(f.attributes["at_buffer_edge"])) if "at_buffer_edge" in f.attributes \
        else 0
    if n_edge:
        click.echo(f"Warning: {n_edge} of {len(f)} {kind} come from planes that reach a chunk's "
                   "buffer edge (column at_buffer_edge): a roof wider than --buffer may be cut "
                   "there; widen --buffer", err=True)
    a = f.attributes
    left = s["left_out"]
    results: dict[str, Any] = {f"n_{kind}": len(f), "n_planes": s["n_planes"],
                               "n_adjacent_pairs": s["n_adjacent_pairs"]}
    if kind == "planes":
        tilt = np.degrees(np.arccos(np.clip(a["nz"], -1, 1)))
        results.update({
            "n_points": s["n_points"], "n_segments": len(f),
            "n_segmented_points": s["n_segmented_points"],
            "segmented_fraction": s["n_segmented_points"] / max(s["n_points"], 1),
            **({"rmse_median_m": float(np.median(a["rmse"])),
                "points_per_segment_median": float(np.median(a["n_points"]))} if len(f) else {}),
            "rmse_m": _stats(a["rmse"]), "n_points_per_plane": _stats(a["n_points"]),
            "n_horizontal": int((tilt < 10).sum()), "n_vertical": int((tilt > 80).sum())})
        said = (f"{len(f)} planes from {s['n_points']:,} points "
                f"({results['segmented_fraction']:.1%} segmented), {s['n_adjacent_pairs']} "
                "adjacent pairs")
    elif kind == "edges":
        lengths = metric_lengths(f)
        results.update({"total_length_m": float(lengths.sum()),
                        "length_m": _stats(lengths), "sigma_line_m": _stats(a["sigma_line"]),
                        "angle_deg": _stats(a["angle_deg"]), "skipped": left})
        said = (f"{len(f)} edges ({results['total_length_m']:.1f} m) from {s['n_planes']} "
                f"planes; {sum(left.values())} adjacent pairs skipped")
    else:
        sig = np.sqrt(a["sigma_x"] ** 2 + a["sigma_y"] ** 2 + a["sigma_z"] ** 2) if len(f) \
            else np.zeros(0)
        results.update({"refused": left, "sigma_3d_m": _stats(sig), "det": _stats(a["det"])})
        said = (f"{len(f)} corners from {s['n_planes']} planes; {sum(left.values())} triples "
                "refused")
    per_chunk = Counter(a["chunk"].tolist()) if len(f) else Counter()
    results.update({"output": output, "n_at_buffer_edge": n_edge,
                    "per_chunk": dict(sorted(per_chunk.items()))})
    echo(said + (f" ({', '.join(f'{k}: {v}' for k, v in left.items())})" if left else "")
         + f" -> {output}")
    finish_run(kind, run, on_catalog, record=True, cat_opts=cat,
               inputs={"paths": list(paths), **({} if on_catalog else {"path": paths[0]}),
                       "classes": classes, "source_id": source_id,
                       "n_points_selected": s["n_points"], "crs": crs_name(source.crs)},
               parameters={**s["parameters"], **extra["segment_options"], **extra["options"],
                           "rule": "anchor-in-core (corner point, edge midpoint, plane centroid)"},
               results=results)


def _check_suffix(output: str) -> None:
    from ..errors import OptionError

    if Path(output).suffix.lower() not in _OUT_SUFFIXES:
        raise OptionError(f"output {output}: use a .csv, .gpkg or .geojson file name")


def _stats(values: np.ndarray) -> dict[str, Any]:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if not len(v):
        return {"min": None, "median": None, "max": None}
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}


@click.command()
@_selection_options
@common_options
def planes(paths: tuple[str, ...], output: str, classes: list[int] | None,
           source_id: list[int] | None, **opts: Any) -> None:
    """Segment a point cloud into planes; write one point per plane (at its centroid).

    Columns: id, x, y, z (centroid), nx, ny, nz, rho (n·p = rho), n_points,
    n_inliers, rmse (m), sigma_rho (m), sigma_normal_deg, n_adjacent.

    PATHS is one file, or a catalog (several files, a folder, a glob, a .vpc):
    then the area is cut into chunks with buffers and a plane is kept by the
    chunk whose core holds its centroid (column ``chunk``), so it is reported once.
    """
    _run("planes", paths, output, classes, source_id, opts, {})


@click.command()
@_selection_options
@click.option("--near-dist", type=float, default=None,
              help="Points within this distance (m) of the intersection line support it "
                   "[default: 1.2x the point spacing, 0.15-1 m].")
@click.option("--min-angle", type=float, default=10.0, show_default=True,
              help="Plane pairs closer than this angle (degrees) give no edge.")
@click.option("--min-length", type=float, default=0.5, show_default=True,
              help="Drop edges shorter than this (m).")
@common_options
def edges(paths: tuple[str, ...], output: str, classes: list[int] | None,
          source_id: list[int] | None, near_dist: float, min_angle: float, min_length: float,
          **opts: Any) -> None:
    """Extract 3D edges: intersections of adjacent planes bounded by their points.

    CSV columns: id,x1,y1,z1,x2,y2,z2, plane_a, plane_b, angle_deg, support_a,
    support_b, sigma_line (m, at the midpoint), sigma_line_max, length (m).

    PATHS is one file, or a catalog (several files, a folder, a glob, a .vpc):
    then an edge is kept by the chunk whose core holds its midpoint (column
    ``chunk``), so an edge crossing a chunk border is reported once.
    """
    from .._validate import check_positive, check_range

    if near_dist is not None:
        check_positive(near_dist, "--near-dist")
    check_range(min_angle, "--min-angle", 0.0, 90.0)
    check_positive(min_length, "--min-length", allow_zero=True)
    _run("edges", paths, output, classes, source_id, opts,
         {"near_dist": near_dist, "min_angle": min_angle, "min_length": min_length})


@click.command()
@_selection_options
@click.option("--min-det", type=float, default=0.1, show_default=True,
              help="Smallest |det| of the three unit normals (dimensionless, 0..1; conditioning).")
@click.option("--min-angle", type=float, default=10.0, show_default=True,
              help="Smallest angle (degrees) between any two of the three planes.")
@click.option("--max-dist", type=float, default=1.0, show_default=True,
              help="The corner must lie within this distance (m) of each plane's points.")
@common_options
def corners(paths: tuple[str, ...], output: str, classes: list[int] | None,
            source_id: list[int] | None, min_det: float, min_angle: float, max_dist: float,
            **opts: Any) -> None:
    """Extract corners: intersections of three mutually adjacent planes.

    CSV columns: id,x,y,z, plane_a, plane_b, plane_c, det, min_angle_deg,
    sigma_x, sigma_y, sigma_z (m).

    PATHS is one file, or a catalog (several files, a folder, a glob, a .vpc):
    then a corner is kept by the chunk whose core holds it (column ``chunk``).
    """
    from .._validate import check_positive, check_range

    check_range(min_det, "--min-det", 0.0, 1.0)
    check_range(min_angle, "--min-angle", 0.0, 90.0)
    check_positive(max_dist, "--max-dist")
    _run("corners", paths, output, classes, source_id, opts,
         {"min_det": min_det, "min_angle": min_angle, "max_dist": max_dist})
