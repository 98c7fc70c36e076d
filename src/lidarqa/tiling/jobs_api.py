"""The area jobs on a catalog, as Python functions (what the CLI commands call).

Each function takes a catalog (or anything :func:`lidarqa.tiling.open_catalog`
accepts: paths, a folder, a glob, a ``.vpc``), cuts it into chunks with
buffers, runs a pure chunk task on the engine (serial by default, a Dask
LocalCluster or any Dask cluster with ``engine=Engine(...)``) and merges the
chunk results into the result of one in-memory run over the whole area:

* :func:`catalog_features` -- planes, edges or corners, each feature once
  (anchor-in-core rule, :mod:`lidarqa.tiling.jobs_vector`);
* :func:`catalog_vertical_check` -- ``checkpoints --vertical``;
* :func:`catalog_heights` -- map point heights and w-tests against reference
  points (:mod:`lidarqa.tiling.jobs_accuracy`);
* :func:`catalog_roads` -- 3D roads from map polygons (one region: the roads are
  reconstructed in one piece), reference points tested on their levels;
* :func:`catalog_repeatability` -- line repeatability of every flight-strip
  pair over the whole block (:mod:`lidarqa.tiling.jobs_lines`).

Every function returns a :class:`CatalogRun`: the merged ``value`` plus the
catalog, the chunks and the per-chunk outcomes (ok, failed, retried), which the
report shows on its catalog overview map.

Example
-------
>>> from lidarqa.tiling import Engine                          # doctest: +SKIP
>>> from lidarqa.tiling.jobs_api import catalog_features       # doctest: +SKIP
>>> with Engine(workers=2) as eng:                             # doctest: +SKIP
...     run = catalog_features("tiles/", kind="edges", classes=(6,), engine=eng)
>>> run.value.write("edges.gpkg")                              # doctest: +SKIP
"""

from __future__ import annotations

import inspect
import math
import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import OptionError
from ..io.vector import PointSet
from .apply import CatalogRun, chunk_status, open_sources, region_chunks  # noqa: F401
from .jobs_vector import owned

if TYPE_CHECKING:
    from ._types import PathsInput
    from .catalog import Catalog
    from .source import Source

    #: What a job reads: paths, a folder, a glob, a ``.vpc``, or an opened catalog or source.
    Sources = PathsInput | Catalog | Source

__all__ = [
    "CatalogRun",
    "catalog_features",
    "catalog_heights",
    "catalog_repeatability",
    "catalog_roads",
    "catalog_vertical_check",
    "open_sources",
]


def _run(catalog: Any, chunks: Sequence[Any], task: Any, run_opts: dict[str, Any],
         description: str) -> tuple[list[Any], list[Any | None]]:
    """Run `task` on `chunks` through :func:`~lidarqa.tiling.apply.apply` (retries, resume)."""
    from .apply import apply

    run = apply(catalog, task, chunks=chunks, description=description, **run_opts)
    return list(run.outcomes), run.value


#: The engine options of every job (see :func:`~lidarqa.tiling.apply.apply`).
RUN_KEYS = ("engine", "progress", "retries", "skip_failed", "order_seed", "work_dir", "resume")
#: Every common keyword argument of a job: how to open the source, chunk it and run it.
COMMON_KEYS = ("skip_bad", "crs", "chunk_size", "buffer", "origin", *RUN_KEYS)


def _split(kw: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """(open options, chunk options, run options) from the common keyword arguments."""
    open_opts = {"skip_bad": kw.pop("skip_bad", False), "crs": kw.pop("crs", None)}
    chunk_opts = {"chunk_size": kw.pop("chunk_size", None), "buffer": kw.pop("buffer", None),
                  "origin": kw.pop("origin", (0.0, 0.0))}
    run_opts: dict[str, Any] = {k: kw.pop(k) for k in RUN_KEYS if k in kw}
    run_opts.setdefault("progress", False)
    if kw:
        raise OptionError(f"unknown option(s): {', '.join(sorted(kw))}")
    return open_opts, chunk_opts, run_opts


# ------------------------------------------------------------------ vector features


def catalog_features(
    sources: Sources,
    *,
    kind: str,
    classes: Sequence[int] | None = None,
    source_id: Sequence[int] | None = None,
    segment_options: Mapping[str, object] | None = None,
    options: Mapping[str, object] | None = None,
    tolerance: float = 0.05,
    **common: object,
) -> CatalogRun:
    """Planes, edges or corners of a whole catalog, each feature once.

    Parameters
    ----------
    sources : Catalog, path, folder, glob, .vpc or a list of those
    kind : {"planes", "edges", "corners"}
    classes, source_id : sequence of int, optional
        Point selection (e.g. ``(6,)`` for buildings).
    segment_options, options : dict, optional
        Plane segmentation and edge/corner options (a keyword of
        :func:`~lidarqa.geometry.segmentation.segment_planes` given in `options`
        is a segmentation option). Data-driven defaults
        (growing radius, support distance) are measured once on the source's
        central sample window and used for every chunk. The default buffer is
        the task's (:func:`~lidarqa.tiling.jobs_vector.feature_buffer`: the
        largest plane of the sample window plus a few point spacings).
    tolerance : float, default 0.05
        Near-duplicate distance (m) of the merge.
    **common
        ``chunk_size``, ``buffer``, ``origin``, ``engine``, ``progress``,
        ``retries``, ``skip_failed``, ``order_seed`` (shuffled submission, for
        tests), ``skip_bad``, ``crs``, ``work_dir`` and ``resume`` (see
        :func:`~lidarqa.tiling.apply.apply`).

    Returns
    -------
    CatalogRun
        ``value`` the features; ``extra`` the fixed ``segment_options`` and
        ``options`` and the ``summary`` of the chunks' segmentations
        (:func:`~lidarqa.tiling.jobs_vector.merge_summaries`).
    """
    from ..geometry.segmentation import segment_planes
    from .jobs_vector import (
        VectorTask,
        feature_buffer,
        fixed_auto_options,
        merge_summaries,
        merge_vector_parts,
    )

    open_opts, chunk_opts, run_opts = _split(dict(common))
    catalog = open_sources(sources, classes=classes or None, source_id=source_id or None,
                           z_to_metres=False, **open_opts)
    seg_keys = set(inspect.signature(segment_planes).parameters) - {"points", "progress"}
    given = dict(options or {})
    seg_opts = {**{k: v for k, v in given.items() if k in seg_keys}, **dict(segment_options or {})}
    # the defaults are measured with heights in metres, as the chunks fit their planes
    # (VectorTask; x, y in feet or degrees are refused by the commands)
    from ..io.crs import heights_to_metres

    sample = heights_to_metres(catalog.sample().xyz, catalog.native_crs)
    seg_opts, opts = fixed_auto_options(sample, kind=kind, segment_options=seg_opts,
                                        options={k: v for k, v in given.items()
                                                 if k not in seg_keys})
    margin = None
    if chunk_opts["buffer"] is None and (catalog.is_catalog or chunk_opts["chunk_size"]):
        margin = feature_buffer(sample, segment_options=seg_opts)
    task = VectorTask(kind=kind, segment_options=seg_opts,
                      options=opts, bounds=catalog.area_bounds, margin=margin)
    chunks = region_chunks(catalog, task, **chunk_opts)
    outcomes, parts = _run(catalog, chunks, task, run_opts, f"{kind.capitalize()}")
    value = merge_vector_parts(parts, tolerance=tolerance, crs=catalog.crs)
    return CatalogRun(value, catalog, tuple(chunks), tuple(outcomes),
                      {"segment_options": seg_opts, "options": opts,
                       "summary": merge_summaries(parts)})


# ------------------------------------------------------------------ check points, heights


def catalog_vertical_check(
    sources: Sources,
    check: PointSet | ArrayLike,
    *,
    classes: Sequence[int] | None = (2,),
    source_id: Sequence[int] | None = None,
    max_edge: float | None = None,
    search_radius: float | None = None,
    checkpoint_rmse_v: float = 0.0,
    **common: object,
) -> CatalogRun:
    """``checkpoints --vertical`` over a catalog: only chunks holding check points are read.

    The check points are in the source's CRS and units (heights are converted to
    metres with the source's factor, as the cloud's); ``source_id`` selects the
    strips read, ``classes`` the points of the ground TIN. The buffer must be at
    least ``2 x max_edge`` (the ground TIN's reach); the default buffer (tens of
    metres) is far above that for dense ground.

    Raises
    ------
    NothingToMeasureError
        No check point could be compared (as for one file).
    """
    from ..io.vector import as_pointset
    from .jobs_accuracy import (
        CheckSpacingTask,
        VerticalCheckTask,
        chunks_with_points,
        max_edge_from_spacing,
        merge_vertical,
    )

    open_opts, chunk_opts, run_opts = _split(dict(common))
    catalog = open_sources(sources, source_id=source_id or None, **open_opts)
    cp = as_pointset(check, "check")
    if catalog.z_factor != 1.0:
        xyz = cp.xyz.copy()
        xyz[:, 2] *= catalog.z_factor
        cp = PointSet(cp.ids, xyz, dict(cp.attributes), crs=cp.crs)
    chunks = chunks_with_points(region_chunks(catalog, **chunk_opts), cp.xyz)
    cls = tuple(int(c) for c in classes) if classes is not None else None
    if max_edge is None and not chunks:  # no check point inside the catalog: nothing to compare
        max_edge = math.nan
    if max_edge is None:
        _, spacing = _run(catalog, chunks, CheckSpacingTask(cp.xyz, classes=cls), run_opts,
                          "Ground spacing")
        max_edge = max_edge_from_spacing(spacing) * catalog.xy_factor
    task = VerticalCheckTask(cp, max_edge=float(max_edge), search_radius=search_radius,
                             classes=cls, xy_factor=catalog.xy_factor,
                             bounds=catalog.area_bounds)
    outcomes, parts = _run(catalog, chunks, task, run_opts, "Check points")
    if catalog.xy_factor != 1.0:
        xyz = cp.xyz.copy()
        xyz[:, :2] *= catalog.xy_factor
        cp = PointSet(cp.ids, xyz, dict(cp.attributes), crs=cp.crs)
    value = merge_vertical(parts, cp, max_edge=float(max_edge), search_radius=search_radius,
                           checkpoint_rmse_v=checkpoint_rmse_v)
    return CatalogRun(value, catalog, tuple(chunks), tuple(outcomes), {"max_edge": max_edge})


def catalog_heights(
    sources: Sources,
    map_xy: PointSet | ArrayLike,
    reference_xyz: PointSet | ArrayLike,
    *,
    classes: Sequence[int] | None = None,
    source_id: Sequence[int] | None = None,
    options: Mapping[str, object] | None = None,
    **common: object,
) -> CatalogRun:
    """Height quality (map point heights, TIN, w-tests) over a catalog.

    The laser points are read through the source: its selection (``classes``,
    ``source_id``) and its heights in metres. Map and reference points given as
    :class:`~lidarqa.io.vector.PointSet` are checked against the source's CRS
    (horizontal and vertical parts; ``crs`` is theirs when they declare none) and
    the reference heights converted to metres (:func:`points_in_metres`); arrays
    are taken as already in the source's CRS, heights in metres.
    One file (without `chunk_size` or `buffer`) is one region: the in-memory run.

    Map points are fitted from the chunk that owns them; a chunk whose buffer
    is too narrow for the fits or the TIN around its reference points fails
    with a message naming it (see :mod:`lidarqa.tiling.jobs_accuracy`). The
    default buffer is :func:`heights_buffer`. The w-tests and data snooping run
    once over all reference points.
    """
    from .jobs_accuracy import HeightsTask, merge_heights

    open_opts, chunk_opts, run_opts = _split(dict(common))
    catalog = open_sources(sources, classes=classes or None, source_id=source_id or None,
                           **open_opts)
    if isinstance(map_xy, PointSet) and isinstance(reference_xyz, PointSet):
        from ..io.crs import ensure_same_crs_parts

        ensure_same_crs_parts(map_xy.crs, reference_xyz.crs, what=("map", "reference"))
    if isinstance(map_xy, PointSet):
        map_xy = points_in_metres(map_xy, catalog, "map").xyz[:, :2]
    if isinstance(reference_xyz, PointSet):
        reference_xyz = points_in_metres(reference_xyz, catalog, "reference").xyz
    mxy = np.asarray(map_xy, dtype=np.float64)
    mxy = mxy.reshape(-1, mxy.shape[-1] if mxy.ndim == 2 else 2)[:, :2]
    ref = np.asarray(reference_xyz, dtype=np.float64).reshape(-1, 3)
    if chunk_opts["buffer"] is None and (catalog.is_catalog or chunk_opts["chunk_size"]):
        chunk_opts["buffer"] = heights_buffer(mxy, options)
    task = HeightsTask(mxy, ref, options=dict(options or {}), classes=None,
                       bounds=catalog.area_bounds)
    chunks = region_chunks(catalog, **chunk_opts)
    if (options or {}).get("largest_segment") and len(chunks) > 1:
        raise OptionError("--largest-segment segments the whole cloud at once: it needs one "
                          "file without --chunk-size or --buffer")
    chunks = [c for c in chunks if owned(task.clamp(mxy), c).any()
              or owned(task.clamp(ref), c).any()]
    outcomes, parts = _run(catalog, chunks, task, run_opts, "Heights")
    value = merge_heights(parts, mxy, ref, options=dict(options or {}))
    return CatalogRun(value, catalog, tuple(chunks), tuple(outcomes))


def points_in_metres(points: PointSet, source: Source, what: str) -> PointSet:
    """`points` checked against `source`'s CRS, heights in metres (as the source reads its own).

    The CRS of `points` (the source's given one, ``--crs``, when they declare none) must
    agree with the source's files on the horizontal and on the vertical part; heights are
    converted with the factor of their own vertical unit (the source's when they have no
    CRS). x, y stay in the CRS's units, as the source's points.

    Raises
    ------
    CRSMismatchError
        The CRSs differ (named with `what`).
    """
    from ..io.crs import ensure_same_crs_parts, z_to_metres_factor

    crs = points.crs if points.crs is not None else source.given_crs
    ensure_same_crs_parts(source.native_crs, crs, what=("cloud", what))
    xyz = np.array(points.xyz, dtype=np.float64)
    xyz[:, 2] *= z_to_metres_factor(crs if crs is not None else source.native_crs)
    return PointSet(points.ids, xyz, dict(points.attributes), crs=crs)


def catalog_roads(
    sources: Sources,
    polygons: str | os.PathLike[str],
    *,
    reference: PointSet | ArrayLike | None = None,
    classes: Sequence[int] | None = (2, 17),
    source_id: Sequence[int] | None = None,
    options: Mapping[str, object] | None = None,
    compare_options: Mapping[str, object] | None = None,
    **common: object,
) -> CatalogRun:
    """3D roads from the map polygons at `polygons`, over a file or a catalog.

    The one road job of ``lidarqa roads``, ``lidarqa heights`` with a polygon map and
    the report's ``[roads]``: the selected points of the whole area are read through
    the source (heights in metres) and the roads reconstructed in one piece
    (:func:`~lidarqa.accuracy.roads.reconstruct_roads`). The map's CRS (``crs``, or the
    source's given CRS, when it declares none) must agree with the cloud's
    (:func:`~lidarqa.io.crs.check_map_crs`). `reference` points (a PointSet: checked and
    converted as by :func:`points_in_metres`; an array: metres) are tested on their
    road levels (:func:`~lidarqa.accuracy.roads.compare_road_heights` with
    `compare_options`).

    Parameters
    ----------
    sources : Catalog, Source, path, folder, glob, .vpc or a list of those
    polygons : path
        Road polygons (.gpkg, .geojson).
    reference : PointSet or array of shape (R, 3), optional
    classes, source_id : sequence of int, optional
        Laser points used (default ground and bridge deck, 2 and 17).
    options : dict, optional
        Keywords of :func:`~lidarqa.accuracy.roads.reconstruct_roads`.
    compare_options : dict, optional
        ``sigma_ref``, ``alpha``, ``estimate_offset``.
    **common
        ``crs``, ``skip_bad``. The roads are one region, in this process: ``chunk_size``,
        ``buffer``, ``resume`` and an `engine` of 2 or more workers or a scheduler address
        are refused (:class:`~lidarqa.errors.OptionError`); the other run options do nothing.

    Returns
    -------
    CatalogRun
        ``value`` the :class:`~lidarqa.accuracy.roads.RoadReconstruction`; ``extra``
        ``comparison`` (or None), ``reference_xyz`` (m), ``points`` (the laser points
        used, m), ``n_polygons``, ``crs`` (of the outputs: the cloud's, else the map's).
    """
    from ..accuracy.roads import compare_road_heights, read_road_polygons, reconstruct_roads
    from ..io.crs import check_map_crs, parse_crs

    open_opts, chunk_opts, run_opts = _split(dict(common))
    eng = run_opts.get("engine")
    scheduler = eng is not None and eng.scheduler not in (None, "serial")
    refused = [o for o, on in (
        ("--chunk-size", chunk_opts["chunk_size"] is not None),
        ("--buffer", chunk_opts["buffer"] is not None),
        ("--workers", eng is not None and not scheduler and (eng.workers or 1) > 1),
        ("--scheduler", scheduler), ("--resume", run_opts.get("resume"))) if on]
    if refused:
        raise OptionError(f"roads are reconstructed in one piece, in this process: "
                          f"{', '.join(refused)} cannot be used")
    catalog = open_sources(sources, classes=classes or None, source_id=source_id or None,
                           **open_opts)
    cloud = catalog.read(require_points=False)
    polys, ids, map_crs = read_road_polygons(polygons)
    if map_crs is None:  # the CRS of inputs that declare none
        given = parse_crs(open_opts["crs"])
        map_crs = given if given is not None else catalog.given_crs
    check_map_crs(catalog.native_crs, map_crs, polys, polygons)
    recon: dict[str, Any] = dict(options or {})
    rec = reconstruct_roads(cloud.xyz, polys, ids=ids, **recon)
    comp, ref_xyz = None, None
    if reference is not None:
        ref_xyz = (points_in_metres(reference, catalog, "reference").xyz
                   if isinstance(reference, PointSet)
                   else np.asarray(reference, dtype=np.float64).reshape(-1, 3))
        compare: dict[str, Any] = dict(compare_options or {})
        comp = compare_road_heights(rec, ref_xyz, **compare)
    return CatalogRun(rec, catalog, (), (),
                      {"comparison": comp, "reference_xyz": ref_xyz, "points": cloud.xyz,
                       "n_polygons": len(polys), "crs": catalog.crs or map_crs})


def heights_buffer(map_xy: ArrayLike, options: Mapping[str, object] | None = None) -> float:
    """Default buffer of a heights job (m): room for the map point TIN around a chunk.

    ``max(60, 3 x the largest nearest-neighbour distance between map points + 10)``:
    a reference point's triangle and the map points that decide it lie within a
    few map spacings, and their fits reach a few metres in dense data.
    """
    from scipy.spatial import cKDTree

    from .chunks import DEFAULT_BUFFER

    xy = np.asarray(map_xy, dtype=np.float64)[:, :2]
    if len(xy) < 2:
        return float(DEFAULT_BUFFER)
    d, _ = cKDTree(xy).query(xy, k=2)
    return float(max(DEFAULT_BUFFER, 3.0 * float(np.max(d[:, 1])) + 10.0))


# ------------------------------------------------------------------ strips


def catalog_repeatability(
    sources: Sources,
    *,
    classes: Sequence[int] | None = None,
    source_id: Sequence[int] | None = None,
    segment_options: Mapping[str, object] | None = None,
    edge_options: Mapping[str, object] | None = None,
    match_options: Mapping[str, object] | None = None,
    tolerance: float = 0.05,
    **common: object,
) -> CatalogRun:
    """Line repeatability of every pair of flight strips (point_source_id) over the block.

    One file (without `chunk_size` or `buffer`) is one region: the same code
    gives the file answer and the catalog answer. Each strip's data-driven
    defaults and point spacing are measured once on its points in the central
    sample window (:func:`~lidarqa.tiling.jobs_lines.strip_samples`).

    ``value`` is the list of pair rows (as ``lidarqa repeatability``);
    ``extra["strips"]`` the whole-block edges of each strip and
    ``extra["strip_chunks"]`` the chunks where each strip gave edges,
    ``extra["strip_options"]`` each strip's fixed ``segment_options``,
    ``edge_options`` and ``point_spacing`` (m). `match_options` may hold ``shared_threshold`` (see
    :func:`~lidarqa.tiling.jobs_lines.strip_pairs`).
    """
    from .jobs_lines import (
        StripEdgesTask,
        merge_strip_edges,
        strip_options,
        strip_pairs,
        strip_samples,
    )
    from .jobs_vector import feature_buffer

    open_opts, chunk_opts, run_opts = _split(dict(common))
    catalog = open_sources(sources, classes=classes or None, source_id=source_id or None,
                           z_to_metres=False, **open_opts)
    # heights in metres, as the chunks find their edges (StripEdgesTask)
    from ..io.crs import heights_to_metres

    samples = {s: heights_to_metres(xyz, catalog.native_crs)
               for s, xyz in strip_samples(catalog).items()}
    fixed = strip_options(samples, segment_options=segment_options, edge_options=edge_options)
    margin = None
    if chunk_opts["buffer"] is None and (catalog.is_catalog or chunk_opts["chunk_size"]):
        margin = max((feature_buffer(samples[s], segment_options=fixed[s][0])
                      for s in samples), default=None)
    seg_opts = dict(segment_options or {})
    e_opts = dict(edge_options or {})
    task = StripEdgesTask(segment_options=seg_opts, edge_options=e_opts, strips=fixed,
                          margin=margin)
    chunks = region_chunks(catalog, task, **chunk_opts)
    outcomes, parts = _run(catalog, chunks, task, run_opts, "Strip edges")
    strips = merge_strip_edges(parts, tolerance=tolerance)
    match_kw: dict[str, Any] = dict(match_options or {})  # checked by strip_pairs
    rows = strip_pairs(strips, **match_kw)
    where: dict[int, list[str]] = {}
    for p in parts:
        if p is not None:
            for s in p[1]:
                where.setdefault(int(s), []).append(p[0])
    # the options of the strips, for the run's record (the first strip's when they differ)
    first = next(iter(fixed.values()), ({}, {}, float("nan")))
    return CatalogRun(rows, catalog, tuple(chunks), tuple(outcomes),
                      {"strips": strips, "strip_chunks": where,
                       "segment_options": {**seg_opts, **first[0]},
                       "edge_options": {**e_opts, **first[1]},
                       "strip_options": {int(k): {"segment_options": v[0], "edge_options": v[1],
                                                  "point_spacing": v[2]}
                                         for k, v in fixed.items()}})

