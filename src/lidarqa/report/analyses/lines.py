"""The ``lines`` analysis: match test and model 3D segments (LHD, both ways)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError
from ...io.vector import heights_in_metres
from .._context import (
    RunContext,
    SectionResult,
    keyword_defaults,
    library_attr,
    selection_label,
    write_vector,
)
from .._registry import ResolveContext, register
from .._schema import (
    FORMAT_KEY,
    AnalysisItem,
    Key,
    Target,
    check_params,
    check_table,
    need_input,
    targets,
)
from ..html import Figure, Table, fmt


def _lines_params(options: dict) -> dict[str, Any]:
    match_segments = library_attr("lidarqa.accuracy.lines", "match_segments", "lines")
    return keyword_defaults(match_segments, exclude=("ground_truth",))


def _segment_source(ctx: RunContext, source: dict, edge_options: dict) -> tuple[Any, str]:
    # matched with heights in metres, as `lidarqa lines` does
    if "segments" in source:
        return heights_in_metres(ctx.segments(source["segments"])), source["segments"]
    seg = ctx.edges(source["cloud"], source.get("classes"), source.get("source_id"), edge_options)
    return heights_in_metres(seg), selection_label(source["cloud"], source.get("classes"),
                                                   source.get("source_id"))


def _threshold_curve(th: Any, label: str) -> dict[str, Any]:
    k = int(getattr(th, "peak_index", -1))
    return {
        "label": f"{label} (δ = {th.threshold:.3f} m, {th.reason})",
        "sorted": np.asarray(th.sorted_nearest),
        "second_diff": np.asarray(th.second_diff),
        "second_diff_offset": 1,
        "peak_index": (k + 1) if k >= 0 else None,
        "threshold": float(th.threshold),
    }


_SOURCE_HELP = "a segments input name or { cloud = ..., classes = [...], source_id = N }"
KEYS = {
    "test": Key("ref", required=True, help=_SOURCE_HELP, input=("segments", "clouds")),
    "model": Key("ref", required=True, help=_SOURCE_HELP, input=("segments", "clouds")),
    "ground_truth": Key("str", help="CSV of true pairs (test_id,model_id), relative to the config"),
    "edges": Key("table", default=None, help="edge-extraction options for cloud inputs"),
    "format": FORMAT_KEY,
}
TARGETS = targets(
    Target("lhd", ("lhd",), "max", "LHD", "m"),
    Target("olhd_tm", ("olhd_tm",), "max", "OLHD test→model", "m"),
    Target("olhd_mt", ("olhd_mt",), "max", "OLHD model→test", "m"),
)
#: ``test = { cloud = ..., classes = [...], source_id = N }``: edges extracted from a cloud
SELECTION_KEYS = {
    "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
    "classes": Key("int_list", default=None),
    "source_id": Key("int_list", default=None),
}


def _segment_table(value: Any, ctx: ResolveContext, side: str) -> dict:
    sub_where = f"{ctx.where} key {side!r}"
    if isinstance(value, str):
        need_input(ctx.inputs, value, ("segments", "clouds"), ctx.where, side)
        if ctx.inputs[value].kind == "clouds":
            return {"cloud": value, "classes": None, "source_id": None}
        return {"segments": value}
    if "segments" in value:
        sub = check_table(value, {"segments": Key("str", required=True)}, sub_where)
        need_input(ctx.inputs, sub["segments"], ("segments",), sub_where, "segments")
        return sub
    sub = check_table(value, SELECTION_KEYS, sub_where)
    need_input(ctx.inputs, sub["cloud"], ("clouds",), sub_where, "cloud")
    return sub


def _resolve(opts: dict, ctx: ResolveContext) -> None:
    for side in ("test", "model"):
        opts[side] = _segment_table(opts[side], ctx, side)
    if "cloud" in opts["test"] or "cloud" in opts["model"] or opts["edges"] is not None:
        edge_defaults = ctx.library_params("edges", {})
        sub = f"{ctx.where} key 'edges'"
        check_table(opts["edges"] or {}, {}, sub, extra=edge_defaults)
        opts["edges"] = check_params(opts["edges"] or {}, edge_defaults, sub)
    else:
        opts["edges"] = {}
    if opts["ground_truth"] is not None:
        gt = Path(opts["ground_truth"])
        gt = gt if gt.is_absolute() else ctx.base / gt
        if not gt.is_file():
            raise ConfigError(f"key 'ground_truth' in {ctx.where}: file {gt} does not exist")
        opts["ground_truth"] = gt


@register(
    "lines",
    _lines_params,
    keys=KEYS,
    targets=TARGETS,
    title="Line matching",
    resolve=_resolve,
    order=40,
)
def run_lines(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Match test and model segments (Poreba & Goulette modified LHD), both ways."""
    from ...io.vector import Segments
    from .. import plots

    match_segments = library_attr("lidarqa.accuracy.lines", "match_segments", "lines")
    opts = item.options
    test, tlabel = _segment_source(ctx, opts["test"], opts["edges"])
    model, mlabel = _segment_source(ctx, opts["model"], opts["edges"])
    notes: list[str] = []
    gt = None
    if opts["ground_truth"] is not None:
        from ...accuracy.lines_io import read_pairs

        gt = read_pairs(opts["ground_truth"])
    if len(test) == 0 or len(model) == 0:
        from ...errors import DegenerateGeometryError

        raise DegenerateGeometryError(
            f"no segments to match: {len(test)} test ({tlabel}), {len(model)} model ({mlabel})"
        )
    with ctx.step(f"Matching {len(test):,} × {len(model):,} segments") as progress:
        m = match_segments(test, model, ground_truth=gt, progress=progress, **item.params)
    res = m.to_dict()
    res.update(
        test=tlabel,
        model=mlabel,
        cutoff=m.cutoff,
        gao_leung_tm=m.gao_leung_tm,
        gao_leung_mt=m.gao_leung_mt,
        hausdorff_tm=m.hausdorff_tm,
        hausdorff_mt=m.hausdorff_mt,
        threshold_reason_tm=m.auto_tm.reason,
        threshold_reason_mt=m.auto_mt.reason,
    )
    p, q = m.p, m.q

    # Output files: segments used (when extracted), correspondences both ways.
    fmt = opts["format"]
    for side, seg, src in (("test", test, opts["test"]), ("model", model, opts["model"])):
        if "cloud" in src:
            write_vector(ctx, item, seg, f"edges_{side}", fmt, notes)
    ti, mi, d = m.pairs_tm()
    best = np.full(p, np.nan)
    best_model = np.full(p, -1, dtype=np.int64)
    if len(ti):
        order = np.lexsort((d, ti))
        first = np.ones(len(order), bool)
        first[1:] = ti[order][1:] != ti[order][:-1]
        sel = order[first]
        best[ti[sel]] = d[sel]
        best_model[ti[sel]] = mi[sel]
    attrs = {
        "matched": np.isfinite(best),
        "model_id": np.array(
            [str(model.ids[j]) if j >= 0 else "" for j in best_model], dtype=object
        ),
        "distance": best,
    }
    matched_test = Segments(test.ids, test.start, test.end, attrs, test.crs)
    write_vector(ctx, item, matched_test, "matched_test", fmt, notes)
    comp = m.pair_components
    for base, mask, dcol in (
        ("pairs_tm", m.match_tm, comp[:, 3]),
        ("pairs_mt", m.match_mt, m.pair_d_mt),
    ):
        # One row per pair: the test segment's geometry with both ids and the distance parts.
        k = np.flatnonzero(mask)
        ti_k, mi_k = m.pair_test[k], m.pair_model[k]
        pairs = Segments(
            np.arange(len(k)),
            test.start[ti_k],
            test.end[ti_k],
            {
                "test_id": np.array([str(v) for v in test.ids[ti_k]], dtype=object),
                "model_id": np.array([str(v) for v in model.ids[mi_k]], dtype=object),
                "d": dcol[k],
                "d_angle": comp[k, 0],
                "d_parallel": comp[k, 1],
                "d_perpendicular": comp[k, 2],
            },
            test.crs,
        )
        write_vector(ctx, item, pairs, base, fmt, notes)
        if fmt != "csv":
            write_vector(ctx, item, pairs, base, "csv", notes)

    figures: list[Figure] = []
    with ctx.step("Plotting line matching"):
        if p * q <= 4_000_000:
            sim = np.full((p, q), np.nan)
            sim[m.pair_test, m.pair_model] = comp[:, 3]
            figures.append(
                Figure(
                    "Similarity matrix",
                    plots.plot_matrix(sim, f"Segment distances d (p = {p}, q = {q})", label="d"),
                    "rows: test segments, columns: model segments; "
                    "blank = pruned pairs (far apart)",
                )
            )
            cor = np.zeros((p, q), dtype=np.int8)
            cor[m.pair_test[m.match_tm], m.pair_model[m.match_tm]] = 1
            figures.append(
                Figure(
                    "Correspondence matrix",
                    plots.plot_matrix(
                        cor, f"Correspondence test → model ({m.n_pairs_tm} pairs)", binary=True
                    ),
                    "a dark cell is a pair with d ≤ δ (test → model)",
                )
            )
        else:
            notes.append(
                f"similarity and correspondence matrices not drawn: {p} × {q} is too large"
            )
        figures.append(
            Figure(
                "Automatic threshold",
                plots.plot_threshold_curve(
                    [
                        _threshold_curve(m.auto_tm, "test → model"),
                        _threshold_curve(m.auto_mt, "model → test"),
                    ]
                ),
                "sorted nearest distances (top) and their second differences (bottom); "
                "circles mark the "
                "chosen peak, dashed lines the thresholds",
            )
        )
        figures.append(
            Figure(
                "Matched segments",
                plots.plot_matched_segments(
                    (test.start, test.end),
                    (model.start, model.end),
                    best,
                    "Test segments coloured by distance to their match",
                ),
                f"test: {tlabel}; model: {mlabel}",
            )
        )
    tables = [lines_table(m)]
    k = np.flatnonzero(m.match_tm)
    k = k[np.argsort(comp[k, 3], kind="stable")]
    tables.append(
        Table(
            "Pairs test → model",
            ["test id", "model id", "d (m)", "angle part", "parallel (m)", "perpendicular (m)"],
            [
                [
                    str(test.ids[m.pair_test[j]]),
                    str(model.ids[m.pair_model[j]]),
                    float(comp[j, 3]),
                    *comp[j, :3].tolist(),
                ]
                for j in k[:50]
            ],
            note=f"{len(k)} pairs"
            + ("; the 50 closest shown, all in the output files" if len(k) > 50 else ""),
        )
    )
    if not (m.threshold_found_tm and m.threshold_found_mt) and item.params.get("threshold") is None:
        notes.append(
            "the automatic threshold fell back to the largest nearest distance in at least one "
            "direction (no clear knee); read the LHD with care"
        )
    headline = f"LHD {m.lhd:.3f} m ({m.n_pairs_tm} pairs; p = {p}, q = {q})"
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=[
            f"Test: {tlabel}. Model: {mlabel}. Distances combine angle, "
            "parallel and perpendicular components (weight W on the angle); "
            "OLHD is the length-weighted mean distance of matched pairs."
        ],
    )


def lines_table(m: Any) -> Table:
    """The figures of a line matching, both directions: the report's table and ``lidarqa lines``'.

    The LHD in the title; thresholds (and how they were chosen), pairs, OLHD and the
    Gao–Leung primary LHD, and with a ground truth the confusion counts and detection rates.
    """
    def how(auto: Any) -> str:
        return {"peak": "auto", "fixed": "fixed"}.get(auto.reason, f"fallback: {auto.reason}")

    rows = [
        ["threshold δ (m)", m.threshold_tm, m.threshold_mt, f"{how(m.auto_tm)} / {how(m.auto_mt)}"],
        ["pairs", m.n_pairs_tm, m.n_pairs_mt, ""],
        ["OLHD (m)", m.olhd_tm, m.olhd_mt, ""],
        ["Gao–Leung primary LHD (m)", m.gao_leung_tm, m.gao_leung_mt, "no threshold"],
    ]
    g = m.ground_truth
    if g:
        rows += [[k.upper(), g[f"{k}_tm"], g[f"{k}_mt"], ""] for k in ("tp", "fp", "fn", "tn")]
        rows.append(["detection rate (%)", 100 * g["detection_rate_tm"],
                     100 * g["detection_rate_mt"], "(TP + TN) / (p·q)"])
    return Table(
        f"Line matching: LHD {fmt(m.lhd)} m (the larger OLHD)",
        ["quantity", "test→model", "model→test", "note"],
        rows,
        note=f"p = {m.p} test segments, q = {m.q} model segments",
    )
