"""The report's catalog section: an overview map of tiles, chunks and strips, and chunk status.

A job on a catalog (:mod:`lidarqa.tiling.jobs_api`) returns its merged value
with the catalog, the chunks and each chunk's outcome. This module turns that
into what a reader of the report needs to trust the figures:

* an overview map (top view): the tiles as outlines with their names, the
  chunk grid coloured by status (ok, retried, failed, skipped, resumed) and, when the
  job knows them, the flight strips as the outline of the chunks where each
  strip was found;
* a per-chunk status table (failed and retried chunks first, with the error),
  and the counts per status.

Everything here takes plain data (bounds, ids, status dicts), so it works with
any object that follows the catalog contract and is easy to test.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .html import Figure, Table

__all__ = ["STATUS_COLOURS", "catalog_section", "plot_catalog_overview", "status_table",
           "with_overview"]

#: Fill colour of a chunk by status.
STATUS_COLOURS = {
    "ok": "#a5d6a7",
    "retried": "#ffcc80",
    "failed": "#ef5350",
    "skipped": "#e0e0e0",
    "resumed": "#a9bcd0",  # kept from an earlier run (--resume); hatched as well
    "not run": "#ffffff",
}
_STRIP_COLOURS = ["#1f77b4", "#9467bd", "#17becf", "#bcbd22", "#e377c2", "#8c564b", "#7f7f7f"]


def _stem(path: Any) -> str:
    from pathlib import Path

    return Path(str(path)).stem


def plot_catalog_overview(
    tiles: Sequence[tuple[str, Sequence[float]]],
    chunks: Sequence[tuple[str, Sequence[float]]],
    status: Mapping[str, str],
    *,
    strips: Mapping[Any, Sequence[str]] | None = None,
    title: str = "Catalog overview",
) -> bytes:
    """Top-view map of a catalog run, as PNG bytes.

    Parameters
    ----------
    tiles : sequence of (name, (xmin, ymin, xmax, ymax, ...))
        Tile names and header bounds.
    chunks : sequence of (chunk id, core (xmin, ymin, xmax, ymax))
    status : mapping chunk id -> "ok" | "retried" | "failed" | "skipped" | "resumed"
        Chunks absent from it are drawn as "not run".
    strips : mapping strip id -> chunk ids, optional
        Where each flight strip was found; drawn as the outline of those chunks.
    """
    from matplotlib.patches import Patch, Rectangle

    from .plots import _map_axes, _plt, _png

    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 6.5))
    corners = [(b[0], b[1]) for _, b in tiles] + [(b[2], b[3]) for _, b in tiles]
    corners += [(c[0], c[1]) for _, c in chunks] + [(c[2], c[3]) for _, c in chunks]
    xy = np.asarray(corners, dtype=float).reshape(-1, 2)
    x0, y0 = _map_axes(ax, xy)
    ax.set_aspect("equal", adjustable="box")  # fixed limits below: shrink the box, not them
    core_of = {cid: core for cid, core in chunks}
    for cid, c in chunks:
        st = status.get(cid, "not run")
        ax.add_patch(Rectangle((c[0] - x0, c[1] - y0), c[2] - c[0], c[3] - c[1],
                               facecolor=STATUS_COLOURS.get(st, "#ffffff"), edgecolor="#9e9e9e",
                               hatch="//" if st == "resumed" else None, linewidth=0.5, zorder=1))
        if st in ("failed", "retried") and len(chunks) <= 400:
            ax.text(0.5 * (c[0] + c[2]) - x0, 0.5 * (c[1] + c[3]) - y0, cid, ha="center",
                    va="center", fontsize=6, zorder=4)
    for name, b in tiles:
        ax.add_patch(Rectangle((b[0] - x0, b[1] - y0), b[2] - b[0], b[3] - b[1], fill=False,
                               edgecolor="#212121", linewidth=1.2, zorder=3))
        if len(tiles) <= 60:
            ax.text(b[0] - x0 + 0.02 * (b[2] - b[0]), b[3] - y0 - 0.02 * (b[3] - b[1]), name,
                    ha="left", va="top", fontsize=6, color="#212121", zorder=4)
    handles = [Patch(facecolor=STATUS_COLOURS[s], edgecolor="#9e9e9e",
                     hatch="//" if s == "resumed" else None,
                     label=f"chunk {s}" + (" (from an earlier run)" if s == "resumed" else ""))
               for s in ("ok", "retried", "failed", "skipped", "resumed")
               if s in set(status.values())]
    handles.append(Patch(fill=False, edgecolor="#212121", label="tile"))
    for k, (sid, ids) in enumerate(sorted((strips or {}).items(), key=lambda kv: str(kv[0]))):
        boxes = [core_of[i] for i in ids if i in core_of]
        if not boxes:
            continue
        col = _STRIP_COLOURS[k % len(_STRIP_COLOURS)]
        inset = 0.04 * (k % 5 + 1) * (boxes[0][2] - boxes[0][0]) / 2
        for c in boxes:  # outline of each chunk of the strip, inset so strips stay distinct
            ax.add_patch(Rectangle((c[0] - x0 + inset, c[1] - y0 + inset),
                                   c[2] - c[0] - 2 * inset, c[3] - c[1] - 2 * inset, fill=False,
                                   edgecolor=col, linewidth=0.9, linestyle="--", zorder=2))
        handles.append(Patch(fill=False, edgecolor=col, linestyle="--", label=f"strip {sid}"))
    ax.set_xlim(xy[:, 0].min() - x0, xy[:, 0].max() - x0)
    ax.set_ylim(xy[:, 1].min() - y0, xy[:, 1].max() - y0)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              frameon=False)
    ax.set_title(title)
    return _png(fig)


def status_table(status_rows: Sequence[Mapping[str, Any]], *, limit: int = 200) -> Table:
    """Per-chunk status, failed and retried chunks first (at most `limit` rows)."""
    rank = {"failed": 0, "retried": 1, "skipped": 2, "ok": 3}
    rows = sorted(status_rows, key=lambda r: (rank.get(r["status"], 4), r["chunk"]))
    shown = rows[:limit]
    note = f"{len(rows) - limit} more chunks not listed" if len(rows) > limit else ""
    return Table("Chunks", ["chunk", "status", "attempts", "error"],
                 [[r["chunk"], r["status"], r.get("attempts", 1), r.get("error") or ""]
                  for r in shown], note=note)


def catalog_section(run: Any, *, title: str = "Catalog") -> dict[str, Any]:
    """Results, figure and tables of a :class:`~lidarqa.tiling.jobs_api.CatalogRun`.

    Returns
    -------
    dict
        ``{"results", "headline", "figures", "tables", "notes"}``, ready to merge
        into an analysis' section.
    """
    cat = run.catalog
    rows = run.chunk_status()
    status = {r["chunk"]: r["status"] for r in rows}
    summary = run.to_dict()  # the counts of the --json record (CatalogRun.to_dict)
    counts = summary["chunk_status"]
    tiles = [(_stem(t.path), t.bounds) for t in cat.tiles]
    chunks = [(c.id, c.core) for c in run.chunks]
    strips = run.extra.get("strip_chunks") if isinstance(run.extra, dict) else None
    fig = Figure(
        f"{title}: tiles, chunks" + (" and strips" if strips else ""),
        plot_catalog_overview(tiles, chunks, status, strips=strips, title=title),
        "top view: tile outlines (black), chunk cores coloured by status"
        + ("; dashed: the chunks where each flight strip gave edges" if strips else ""),
    )
    tab_tiles = Table("Tiles", ["tile", "points", "x range", "y range"],
                      [[_stem(t.path), t.n_points, f"{t.bounds[0]:.1f} .. {t.bounds[2]:.1f}",
                        f"{t.bounds[1]:.1f} .. {t.bounds[3]:.1f}"] for t in cat.tiles[:200]],
                      note=(f"{len(cat.tiles) - 200} more tiles" if len(cat.tiles) > 200 else ""))
    bad = list(getattr(cat, "bad", ()) or ())
    notes = [f"skipped bad tile {p}: {why}" for p, why in bad]
    if summary["failed_chunks"]:
        notes.append(f"{len(summary['failed_chunks'])} chunk(s) failed; their area is missing "
                     "from the figures: " + ", ".join(summary["failed_chunks"]))
    results = {
        "n_tiles": summary["n_tiles"], "n_points": int(cat.n_points), "bounds": list(cat.bounds),
        "n_chunks": summary["n_chunks"], "chunk_status": counts,
        "failed_chunks": summary["failed_chunks"],
        "bad_tiles": [{"path": str(p), "reason": str(why)} for p, why in bad],
    }
    headline = (f"{len(cat.tiles)} tiles, {int(cat.n_points):,} points, {len(run.chunks)} chunks: "
                + ", ".join(f"{v} {k}" for k, v in counts.items() if v))
    return {"results": results, "headline": headline, "figures": [fig],
            "tables": [status_table(rows), tab_tiles], "notes": notes}


def with_overview(res: Any, run: Any, title: str) -> Any:
    """`res` (a SectionResult) with the catalog overview map and chunk table of `run` added.

    `run` None (not a catalog): `res` as it is.
    """
    if run is None:
        return res
    sec = catalog_section(run, title=title)
    res.figures = [*res.figures, *sec["figures"]]
    res.tables = [*res.tables, *sec["tables"]]
    res.notes = [*res.notes, *sec["notes"]]
    res.results["catalog"] = sec["results"]
    return res
