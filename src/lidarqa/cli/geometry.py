"""``lidarqa planes``, ``lidarqa edges`` and ``lidarqa corners``: plane segmentation products."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from ._catalog import (
    catalog_engine,
    catalog_options,
    echo_run,
    failed_exit,
    job_options,
    open_catalog_source,
    pop_catalog_options,
    reproducible_vectors,
    run_summary,
    wants_catalog,
)
from ._common import (
    Steps,
    classes_option,
    common_options,
    crs_option,
    echo,
    finish,
    input_crs,
    prepare_outputs,
    settings,
    source_id_option,
)

_OUT_SUFFIXES = (".csv", ".gpkg", ".geojson", ".json")


def _selection_options(func: Callable[..., Any]) -> Callable[..., Any]:
    opts: list[Callable[..., Any]] = [
        click.argument("paths", nargs=-1, required=True, type=click.Path()),
        click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                     help="Output file: .csv, .gpkg or .geojson (by extension)."),
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


_SEGMENT_KEYS = ("grow_radius", "grow_dist", "seed_method", "min_segment_size", "max_rmse")


def _on_catalog(kind: str, paths: tuple[str, ...], output: str, classes: Any, source_id: Any,
                opts: dict[str, Any], options: dict[str, Any]) -> bool:
    """Run on a catalog (several files, a folder, a glob, a .vpc); False for one file.

    Each feature is kept once, by the chunk whose core holds its anchor.
    """
    from ..io.vector import write_points, write_segments
    from ..tiling.jobs_api import catalog_features

    cat = pop_catalog_options(opts)
    if not wants_catalog(paths, cat):
        return False
    _check_suffix(output)
    prepare_outputs(output, inputs=tuple(paths))
    source = open_catalog_source(paths, cat, crs=input_crs(opts.get("crs")), z_to_metres=False)
    with catalog_engine(cat) as eng:
        run = catalog_features(source, kind=kind, classes=classes, source_id=source_id,
                               segment_options={k: opts[k] for k in _SEGMENT_KEYS if k in opts},
                               options=options, **job_options(cat, eng))
    f = run.value
    with Steps()(f"Writing {output}"), reproducible_vectors():
        write = write_segments if kind == "edges" else write_points
        write(f, output, overwrite=settings().overwrite, layer=kind)
    results: dict[str, Any] = {f"n_{kind}": len(f), "output": output, "catalog": run_summary(run)}
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
    extra: dict[str, Any] = run.extra  # the job's details
    echo(f"{len(f)} {kind} from {len(run.catalog.tiles)} tile(s) -> {output}")
    echo_run(run)
    c = run.chunks[0] if run.chunks else None
    finish(kind, inputs={"paths": list(paths), "classes": classes, "source_id": source_id},
           parameters={**extra.get("segment_options", {}), **extra.get("options", {}),
                       "chunk_size": c.size if c else None,
                       "buffer": (c.buffered[2] - c.core[2]) if c else None,
                       "workers": cat.get("workers"), "scheduler": cat.get("scheduler"),
                       "rule": "anchor-in-core (corner point, edge midpoint, plane centroid)"},
           results=results)
    failed_exit(run)
    return True


def _one(paths: tuple[str, ...]) -> str:
    """The single file of a non-catalog run."""
    return paths[0]


def _check_suffix(output: str) -> None:
    from ..errors import OptionError

    if Path(output).suffix.lower() not in _OUT_SUFFIXES:
        raise OptionError(f"output {output}: use a .csv, .gpkg or .geojson file name")


def _load(path: str, classes: list[int] | None, source_id: list[int] | None, steps: Steps,
          crs: str | None = None):
    """Read and select; return (cloud selection, xyz in metres, z factor)."""
    from ..errors import InvalidPointsError
    from ..io import read
    from ..io.crs import require_metric_xy, z_to_metres_factor

    given = input_crs(crs)
    with steps(f"Reading {path}"):
        cloud = read(path, crs=given)
    sub = cloud.select(classes=classes, source_id=source_id) if (classes or source_id) else cloud
    if len(sub) < 3:
        what = []
        if classes:
            what.append(f"classes {','.join(map(str, classes))}")
        if source_id:
            what.append(f"source ids {','.join(map(str, source_id))}")
        sel = (" with " + " and ".join(what)) if what else ""
        raise InvalidPointsError(f"{path}: {len(sub)} point(s){sel}; at least 3 are needed")
    # fitted in metres: x, y in feet or degrees mixed with z in metres would distort them
    require_metric_xy(sub.crs, path, "planes, edges and corners need")
    f = z_to_metres_factor(sub.crs) if sub.crs is not None else 1.0
    xyz = sub.xyz.copy()
    if f != 1.0:
        xyz[:, 2] *= f
    return sub, xyz, f


def _auto(path: str, sub: Any, kind: str, opts: dict, options: dict) -> tuple[dict, dict]:
    """Data-driven defaults (growing radius, support distance) of the central sample window.

    The catalog run measures them there too, so a file and a folder of its tiles get the
    same ones.
    """
    from ..tiling.jobs_vector import fixed_auto_options
    from ..tiling.source import open_source, sample_points

    bounds = open_source(path, z_to_metres=False).area_bounds  # headers only for LAS/LAZ
    seg = {k: opts[k] for k in _SEGMENT_KEYS if k in opts}
    return fixed_auto_options(sample_points(sub.xyz, bounds), kind=kind, segment_options=seg,
                              options=options)


def _segment(xyz: np.ndarray, opts: dict, steps: Steps):
    from ..geometry.segmentation import segment_planes

    with steps(f"Segmenting {len(xyz):,} points into planes") as progress:
        return segment_planes(xyz, grow_radius=opts["grow_radius"], grow_dist=opts["grow_dist"],
                              seed_method=opts["seed_method"],
                              min_segment_size=opts["min_segment_size"], max_rmse=opts["max_rmse"],
                              progress=progress)


def _stats(values: np.ndarray) -> dict[str, Any]:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if not len(v):
        return {"min": None, "median": None, "max": None}
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}


def _inputs(path: str, classes: Any, source_id: Any, n: int, crs: Any) -> dict[str, Any]:
    from ..io.crs import crs_name

    return {"path": path, "classes": classes, "source_id": source_id, "n_points_selected": n,
            "crs": crs_name(crs) if crs is not None else None}


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
    from ..io.vector import PointSet, write_points

    if _on_catalog("planes", paths, output, classes, source_id, opts, {}):
        return
    path = _one(paths)
    _check_suffix(output)
    prepare_outputs(output, inputs=(path,))
    steps = Steps()
    sub, xyz, f = _load(path, classes, source_id, steps, opts.pop("crs", None))
    opts["grow_radius"] = _auto(path, sub, "planes", opts, {})[0]["grow_radius"]
    seg = _segment(xyz, opts, steps)
    cen = seg.centroid.copy()
    cen[:, 2] /= f
    deg = np.bincount(seg.adjacency.ravel(), minlength=seg.n_segments) if seg.n_segments else \
        np.zeros(0, dtype=np.int64)
    sn = np.sqrt(np.maximum(np.trace(seg.covariance[:, :3, :3], axis1=1, axis2=2), 0.0))
    ps = PointSet(ids=np.arange(seg.n_segments, dtype=np.int64), xyz=cen, crs=sub.crs, attributes={
        "nx": seg.normal[:, 0], "ny": seg.normal[:, 1], "nz": seg.normal[:, 2], "rho": seg.rho,
        "n_points": seg.n_points, "n_inliers": seg.n_inliers, "rmse": seg.rmse,
        "sigma_rho": seg.sigma_rho, "sigma_normal_deg": np.degrees(sn), "n_adjacent": deg})
    with steps(f"Writing {output}"):
        write_points(ps, output, overwrite=settings().overwrite, layer="planes")
    d = seg.to_dict()
    tilt = np.degrees(np.arccos(np.clip(seg.normal[:, 2], -1, 1)))
    results = {**{k: v for k, v in d.items() if k != "parameters"},
               "rmse_m": _stats(seg.rmse), "n_points_per_plane": _stats(seg.n_points),
               "n_horizontal": int((tilt < 10).sum()), "n_vertical": int((tilt > 80).sum()),
               "output": output}
    echo(f"{seg.n_segments} planes from {len(xyz):,} points "
         f"({d['segmented_fraction']:.1%} segmented), {len(seg.adjacency)} adjacent pairs "
         f"-> {output}")
    finish("planes", inputs=_inputs(path, classes, source_id, len(xyz), sub.crs),
           parameters=d["parameters"], results=results)


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
    from ..geometry.edges import edges_from_segmentation
    from ..io.vector import write_segments

    _check_suffix(output)
    if near_dist is not None:
        check_positive(near_dist, "--near-dist")
    check_range(min_angle, "--min-angle", 0.0, 90.0)
    check_positive(min_length, "--min-length", allow_zero=True)
    if _on_catalog("edges", paths, output, classes, source_id, opts,
                   {"near_dist": near_dist, "min_angle": min_angle, "min_length": min_length}):
        return
    path = _one(paths)
    prepare_outputs(output, inputs=(path,))
    steps = Steps()
    sub, xyz, f = _load(path, classes, source_id, steps, opts.pop("crs", None))
    seg_auto, e_auto = _auto(path, sub, "edges", opts, {"near_dist": near_dist})
    opts["grow_radius"], near_dist = seg_auto["grow_radius"], e_auto["near_dist"]
    seg = _segment(xyz, opts, steps)
    with steps("Intersecting adjacent planes"):
        e, skipped = edges_from_segmentation(xyz, seg, near_dist=near_dist, min_angle=min_angle,
                                             min_length=min_length, crs=sub.crs)
    if f != 1.0:
        e.start[:, 2] /= f
        e.end[:, 2] /= f
    with steps(f"Writing {output}"):
        write_segments(e, output, overwrite=settings().overwrite, layer="edges")
    reasons = Counter(s["reason"] for s in skipped)
    if near_dist is None:
        from ..geometry.edges import auto_near_dist

        near_dist = auto_near_dist(seg)
    results = {"n_planes": seg.n_segments, "n_adjacent_pairs": int(len(seg.adjacency)),
               "n_edges": len(e), "total_length_m": float(e.lengths.sum()) if len(e) else 0.0,
               "length_m": _stats(e.lengths), "sigma_line_m": _stats(e.attributes["sigma_line"]),
               "angle_deg": _stats(e.attributes["angle_deg"]), "skipped": dict(reasons),
               "output": output}
    echo(f"{len(e)} edges ({results['total_length_m']:.1f} m) from {seg.n_segments} planes; "
         f"{len(skipped)} adjacent pairs skipped"
         + (f" ({', '.join(f'{k}: {v}' for k, v in reasons.items())})" if reasons else "")
         + f" -> {output}")
    finish("edges", inputs=_inputs(path, classes, source_id, len(xyz), sub.crs),
           parameters={**seg.parameters, "near_dist": near_dist, "min_angle": min_angle,
                       "min_length": min_length}, results=results)


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
    from ..geometry.corners import corners_from_segmentation
    from ..io.vector import write_points

    _check_suffix(output)
    check_range(min_det, "--min-det", 0.0, 1.0)
    check_range(min_angle, "--min-angle", 0.0, 90.0)
    check_positive(max_dist, "--max-dist")
    if _on_catalog("corners", paths, output, classes, source_id, opts,
                   {"min_det": min_det, "min_angle": min_angle, "max_dist": max_dist}):
        return
    path = _one(paths)
    prepare_outputs(output, inputs=(path,))
    steps = Steps()
    sub, xyz, f = _load(path, classes, source_id, steps, opts.pop("crs", None))
    opts["grow_radius"] = _auto(path, sub, "corners", opts, {})[0]["grow_radius"]
    seg = _segment(xyz, opts, steps)
    with steps("Intersecting plane triples"):
        c, refused = corners_from_segmentation(seg, xyz, min_det=min_det, min_angle=min_angle,
                                               max_dist=max_dist, crs=sub.crs)
    if f != 1.0:
        c.xyz[:, 2] /= f
    with steps(f"Writing {output}"):
        write_points(c, output, overwrite=settings().overwrite, layer="corners")
    reasons = Counter(r["reason"] for r in refused)
    sig = np.sqrt(c.attributes["sigma_x"] ** 2 + c.attributes["sigma_y"] ** 2
                  + c.attributes["sigma_z"] ** 2) if len(c) else np.zeros(0)
    results = {"n_planes": seg.n_segments, "n_corners": len(c), "refused": dict(reasons),
               "sigma_3d_m": _stats(sig), "det": _stats(c.attributes["det"]), "output": output}
    echo(f"{len(c)} corners from {seg.n_segments} planes; {len(refused)} triples refused"
         + (f" ({', '.join(f'{k}: {v}' for k, v in reasons.items())})" if reasons else "")
         + f" -> {output}")
    finish("corners", inputs=_inputs(path, classes, source_id, len(xyz), sub.crs),
           parameters={**seg.parameters, "min_det": min_det, "min_angle": min_angle,
                       "max_dist": max_dist}, results=results)
