"""The ``roads`` assessment analysis: 3D roads from map polygons on their height levels (issue #15).

Registered with :func:`lidarqa.report._registry.register` when
:mod:`lidarqa.report.analyses` is imported. Config keys: ``cloud`` and
``classes`` (default ground and bridge, ``[2, 17]``), ``map`` (a polygons
input), optional ``reference`` (a points input tested on its level),
``map_spacing``, ``format``, and any keyword of
:func:`lidarqa.accuracy.roads.reconstruct_roads`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._context import SectionResult, keyword_defaults, selection_label
from .._context import import_module as _import
from .._context import library_attr as _attr
from .._registry import CLOUD_KEY, register
from .._schema import FORMAT_KEY, Key, Target, targets
from ..html import Figure, Table
from ..labels import Label

KEYS = {
    "cloud": CLOUD_KEY,
    "classes": Key("int_list", default=[2, 17], help="laser-point classes (road, bridge)"),
    "source_ids": Key("int_list", default=None, help="laser-point strips used"),
    "map": Key(
        "str", required=True, help="a polygons input name (road polygons)", input=("polygons",)
    ),
    "reference": Key(
        "str", default=None, help="a points input tested on its road level", input=("points",)
    ),
    "map_spacing": Key("float", default=10.0, help="map points along boundaries every (m)"),
    "format": FORMAT_KEY,
}
TARGETS = targets(Target("sigma_mean", ("sigma_mean",), "max", "mean predicted σ", "m"))


def _roads_params(options: dict) -> dict[str, Any]:
    f = _attr("lidarqa.accuracy.roads", "reconstruct_roads", "roads")
    return keyword_defaults(f, exclude=("ids", "labels", "spacing", "shift"))


#: report labels of the roads parameters (shared keys are in labels.py)
LABELS = {
    "margin": Label("points may join a polygon from this far outside", "m"),
    "max_shift": Label("largest map-to-laser shift searched (0 = none)", "m"),
    "max_step": Label("smooth segments: height step at most", "m"),
    "min_area": Label("smooth segments: smallest area kept", "m²"),
    "tolerance": Label("parts continue each other within", "m"),
}


@register(
    "roads",
    _roads_params,
    keys=KEYS,
    targets=TARGETS,
    title="3D roads",
    order=80,
    labels=LABELS,
)
def run_roads(ctx: Any, item: Any) -> SectionResult:
    """Reconstruct the 3D roads, write them, and w-test reference points on their levels."""
    from ...errors import MissingDependencyError
    from ...tiling.jobs_api import catalog_roads
    from .. import plots

    mod = _import("lidarqa.accuracy.roads", "roads")
    opts = item.options
    notes: list[str] = []
    label = selection_label(opts["cloud"], opts["classes"], opts["source_ids"])
    # the one road job of `lidarqa roads` and `lidarqa heights` with polygons: heights in
    # metres, the map's CRS checked against the cloud's
    spec = ctx.config.inputs[opts["map"]]
    ref = None if opts["reference"] is None else ctx.points(opts["reference"])
    with ctx.step("Reconstructing the road polygons"):
        run = catalog_roads(ctx.source(opts["cloud"]), spec.path, reference=ref,
                            classes=opts["classes"], source_id=opts["source_ids"],
                            crs=spec.effective_crs or ctx.crs,
                            options=dict(item.params, spacing=opts["map_spacing"]))
    extra: dict[str, Any] = run.extra
    rec, comp, laser, n_polys = run.value, extra["comparison"], extra["points"], extra["n_polygons"]
    res = rec.to_dict()
    mp = rec.map_points
    path = ctx.output_path(item, "roads3d.gpkg")
    try:
        mod.write_roads(rec, path, crs=ctx.crs, overwrite=True)
    except MissingDependencyError as exc:  # no 'vector' extra: keep the map points as CSV
        ctx.outputs[item.id].pop()
        notes.append(f"roads3d.gpkg not written ({exc}); map points as CSV instead")
        from .heights import SIGMAS, map_point_set

        pts = map_point_set(mp, mp.xy, ctx.crs, ("road", *SIGMAS))
        from ...io.vector import write_points

        write_points(pts, ctx.output_path(item, "map_points.csv"), overwrite=True)
    if comp is not None:
        res["reference"] = comp.to_dict()
    lo, hi = mp.xy_laser.min(axis=0) - 20.0, mp.xy_laser.max(axis=0) + 20.0
    near = np.all((laser[:, :2] >= lo) & (laser[:, :2] <= hi), axis=1)
    background = laser[near, :2]
    for flag in rec.flags:
        notes.append(
            {
                "shift_not_significant": "no significant map–laser shift in the data: map kept",
                "polygons_outside_cloud": "some polygons lie outside the laser points",
                "polygons_without_points": "some polygons have no laser points on any road",
                "map_points_failed": "some map points have no height (see the map_points layer)",
            }.get(flag, flag)
        )
    figures = [
        Figure(
            "Map-point σ",
            plots.plot_sigma_classes(
                mp.xy_laser, np.where(mp.failed, np.nan, mp.sigma), background=background
            ),
            "predicted σ of the 3D map points (< 20 cm, 20–50 cm, > 50 cm)",
        ),
        Figure(
            "Map-point heights",
            plots.plot_values(
                mp.xy_laser, mp.height, "height of the 3D map points", label="height (m)", size=6
            ),
            "each road level on its own; where levels cross a location has several heights",
        ),
    ]
    if comp is not None:
        figures.append(
            Figure(
                "w-tests",
                plots.plot_w_histogram(comp.w.w, critical=comp.w.critical),
                "w = Δh / σ_Δh of reference points, each on its own road level",
            )
        )
    status = rec.polygon_status.astype(str)
    tables = [
        roads_table(res, rec.flags),
        Table(
            "Polygons",
            ["polygon", "road", "status", "level (m)", "points", "other level"],
            [
                [
                    str(rec.polygon_ids[i]),
                    int(rec.polygon_road[i]),
                    status[i],
                    float(rec.polygon_level[i]),
                    int(rec.polygon_points[i]),
                    int(rec.polygon_other[i]),
                ]
                for i in range(len(status))
            ][:50],
        ),
    ]
    notes.extend(polygon_issues(rec))
    if comp is not None:  # the reference tested on its levels, as by `lidarqa heights`
        from .heights import heights_tables

        ref_res = res["reference"]
        tables += heights_tables(None, ref_res["comparison"], ref_res["w"],
                                 n_reference=len(extra["reference_xyz"]))
    headline = (
        f"{res['n_roads']} road level(s) from {res['n_polygons']} polygons; "
        f"{res['n_map_points']} map points, mean σ {res['sigma_mean']:.3f} m; "
        f"map shift ({res['shift'][0]:+.2f}, {res['shift'][1]:+.2f}) m"
    )
    if comp is not None:
        w = comp.w.to_dict()
        headline += f"; std(w) {w['std']:.2f}"
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=[f"Laser points: {label}. Map: {opts['map']} ({n_polys} polygons)."],
    )


def roads_table(res: dict[str, Any], flags: Any = ()) -> Table:
    """The figures of a road reconstruction: the report's table and ``lidarqa roads``' summary.

    Parameters
    ----------
    res : dict
        ``RoadReconstruction.to_dict()``.
    flags : sequence of str
        The reconstruction's flags (``shift_not_significant`` names why the map was kept).

    Returns
    -------
    Table
        Shift, polygons and roads, map points and their predicted σ (m), TIN size.
    """
    how = "estimated" if res["shift_estimated"] else "given"
    if "shift_not_significant" in flags:
        how = "no significant shift in the data: map kept"
    return Table(
        "Roads",
        ["quantity", "value"],
        [
            ["map shift dx (m)", res["shift"][0]],
            ["map shift dy (m)", res["shift"][1]],
            ["shift", how],
            ["polygons", res["n_polygons"]],
            ["roads (levels)", res["n_roads"]],
            ["polygons grown from a neighbour", res["polygons_grown"]],
            ["polygons without points", res["polygons_without_points"]],
            ["map points", res["n_map_points"]],
            ["map points without height", res["n_failed"]],
            ["mean predicted σ (m)", res["sigma_mean"]],
            ["95th percentile σ (m)", res["sigma_p95"]],
            ["points on other levels (not used)", res["points_other_level"]],
            ["TIN triangles", res["n_triangles"]],
        ],
    )


def polygon_issues(rec: Any) -> list[str]:
    """``polygon ID: status`` of each polygon that did not get a road level."""
    status = rec.polygon_status.astype(str)
    return [f"polygon {rec.polygon_ids[i]}: {status[i]}" for i in np.flatnonzero(status != "ok")]
