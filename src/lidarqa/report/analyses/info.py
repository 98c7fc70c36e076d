"""The ``info`` analysis: describe a cloud and show it from above."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from .._context import RunContext, SectionResult
from .._registry import CLOUD_KEY, register
from .._schema import AnalysisItem
from ..html import Figure, Table


@register("info", keys={"cloud": CLOUD_KEY}, title="Input cloud", order=10)
def run_info(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Describe the cloud and show it from above, coloured by class and by flight strip."""
    from ...io.info import describe_cloud
    from .. import plots

    name = item.options["cloud"]
    if ctx.is_catalog(name):
        return _run_on_catalog(ctx, item)
    cloud = ctx.cloud(name)
    info = describe_cloud(cloud).to_dict()
    figures = []
    with ctx.step(f"Plotting {name}"):
        if cloud.classification is not None:
            figures.append(
                Figure(
                    "Classes",
                    plots.plot_classes(
                        cloud.xyz[:, :2],
                        cloud.classification,
                        f"{name}: classes",
                        z=cloud.xyz[:, 2],
                    ),
                    "top view, coloured by the file's classification",
                )
            )
        psid = cloud.point_source_id
        if psid is not None and len(np.unique(psid)) > 1:
            figures.append(
                Figure(
                    "Flight strips",
                    plots.plot_categories(
                        cloud.xyz[:, :2],
                        psid,
                        f"{name}: flight strips (point_source_id)",
                        z=cloud.xyz[:, 2],
                    ),
                    "top view, coloured by point_source_id",
                )
            )
        figures.append(
            Figure(
                "Heights",
                plots.plot_values(
                    cloud.xyz[:, :2],
                    cloud.xyz[:, 2],
                    f"{name}: heights",
                    label="z (m)",
                    z=cloud.xyz[:, 2],
                ),
                "top view, coloured by height (1st–99th percentile)",
            )
        )
    return _section(info, figures)


def _section(info: dict[str, Any], figures: list[Figure],
             catalog: dict[str, Any] | None = None) -> SectionResult:
    """The tables and headline of a description (with a catalog's own section, if any)."""
    b = info["bounds"]
    rows = [
        ["points", info["n_points"]],
        ["x range", f"{b['min_x']:.2f} .. {b['max_x']:.2f}" if info["n_points"] else "–"],
        ["y range", f"{b['min_y']:.2f} .. {b['max_y']:.2f}" if info["n_points"] else "–"],
        ["z range", f"{b['min_z']:.2f} .. {b['max_z']:.2f}" if info["n_points"] else "–"],
        [
            "CRS",
            (info["crs_name"] or "none")
            + (f" (EPSG:{info['crs_epsg']})" if info["crs_epsg"] else ""),
        ],
        ["density (pts/m²)", info["density_per_m2"]],
        [
            "return numbers",
            "valid"
            if info["returns"].get("valid")
            else (
                "absent" if not info["returns"].get("present") else "present, partly invalid/zero"
            ),
        ],
    ]
    from ..plots import CLASS_NAMES

    if catalog is not None:
        rows += catalog["rows"]
    tables = [Table("Cloud", ["property", "value"], rows)]
    if info["classes"]:
        tables.append(
            Table(
                "Classes",
                ["class", "name", "points"],
                [[int(k), CLASS_NAMES.get(int(k), ""), v] for k, v in info["classes"].items()],
            )
        )
    if info["point_source_ids"]:
        tables.append(
            Table(
                "Flight strips",
                ["flight strip (point source ID)", "points"],
                [[str(int(k)), v] for k, v in info["point_source_ids"].items()],
            )
        )
    dens = info["density_per_m2"]
    headline = (
        f"{info['n_points']:,} points"
        + (f", {dens:.1f} pts/m²" if dens else "")
        + (f", {len(info['point_source_ids'])} flight strips" if info["point_source_ids"] else "")
    )
    info.pop("header", None)
    if catalog is None:
        return SectionResult(results=info, headline=headline, figures=figures, tables=tables)
    return SectionResult(results={**info, **catalog["results"]},
                         headline=f"catalog of {catalog['results']['n_tiles']} tiles, " + headline,
                         figures=catalog["figures"], tables=[*tables, *catalog["tables"]],
                         notes=catalog["notes"])


def _run_on_catalog(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """The same description, read tile by tile, with the chunks a job would use."""
    from ...io.info import describe_files
    from ...tiling import make_chunks, open_catalog
    from ...tiling.apply import CatalogRun
    from ..catalog_overview import catalog_section

    name = item.options["cloud"]
    with ctx.step(f"Reading {name} tile by tile"):
        cat = open_catalog(str(ctx.config.inputs[name].path))
        info = describe_files([t.path for t in cat.tiles], crs=cat.crs).to_dict()
    chunks = make_chunks(cat)
    run = CatalogRun(None, cat, tuple(chunks), ())  # no job: the chunks a job would use
    sec = catalog_section(run, title=f"{name}: catalog")
    d = cat.to_dict()
    results = {**sec["results"], "gaps": len(cast(list, d.get("gaps", []))),
               "overlaps": len(cast(list, d.get("overlaps", []))),
               "chunk_size": chunks[0].size if chunks else None}
    rows = [["tiles", len(cat.tiles)], ["gaps (missing tile cells)", results["gaps"]],
            ["duplicate overlaps", results["overlaps"]],
            ["default chunks", f"{len(chunks)} of {results['chunk_size']:g} m"
             if chunks else "–"]]
    return _section(info, [], {"results": results, "rows": rows, "figures": sec["figures"],
                               "tables": [sec["tables"][1]], "notes": sec["notes"]})
