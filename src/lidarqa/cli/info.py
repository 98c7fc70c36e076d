"""``lidarqa info`` and ``lidarqa polar``."""

from __future__ import annotations

import click

from ._common import (
    Steps,
    common_options,
    crs_option,
    echo,
    finish,
    input_crs,
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
    help="Catalog: also count the points of each strip (point source id); reads every point.",
)
@crs_option
@common_options
def info(paths: tuple[str, ...], skip_bad: bool, strips: bool, crs: str | None) -> None:
    """Describe a point cloud: points, bounds, CRS, classes, strips, density, returns.

    With a catalog (a folder, glob pattern, .vpc or several files): a summary from the
    file headers (tiles, points, bounds, CRS, strips, gaps, overlaps, default chunks).
    """
    from ..io.info import describe
    from ._catalog import info_on_catalog, is_catalog

    given = input_crs(crs)
    if is_catalog(paths) or skip_bad or strips:
        info_on_catalog(paths, skip_bad=skip_bad, strips=strips, crs=given)
        return
    path = paths[0]
    prepare_outputs(inputs=(path,))
    with Steps()("Reading " + path):
        result = describe(path, crs=given)
    d = result.to_dict()
    b = d["bounds"]
    echo(f"{path}")
    echo(f"  points          {d['n_points']:,}")
    if d["n_points"]:
        echo(f"  x               {b['min_x']:.3f} .. {b['max_x']:.3f}")
        echo(f"  y               {b['min_y']:.3f} .. {b['max_y']:.3f}")
        echo(f"  z               {b['min_z']:.3f} .. {b['max_z']:.3f}")
    echo(
        f"  CRS             {d['crs_name'] or 'none'}"
        + (f" (EPSG:{d['crs_epsg']})" if d["crs_epsg"] else "")
        + (" (from --crs)" if given is not None and d["crs_name"] else "")
    )
    if not d["crs_name"]:
        echo(
            "                  (the file declares no CRS: pass --crs, e.g. --crs EPSG:2154, "
            "to every command that reads it, so that its outputs carry one)"
        )
    if d["vertical_unit"]:
        echo(f"  vertical unit   {d['vertical_unit']}")
    if d["density_per_m2"]:
        echo(f"  density         {d['density_per_m2']:.3g} pts/m²")
    if d["classes"]:
        echo("  classes         " + ", ".join(f"{k}: {v:,}" for k, v in d["classes"].items()))
    if d["point_source_ids"]:
        echo(
            "  strips          "
            + ", ".join(f"{k}: {v:,}" for k, v in d["point_source_ids"].items())
        )
    r = d["returns"]
    echo(
        "  returns         "
        + (
            "absent"
            if not r["present"]
            else (
                "valid"
                if r["valid"]
                else f"present, {r['n_zero_return_number']:,} zero / {r['n_invalid']:,} invalid"
            )
        )
    )
    finish("info", inputs={"path": path}, parameters={"crs": crs}, results=d)


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
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Point list (.csv/.gpkg/.geojson) or point cloud (.las/.laz).",
)
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
    from ..io._atomic import check_output
    from ..io.vector import VECTOR_SUFFIXES

    suffix = Path(output).suffix.lower()
    check_output(output, overwrite=settings().overwrite)
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
