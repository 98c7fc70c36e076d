"""The ``checkpoints`` analysis: residuals, RMSE and ASPRS/NSSDA accuracy figures."""

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
from .._registry import ResolveContext, register
from .._schema import FORMAT_KEY, AnalysisItem, Key, Target, check_table, need_input, targets
from ..html import Figure, Table
from ..labels import labelled_rows


def _checkpoint_params(options: dict) -> dict[str, Any]:
    if options.get("vertical"):
        f = library_attr("lidarqa.accuracy.checkpoints", "vertical_check", "checkpoints")
        return keyword_defaults(f, exclude=("classification",))
    f = library_attr("lidarqa.accuracy.checkpoints", "assess_checkpoints", "checkpoints")
    return keyword_defaults(f)


def sample_check_points(
    xyz: np.ndarray,
    *,
    n: int,
    seed: int,
    min_spacing: float,
    near: np.ndarray | None = None,
) -> np.ndarray:
    """Indices of up to `n` well-spread points (one per `min_spacing` cell, deterministic).

    With `near`, only points within 1 m (XY) of a point of `near` qualify
    (so that check points fall where the tested cloud has data).
    """
    cand = np.arange(len(xyz))
    if near is not None and len(near):
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(near[:, :2]).query(xyz[:, :2], k=1, distance_upper_bound=1.0)
        cand = cand[np.isfinite(dist)]
    if len(cand) == 0:
        return cand
    rng = np.random.default_rng(seed)
    cand = cand[rng.permutation(len(cand))]
    cell = np.floor(xyz[cand, :2] / max(min_spacing, 1e-9)).astype(np.int64)
    _, first = np.unique(cell, axis=0, return_index=True)
    first = np.sort(first)  # keep the random order among cells
    return np.sort(cand[first[:n]])


def _is_sample_size(warning: str) -> bool:
    """A warning that the standards' minimum number of check points is not met."""
    w = warning.lower()
    return "check point" in w and ("only" in w or "at least" in w)


KEYS = {
    "measured": Key(
        "str",
        required=True,
        help="a points input name, or a cloud input name with vertical = true",
        input=("points", "clouds"),
    ),
    "check": Key(
        "ref",
        required=True,
        help="a points input name or { from_cloud = ..., classes = [...], n = 20, seed = 0 }",
        input=("points",),
    ),
    "vertical": Key("bool", default=False, help="compare check heights with a TIN of the cloud"),
    "source_ids": Key("int_list", default=None, help="cloud strips of the TIN (vertical check)"),
    "format": FORMAT_KEY,
}
TARGETS = targets(
    Target("rmse_z", ("rmse_z",), "max", "RMSE z", "m"),
    Target("rmse_h", ("rmse_h",), "max", "RMSE horizontal", "m"),
    Target("rmse_3d", ("rmse_3d",), "max", "RMSE 3D", "m"),
    Target("mean_z", ("mean_z",), "max", "|mean z|", "m"),
)
#: ``check = { from_cloud = ..., ... }``: check points sampled from a cloud
SAMPLE_KEYS = {
    "from_cloud": Key(
        "any", required=True, help="a cloud input name (or true: the analysis' cloud)"
    ),
    "classes": Key("int_list", default=[2]),
    "source_id": Key("int_list", default=None),
    "n": Key("int", default=20, help="number of points"),
    "seed": Key("int", default=0),
    "min_spacing": Key("float", default=2.0, help="minimum horizontal spacing between samples (m)"),
}


def _resolve(opts: dict, ctx: ResolveContext) -> None:
    where = ctx.where
    if opts["vertical"]:
        need_input(ctx.inputs, opts["measured"], ("clouds",), where, "measured")
    else:
        need_input(ctx.inputs, opts["measured"], ("points",), where, "measured")
    check = opts["check"]
    if isinstance(check, str):
        need_input(ctx.inputs, check, ("points",), where, "check")
        return
    sub = check_table(check, SAMPLE_KEYS, f"{where} key 'check'")
    src = sub["from_cloud"]
    if src is True:
        if not opts["vertical"]:
            raise ConfigError(
                f"key 'check' in {where}: from_cloud = true needs vertical = true "
                "(or name a cloud input)"
            )
        src = opts["measured"]
    need_input(ctx.inputs, src, ("clouds",), f"{where} key 'check'", "from_cloud")
    sub["from_cloud"] = src
    if sub["n"] < 1:
        raise ConfigError(f"key 'n' in {where} key 'check' must be >= 1, got {sub['n']}")
    opts["check"] = sub


def _title(opts: dict) -> str:
    return "Vertical check" if opts.get("vertical") else "Check points"


@register(
    "checkpoints",
    _checkpoint_params,
    keys=KEYS,
    targets=TARGETS,
    title=_title,
    resolve=_resolve,
    order=50,
)
def run_checkpoints(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Check points: residuals, RMSE and ASPRS/NSSDA figures (or the vertical check of a cloud)."""
    from ...io.vector import PointSet
    from ...tiling.source import is_catalog_input
    from .. import plots
    from ..catalog_overview import with_overview

    mod = import_module("lidarqa.accuracy.checkpoints", "checkpoints")
    opts = item.options
    notes: list[str] = []
    paragraphs: list[str] = []
    # Check points: a file, or sampled from a cloud.
    if isinstance(opts["check"], str):
        check = ctx.points(opts["check"])
        check_label = opts["check"]
    else:
        c = opts["check"]
        src = ctx.select(c["from_cloud"], c["classes"], c["source_id"])
        near = None
        if opts["vertical"]:
            tested = ctx.select(opts["measured"], None, opts["source_ids"])
            cls = tested.classification
            wanted = item.params.get("classes", (2,))
            near = tested.xyz if cls is None else tested.xyz[np.isin(cls, np.atleast_1d(wanted))]
        idx = sample_check_points(
            src.xyz, n=c["n"], seed=c["seed"], min_spacing=c["min_spacing"], near=near
        )
        if len(idx) == 0:
            from ...errors import InvalidPointsError

            raise InvalidPointsError(
                "no check point could be sampled (empty selection or no overlap)"
            )
        check = PointSet(
            ids=np.array([f"cp{k + 1}" for k in range(len(idx))], dtype=object),
            xyz=src.xyz[idx],
            crs=src.crs,
        )
        check_label = (
            f"{len(idx)} points sampled from "
            f"{selection_label(c['from_cloud'], c['classes'], c['source_id'])} (seed {c['seed']})"
        )
        if len(idx) < c["n"]:
            notes.append(f"only {len(idx)} of the {c['n']} requested check points could be sampled")
        write_vector(ctx, item, check, "check_points", opts["format"], notes)
    run = None
    if opts["vertical"]:
        measured_label = selection_label(opts["measured"], None, opts["source_ids"])
        spec = ctx.config.inputs[opts["measured"]]
        # one job for a file (the report's cloud, one in-memory region) and a catalog (chunk
        # by chunk, only the chunks holding check points are read)
        from ...tiling.jobs_api import catalog_vertical_check

        on_catalog = is_catalog_input(str(spec.path))
        source = ctx.source(opts["measured"])  # as the CLI: its CRS, heights in metres
        notes.extend(mod.metric_units(source.native_crs, check.crs)[3])
        params = dict(item.params)
        classes = params.pop("classes", (2,))
        no_classes = source.cloud is not None and source.cloud.classification is None
        with ctx.step(f"Vertical check of {measured_label}"):
            job = catalog_vertical_check(
                source, check, classes=None if no_classes else tuple(np.atleast_1d(classes)),
                source_id=opts["source_ids"], skip_failed=on_catalog, **params)
        rep = job.value
        fh, fv = source.xy_factor, source.z_factor
        if on_catalog:
            run = job
            paragraphs.append(
                f"{opts['measured']} is a catalog: each check point is compared in the "
                "chunk whose core holds it; only those chunks are read.")
        residuals = np.column_stack([np.zeros(len(rep.dz)), np.zeros(len(rep.dz)), rep.dz])
        ok = rep.flag == "ok"
        residuals[~ok] = np.nan
        xyz = rep.check_xyz
        paragraphs.append(
            f"Heights of a TIN of {measured_label} (class "
            f"{', '.join(map(str, np.atleast_1d(item.params.get('classes', (2,)))))}) "
            f"at the XY of the check points ({check_label}), minus the check heights."
        )
    else:
        measured = ctx.points(opts["measured"])
        # the unit rule of `lidarqa checkpoints`: both in metres, a conversion noted
        _, fh, fv, converted = mod.metric_units(measured.crs, check.crs)
        notes.extend(converted)
        with ctx.step("Comparing check points"):
            rep = mod.assess_checkpoints(mod.scale_points(measured, fh, fv),
                                         mod.scale_points(check, fh, fv), **item.params)
        residuals = rep.residuals
        xyz = rep.check_xyz
        paragraphs.append(
            f"Measured points: {opts['measured']}; check points: {check_label}. Residual = "
            "(transformed) measured − check."
        )
    res = rep.to_dict()
    # as `lidarqa checkpoints -o`: the check points in their own (unconverted) coordinates,
    # the residuals in metres
    res_pts = mod.scale_points(rep.residual_points(), 1.0 / fh, 1.0 / fv)
    res_pts.crs = check.crs if check.crs is not None else ctx.crs  # outputs carry the CRS
    write_vector(ctx, item, res_pts, "residuals", opts["format"], notes)
    if opts["format"] != "csv":
        write_vector(ctx, item, res_pts, "residuals", "csv", notes)
    # Sample-size warnings qualify the verdict: the report shows them beside it.
    caveats = [str(w) for w in res.get("warnings", []) if _is_sample_size(str(w))]
    notes.extend(str(w) for w in res.get("warnings", []) if not _is_sample_size(str(w)))
    figures = []
    with ctx.step("Plotting residuals"):
        figures.append(
            Figure(
                "Residual vectors",
                plots.plot_residual_vectors(xyz, residuals, "Check-point residuals"),
                "colour: vertical residual",
            )
        )
        figures.append(Figure("Residual histograms", plots.plot_residual_histograms(residuals)))
    tables = checkpoint_tables(res, opts["vertical"])
    if opts["vertical"]:
        resid_cols = ["id", "cloud z (TIN)", "dz", "flag"]
        resid_rows = [
            [str(r.get("id")), r.get("tin_z"), r.get("dz"), r.get("flag")]
            for r in res.get("residuals", [])[:100]
        ]
    else:
        resid_cols = ["id", "dx", "dy", "dz", "role"]
        resid_rows = [
            [str(r.get("id")), r.get("dx"), r.get("dy"), r.get("dz"), r.get("role")]
            for r in res.get("residuals", [])[:100]
        ]
    tables.append(
        Table(
            "Residuals per point (m)",
            resid_cols,
            resid_rows,
            decimals=3,  # metres to the millimetre, heights and residuals alike
            note="first 100 points; all in the output files"
            if len(res.get("residuals", [])) > 100
            else "",
        )
    )
    if opts["vertical"]:
        headline = (
            f"RMSE z {res['rmse_z']:.3f} m, mean {res['mean_z']:+.3f} m over {res['n_check']} "
            f"check points"
        )
    else:
        headline = (
            f"RMSE z {res['rmse_z']:.3f} m, RMSE h {res['rmse_h']:.3f} m over {res['n_check']} "
            f"check points"
        )
    out = SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=paragraphs,
        caveats=caveats,
    )
    return with_overview(out, run, f"{opts['measured']}: chunks read")


def checkpoint_tables(res: dict[str, Any], vertical: bool) -> list[Table]:
    """The figures of a check-point test: the report section's and ``lidarqa checkpoints``'.

    Parameters
    ----------
    res : dict
        ``CheckpointReport.to_dict()`` (or the vertical check's), residuals in metres.
    vertical : bool
        A vertical check of a cloud: z statistics only, and the TIN's figures.

    Returns
    -------
    list of Table
        Residual statistics, the TIN (vertical), the accuracy figures (ASPRS Ed. 2, NSSDA)
        and the transformation when one was fitted.
    """
    stat_rows = [
        [axis, res.get(f"mean_{axis}"), res.get(f"std_{axis}"), res.get(f"rmse_{axis}"),
         res.get(f"max_abs_{axis}")]
        for axis in (("z",) if vertical else ("x", "y", "z"))
    ]
    tables = [
        Table(
            "Residual statistics (m)",
            ["axis", "mean", "std", "RMSE", "max |residual|"],
            stat_rows,
            decimals=4,  # metres to a tenth of a millimetre
            note=f"{res['n_check']} check points"
            + (f", {res['n_control']} control points" if res.get("n_control") else ""),
        ),
    ]
    v = res.get("vertical")
    if vertical and v:
        tables.append(Table("TIN of the cloud", ["quantity", "value"], [
            ["ground points", v["n_ground"]],
            ["longest TIN edge at a check point (m)", v["max_edge"]],
            *[[f"check points: {flag}", n] for flag, n in v["flags"].items()],
        ]))
    figures_json = {
        "rmse_h": res.get("rmse_h"),
        "rmse_3d": res.get("rmse_3d"),
        "nssda": {k: x for k, x in (res.get("nssda") or {}).items() if k != "warnings"},
        "asprs2023": {k: x for k, x in (res.get("asprs2023") or {}).items() if k != "warnings"},
    }
    acc_rows = [
        r for r in labelled_rows(figures_json, none="") if r[1] != "" and r[1] == r[1]
    ]  # undefined (None, NaN) figures are left out
    tables.append(
        Table(
            "Accuracy figures",
            ["figure", "value", "key in report.json"],
            acc_rows,
            code_columns=(2,),
        )
    )
    tr = res.get("transform") or {}
    if tr.get("name") not in (None, "none"):
        params, sigmas = tr.get("params") or {}, tr.get("sigmas") or {}
        order = sorted(params, key=lambda k: k not in ("tx", "ty", "tz"))
        o = tr.get("origin")
        tables.append(
            Table(
                f"Transformation: {tr['name']}",
                ["parameter", "value ± σ"],
                [[k.removesuffix("_deg"), _param_text(k, params[k], sigmas.get(k))]
                 for k in order if k not in ("c", "d", "e")],  # c, d at the origin; e = tz
                note=f"σ0 = {_fixed(tr.get('sigma0'), 4)} m"
                + (f"; about the control-point centroid x {o['x']:.3f}  y {o['y']:.3f}  "
                   f"z {o['z']:.3f} m (tx, ty, tz: its shift)" if o else ""),
            )
        )
    return tables


def _fixed(v: float | None, digits: int) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def _param_text(key: str, value: float | None, sigma: float | None) -> str:
    """``value ± σ unit`` of a transformation parameter, as in a surveyor's adjustment report."""
    from ...units import param_unit

    if key == "scale" and not sigma:
        return "1 (fixed)"
    digits = 7 if key in ("scale", "a", "b") else 4
    text = f"{_fixed(value, digits)} ± {_fixed(sigma, digits)} {param_unit(key)}".rstrip()
    if key == "scale" and value is not None and sigma is not None:  # surveyors read ppm
        text += f"   ({(value - 1.0) * 1e6:+.1f} ± {sigma * 1e6:.1f} ppm)"
    return text
