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
    tables = info_tables({**(catalog or {}).get("catalog", {}), **info})  # info's own figures
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
    cres = catalog_results(cat, chunks)
    results = {**sec["results"], "gaps": len(cast(list, cres["gaps"])),
               "overlaps": len(cast(list, cres["overlaps"])),
               "chunk_size": cres["default_chunks"]["chunk_size"]}
    return _section(info, [], {"results": results, "catalog": cres, "figures": sec["figures"],
                               "tables": [sec["tables"][1]], "notes": sec["notes"]})


def catalog_results(cat: Any, chunks: Any = None) -> dict[str, Any]:
    """The catalog's own keys: tiles, header bounds, gaps, overlaps and default chunks."""
    from ...tiling import make_chunks

    d = cat.to_dict()
    chunks = make_chunks(cat) if chunks is None else chunks
    d["default_chunks"] = {
        "n_chunks": len(chunks),
        "chunk_size": chunks[0].size if chunks else None,
        "buffer": float(chunks[0].buffered[2] - chunks[0].core[2]) if chunks else None,
    }
    return d


def info_tables(d: dict[str, Any]) -> list[Table]:
    """The description of a cloud or a catalog: the report's tables and ``lidarqa info``'s.

    `d` is ``describe(...).to_dict()``, with a catalog's :func:`catalog_results` merged in
    (tiles, header bounds, gaps, overlaps, default chunks).
    """
    from ..plots import CLASS_NAMES

    catalog = "n_tiles" in d
    b = d["bounds"]
    if isinstance(b, list):  # a catalog's header bounds (x, y) and z range
        b = dict(zip(("min_x", "min_y", "max_x", "max_y"), b, strict=True))
        b.update(min_z=d["zrange"][0], max_z=d["zrange"][1])
    r = d["returns"]
    read = d.get("points_read", True)
    rows: list[list[Any]] = []
    if catalog:
        rows.append(["tiles", f"{d['n_tiles']:,}" + (f" ({d['n_copc']} COPC)" if d["n_copc"]
                                                     else "")])
    rows += [
        ["points", d["n_points"]],
        *[[f"{a} range", f"{b['min_' + a]:.3f} .. {b['max_' + a]:.3f}" if d["n_points"] else "–"]
          for a in "xyz"],
        ["CRS", (d["crs_name"] or "none") + (f" (EPSG:{d['crs_epsg']})" if d["crs_epsg"] else "")],
        ["vertical unit", d.get("vertical_unit")],
        ["density (pts/m², points / occupied area)", d["density_per_m2"] if read else None],
        ["return numbers", "not read (--headers)" if not read else "absent" if not r["present"]
         else "valid" if r["valid"]
         else f"present, {r['n_zero_return_number']:,} zero / {r['n_invalid']:,} invalid"],
    ]
    if catalog:
        dc = d["default_chunks"]
        rows += [
            ["tile size (m, median)", d["tile_size"]],
            ["point formats", ", ".join(str(f) for f in d["point_formats"])],
            ["gaps (missing tile cells)", len(d["gaps"])],
            ["duplicate overlaps", len(d["overlaps"])],
            ["default chunks", f"{dc['n_chunks']} of {dc['chunk_size']:g} m, buffer "
             f"{dc['buffer']:g} m" if dc["n_chunks"] else "–"],
            ["bad inputs", len(d.get("bad") or [])],
        ]
    tables = [Table("Cloud", ["property", "value"], rows)]
    if d["classes"]:
        tables.append(
            Table(
                "Classes",
                ["class", "name", "points"],
                [[int(k), CLASS_NAMES.get(int(k), ""), v] for k, v in d["classes"].items()],
            )
        )
    if d["point_source_ids"]:
        tables.append(
            Table(
                "Flight strips",
                ["flight strip (point source ID)", "points"],
                [[str(int(k)), v] for k, v in d["point_source_ids"].items()],
            )
        )
    return tables
