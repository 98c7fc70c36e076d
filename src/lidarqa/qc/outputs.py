"""The files of a ``qc`` run: qc.json, qc.gpkg (tiles, voids), density.tif, qc.html."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import WriteError
from .conformance import CHECK_ORDER

__all__ = ["OUTPUT_NAMES", "check_outputs", "write_outputs", "block_map_png"]

#: Output name -> file name in the output folder.
OUTPUT_NAMES = {"json": "qc.json", "gpkg": "qc.gpkg", "density": "density.tif",
                "html": "qc.html", "ground": "ground_consistency.tif"}
_COLOURS = {"pass": "#3a9a4a", "warn": "#e0a526", "fail": "#c8352b"}


def check_outputs(out: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Refuse an output folder that holds a previous run's files (unless `overwrite`)."""
    from .._atomic import check_output_folder

    return check_output_folder(out, OUTPUT_NAMES.values(), overwrite=overwrite)


def write_outputs(result: Any, out: str | os.PathLike, *, overwrite: bool = False,
                  html: bool = True, document: dict | None = None) -> dict[str, str]:
    """Write every output of `result` into folder `out`; returns name -> path."""
    from .._atomic import note_created

    d = Path(out)
    if not d.exists():
        d.mkdir(parents=True)
        note_created(d)
    paths: dict[str, str] = {}
    gpkg = d / OUTPUT_NAMES["gpkg"]
    _write_gpkg(result, gpkg, overwrite=overwrite)
    paths["gpkg"] = str(gpkg)
    if result.density is not None:
        from ..io.raster import write_geotiff

        r = result.density
        tif = d / OUTPUT_NAMES["density"]
        write_geotiff(tif, r["array"], x0=r["x0"], y1=r["y1"], cell_size=r["cell"],
                      crs=result.crs, overwrite=overwrite)
        paths["density"] = str(tif)
    if result.ground is not None:
        from ..io.raster import write_geotiff

        r = result.ground["raster"]
        tif = d / OUTPUT_NAMES["ground"]
        write_geotiff(tif, r["array"], x0=r["x0"], y1=r["y1"], cell_size=r["cell"],
                      crs=result.crs, overwrite=overwrite)
        paths["ground"] = str(tif)
    if html:
        page = d / OUTPUT_NAMES["html"]
        _write_html(result, page, overwrite=overwrite)
        paths["html"] = str(page)
    js = d / OUTPUT_NAMES["json"]
    paths["json"] = str(js)
    doc = document or qc_document(result, paths)
    from .._atomic import atomic_output
    from .._json import to_jsonable

    with atomic_output(js, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(to_jsonable(doc), indent=2, allow_nan=False) + "\n",
                       encoding="utf-8")
    return paths


def qc_document(result: Any, paths: dict[str, str]) -> dict[str, Any]:
    """The qc.json document (the same layout as every command's ``--json``)."""
    from .._version import __version__

    res = result.to_dict()
    res["outputs"] = dict(paths)
    return {"lidarqa_version": __version__, "command": "qc",
            "inputs": {"tiles": [t.path for t in result.tiles]},
            "parameters": {"spec": result.spec.name}, "results": res}


def _write_gpkg(result: Any, path: Path, *, overwrite: bool) -> None:
    from .._atomic import atomic_output
    from .._validate import require

    pyogrio = require("pyogrio", "vector")
    shapely = require("shapely", "vector")

    names = [k for k in CHECK_ORDER if any(k in t.checks for t in result.tiles)]
    tiles = [t for t in result.tiles]
    geoms = np.array([shapely.to_wkb(shapely.box(*t.footprint)) if t.footprint else None
                      for t in tiles], dtype=object)
    fields: dict[str, np.ndarray] = {
        "path": np.array([t.path for t in tiles], dtype=object),
        "status": np.array([t.status for t in tiles], dtype=object),
        "n_points": np.array([t.n_points for t in tiles], dtype=np.int64),
    }
    for k in names:
        fields[k] = np.array([t.checks[k].status if k in t.checks else "" for t in tiles],
                             dtype=object)
    for k in ("density", "spatial_distribution", "voids"):
        if k in names:
            fields[f"{k}_value"] = np.array(
                [float(t.checks[k].value) if k in t.checks and t.checks[k].value is not None
                 else np.nan for t in tiles])
    vgeoms = np.array([shapely.to_wkb(g) for _, g, _ in result.voids], dtype=object)
    vfields = {"path": np.array([p for p, _, _ in result.voids], dtype=object),
               "area_m2": np.array([a for _, _, a in result.voids], dtype=np.float64)}
    layers = [("tiles", "Polygon", geoms, fields), ("voids", "MultiPolygon", vgeoms, vfields)]
    if result.ground is not None:
        gp = result.ground["polygons"]
        layers.append(("ground_disagreement", "MultiPolygon",
                       np.array([shapely.to_wkb(g) for g, _ in gp], dtype=object),
                       {"kind": np.array([k for _, k in gp], dtype=object),
                        "area_m2": np.array([g.area for g, _ in gp], dtype=np.float64)}))
    crs_wkt = result.crs.to_wkt() if result.crs is not None else None
    import warnings

    with atomic_output(path, overwrite=overwrite) as tmp:
        target = tmp.with_suffix(".gpkg")
        try:
            for i, (layer, gtype, g, f) in enumerate(layers):
                if gtype == "MultiPolygon" and len(g):
                    g = np.array([shapely.to_wkb(shapely.multipolygons(
                        shapely.get_parts(shapely.from_wkb(w)))) for w in g], dtype=object)
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message=".*'crs' was not provided.*")
                    pyogrio.raw.write(str(target), g, geometry_type=gtype,
                                      field_data=list(f.values()), fields=list(f), crs=crs_wkt,
                                      driver="GPKG", layer=layer, encoding="UTF-8",
                                      append=i > 0)
            os.replace(target, tmp)
        except WriteError:
            raise
        except Exception as exc:
            raise WriteError(f"cannot write {path}: {exc}") from exc
        finally:
            if target.exists():
                target.unlink()


def block_map_png(result: Any) -> bytes:
    """The block map: tile footprints coloured by status, voids outlined (PNG bytes)."""
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    from .._plotting import png, pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 6.0))
    tiles = [t for t in result.tiles if t.footprint]
    if tiles:
        b = np.array([t.footprint for t in tiles])
        x0 = float(np.floor(b[:, 0].min() / 10) * 10)
        y0 = float(np.floor(b[:, 1].min() / 10) * 10)
        # one collection for every tile (a patch per tile is slow for thousands of tiles)
        xa, ya, xb, yb = (b[:, 0] - x0, b[:, 1] - y0, b[:, 2] - x0, b[:, 3] - y0)
        boxes = np.stack([np.c_[xa, ya], np.c_[xb, ya], np.c_[xb, yb], np.c_[xa, yb]], axis=1)
        ax.add_collection(PolyCollection(
            list(boxes), facecolors=[_COLOURS.get(t.status, "#999") for t in tiles], alpha=0.75,
            edgecolors="black", linewidths=0.6))
        for t in tiles if len(tiles) <= 60 else ():
            xa, ya, xb, yb = t.footprint
            bad = [k for k, c in t.checks.items() if c.status == "fail"]
            if bad:
                ax.text((xa + xb) / 2 - x0, (ya + yb) / 2 - y0, "\n".join(bad[:3]),
                        ha="center", va="center", fontsize=6)
        outline = _void_path([g for _, g, _ in result.voids], x0, y0)
        if outline is not None:  # one artist for every void: thousands stay fast to draw
            from matplotlib.collections import PathCollection

            # autolim=False: the limits are the tiles'; matplotlib's limit update walks
            # every segment in Python (seconds for a large block)
            ax.add_collection(PathCollection([outline], facecolors="none",
                                             edgecolors="#1b4f9c", linewidths=0.8),
                              autolim=False)
        ax.set_xlim(b[:, 0].min() - x0, b[:, 2].max() - x0)
        ax.set_ylim(b[:, 1].min() - y0, b[:, 3].max() - y0)
        ax.set_xlabel(f"x − {x0:,.0f} (m)")
        ax.set_ylabel(f"y − {y0:,.0f} (m)")
    ax.set_aspect("equal")
    n = result.summary()
    ax.legend(handles=[Patch(facecolor=_COLOURS["pass"], label=f"pass ({n['n_pass']})"),
                       Patch(facecolor=_COLOURS["warn"], label=f"warn ({n['n_warn']})"),
                       Patch(facecolor=_COLOURS["fail"], label=f"fail ({n['n_fail']})"),
                       Patch(facecolor="none", edgecolor="#1b4f9c", label="void")],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(f"{result.spec.title}: {n['n_tiles']} tile(s)")
    return png(fig)


def _share_png(r: dict[str, Any]) -> bytes:
    """A 0-1 share raster (row 0 north) as a PNG."""
    from .._plotting import png, pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 5.5))
    a = r["array"]
    h, w = a.shape
    im = ax.imshow(a, vmin=0.0, vmax=1.0, cmap="magma_r", interpolation="nearest",
                   extent=(0.0, w * r["cell"], 0.0, h * r["cell"]))
    fig.colorbar(im, ax=ax, label="share of points disagreeing")
    ax.set_xlabel(f"x − {r['x0']:,.0f} (m)")
    ax.set_ylabel(f"y − {r['y1'] - h * r['cell']:,.0f} (m)")
    return png(fig)


def _void_path(geoms: list[Any], x0: float, y0: float) -> Any:
    """Every ring (outer and holes) of `geoms` as one compound matplotlib Path, or None.

    Built from flat coordinate arrays (linear in the vertices): one patch per void made
    a block with ten thousand voids take minutes to draw.
    """
    if not geoms:
        return None
    import shapely
    from matplotlib.path import Path as MplPath

    parts = shapely.get_parts(np.asarray(geoms, dtype=object))
    parts = parts[shapely.get_type_id(parts) == 3]  # polygons
    if not len(parts):
        return None
    rings = shapely.get_rings(parts)
    xy, ring = shapely.get_coordinates(rings, return_index=True)
    if not len(xy):
        return None
    codes = np.full(len(xy), MplPath.LINETO, dtype=np.uint8)
    start = np.r_[True, ring[1:] != ring[:-1]]
    end = np.r_[ring[1:] != ring[:-1], True]
    codes[start] = MplPath.MOVETO
    codes[end] = MplPath.CLOSEPOLY
    return MplPath(xy - np.array([x0, y0]), codes)


def _write_html(result: Any, path: Path, *, overwrite: bool) -> None:
    from .._atomic import atomic_output
    from .._version import __version__
    from ..report.html import Figure, Report, Section, SummaryRow, Table, render_html

    spec = result.spec
    summ = result.summary()
    names = [k for k in CHECK_ORDER if any(k in t.checks for t in result.tiles)]
    rows, sections = [], []
    for k in names:
        failing = [t for t in result.tiles if k in t.checks and t.checks[k].status != "pass"]
        n_fail = sum(1 for t in failing if t.checks[k].status == "fail")
        verdict = "fail" if n_fail else "pass"
        src = spec.source(_LIMIT_KEY.get(k, k))
        head = (f"{n_fail} of {len(result.tiles)} tile(s) fail" if n_fail else
                "every tile passes" + (f" ({len(failing)} warn)" if failing else ""))
        rows.append(SummaryRow(k.replace("_", " "), f"check-{k}", head, verdict, src))
        sec = Section(id=f"check-{k}", title=k.replace("_", " "), kind="qc", headline=head,
                      verdict=verdict)
        if src:
            sec.paragraphs.append(f"Limit from: {src}.")
        if failing:
            sec.tables.append(Table("Tiles that fail or warn", ["tile", "status", "value",
                                                                 "limit", "message"],
                                    [[Path(t.path).name, t.checks[k].status,
                                      _cell(t.checks[k].value), _cell(t.checks[k].limit),
                                      t.checks[k].message] for t in failing]))
        sections.append(sec)
    for k, b in result.block.items():
        rows.append(SummaryRow(k.upper().replace("_", " "), f"block-{k}", b.get("message", ""),
                               b.get("status", "n/a") if b.get("status") != "warn" else "n/a",
                               spec.source(_BLOCK_KEY[k]) if k in _BLOCK_KEY else ""))
        sec = Section(id=f"block-{k}", title=k.upper().replace("_", " "), kind="qc",
                      headline=b.get("message", ""), verdict=b.get("status", "n/a"))
        scalar = [[kk, _cell(v)] for kk, v in b.items()
                  if not isinstance(v, dict | list) and kk not in ("message",)]
        scalar += [[f"limit {kk}", _cell(v)] for kk, v in (b.get("limits") or {}).items()]
        sec.tables.append(Table("", ["item", "value"], scalar))
        if k == "ground_consistency" and result.ground is not None:
            try:
                sec.figures.append(Figure(
                    "Ground disagreement", _share_png(result.ground["raster"]),
                    "share of the last returns on which the delivery's class 2 and lidarqa's "
                    "ground filter disagree, per cell (information, not judged)"))
            except Exception:  # noqa: BLE001 - no matplotlib: the table alone
                pass
        if isinstance(b.get("matrix"), list):
            codes = b.get("codes", [])
            sec.tables.append(Table("Confusion matrix (rows: reference, columns: delivery)",
                                    ["reference \\ delivery"] + [str(c) for c in codes],
                                    [[str(c)] + list(r) for c, r in zip(codes, b["matrix"],
                                                                        strict=True)]))
        sections.append(sec)
    lead = []
    try:
        lead.append(Figure("Block map", block_map_png(result),
                           "tiles coloured by status (failing checks written in the tile); "
                           "voids outlined in blue"))
    except Exception:  # noqa: BLE001 - no matplotlib: the page without its map
        pass
    report = Report(
        title=f"Delivery acceptance: {spec.title}",
        subtitle=(f"{summ['n_tiles']} tile(s): {summ['n_pass']} pass, {summ['n_warn']} warn, "
                  f"{summ['n_fail']} fail; verdict {summ['status'].upper()}"),
        summary=rows, sections=sections, parameters={"spec": spec.to_dict()},
        provenance=[("lidarqa", __version__), ("spec", spec.name)],
        inputs=[], versions={}, lead=lead)
    with atomic_output(path, overwrite=overwrite) as tmp:
        tmp.write_text(render_html(report), encoding="utf-8")


_BLOCK_KEY = {"nva": "max_nva_rmse_m", "relative_accuracy": "max_swath_rmsdz_m"}
_LIMIT_KEY = {"las_version": "las_versions", "point_format": "point_formats", "crs": "require_wkt",
              "gps_time": "gps_time_type", "classes": "allowed_classes",
              "duplicates": "max_duplicates", "density": "min_anpd",
              "spatial_distribution": "min_spatial_distribution", "voids": "void_factor"}


def _cell(v: Any) -> Any:
    if isinstance(v, list):
        return ", ".join(map(str, v[:12])) + (" ..." if len(v) > 12 else "")
    return "–" if v is None else v
