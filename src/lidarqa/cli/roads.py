"""``lidarqa roads``: 3D roads from 2D map polygons, each on its own height level."""

from __future__ import annotations

from pathlib import Path

import click

from ..accuracy.heights import (
    CURVATURE,
    SIGMA_STRIP,
)
from ._common import (
    Steps,
    classes_option,
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
from .heights import laser_noise_options


def _parse_shift(value: str | None) -> tuple[float, float] | None:
    if value is None or value.strip().lower() == "auto":
        return None
    from ..errors import OptionError

    try:
        dx, dy = (float(v) for v in value.split(","))
    except ValueError:
        raise OptionError(f"--shift must be 'auto' or DX,DY in metres, got {value!r}") from None
    return dx, dy


@click.command()
@click.argument("cloud", type=click.Path())
@click.argument("map_path", metavar="MAP", type=click.Path())
@output_option("GeoPackage with layers map_points, polygons_3d and tin.", required=True)
@classes_option(default="2,17", help="Laser point classes used (ground/road and bridge deck).")
@click.option(
    "--spacing",
    type=float,
    default=10.0,
    show_default=True,
    help="Map points every this many metres along polygon boundaries.",
)
@click.option(
    "--shift",
    "shift",
    default="auto",
    show_default=True,
    help="Map-to-laser shift DX,DY (m), or 'auto' to estimate it.",
)
@click.option(
    "--max-shift",
    type=float,
    default=1.5,
    show_default=True,
    help="Largest map-to-laser shift searched (m).",
)
@click.option(
    "--tolerance",
    type=float,
    default=0.5,
    show_default=True,
    help="Height difference (m) within which two parts belong to one level.",
)
@click.option(
    "--min-area",
    type=float,
    default=20.0,
    show_default=True,
    help="Smooth segments smaller than this (m²) are dropped (cars, signs).",
)
@laser_noise_options
@click.option(
    "--sigma-strip",
    type=float,
    default=SIGMA_STRIP,
    show_default=True,
    help="E4: strip adjustment noise (m).",
)
@click.option(
    "--curvature",
    type=float,
    default=CURVATURE,
    show_default=True,
    help="Maximum road curvature (1/m) of the model term.",
)
@crs_option
@common_options
def roads(
    cloud: str,
    map_path: str,
    output: str,
    classes: list[int] | None,
    spacing: float,
    shift: str,
    max_shift: float,
    tolerance: float,
    min_area: float,
    radius: float,
    max_radius: float,
    min_points: int,
    sigma_point: float,
    sigma_gps: float,
    sigma_ins: float,
    sigma_strip: float,
    curvature: float,
    crs: str | None,
) -> None:
    """Reconstruct 3D roads: heights for the map polygons of MAP from the CLOUD.

    Laser points are assigned to the road polygons at the right height level
    (a road under a bridge gets the points of the lower level), neighbouring
    polygons of one road are merged, and map points every --spacing m along the
    boundaries get heights from least-squares planes with their predicted σ
    (plane, laser block and model terms). The map-to-laser shift is estimated
    unless given. Writes 3D map points, 3D polygons (one per level) and a TIN.
    """
    from ..accuracy.roads import write_roads
    from ..tiling.jobs_api import catalog_roads

    given_crs = input_crs(crs)
    prepare_outputs(output, inputs=(cloud, map_path))
    given = _parse_shift(shift)
    steps = Steps()
    with steps(f"Reconstructing the roads of {map_path} from {cloud}"):
        # a file, or a catalog (folder, glob, .vpc) read as one region, heights in metres
        run = catalog_roads(
            cloud, map_path, classes=classes or None, crs=given_crs,
            options=dict(spacing=spacing, shift=given, max_shift=max_shift,
                         tolerance=tolerance, min_area=min_area, radius=radius,
                         max_radius=max_radius, min_points=min_points, sigma_point=sigma_point,
                         sigma_gps=sigma_gps, sigma_ins=sigma_ins, sigma_strip=sigma_strip,
                         curvature=curvature))
    rec = run.value
    with steps("Writing " + output):
        write_roads(rec, output, crs=run.extra["crs"], overwrite=settings().overwrite)
    res = rec.to_dict()
    from ..report.analyses.roads import polygon_issues, roads_table

    echo_tables(roads_table(res, rec.flags))
    for issue in polygon_issues(rec):
        echo(f"  {issue}")
    if rec.flags:
        echo("flags             " + ", ".join(rec.flags))
    params = dict(rec.parameters)
    params.update(classes=classes, shift=shift)
    finish(
        "roads",
        inputs={"cloud": cloud, "map": map_path, "output": str(Path(output))},
        parameters=params,
        results=res,
    )
