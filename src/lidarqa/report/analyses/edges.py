"""The ``edges`` analysis: 3D edges where building planes meet, per flight strip."""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from ...io.vector import metric_lengths
from .._context import (
    RunContext,
    SectionResult,
    keyword_defaults,
    library_attr,
    selection_label,
    write_vector,
)
from .._registry import CLOUD_KEY, register
from .._schema import FORMAT_KEY, AnalysisItem, AnalysisUnavailableError, Key, Target, targets
from ..html import Figure, Table


def _edge_params(options: dict) -> dict[str, Any]:
    extract_edges = library_attr("lidarqa.geometry.edges", "extract_edges", "edges")
    out = keyword_defaults(extract_edges, exclude=("segmentation", "crs", "left_out"))
    # extract_edges passes **segment_options to segment_planes: accept those names too.
    with contextlib.suppress(AnalysisUnavailableError):
        segment_planes = library_attr("lidarqa.geometry.segmentation", "segment_planes", "edges")
        out.add_missing(keyword_defaults(segment_planes))
    return out


KEYS = {
    "cloud": CLOUD_KEY,
    "classes": Key("int_list", default=None, help="classes to use (e.g. [6], buildings)"),
    "source_ids": Key(
        "int_list",
        default=None,
        help="flight strips (point_source_id), each processed separately",
    ),
    "format": FORMAT_KEY,
}
TARGETS = targets(Target("n_edges", ("n_edges",), "min", "edges found", ""))


@register("edges", _edge_params, keys=KEYS, targets=TARGETS, title="Edges", order=30)
def run_edges(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Extract edges (plane intersections) per flight strip and write them."""
    from .. import plots

    opts = item.options
    strips = opts["source_ids"] or [None]
    notes: list[str] = []
    per: dict[str, Any] = {}
    groups = []
    rows = []
    for sid in strips:
        seg = ctx.edges(opts["cloud"], opts["classes"], sid, item.params)
        key = "all" if sid is None else str(sid)
        lengths = metric_lengths(seg)
        per[key] = {
            "n_edges": len(seg),
            "total_length": float(lengths.sum()),
            "median_length": float(np.median(lengths)) if len(lengths) else None,
        }
        for attr in ("angle_deg", "sigma_line"):
            if attr in seg.attributes and len(seg):
                per[key][f"median_{attr}"] = float(
                    np.nanmedian(np.asarray(seg.attributes[attr], float))
                )
        base = "edges" if sid is None else f"edges_{sid}"
        if len(seg):
            write_vector(ctx, item, seg, base, opts["format"], notes)
        groups.append((seg.start, seg.end, "all" if sid is None else f"strip {sid}"))
        rows.append(
            [
                key,
                len(seg),
                float(lengths.sum()),
                per[key]["median_length"],
                per[key].get("median_sigma_line"),
            ]
        )
    n_total = sum(v["n_edges"] for v in per.values())
    with ctx.step("Plotting edges"):
        fig = plots.plot_segments(
            groups, "Edges (" + selection_label(opts["cloud"], opts["classes"], None) + ")"
        )
    res = {"n_edges": n_total, "by_source_id": per, "classes": opts["classes"]}
    table = Table(
        "Edges",
        ["strip", "edges", "total length (m)", "median length (m)", "median σ line (m)"],
        rows,
    )
    headline = ", ".join(
        f"{v['n_edges']} edges ({'strip ' + k if k != 'all' else 'all points'})"
        for k, v in per.items()
    )
    return SectionResult(
        results=res,
        headline=headline,
        figures=[Figure("Edges", fig, "top view")],
        tables=[table],
        notes=notes,
    )
