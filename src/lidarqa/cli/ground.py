"""``lidarqa ground``: classify ground with segment-based or point-based PTD."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click

from ._catalog import (
    catalog_options,
    catalog_settings,
    open_catalog_source,
    sigterm_as_interrupt,
    wants_catalog,
)
from ._common import (
    INT_LIST,
    Steps,
    common_options,
    crs_option,
    echo,
    echo_tables,
    finish,
    input_crs,
    prepare_outputs,
    settings,
)

if TYPE_CHECKING:
    from ..ground.metrics import FilterErrors


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(),
    help="Output cloud (.las/.laz, or .csv/.txt text with a .prj CRS file): every point, input "
    "order, all dimensions; coordinates to the input's precision (its LAS scale). "
    "For a catalog (folder, glob, .vpc or several files): the output folder.",
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
    type=click.Choice(["auto", "als", "mls"]),
    default="auto",
    show_default=True,
    help="Parameter set: auto (measured from the cloud: density, returns, sensor), "
    "als (airborne, ~1 pt/m2) or mls (Lin & Zhang Table 1); explicit options override it.",
)
@click.option(
    "--sensor",
    type=click.Choice(["auto", "als", "mls"]),
    default="auto",
    show_default=True,
    help="With --preset auto: airborne (als) or mobile (mls) scan, if known; auto measures it.",
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
    "--filter-density",
    type=float,
    default=None,
    help="segment-ptd: points per m2 (1/m²; 0 = every point) a dense cloud is filtered at: the "
    "lowest point per cell of 1/sqrt(D) m, the other points joined by a plane test "
    "[default: 4 on airborne clouds of 6 per m2 or more, else 0].",
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
@catalog_options(
    buffer="Catalog: margin read around each chunk, m (default: the seed cell, two under "
    "a canopy, see docs/catalogs.md).",
    resume="Catalog: re-use the chunks finished by an interrupted run (kept in "
    "OUTPUT/.lidarqa-work).",
)
@common_options
def ground(
    paths,
    output,
    method,
    preset,
    sensor,
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
    filter_density,
    all_returns,
    exclude_classes,
    evaluate,
    ignore_classes,
    crs,
    **cat_opts,
) -> None:
    """Classify ground points of PATHS and write them (class 2) to OUTPUT.

    Points that were class 2 but are not ground become class 1; all other
    classes are kept. Existing ground labels are never used as input.

    PATHS is one file, or a catalog: a folder, a glob pattern, a .vpc virtual point
    cloud or several files. A catalog is filtered chunk by chunk with a buffer and
    OUTPUT is a folder receiving one file per input tile plus a .vpc of them.
    """
    import warnings

    import numpy as np

    from ..errors import DataQualityWarning, OptionError
    from ..ground import classify_ground, relabel_classification
    from ..io import read, write

    given_crs = input_crs(crs)
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
        "filter_density": filter_density,
    }
    given = {k: v for k, v in seg_only.items() if v is not None}
    if given and method != "segment-ptd":
        raise OptionError(
            "--"
            + ", --".join(k.replace("_", "-") for k in given)
            + " only apply to --method segment-ptd"
        )
    params.update(given)
    # the filter's options, the same for one file and a catalog
    job = {"method": method, "preset": preset, "sensor": sensor,
           "last_returns_only": not all_returns, "exclude_classes": list(exclude_classes or []),
           "ignore_classes": list(ignore_classes or []), "evaluate": evaluate}
    if wants_catalog(paths, cat_opts):
        from ..tiling.ground import ground_catalog

        prepare_outputs(inputs=tuple(paths))  # the --json path (OUTDIR: ground_catalog)
        s = settings()
        catalog = open_catalog_source(paths, cat_opts, crs=given_crs,
                                      z_to_metres=False).catalog
        with sigterm_as_interrupt():
            cres = ground_catalog(catalog, output, **job, **cat_opts, overwrite=s.overwrite,
                                  progress=not s.quiet, **params)
        res: dict = cres.to_dict()
        for msg in cres.warnings:
            click.echo(f"Warning: {msg}", err=True)
        echo(f"{len(catalog.tiles)} tile(s) -> {output}  ({cres.vpc})")
        from ..io.crs import horizontal_unit, metre_factors

        # chunks are laid in the tiles' own units
        unit = "m" if metre_factors(catalog.crs)[0] == 1.0 else horizontal_unit(catalog.crs)[0]
        echo(f"  method          {method}")
        auto = cres.parameters.get("auto")
        if auto:
            echo(f"  parameters      auto: {auto['regime']} (measured once on a sample of "
                 "whole tiles)")
        echo_ground_counts(res, cres.evaluation, "counts summed over chunks", ignore_classes,
                           cres, unit or "CRS units")
        if catalog.bad:
            echo(f"  skipped         {len(catalog.bad)} bad input(s)")
        finish(
            "ground",
            inputs={"paths": list(paths), "output": output},
            parameters={
                **{k: v for k, v in job.items() if k != "evaluate"},
                **catalog_settings(cat_opts, cres.chunk_size, cres.buffer),
                **cres.parameters.get("filter", {}),
                **({"auto": cres.parameters["auto"]} if "auto" in cres.parameters else {}),
            },
            results=res,
        )
        return
    path = paths[0]
    prepare_outputs(output, inputs=(path,))
    steps = Steps()
    with steps("Reading " + path):
        cloud = read(path, crs=given_crs)
    from ..ground import kernels_cached

    if not kernels_cached():
        click.echo(
            "First run: compiling the ground filter's kernels (about 20-30 s, once; "
            "they are cached for later runs)",
            err=True,
        )
    with (
        steps(f"Filtering ({method}, {len(cloud):,} points)") as progress,
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always", DataQualityWarning)
        result = classify_ground(cloud, **job, progress=progress, **params)
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
    echo(f"  method          {method} (preset {preset})")
    m = result.measures
    if m is not None:
        echo(
            f"  measured        {m.density:.2f} pts/m2 (spacing {m.spacing:.2f} m), "
            f"{100 * m.concentration:.0f} % of points in crowded cells, "
            f"sensor {m.sensor}, multi-return share "
            + (f"{m.multi_return_share:.2f}" if m.has_returns else "n/a")
            + f", slope median/p90 {m.slope_median:.1f}/{m.slope_p90:.1f} deg, "
            f"largest object {m.largest_object_diameter:.0f} m"
        )
        echo(f"  regime          {result.regime} ({result.regime_reason})")
    src = result.parameter_sources
    shown = {k: v for k, v in result.parameters.items() if src.get(k) != "default"}
    if shown:
        echo(
            "  parameters      "
            + ", ".join(f"{k}={v} ({result.parameter_sources[k]})" for k, v in shown.items())
        )
    for msg in result.warnings:
        echo(f"  note            {msg}")
    echo_ground_counts(res, result.evaluation, ignore=ignore_classes)
    echo_terrain(res.get("terrain"))
    finish(
        "ground",
        inputs={"path": path, "output": output},
        parameters={
            **{k: v for k, v in job.items() if k != "evaluate"},
            "regime": result.regime,
            "measured": res["measured"],
            "parameter_sources": result.parameter_sources,
            "parameter_notes": result.parameter_notes,
            "regime_reason": result.regime_reason,
            "crs": crs,
            **result.parameters,
        },
        results=res,
    )


def echo_ground_counts(res: dict, evaluation: FilterErrors | None, how: str = "",
                       ignore: list[int] | None = None, chunked: Any = None,
                       unit: str = "m") -> None:
    """The filter run's counts and, with --evaluate, the ISPRS filter errors (file or catalog)."""
    from ..report.analyses.ground import filter_run_table, isprs_tables

    echo_tables(filter_run_table(res, chunked, unit),
                *isprs_tables(evaluation, list(ignore or []), how)[0])


def echo_terrain(t: dict | None) -> None:
    """With --evaluate: the terrain model against the reference's, and the thinned note."""
    from ..report.analyses.ground import terrain_table

    if not t:
        return
    echo_tables(terrain_table(t))
    if t["reference_thinned"]:
        echo(f"note: {t['note']}")
