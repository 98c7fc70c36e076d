"""The ``heights`` analysis: height precision of map points and w-tests of reference heights."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import ConfigError
from .._context import (
    RunContext,
    SectionResult,
    import_module,
    keyword_defaults,
    library_attr,
    selection_label,
    write_vector,
)
from .._registry import CLOUD_KEY, ResolveContext, register
from .._schema import FORMAT_KEY, AnalysisItem, Key, Target, check_table, need_input, targets
from ..html import Figure, Table
from ..labels import labelled_rows


def _heights_params(options: dict) -> dict[str, Any]:
    f = library_attr("lidarqa.accuracy.heights", "assess_heights", "heights")
    return keyword_defaults(f, exclude=("labels", "covariance"))


def grid_map_points(xyz: np.ndarray, spacing: float, *, min_points: int = 3) -> np.ndarray:
    """XY of a grid over the points' extent, kept where ≥ `min_points` lie within spacing/2."""
    from scipy.spatial import cKDTree

    lo = np.floor(xyz[:, :2].min(axis=0) / spacing) * spacing + spacing / 2
    hi = xyz[:, :2].max(axis=0)
    gx = np.arange(lo[0], hi[0] + 1e-9, spacing)
    gy = np.arange(lo[1], hi[1] + 1e-9, spacing)
    gxy = np.column_stack([a.ravel() for a in np.meshgrid(gx, gy)])
    if len(gxy) == 0:
        return gxy
    counts = np.array([len(v) for v in cKDTree(xyz[:, :2]).query_ball_point(gxy, r=spacing / 2)])
    return gxy[counts >= min_points]


KEYS = {
    "cloud": CLOUD_KEY,
    "classes": Key("int_list", default=[2], help="laser-point classes used for the planes"),
    "source_ids": Key("int_list", default=None, help="laser-point strips used for the planes"),
    "map": Key(
        "ref",
        required=True,
        help="a points/polygons input name, or { grid = 5.0 } for a grid of map points",
        input=("points", "polygons"),
    ),
    "reference": Key(
        "ref",
        required=True,
        help="a points input name, or { from_cloud = true, fraction = 0.5, seed = 0 }",
        input=("points",),
    ),
    "map_spacing": Key(
        "float", default=10.0, help="spacing of map points along polygon boundaries (m)"
    ),
    "format": FORMAT_KEY,
}
TARGETS = targets(
    Target("rms", ("comparison", "rms"), "max", "RMS Δh", "m"),
    Target("max_abs", ("comparison", "max_abs"), "max", "max |Δh|", "m"),
    Target("sigma_mean", ("map_points", "sigma_mean"), "max", "mean predicted σ", "m"),
)
#: ``reference = { from_cloud = true, ... }``: reference heights held apart from the laser points
SPLIT_KEYS = {
    "from_cloud": Key("bool", required=True, help="true: hold apart part of the analysis' cloud"),
    "fraction": Key("float", default=0.5, help="share of the selected points held apart"),
    "seed": Key("int", default=0),
    "max_points": Key("int", default=5000, help="at most this many reference points (sampled)"),
}
#: ``map = { grid = ... }``: a grid of map points over the cloud
GRID_KEYS = {
    "grid": Key("float", required=True, help="spacing of the map-point grid (m)"),
    "min_points": Key("int", default=3, help="laser points needed within grid/2 to keep a node"),
}


def _resolve(opts: dict, ctx: ResolveContext) -> None:
    where = ctx.where
    m = opts["map"]
    if isinstance(m, str):
        need_input(ctx.inputs, m, ("points", "polygons"), where, "map")
    else:
        sub = check_table(m, GRID_KEYS, f"{where} key 'map'")
        if not sub["grid"] > 0:
            raise ConfigError(f"key 'grid' in {where} key 'map' must be > 0, got {sub['grid']}")
        opts["map"] = sub
    r = opts["reference"]
    if isinstance(r, str):
        need_input(ctx.inputs, r, ("points",), where, "reference")
    else:
        sub = check_table(r, SPLIT_KEYS, f"{where} key 'reference'")
        if sub["from_cloud"] is not True:
            raise ConfigError(
                f"key 'from_cloud' in {where} key 'reference' must be true "
                '(or give reference = "<points input>")'
            )
        if not 0.0 < sub["fraction"] < 1.0:
            raise ConfigError(
                f"key 'fraction' in {where} key 'reference' must be in (0, 1), "
                f"got {sub['fraction']}"
            )
        opts["reference"] = sub


@register(
    "heights",
    _heights_params,
    keys=KEYS,
    targets=TARGETS,
    title="Height quality",
    resolve=_resolve,
    order=60,
)
def run_heights(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Height quality (Oude Elberink & Vosselman): predicted map-point σ, w-tests.

    One job (:func:`~lidarqa.tiling.jobs_api.catalog_heights`) for a file and a
    catalog: the report's cloud (selected, and without the points held apart as
    reference) is one in-memory region; a catalog with map and reference inputs
    is read chunk by chunk, each map and reference point owned by one chunk.
    """
    from ...tiling.jobs_api import catalog_heights
    from ...tiling.source import open_source
    from ..catalog_overview import with_overview

    mod = import_module("lidarqa.accuracy.heights", "heights")
    opts = item.options
    label = selection_label(opts["cloud"], opts["classes"], opts["source_ids"])
    r, m = opts["reference"], opts["map"]
    on_catalog = isinstance(r, str) and isinstance(m, str) and ctx.is_catalog(opts["cloud"])
    laser: Any = None  # the laser points of one in-memory region (None on a catalog)
    # the cloud as the CLI reads it: its CRS, heights in metres, the selection
    source: Any = ctx.source(opts["cloud"], opts["classes"], opts["source_ids"])
    if on_catalog:
        label += (" (a catalog: each map point is fitted, and each reference point compared, "
                  "in the chunk whose core holds it)")
    else:
        sel = source.read(require_points=False)
        keep = np.arange(len(sel))
        if not isinstance(r, str):  # reference points held apart from the laser points
            rng = np.random.default_rng(r["seed"])
            perm = rng.permutation(len(sel))
            n_ref = int(round(r["fraction"] * len(sel)))
            ref_idx, keep = perm[:n_ref], np.sort(perm[n_ref:])
            if len(ref_idx) > r["max_points"]:
                ref_idx = rng.choice(ref_idx, size=r["max_points"], replace=False)
            ref_xyz = sel.xyz[np.sort(ref_idx)]
        cloud = sel.subset(keep) if len(keep) < len(sel) else sel
        laser = cloud.xyz
        source = open_source(cloud, crs=source.given_crs)  # read: heights already in metres
    ref: Any = None
    if isinstance(r, str):  # checked against the cloud's CRS, heights to metres by the job
        ref = ctx.points(r)
        ref_label = r
    else:
        ref_label = (
            f"{len(ref_xyz):,} points held apart from {label} (fraction {r['fraction']}, "
            f"seed {r['seed']}); the planes use the other {len(laser):,}"
        )
    map_xy: Any
    if isinstance(m, str):
        spec = ctx.config.inputs[m]
        map_xy = mod.read_map_points(spec.path, spacing=opts["map_spacing"],
                                     crs=spec.effective_crs or ctx.crs)
        map_label = f"{len(map_xy)} map points from {m}"
    else:
        map_xy = grid_map_points(laser, m["grid"], min_points=m["min_points"])
        map_label = f"{len(map_xy)} map points on a {m['grid']:g} m grid where laser points exist"
    with ctx.step(f"Heights of {len(map_xy):,} map points, "
                  f"{len(ref if ref is not None else ref_xyz):,} reference points"):
        run = catalog_heights(source, map_xy, ref if ref is not None else ref_xyz,
                              options=dict(item.params), skip_failed=on_catalog)
    ref_xyz = run.value.reference_xyz
    out = _heights_section(ctx, item, run.value, laser, ref_xyz,
                           f"Laser points: {label}. Map points: {map_label}. "
                           f"Reference: {ref_label}.")
    return with_overview(out, run if on_catalog else None, f"{opts['cloud']}: chunks")


def _heights_section(ctx: RunContext, item: AnalysisItem, rep: Any, laser: Any, ref_xyz: Any,
                     what: str) -> SectionResult:
    """The section half: tables, figures and outputs of a HeightReport (file or catalog)."""
    from ...io.vector import PointSet
    from .. import plots

    opts = item.options
    res = rep.to_dict()
    mpts = rep.map_points
    sig_cls = plots.sigma_class(np.where(mpts.failed, np.nan, mpts.sigma))
    res["sigma_classes"] = {
        lab: int(np.sum(sig_cls == k)) for k, (_, lab, _) in enumerate(plots.SIGMA_CLASSES)
    }
    res.update(
        n_laser_points=None if laser is None else int(len(laser)),
        n_reference=int(len(ref_xyz)),
        n_reference_outside=int(rep.n_outside),
        flags=list(rep.flags),
    )
    notes: list[str] = []
    paragraphs = [what]
    # Outputs.
    mp_set = map_point_set(mpts, mpts.xy, ctx.crs,
                           (*SIGMAS, "n_points", "radius", "failed", "reason"))
    mp_ok = mp_set.subset(~mpts.failed) if mpts.failed.any() else mp_set
    write_vector(ctx, item, mp_ok, "map_points", opts["format"], notes)
    ref_set = PointSet(
        ids=np.arange(len(ref_xyz)),
        xyz=ref_xyz,
        crs=ctx.crs,
        attributes={
            "model_height": rep.tin.height,
            "dh": rep.dh,
            "sigma_dh": rep.sigma_dh,
            "w": rep.w_values,
            "outlier": rep.outlier,
            "inside": rep.inside,
        },
    )
    write_vector(ctx, item, ref_set, "reference_points", opts["format"], notes)
    if mpts.failed.any():
        notes.append(
            f"{int(mpts.failed.sum())} map point(s) could not be fitted (too few laser points)"
        )
    if rep.n_outside:
        notes.append(f"{rep.n_outside} reference point(s) lie outside the TIN of the map points")
    figures = []
    with ctx.step("Plotting heights"):
        figures.append(
            Figure(
                "Map-point σ",
                plots.plot_sigma_classes(
                    mpts.xy, np.where(mpts.failed, np.nan, mpts.sigma),
                    background=None if laser is None else laser[:, :2],
                ),
                "predicted σ of the map-point heights in the three classes of "
                "Oude Elberink & Vosselman "
                "(< 20 cm, 20–50 cm, > 50 cm)",
            )
        )
        figures.append(
            Figure(
                "w-tests",
                plots.plot_w_histogram(rep.w_values, critical=rep.w.critical),
                "w = Δh / σ_Δh; the red curve is the standard normal density",
            )
        )
        figures.append(
            Figure(
                "Height differences",
                plots.plot_values(
                    ref_xyz[:, :2],
                    rep.dh,
                    "Δh = model − reference",
                    label="Δh (m)",
                    cmap="RdBu_r",
                    size=3,
                    symmetric=True,
                ),
                "at the reference points",
            )
        )
    c, w, mpd = res["comparison"], res["w"], res["map_points"]
    tables = heights_tables(mpd, c, w, n_reference=res["n_reference"],
                            n_outside=res["n_reference_outside"],
                            sigma_classes=res["sigma_classes"])
    wv = np.asarray(rep.w_values, dtype=float)
    order = np.argsort(-np.nan_to_num(np.abs(wv), nan=-1.0), kind="stable")[:10]
    order = order[np.isfinite(wv[order])]
    if len(order):
        tables.append(
            Table(
                "Largest |w|",
                ["reference point", "x", "y", "Δh (m)", "σ_Δh (m)", "w", "outlier"],
                [
                    [
                        str(int(i)),  # an index, not a quantity: no thousands separator
                        f"{ref_xyz[i, 0]:.2f}",
                        f"{ref_xyz[i, 1]:.2f}",
                        float(rep.dh[i]),
                        float(rep.sigma_dh[i]),
                        float(wv[i]),
                        bool(rep.outlier[i]),
                    ]
                    for i in order
                ],
            )
        )
    headline = (
        f"RMS Δh {c['rms']:.3f} m over {c['n']} reference points; mean σ map "
        f"{mpd['sigma_mean']:.3f} m; std(w) {w['std']:.2f}"
    )
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=paragraphs,
    )


#: the predicted σ of a map point and its three terms (m)
SIGMAS = ("sigma", "sigma_plane", "sigma_block", "sigma_model")


def map_point_set(mp: Any, xy: Any, crs: Any, fields: tuple[str, ...]) -> Any:
    """Map points (at `xy`, their fitted height) with the `fields` of `mp` as attributes."""
    from ...io.vector import PointSet

    return PointSet(ids=np.arange(len(mp)), xyz=np.column_stack([xy, mp.height]), crs=crs,
                    attributes={k: np.asarray(getattr(mp, k), dtype=object if k == "reason"
                                              else None) for k in fields})


def heights_tables(map_points: dict[str, Any] | None, comparison: dict[str, Any] | None,
                   w: dict[str, Any] | None, *, n_reference: int | None = None,
                   n_outside: int | None = None,
                   sigma_classes: dict[str, int] | None = None) -> list[Table]:
    """The figures of a height test: the report section's tables and ``lidarqa heights``' summary.

    Parameters
    ----------
    map_points : dict or None
        ``n``, ``n_failed``, ``sigma_mean`` and ``sigma_p95`` of the map points (m; None: no
        map-point table).
    comparison, w : dict or None
        ``HeightReport.to_dict()["comparison"]`` and ``["w"]`` (None: no reference points).
    n_reference, n_outside : int, optional
        Reference points given, and those outside the TIN of the fitted map points.
    sigma_classes : dict, optional
        Map points per σ class (label -> count).

    Returns
    -------
    list of Table
        Map points; with `comparison`, the comparison with the reference and the w-tests.
    """
    tables = [] if map_points is None else [
        Table(
            "Map points",
            ["quantity", "value"],
            [
                ["map points", map_points["n"]],
                ["not fitted", map_points["n_failed"]],
                ["mean predicted σ (m)", map_points["sigma_mean"]],
                ["95th percentile σ (m)", map_points["sigma_p95"]],
                *[[f"σ class {k}", v] for k, v in (sigma_classes or {}).items()],
            ],
        ),
    ]
    if comparison is None or w is None:
        return tables
    given = [["reference points", n_reference, "n_reference"]] if n_reference is not None else []
    if n_outside is not None:
        given.append(["outside the TIN of the map points", n_outside, "n_reference_outside"])
    tables += [
        Table(
            "Comparison with the reference",
            ["quantity", "value", "key in report.json"],
            given + labelled_rows(
                {k: v for k, v in comparison.items() if not isinstance(v, list | dict)},
                prefix="comparison",
            ),
            code_columns=(2,),
        ),
        Table(
            "w-tests",
            ["quantity", "value", "key in report.json"],
            labelled_rows(dict(w), prefix="w"),
            code_columns=(2,),
        ),
    ]
    return tables
