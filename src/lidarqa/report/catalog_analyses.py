"""Assessment analyses whose cloud input is a catalog (a folder, a glob or a ``.vpc``).

``[inputs.clouds]`` may name a whole delivery instead of one file::

    [inputs.clouds]
    block = "tiles/"            # or "tiles/*.laz", or "delivery.vpc"

An analysis whose cloud is such a catalog runs the catalog job (chunks with
buffers, merged exactly, see :mod:`lidarqa.tiling.jobs_api`) instead of
reading the cloud into memory, and its report section adds the catalog
overview map (tiles, chunks coloured by status, strips) and the per-chunk
status table (:mod:`lidarqa.report.catalog_overview`). Available on catalogs:
``info`` (the catalog summary from the headers), ``edges``, ``swaths`` (strips by
``point_source_id``), ``ground`` (the catalog ground job, ISPRS counts summed over the
chunks), and ``lines`` (edges of catalog inputs extracted chunk by chunk).
``checkpoints`` with ``vertical = true`` and ``heights`` with map-point and
reference-point files run chunk by chunk from their own modules (one section code for
a file and a catalog). Every other analysis
(and heights with points derived from the cloud) runs its file analysis on the
catalog read into memory through its source, as one region, so a catalog input
is never refused. Chunks use the default size and buffer and run in this process.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .html import Figure, Table

__all__ = ["catalog_analysis", "catalog_crs", "catalog_record", "is_catalog_path"]


def is_catalog_path(path: str | Path) -> bool:
    """A folder, a ``.vpc`` file or a glob pattern (a catalog), not one cloud file."""
    p = Path(path)
    s = str(path)
    if p.is_dir() or p.suffix.lower() == ".vpc":
        return True
    return any(ch in s for ch in "*?[") and not p.exists()


def _open(path: str | Path) -> Any:
    from ..tiling import open_catalog

    return open_catalog(str(path))


def catalog_crs(path: str | Path) -> Any:
    """The catalog's CRS from its tile headers (refuses mixed CRSs, bad tiles, empty folders)."""
    return _open(path).crs


def catalog_record(name: str, spec: Any) -> dict[str, Any]:
    """The report's input record of a catalog: tiles, points and a fingerprint.

    Hashing every byte of a delivery would read it all; the fingerprint is the
    SHA-256 of the sorted tile names, sizes and header bounds instead.
    """
    from ..io.crs import crs_epsg, crs_name

    cat = _open(spec.path)
    h = hashlib.sha256()
    for t in cat.tiles:
        size = Path(t.path).stat().st_size if Path(t.path).exists() else -1
        h.update(f"{Path(t.path).name}|{size}|{t.n_points}|{t.bounds}\n".encode())
    crs = spec.effective_crs or cat.crs
    return {"name": name, "kind": spec.kind, "path": str(spec.path), "catalog": True,
            "n_tiles": len(cat.tiles), "n_points": int(cat.n_points),
            "size": int(sum(Path(t.path).stat().st_size for t in cat.tiles
                            if Path(t.path).exists())),
            "sha256": h.hexdigest(), "fingerprint": "tile names, sizes, point counts, bounds",
            "crs_epsg": crs_epsg(crs), "crs_name": crs_name(crs)}


def _cloud_input(item: Any) -> str | None:
    opts = item.options
    if item.kind == "checkpoints":
        return opts.get("measured") if opts.get("vertical") else None
    if item.kind == "lines":
        for side in ("test", "model"):
            v = opts.get(side)
            if isinstance(v, dict) and "cloud" in v:
                return v["cloud"]
        return None
    return opts.get("cloud") if isinstance(opts.get("cloud"), str) else None


def catalog_analysis(ctx: Any, item: Any) -> Callable[[Any, Any], Any] | None:
    """The catalog version of `item`'s analysis when its cloud input is a catalog, else None."""
    name = _cloud_input(item)
    spec = ctx.config.inputs.get(name) if name else None
    if spec is None or spec.kind != "clouds" or not is_catalog_path(spec.path):
        return None
    # the others (and checkpoints, which handles catalogs itself) run their file analysis:
    # the catalog is read through its source as one region (RunContext.cloud)
    return _CATALOG_ANALYSES.get(item.kind)


# ------------------------------------------------------------------ sections


def _with_overview(res: Any, run: Any, title: str) -> Any:
    from .catalog_overview import with_overview

    return with_overview(res, run, title)


def _info(ctx: Any, item: Any) -> Any:
    from ..tiling import make_chunks
    from ..tiling.jobs_api import CatalogRun
    from ._context import SectionResult
    from .catalog_overview import catalog_section

    name = item.options["cloud"]
    with ctx.step(f"Reading the headers of {name}"):
        cat = _open(ctx.config.inputs[name].path)
    chunks = make_chunks(cat)
    run = CatalogRun(None, cat, tuple(chunks), ())  # no job: the chunks a job would use
    sec = catalog_section(run, title=f"{name}: catalog")
    d = cat.to_dict()
    results = {**sec["results"], "crs_name": d.get("crs_name"), "crs_epsg": d.get("crs_epsg"),
               "density_per_m2": d.get("density_per_m2"), "gaps": len(d.get("gaps", [])),
               "overlaps": len(d.get("overlaps", [])),
               "chunk_size": chunks[0].size if chunks else None}
    rows = [["tiles", len(cat.tiles)], ["points", int(cat.n_points)],
            ["CRS", d.get("crs_name") or "none"], ["density (pts/m²)", d.get("density_per_m2")],
            ["gaps (missing tile cells)", results["gaps"]],
            ["duplicate overlaps", results["overlaps"]],
            ["default chunks", f"{len(chunks)} of {results['chunk_size']:g} m"
             if chunks else "–"]]
    headline = (f"catalog of {len(cat.tiles)} tiles, {int(cat.n_points):,} points"
                + (f", {d['density_per_m2']:.1f} pts/m²" if d.get("density_per_m2") else ""))
    return SectionResult(results=results, headline=headline,
                         figures=sec["figures"],
                         tables=[Table("Catalog", ["property", "value"], rows),
                                 sec["tables"][1]],
                         notes=sec["notes"])


_SEGMENT_KEYS = ("grow_radius", "grow_dist", "seed_method", "min_segment_size", "max_rmse")


def _edge_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(plane segmentation options, edge options) from ``extract_edges`` keywords."""
    params = dict(options)
    return {k: params.pop(k) for k in _SEGMENT_KEYS if k in params}, params


def _edges(ctx: Any, item: Any) -> Any:
    from ..tiling.jobs_api import catalog_features
    from . import plots
    from ._context import SectionResult, selection_label
    from ._context import write_vector as _write_vector_safe

    opts = item.options
    name = opts["cloud"]
    seg_opts, params = _edge_options(item.params)
    per: dict[str, Any] = {}
    groups, rows, runs = [], [], []
    notes: list[str] = []
    for sid in opts["source_ids"] or [None]:
        with ctx.step(f"Edges of the catalog {name}" + (f", strip {sid}" if sid else "")):
            run = catalog_features(ctx.config.inputs[name].path, kind="edges",
                                   classes=opts["classes"], source_id=None if sid is None
                                   else [sid], segment_options=seg_opts, options=params,
                                   skip_failed=True)
        runs.append(run)
        seg = run.value
        key = "all" if sid is None else str(sid)
        lengths = seg.lengths if len(seg) else np.empty(0)
        per[key] = {"n_edges": len(seg), "total_length": float(lengths.sum()),
                    "median_length": float(np.median(lengths)) if len(lengths) else None}
        if len(seg):
            _write_vector_safe(ctx, item, seg, "edges" if sid is None else f"edges_{sid}",
                               opts["format"], notes)
        groups.append((seg.start, seg.end, "all" if sid is None else f"strip {sid}"))
        rows.append([key, len(seg), float(lengths.sum()), per[key]["median_length"]])
    with ctx.step("Plotting edges"):
        fig = plots.plot_segments(groups, "Edges (" + selection_label(name, opts["classes"],
                                                                       None) + ")")
    res = SectionResult(
        results={"n_edges": sum(v["n_edges"] for v in per.values()), "by_source_id": per,
                 "classes": opts["classes"],
                 "rule": "anchor-in-core: an edge is kept by the chunk holding its midpoint"},
        headline=", ".join(f"{v['n_edges']} edges ({'strip ' + k if k != 'all' else 'all'})"
                           for k, v in per.items()) + " over the catalog",
        figures=[Figure("Edges", fig, "top view")],
        tables=[Table("Edges", ["strip", "edges", "total length (m)", "median length (m)"],
                      rows)],
        notes=notes,
        paragraphs=[f"{name} is a catalog: edges were found chunk by chunk with a buffer and "
                    "each edge is kept once, by the chunk whose core holds its midpoint."],
    )
    return _with_overview(res, runs[0], f"{name}: chunks")


def _swaths(ctx: Any, item: Any) -> Any:
    from ..tiling.jobs_swaths import catalog_swaths
    from .analyses.swaths import swaths_section

    opts = item.options
    name = opts["cloud"]
    with ctx.step(f"Comparing the flight strips of the catalog {name}"):
        run = catalog_swaths(ctx.config.inputs[name].path, by_source_id=True,
                             classes=opts["classes"], source_ids=opts["source_ids"],
                             all_returns=not opts["last_returns"], skip_failed=True,
                             **item.params)
    out = swaths_section(ctx, item, run.value, run.catalog.crs)
    out.paragraphs = [*out.paragraphs,
                      f"{name} is a catalog: every grid cell is fitted in the chunk that owns "
                      "it, with all its points; the figures are those of one run over the "
                      "whole block."]
    return _with_overview(out, run, f"{name}: chunks")


def _ground(ctx: Any, item: Any) -> Any:
    """Ground over the catalog (:func:`~lidarqa.tiling.ground.ground_catalog`, in this process)."""
    import tempfile
    from types import SimpleNamespace

    from ..tiling.ground import ground_catalog
    from ._context import SectionResult

    opts = item.options
    name = opts["cloud"]
    cat = _open(ctx.config.inputs[name].path)
    params = {k: v for k, v in item.params.items() if k != "progress"}
    ignore = list(opts["ignore_classes"] or [])
    notes: list[str] = []
    with contextlib.ExitStack() as stack:
        if opts["write_cloud"]:
            out_dir = ctx.output_path(item, f"{name}_ground")
            if opts["cloud_format"] != "laz":
                notes.append("on a catalog the output tiles keep the input tiles' format "
                             "(cloud_format is not used)")
        else:
            out_dir = Path(stack.enter_context(tempfile.TemporaryDirectory())) / "ground"
        with ctx.step(f"Ground filtering the catalog {name} ({int(cat.n_points):,} points, "
                      f"{opts['method']})"):
            res = ground_catalog(cat, out_dir, method=opts["method"],
                                 evaluate=bool(opts["evaluate"]), ignore_classes=ignore or None,
                                 workers=1, overwrite=True, **params)
    d = res.to_dict()
    if not opts["write_cloud"]:  # the tiles were written to a temporary folder, now gone
        d.update(outputs=[], vpc=None)
    notes.extend(res.warnings)
    e = res.evaluation
    tables = []
    if e is not None:
        d.update(type_i_pct=e.type_i_pct, type_ii_pct=e.type_ii_pct, total_pct=e.total_pct,
                 ignore_classes=ignore)
        tables.append(Table("Cross table (points)", ["reference \\ filter", "ground", "object",
                                                     "total"],
                            [["ground", e.a, e.b, e.a + e.b], ["object", e.c, e.d, e.c + e.d],
                             ["total", e.a + e.c, e.b + e.d, e.n]],
                            note=("classes " + ", ".join(map(str, ignore)) + " not evaluated")
                            if ignore else ""))
        headline = (f"total error {e.total_pct:.2f} % (type I {e.type_i_pct:.2f} %, type II "
                    f"{e.type_ii_pct:.2f} %), κ {e.kappa:.3f} (catalog)")
    else:
        headline = (f"{res.n_ground:,} of {res.n_points:,} points classified as ground "
                    "(catalog)")
    tables.append(Table("Filter run", ["quantity", "value"],
                        [["points", res.n_points], ["ground points", res.n_ground],
                         ["chunks", res.n_chunks], ["chunk size (m)", res.chunk_size],
                         ["buffer (m)", res.buffer]]))
    out = SectionResult(
        results=d, headline=headline, tables=tables, notes=notes,
        parameters={"filter": dict(res.parameters)},
        paragraphs=[f"{name} is a catalog: the filter runs chunk by chunk with a {res.buffer:g} m "
                    "buffer and keeps each chunk's core labels; the ISPRS counts are summed "
                    "over the chunks, which gives those of one run over the whole area."
                    + (" The classified tiles and a .vpc of them are in the outputs."
                       if opts["write_cloud"] else "")],
    )
    chunks = tuple(SimpleNamespace(id=c["id"], core=tuple(c["core"])) for c in res.chunks)
    status = [{"chunk": c["id"], "status": "ok", "attempts": 1, "error": None}
              for c in res.chunks]
    run = SimpleNamespace(catalog=cat, chunks=chunks, extra={}, chunk_status=lambda: status)
    return _with_overview(out, run, f"{name}: chunks")


def _lines(ctx: Any, item: Any) -> Any:
    from .analyses.lines import run_lines

    out = run_lines(ctx, item)  # ctx.edges extracts a catalog's edges chunk by chunk
    out.paragraphs = [*out.paragraphs,
                      "Edges of catalog inputs were extracted chunk by chunk, each edge kept by "
                      "the chunk holding its midpoint (the edges of one run over the whole area)."]
    return out


_CATALOG_ANALYSES: dict[str, Callable[[Any, Any], Any]] = {
    "info": _info,
    "ground": _ground,
    "lines": _lines,
    "swaths": _swaths,
    "edges": _edges,
}
