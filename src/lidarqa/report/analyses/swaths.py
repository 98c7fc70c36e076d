"""The ``swaths`` analysis of an assessment: relative accuracy of flight strips.

Registered with :func:`lidarqa.report._registry.register`; also provides the DZ
map used by ``lidarqa swaths``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._context import RunContext, SectionResult, keyword_defaults
from .._registry import CLOUD_KEY, register
from .._schema import AnalysisItem, Key, Target, targets
from ..html import Figure, Table
from ..labels import Label

__all__ = ["plot_dz_map", "run_swaths"]


def plot_dz_map(grid: Any, *, vmax: float = 0.16) -> bytes:
    """A diverging colour map of a :class:`~lidarqa.accuracy.swaths.DzGrid` (PNG bytes).

    Colours saturate at ±`vmax` metres (the quality level's max |dz| by default).
    """
    from ..plots import _plt, _png

    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    rows, cols = grid.dz.shape
    extent = (0.0, cols * grid.cell_size, 0.0, rows * grid.cell_size)
    cmap = plt.get_cmap("RdBu_r").with_extremes(bad="#c8c8c8")
    im = ax.imshow(
        np.ma.masked_invalid(grid.dz),
        cmap=cmap,
        vmin=-vmax,
        vmax=vmax,
        extent=extent,
        interpolation="nearest",
    )
    ax.set_aspect("equal")
    ax.set_xlabel(f"x − {grid.x0:,.0f} (m)")
    ax.set_ylabel(f"y − {grid.y1 - rows * grid.cell_size:,.0f} (m)")
    ax.set_title(f"dz = strip {grid.strip_b} − strip {grid.strip_a}")
    fig.colorbar(im, ax=ax, label="dz (m)", shrink=0.85)
    return _png(fig)


def _params(options: dict) -> Any:
    from ..._validate import check_choice
    from ...accuracy.swaths import QUALITY_LEVELS, assess_swaths

    out = keyword_defaults(assess_swaths, exclude=("return_grids",))

    def validate(params: dict[str, Any]) -> None:
        check_choice(params.get("quality_level", "QL1"), tuple(QUALITY_LEVELS), "quality_level")

    out.validate = validate
    return out


def _fmt_m(v: Any) -> str:
    """A length in metres to the millimetre (the unit policy: lengths in metres)."""
    return "–" if v is None or not np.isfinite(v) else f"{v:.3f}"


KEYS = {
    "cloud": CLOUD_KEY,
    "classes": Key("int_list", default=None, help="classes compared (default: 2 and 6)"),
    "source_ids": Key("int_list", default=None, help="strips compared (default: all)"),
    "last_returns": Key("bool", default=True, help="only last/single returns"),
}
TARGETS = targets(
    Target("rmsdz", ("max_rmsdz",), "max", "worst pair RMSDz", "m"),
    Target("max_abs", ("max_abs_dz",), "max", "max |dz|", "m"),
    Target("repeatability", ("max_repeatability",), "max", "repeatability", "m"),
    Target("e4", ("e4",), "max", "E4 strip noise", "m"),
)


#: report labels of the swaths parameters (the keys shared with other analyses are in labels.py)
LABELS = {
    "last_returns": Label("only last/single returns"),
    "estimate_offsets": Label("estimate strip offsets"),
    "max_normal_angle": Label("planes match if their normals differ by at most", "°"),
    "max_roughness": Label("smooth surface: plane residual RMS at most", "m"),
    "max_slope": Label("smooth surface: plane slope at most", "°"),
    "min_overlap_cells": Label("planar cells a pair needs to count as overlapping"),
    "offset_max_slope": Label("steepest plane used for the offsets", "°"),
    "quality_level": Label("quality level of the pass/fail thresholds"),
    "range_cell": Label("repeatability range cell (auto when empty)", "m"),
    "reference_strip": Label("strip held fixed in the network (auto when empty)"),
    "rotations": Label("also estimate small rotations per strip"),
}


@register(
    "swaths",
    _params,
    keys=KEYS,
    targets=TARGETS,
    title="Flight strips",
    order=70,
    labels=LABELS,
)
def run_swaths(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Overlap differences, repeatability and offsets of the strips of one cloud."""
    from ...tiling.jobs_swaths import catalog_swaths
    from ...tiling.source import Source
    from ..catalog_overview import with_overview

    # one job for a file (one region, from the cloud the report already holds) and a catalog
    # (chunk by chunk: every cell fitted by its owner)
    opts = item.options
    name = opts["cloud"]
    on_catalog = ctx.is_catalog(name)
    source = (str(ctx.config.inputs[name].path) if on_catalog
              else Source(catalog=None, cloud=ctx.cloud(name)))
    with ctx.step(f"Comparing the flight strips of {name}"):
        run = catalog_swaths(source, by_source_id=True, classes=opts["classes"],
                             source_ids=opts["source_ids"], all_returns=not opts["last_returns"],
                             skip_failed=on_catalog, **item.params)
    out = swaths_section(ctx, item, run.value, run.catalog.crs)
    if on_catalog:
        out.paragraphs.append(f"{name} is a catalog: every grid cell is fitted in the chunk "
                              "that owns it, with all its points; the figures are those of one "
                              "run over the whole block.")
    return with_overview(out, run if on_catalog else None, f"{name}: chunks")


def swaths_section(ctx: RunContext, item: AnalysisItem, rep: Any, crs: Any) -> SectionResult:
    """The report section of a :class:`~lidarqa.accuracy.swaths.SwathReport` (DZ rasters too)."""
    res = rep.to_dict()
    finite = [p.rmsdz for p in rep.pairs if np.isfinite(p.rmsdz)]
    res["max_rmsdz"] = max(finite) if finite else None
    res["max_abs_dz"] = max((p.max_abs for p in rep.pairs if np.isfinite(p.max_abs)), default=None)
    res["max_repeatability"] = max(
        (r.median_range for r in rep.repeatability if r.assessed), default=None
    )
    figures, outputs = [], []
    notes = list(rep.flags)
    import importlib.util

    has_rasterio = importlib.util.find_spec("rasterio") is not None
    if not has_rasterio and rep.grids:
        notes.append("DZ GeoTIFFs not written: install the 'raster' extra (rasterio)")
    for g in rep.grids:
        if has_rasterio:
            from ...io.raster import write_geotiff

            path = ctx.output_path(item, f"dz_{g.strip_a}_{g.strip_b}.tif")
            write_geotiff(
                path, g.dz, x0=g.x0, y1=g.y1, cell_size=g.cell_size, crs=crs, overwrite=True
            )
            outputs.append(path.name)
        figures.append(
            Figure(
                f"DZ map, strips {g.strip_a} and {g.strip_b}",
                plot_dz_map(g, vmax=rep.thresholds["max_abs"]),
                "dz between the strips' local planes on smooth cells; grey: not compared",
            )
        )
    tables = swaths_tables(rep)
    worst = res["max_rmsdz"]
    overlap_ok = all(p.passed for p in rep.pairs)
    repeat_ok = all(r.passed for r in rep.repeatability if r.assessed)
    headline = (
        f"{len(rep.pairs)} overlapping pair(s), worst RMSDz {_fmt_m(worst)} m, "
        f"E4 {_fmt_m(rep.e4)} m; {rep.quality_level}: overlap "
        f"{'pass' if overlap_ok else 'FAIL'}, repeatability {'pass' if repeat_ok else 'FAIL'}"
    )
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        outputs=outputs,
        notes=notes,
        parameters=dict(rep.parameters),
        paragraphs=[
            "Each strip fits a plane per grid cell; on cells that are smooth in both strips "
            "(low residuals, gentle slope) dz is the difference of the two planes' heights at "
            "the cell centre. Thresholds: USGS Lidar Base Specification (2023 rev.) / ASPRS "
            "Positional Accuracy Standards Ed. 2 (2023) relative vertical accuracy."
        ],
    )


def swaths_tables(rep: Any) -> list[Table]:
    """The figures of a swath report: the report section's tables and ``lidarqa swaths``'.

    Overlap per pair of strips, repeatability per strip (against the quality level's
    thresholds) and the strip offsets with E4, in metres.
    """
    t = rep.thresholds
    tables = [
        Table(
            f"Swath overlap ({rep.quality_level}: RMSDz ≤ {t['rmsdz']:.2f} m, "
            f"max ≤ {t['max_abs']:.2f} m; cells of {rep.cell_size:g} m)",
            [
                "pair",
                "overlap (m²)",
                "compared (m²)",
                "RMSDz (m)",
                "mean (m)",
                "median (m)",
                "p95 |dz| (m)",
                "max |dz| (m)",
                "result",
            ],
            [
                [
                    f"{p.strip_a}–{p.strip_b}",
                    round(p.overlap_area),
                    round(p.area),
                    p.rmsdz,
                    p.mean,
                    p.median,
                    p.p95_abs,
                    p.max_abs,
                    "pass" if p.passed else "FAIL",
                ]
                for p in rep.pairs
            ],
            decimals=3,
        ),
        Table(
            f"Smooth-surface repeatability (≤ {t['repeatability']:.2f} m)",
            [
                "strip",
                "area (m²)",
                "RMSE (m)",
                "range cell (m)",
                "median max−min (m)",
                "p95 (m)",
                "result",
            ],
            [
                [
                    r.strip,
                    round(r.area),
                    r.rmse,
                    r.range_cell,
                    r.median_range,
                    r.p95_range,
                    "pass" if r.passed else "FAIL",
                ]
                for r in rep.repeatability
                if r.assessed
            ],
            decimals=3,
        ),
    ]
    offs = rep.network_offsets or rep.pair_offsets
    if offs:
        tables.append(
            Table(
                "Strip offsets"
                + (f" (network, strip {rep.reference_strip} fixed)" if rep.network_offsets else ""),
                ["strip − reference", "method", "dx (m)", "dy (m)", "dz (m)", "σ dx / dy / dz (m)"],
                [
                    [
                        f"{o.strip_b} − {o.strip_a}",
                        o.method,
                        o.dx,
                        o.dy,
                        o.dz,
                        f"{_fmt_m(o.sigma_dx)} / {_fmt_m(o.sigma_dy)} / {_fmt_m(o.sigma_dz)}",
                    ]
                    for o in offs
                    if o.strip_a != o.strip_b or not rep.network_offsets
                ],
                note=f"E4 (strip height noise) = {_fmt_m(rep.e4)} m",
                decimals=3,
            )
        )
    return tables
