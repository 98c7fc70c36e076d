"""The ``ground`` analysis: filter ground (segment-PTD or PTD) and score it.

Scores: the ISPRS errors per point, and the terrain model of the filter against
that of the reference (:func:`lidarqa.ground.metrics.terrain_scores`), which is
the fair score when the reference ground is a thinned subset (said in a note).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ConfigError
from .._context import (
    RunContext,
    SectionResult,
    dataclass_defaults,
    import_module,
    keyword_defaults,
    library_attr,
)
from .._registry import CLOUD_KEY, register
from .._schema import AnalysisItem, Key, Target, targets
from ..html import Figure, Table
from ..labels import labelled_rows

_GROUND_CLASSES = {"segment-ptd": "SegmentPTD", "ptd": "PTD"}


def _ground_params(options: dict) -> dict[str, Any]:
    """classify_ground's keywords plus the chosen filter's parameters (its dataclass fields)."""
    classify_ground = library_attr("lidarqa.ground", "classify_ground", "ground")
    out = keyword_defaults(classify_ground, exclude=("method", "evaluate", "ignore_classes"))
    filter_cls = library_attr(
        "lidarqa.ground", _GROUND_CLASSES[options.get("method") or "segment-ptd"], "ground"
    )
    out.add_missing(dataclass_defaults(filter_cls))
    own = set(keyword_defaults(classify_ground))

    def validate(params: dict[str, Any]) -> None:
        # Building the filter checks every parameter's range (its __post_init__).
        filter_cls(**{k: v for k, v in params.items() if k not in own})
        mod = import_module("lidarqa.ground", "ground")
        presets = getattr(mod, "PRESET_CHOICES", None) or getattr(mod, "PRESETS", None)
        if (
            params.get("preset") is not None
            and presets is not None
            and params["preset"] not in presets
        ):
            raise ConfigError(
                f"key 'preset' must be one of {', '.join(map(repr, presets))}; "
                f"got {params['preset']!r}"
            )

    out.validate = validate
    return out


KEYS = {
    "cloud": CLOUD_KEY,
    "method": Key("str", default="segment-ptd", choices=("segment-ptd", "ptd")),
    "evaluate": Key("bool", default=True, help="score against the input's classes"),
    "ignore_classes": Key("int_list", default=None, help="classes left out of the evaluation"),
    "write_cloud": Key("bool", default=True, help="write the classified cloud"),
    "cloud_format": Key("str", default="laz", choices=("laz", "las")),
}
TARGETS = targets(
    Target("total", ("total",), "max", "total error", "%", 100.0),
    Target("type_i", ("type_i",), "max", "type I error", "%", 100.0),
    Target("type_ii", ("type_ii",), "max", "type II error", "%", 100.0),
    Target("kappa", ("kappa",), "min", "Cohen's κ", ""),
)


@register(
    "ground", _ground_params, keys=KEYS, targets=TARGETS, title="Ground filtering", order=20
)
def run_ground(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Ground filtering (segment-PTD or PTD) and its ISPRS errors against the input's classes."""
    from .. import plots

    ground_mod = import_module("lidarqa.ground", "ground")
    opts = item.options
    if ctx.is_catalog(opts["cloud"]):
        return _run_on_catalog(ctx, item)
    cloud = ctx.cloud(opts["cloud"])
    n = len(cloud)
    notes: list[str] = []
    cls = cloud.classification
    evaluate = bool(opts["evaluate"])
    if evaluate and cls is None:
        notes.append("the cloud has no classification: nothing to evaluate against")
        evaluate = False
    ignore = list(opts["ignore_classes"] or [])
    import warnings

    with (
        ctx.step(f"Ground filtering ({opts['method']}, {n:,} points)") as progress,
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")  # reported through result.warnings instead
        result = ground_mod.classify_ground(
            cloud,
            progress=progress,
            method=opts["method"],
            evaluate=evaluate,
            ignore_classes=ignore or None,
            **item.params,
        )
    ground = np.asarray(result.ground_mask, dtype=bool)
    res = result.to_dict()
    notes.extend(str(w) for w in res.get("warnings", []))
    errors = result.evaluation
    if errors is not None:
        res.update(
            type_i_pct=errors.type_i_pct,
            type_ii_pct=errors.type_ii_pct,
            total_pct=errors.total_pct,
            ignore_classes=ignore,
        )
    if opts["write_cloud"] and cls is not None:
        from ...io import write

        out = cloud.copy()
        out.fields["classification"] = ground_mod.relabel_classification(cls, ground)
        path = ctx.output_path(item, f"{opts['cloud']}_ground.{opts['cloud_format']}")
        with ctx.step("Writing the classified cloud"):
            write(out, path, overwrite=True)
    figures = []
    evaluated = ~np.isin(cls, ignore) if errors is not None else None
    with ctx.step("Plotting ground maps"):
        cmap, emap = plots.plot_ground_maps(
            cloud.xyz[:, :2], ground, (cls == 2) if errors is not None else None, evaluated
        )
        figures.append(Figure("Ground classification", cmap, "top view of the filter's result"))
        if emap is not None:
            figures.append(
                Figure(
                    "Error map",
                    emap,
                    "type I: reference ground rejected; type II: object accepted as ground",
                )
            )
    tables, headline = isprs_tables(errors, ignore)
    if errors is None:
        headline = f"{int(ground.sum()):,} of {n:,} points classified as ground"
    terrain = res.get("terrain")
    if terrain:
        tables.append(terrain_table(terrain))
        if not terrain["reason"]:
            headline += (
                f"; terrain RMSE {terrain['rmse_m']:.2f} m, "
                f"{100 * terrain['cells_off']:.1f} % of cells off by > "
                f"{terrain['off_limit_m']:g} m"
            )
        if terrain["reference_thinned"]:
            notes.append(
                f"{terrain['note']} ({terrain['reference_on_surface_ratio']:.2f} reference "
                f"non-ground points within {terrain['near_limit_m']:g} m of the reference ground "
                "surface per reference ground point)"
            )
    tables.append(filter_run_table(res))
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        parameters={"filter": dict(result.parameters)},
        paragraphs=[
            f"Method {opts['method']} on {opts['cloud']} ({n:,} points); the filter decides from "
            "geometry (and return numbers) only; the file's classes are used only to score it."
        ],
    )


def filter_run_table(res: dict[str, Any], chunked: Any = None, unit: str = "m") -> Table:
    """Points, candidates, ground (and a catalog's chunks, in `unit`): report and CLI."""
    frac = res.get("ground_fraction")
    rows = [["points", res["n_points"]], ["candidate points", res.get("n_candidates")],
            ["ground points", res["n_ground"]],
            ["ground share (%)", None if frac is None else 100 * frac],
            ["return handling", res.get("return_handling")],
            ["noise points excluded", res.get("n_excluded_noise")]]
    if chunked is not None:
        rows += [["chunks", chunked.n_chunks], ["chunks resumed", chunked.n_chunks_resumed or None],
                 [f"chunk size ({unit})", chunked.chunk_size], [f"buffer ({unit})", chunked.buffer]]
    return Table("Filter run", ["quantity", "value"], [r for r in rows if r[1] is not None])


def terrain_table(terrain: dict[str, Any]) -> Table:
    """The filter's terrain model against the reference's: the report's and ``lidarqa ground``'s."""
    shown = {
        k: v
        for k, v in terrain.items()
        if k not in ("note", "reason") and not (v is None and terrain["reason"])
    }
    return Table(
        "Terrain model (TIN of the filter's ground against the reference's)",
        ["quantity", "value", "key in report.json"],
        labelled_rows(shown, prefix="terrain"),
        code_columns=(2,),
        note=terrain["reason"]
        or "cells: centres of a grid aligned on multiples of the cell, inside the convex "
        "hulls of both ground sets; heights are vertical differences",
    )


def isprs_tables(e: Any, ignore: list[int], how: str = "") -> tuple[list[Table], str]:
    """The cross table and ISPRS errors of an evaluation, and the headline ([] and "" if None).

    The report's and ``lidarqa ground --evaluate``'s; `how` qualifies the counts in a note.
    """
    if e is None:
        return [], ""
    tables = [
        Table(
            "Cross table (points)",
            ["reference \\ filter", "ground", "object", "total"],
            [
                ["ground", e.a, e.b, e.a + e.b],
                ["object", e.c, e.d, e.c + e.d],
                ["total", e.a + e.c, e.b + e.d, e.n],
            ],
            note="; ".join(filter(None, [how, ("classes " + ", ".join(map(str, ignore))
                                                + " not evaluated") if ignore else ""])),
        ),
        Table(
            "ISPRS errors",
            ["measure", "value"],
            [
                ["type I (%)", e.type_i_pct],
                ["type II (%)", e.type_ii_pct],
                ["total (%)", e.total_pct],
                ["Cohen's κ", e.kappa],
                ["points evaluated", e.n],
            ],
        ),
    ]
    headline = (f"total error {e.total_pct:.2f} % (type I {e.type_i_pct:.2f} %, type II "
                f"{e.type_ii_pct:.2f} %), κ {e.kappa:.3f}")
    return tables, headline


def _run_on_catalog(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Ground over a catalog (:func:`~lidarqa.tiling.ground.ground_catalog`, in this process)."""
    import contextlib
    import tempfile
    from pathlib import Path
    from types import SimpleNamespace

    from ...tiling import open_catalog
    from ...tiling.ground import ground_catalog
    from ..catalog_overview import with_overview

    opts = item.options
    name = opts["cloud"]
    cat = open_catalog(str(ctx.config.inputs[name].path))
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
    if e is not None:
        d.update(type_i_pct=e.type_i_pct, type_ii_pct=e.type_ii_pct, total_pct=e.total_pct,
                 ignore_classes=ignore)
    tables, headline = isprs_tables(e, ignore, "counts summed over chunks")
    headline = (headline or f"{res.n_ground:,} of {res.n_points:,} points classified as "
                "ground") + " (catalog)"
    tables.append(filter_run_table(d, res))
    out = SectionResult(
        results=d, headline=headline, tables=tables, notes=notes,
        parameters={"filter": dict(res.parameters)},
        paragraphs=[f"{name} is a catalog: the filter runs chunk by chunk with a {res.buffer:g} m "
                    "buffer and keeps each chunk's core labels; the ISPRS counts are summed "
                    "over the chunks, which gives those of one run over the whole area."
                    + (" The classified tiles and a .vpc of them are in the outputs."
                       if opts["write_cloud"] else "")],
    )
    from ...tiling.apply import CatalogRun

    chunks: Any = tuple(SimpleNamespace(id=c["id"], core=tuple(c["core"])) for c in res.chunks)
    done: Any = tuple(SimpleNamespace(chunk=c, ok=True, error=None, attempts=1) for c in chunks)
    return with_overview(out, CatalogRun(None, cat, chunks, done), f"{name}: chunks")
