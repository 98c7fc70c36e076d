"""``lidarqa info`` and ``lidarqa polar``."""

from __future__ import annotations

from typing import Any

import click

from ._common import (
    Steps,
    common_options,
    crs_option,
    echo,
    echo_tables,
    finish,
    input_crs,
    output_option,
    prepare_outputs,
    settings,
)


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(dir_okay=True))
@click.option(
    "--skip-bad", is_flag=True, help="Catalog: leave out bad tiles (listed) instead of failing."
)
@click.option(
    "--strips",
    is_flag=True,
    help="Read the input as a catalog (also for one file): its tiles, and the strips (point "
    "source ids) of each tile.",
)
@click.option(
    "--headers",
    is_flag=True,
    help="Read the headers only: points, bounds, CRS and (catalog) tiles in seconds; classes, "
    "strips, density and returns are not read.",
)
@crs_option
@common_options
def info(
    paths: tuple[str, ...], skip_bad: bool, strips: bool, headers: bool, crs: str | None
) -> None:
    """Describe a point cloud: points, bounds, CRS, classes, strips, density, returns.

    With a catalog (a folder, glob pattern, .vpc or several files): the same, read tile
    by tile as one cloud, with the catalog's tiles, gaps, overlaps and default chunks.
    """
    from ..io.info import describe, describe_files
    from ..report.analyses.info import catalog_results
    from ._catalog import open_catalog_source, wants_catalog

    given = input_crs(crs)
    prepare_outputs(inputs=tuple(paths))
    cat = None
    if wants_catalog(paths, {"skip_bad": skip_bad}) or strips:
        # --crs for tiles that declare none; a tile whose own CRS contradicts it is an error
        source = open_catalog_source(paths, {"skip_bad": skip_bad}, crs=given, z_to_metres=False)
        cat = source.catalog
    if cat is None:
        with Steps()(("Reading the header of " if headers else "Reading ") + paths[0]):
            d = describe(paths[0], crs=given, headers_only=headers).to_dict()
    else:
        per_tile: dict[str, list[int]] = {}
        with Steps()(f"Reading the {'headers' if headers else 'points'} of "
                     f"{len(cat.tiles)} tile(s)"):
            d = describe_files([t.path for t in cat.tiles], crs=source.native_crs,
                               ids_per_file=None if headers else per_tile,
                               headers_only=headers).to_dict()
        d = {**d, **catalog_results(cat), "strips_per_tile": per_tile,
             "strips": {int(k): v for k, v in d["point_source_ids"].items()},
             # points per occupied area, as for one file (no longer points / tile area)
             "density_per_m2": d["density_per_m2"]}
    _echo_info(paths, d, given)
    finish("info", inputs={"paths": list(paths)} if cat is not None else {"path": paths[0]},
           parameters={"catalog": True, "headers": headers} if cat is not None
           else {"crs": crs, "headers": headers}, results=d)


def _echo_info(paths: tuple[str, ...], d: dict[str, Any], given: Any) -> None:
    """The human summary of one file or a catalog (``d``: the results): the report's tables."""
    from ..report.analyses.info import info_tables

    echo(", ".join(paths))
    echo_tables(*info_tables(d))
    if given is not None and d["crs_name"] and "n_tiles" not in d:
        echo("(CRS from --crs)")
    if not d["crs_name"]:
        echo("(the input declares no CRS: pass --crs, e.g. --crs EPSG:2154, to every command "
             "that reads it, so that its outputs carry one)")
    for o in d.get("overlaps", [])[:10]:
        echo(f"overlap {o['tiles'][0]} / {o['tiles'][1]}: {100 * o['fraction']:.0f} %")


def _station(value: str | None) -> tuple[float, float, float]:
    if not value:
        return (0.0, 0.0, 0.0)
    try:
        parts = [float(v) for v in value.split(",")]
    except ValueError:
        raise click.BadParameter(f"expected X,Y,Z, got {value!r}") from None
    if len(parts) != 3:
        raise click.BadParameter(f"expected X,Y,Z, got {value!r}")
    return parts[0], parts[1], parts[2]


@click.command()
@click.argument("observations", type=click.Path(dir_okay=True))
@output_option("Point list (.csv/.gpkg/.geojson) or point cloud (.las/.laz).", required=True)
@click.option("--station", default=None, help="Station position X,Y,Z in metres (default 0,0,0).")
@click.option(
    "--orientation",
    type=float,
    default=0.0,
    show_default=True,
    help="Azimuth of the instrument's zero direction (in --angle-unit).",
)
@click.option(
    "--instrument-height",
    type=float,
    default=0.0,
    show_default=True,
    help="Instrument height above the station mark (m).",
)
@click.option(
    "--angle-unit", type=click.Choice(["deg", "gon", "rad"]), default="deg", show_default=True
)
@click.option(
    "--crs",
    default=None,
    metavar="CRS",
    help="CRS of the station and so of the output: an EPSG code (2154 or EPSG:2154), WKT, "
    "or a .prj file.",
)
@common_options
def polar(
    observations: str,
    output: str,
    station: str | None,
    orientation: float,
    instrument_height: float,
    angle_unit: str,
    crs: str | None,
) -> None:
    """Convert polar scanner observations (distance, azimuth, elevation/zenith) to X, Y, Z."""
    from pathlib import Path

    import numpy as np

    from ..io import PointCloud, write
    from ..io.crs import parse_crs
    from ..io.polar import Station, read_polar_csv
    from ..io.vector import PointSet, write_points

    prepare_outputs(output, inputs=(observations,))
    x0, y0, z0 = _station(station)
    st = Station(x0, y0, z0, orientation, instrument_height)
    target_crs = parse_crs(crs)
    ids, xyz = read_polar_csv(observations, station=st, angle_unit=angle_unit)
    from ..errors import WriteError
    from ..io.vector import VECTOR_SUFFIXES

    suffix = Path(output).suffix.lower()
    if suffix in {".las", ".laz"}:
        write(
            PointCloud(
                xyz=xyz, fields={"point_source_id": np.zeros(len(xyz), np.uint16)}, crs=target_crs
            ),
            output,
            overwrite=settings().overwrite,
        )
    elif suffix in VECTOR_SUFFIXES:
        write_points(
            PointSet(ids=ids, xyz=xyz, crs=target_crs), output, overwrite=settings().overwrite
        )
    else:
        raise WriteError(f"cannot write {suffix!r}: use .csv, .gpkg, .geojson, .las or .laz")
    echo(f"{len(xyz):,} observations converted -> {output}")
    finish(
        "polar",
        inputs={"observations": observations},
        parameters={
            "station": [x0, y0, z0],
            "orientation": orientation,
            "instrument_height": instrument_height,
            "angle_unit": angle_unit,
            "crs": crs,
        },
        results={"n_points": len(xyz), "output": output},
    )
