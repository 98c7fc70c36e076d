"""``lidarqa ground``: classify ground with segment-based or point-based PTD."""

from __future__ import annotations

import click

from ._common import (
    INT_LIST,
    Steps,
    common_options,
    crs_option,
    echo,
    finish,
    input_crs,
    prepare_outputs,
)


@click.command()
@click.argument("path", type=click.Path(dir_okay=False))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(dir_okay=False),
    help="Output cloud (.las/.laz, or .csv/.txt text with a .prj CRS file): every point, input "
    "order, all dimensions; coordinates to the input's precision (its LAS scale).",
)
@click.option(
    "--method",
    type=click.Choice(["segment-ptd", "ptd"]),
    default="segment-ptd",
    show_default=True,
    help="Segment-based PTD (Lin & Zhang) or point-based PTD (Axelsson).",
)
@click.option(
    "--preset",
    type=click.Choice(["als", "mls"]),
    default=None,
    help="Parameter set: als (airborne, ~1 pt/m2) or mls (Lin & Zhang Table 1, the default); "
    "explicit options override it.",
)
@click.option(
    "--cell-size", type=float, default=None, help="Seed grid cell size (m) [default: 60]."
)
@click.option(
    "--max-terrain-angle", type=float, default=None, help="Steepest facet (degrees) [default: 88]."
)
@click.option(
    "--iter-angle", type=float, default=None, help="Iteration angle (degrees) [default: 6]."
)
@click.option(
    "--iter-distance", type=float, default=None, help="Iteration distance (m) [default: 0.5]."
)
@click.option(
    "--min-edge-length", type=float, default=None, help="Minimum TIN edge length (m) [default: 1]."
)
@click.option("--no-mirror", is_flag=True, help="Do not test points mirrored at steep edges.")
@click.option(
    "--accept-ratio",
    type=float,
    default=None,
    help="segment-ptd: fraction of tested points that must pass (0..1) [default: 0.5].",
)
@click.option(
    "--orientation-thr",
    type=float,
    default=None,
    help="segment-ptd: façade orientation threshold (degrees) [default: 45].",
)
@click.option(
    "--scatter-thr",
    type=float,
    default=None,
    help="segment-ptd: vegetation scatterness threshold (dimensionless) [default: 0.2].",
)
@click.option(
    "--grow-radius",
    type=float,
    default=None,
    help="segment-ptd: surface-growing radius (m) [default: 2.5 x point spacing].",
)
@click.option(
    "--all-returns",
    is_flag=True,
    help="Let every return be ground (default: only last/single returns when recorded).",
)
@click.option(
    "--exclude-classes",
    type=INT_LIST,
    default="7,18",
    show_default=True,
    help="Classes never considered as ground candidates (noise).",
)
@click.option(
    "--evaluate",
    is_flag=True,
    help="Score against the input classification (2 = ground, others object).",
)
@click.option(
    "--ignore-classes",
    type=INT_LIST,
    default=None,
    help="With --evaluate: reference classes left out, e.g. 1,7,9.",
)
@crs_option
@common_options
def ground(
    path,
    output,
    method,
    preset,
    cell_size,
    max_terrain_angle,
    iter_angle,
    iter_distance,
    min_edge_length,
    no_mirror,
    accept_ratio,
    orientation_thr,
    scatter_thr,
    grow_radius,
    all_returns,
    exclude_classes,
    evaluate,
    ignore_classes,
    crs,
) -> None:
    """Classify ground points of PATH and write them (class 2) to OUTPUT.

    Points that were class 2 but are not ground become class 1; all other
    classes are kept. Existing ground labels are never used as input.
    """
    import warnings

    import numpy as np

    from ..errors import DataQualityWarning, OptionError
    from ..ground import classify_ground, relabel_classification
    from ..io import read, write

    given_crs = input_crs(crs)
    prepare_outputs(output, inputs=(path,))
    params = {
        k: v
        for k, v in {
            "cell_size": cell_size,
            "max_terrain_angle": max_terrain_angle,
            "iter_angle": iter_angle,
            "iter_distance": iter_distance,
            "min_edge_length": min_edge_length,
        }.items()
        if v is not None
    }
    if no_mirror:
        params["mirror"] = False
    seg_only = {
        "accept_ratio": accept_ratio,
        "orientation_thr": orientation_thr,
        "scatter_thr": scatter_thr,
        "grow_radius": grow_radius,
    }
    given = {k: v for k, v in seg_only.items() if v is not None}
    if given and method != "segment-ptd":
        raise OptionError(
            "--"
            + ", --".join(k.replace("_", "-") for k in given)
            + " only apply to --method segment-ptd"
        )
    params.update(given)
    steps = Steps()
    with steps("Reading " + path):
        cloud = read(path, crs=given_crs)
    with (
        steps(f"Filtering ({method}, {len(cloud):,} points)") as progress,
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always", DataQualityWarning)
        result = classify_ground(
            cloud,
            method=method,
            last_returns_only=not all_returns,
            exclude_classes=exclude_classes or (),
            evaluate=evaluate,
            ignore_classes=ignore_classes,
            preset=preset,
            progress=progress,
            **params,
        )
    for w in caught:
        click.echo(f"Warning: {w.message}", err=True)
    cls = cloud.fields.get("classification")
    if cls is None:
        cls = np.zeros(len(cloud), dtype=np.uint8)
    cloud.fields["classification"] = relabel_classification(cls, result.ground_mask)
    with steps("Writing " + output):
        write(cloud, output, overwrite=True)
    res = result.to_dict()
    echo(f"{path} -> {output}")
    echo(f"  method          {method}")
    echo(
        f"  points          {res['n_points']:,} ({res['n_candidates']:,} candidates, "
        f"returns: {res['return_handling']})"
    )
    echo(
        f"  ground          {res['n_ground']:,}"
        + (f" ({100 * res['ground_fraction']:.1f} %)" if res["ground_fraction"] is not None else "")
    )
    if result.evaluation is not None:
        e = result.evaluation
        echo(f"  evaluated       {e.n:,} points")
        echo(
            f"  type I          {100 * e.type_i:.2f} %   type II {100 * e.type_ii:.2f} %   "
            f"total {100 * e.total:.2f} %   kappa {e.kappa:.3f}"
        )
    finish(
        "ground",
        inputs={"path": path, "output": output},
        parameters={
            "method": method,
            "preset": preset,
            "last_returns_only": not all_returns,
            "exclude_classes": list(exclude_classes or []),
            "ignore_classes": list(ignore_classes or []),
            "crs": crs,
            **result.parameters,
        },
        results=res,
    )
