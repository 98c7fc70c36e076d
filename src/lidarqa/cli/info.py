"""``lidarqa info`` and ``lidarqa polar``."""

from __future__ import annotations

import click

from ._common import Steps, common_options, echo, finish, prepare_outputs


@click.command()
@click.argument("path", type=click.Path(dir_okay=True))
@common_options
def info(path: str) -> None:
    """Describe a point cloud: points, bounds, CRS, classes, strips, density, returns."""
    from ..io.info import describe

    prepare_outputs(inputs=(path,))
    with Steps()("Reading " + path):
        result = describe(path)
    d = result.to_dict()
    b = d["bounds"]
    echo(f"{path}")
    echo(f"  points          {d['n_points']:,}")
    if d["n_points"]:
        echo(f"  x               {b['min_x']:.3f} .. {b['max_x']:.3f}")
        echo(f"  y               {b['min_y']:.3f} .. {b['max_y']:.3f}")
        echo(f"  z               {b['min_z']:.3f} .. {b['max_z']:.3f}")
    echo(f"  CRS             {d['crs_name'] or 'none'}" + (f" (EPSG:{d['crs_epsg']})" if d["crs_epsg"] else ""))
    if d["vertical_unit"]:
        echo(f"  vertical unit   {d['vertical_unit']}")
    if d["density_per_m2"]:
        echo(f"  density         {d['density_per_m2']:.1f} pts/m²")
    if d["classes"]:
        echo("  classes         " + ", ".join(f"{k}: {v:,}" for k, v in d["classes"].items()))
    if d["point_source_ids"]:
        echo("  strips          " + ", ".join(f"{k}: {v:,}" for k, v in d["point_source_ids"].items()))
    r = d["returns"]
    echo("  returns         " + ("absent" if not r["present"] else
                                 ("valid" if r["valid"] else
                                  f"present, {r['n_zero_return_number']:,} zero / {r['n_invalid']:,} invalid")))
    finish("info", inputs={"path": path}, parameters={}, results=d)
