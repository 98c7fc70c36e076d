"""The analyses an assessment can run, as a registry of section functions.

Each analysis kind (``info``, ``ground``, ``edges``, ``lines``, ``checkpoints``,
``heights``) is a function ``run(ctx, item) -> SectionResult`` registered with
:func:`register`: it takes the run context (loaded inputs, output folder,
progress) and the validated config item, calls the library, and returns the
``results`` dict for ``report.json``, the figures and tables for the HTML page
and the output files it wrote. :func:`library_params` tells the config
validator which library keyword arguments an analysis accepts (by
introspecting the library function), so the config uses the same names as
the API and the CLI.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import inspect
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from .config import AnalysisItem, AnalysisUnavailableError, AssessmentConfig
from .html import Figure, Table

__all__ = [
    "SectionResult",
    "RunContext",
    "ANALYSES",
    "register",
    "library_params",
    "keyword_defaults",
    "ParamDefaults",
    "sha256_file",
]


@dataclass
class SectionResult:
    """What one analysis hands back to the report."""

    results: dict[str, Any]
    headline: str
    figures: list[Figure] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    paragraphs: list[str] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)


AnalysisFunc = Callable[["RunContext", AnalysisItem], SectionResult]
ANALYSES: dict[str, AnalysisFunc] = {}
_PARAMS: dict[str, Callable[[dict], dict[str, Any]]] = {}


def register(
    kind: str, params: Callable[[dict], dict[str, Any]] | None = None
) -> Callable[[AnalysisFunc], AnalysisFunc]:
    """Register the section function of an analysis kind (and its parameter discovery)."""

    def deco(func: AnalysisFunc) -> AnalysisFunc:
        ANALYSES[kind] = func
        _PARAMS[kind] = params or (lambda options: {})
        return func

    return deco


def library_params(kind: str, options: dict) -> dict[str, Any]:
    """Library keyword arguments (name -> default) an analysis accepts in the config."""
    return _PARAMS[kind](options)


def _import(module: str, kind: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise AnalysisUnavailableError(
            f"analysis [{kind}] needs {module}, which is not available in this installation ({exc})"
        ) from exc
    except Exception as exc:  # a broken module must not take the other analyses down
        reason = " ".join(str(exc).split())
        raise AnalysisUnavailableError(
            f"analysis [{kind}] needs {module}, which failed to import "
            f"({type(exc).__name__}: {reason})"
        ) from exc


def _attr(module: str, name: str, kind: str) -> Any:
    mod = _import(module, kind)
    try:
        return getattr(mod, name)
    except AttributeError as exc:
        raise AnalysisUnavailableError(
            f"analysis [{kind}] needs {module}.{name}, which this installation lacks"
        ) from exc


class ParamDefaults(dict):
    """``{name: default}`` of library keyword arguments; their annotations in ``.annotations``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.annotations: dict[str, str] = {}
        #: optional ``validate(params)`` run by the config parser (raises on a bad value)
        self.validate: Callable[[dict[str, Any]], None] | None = None


def keyword_defaults(func: Any, *, exclude: tuple[str, ...] = ()) -> ParamDefaults:
    """Keyword parameters of `func` with their defaults (required ones map to None).

    ``progress`` (the kernels' progress callback) is a runtime hook, never a parameter.
    """
    exclude = (*exclude, "progress")
    out = ParamDefaults()
    for name, p in inspect.signature(func).parameters.items():
        if p.annotation is not inspect.Parameter.empty and name not in exclude:
            out.annotations[name] = (
                p.annotation
                if isinstance(p.annotation, str)
                else getattr(p.annotation, "__name__", str(p.annotation))
            )
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) or name in exclude:
            continue
        if p.kind == p.POSITIONAL_ONLY:
            continue
        if p.default is inspect.Parameter.empty:
            if p.kind == p.KEYWORD_ONLY:
                out[name] = None
            continue
        out[name] = p.default
    return out


def dataclass_defaults(cls: Any, *, exclude: tuple[str, ...] = ()) -> ParamDefaults:
    """Fields of a (parameter) dataclass with their defaults (annotations in ``.annotations``)."""
    import dataclasses

    out = ParamDefaults()
    for f in dataclasses.fields(cls):
        if f.name in exclude or not f.init:
            continue
        out.annotations[f.name] = (
            f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        )
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
            out[f.name] = f.default_factory()  # type: ignore[misc]
        else:
            out[f.name] = None
    return out


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file, streamed."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while True:
            block = fh.read(chunk)
            if not block:
                break
            h.update(block)
    return h.hexdigest()


# ------------------------------------------------------------------ context


class RunContext:
    """Loaded inputs (read once, cached), the output folder and progress for one run."""

    def __init__(
        self,
        config: AssessmentConfig,
        work_dir: Path,
        *,
        step: Callable[[str], contextlib.AbstractContextManager] | None = None,
    ) -> None:
        self.config = config
        self.work_dir = Path(work_dir)
        self._step = step
        self._clouds: dict[str, Any] = {}
        self._segments: dict[str, Any] = {}
        self._points: dict[str, Any] = {}
        self._edges: dict[Any, Any] = {}
        self.outputs: dict[str, list[str]] = {}
        self.crs = config.crs
        if self.crs is None:
            for spec in config.inputs.values():
                if spec.effective_crs is not None:
                    self.crs = spec.effective_crs
                    break

    @contextlib.contextmanager
    def step(self, description: str) -> Iterator[Any]:
        """Progress display for a long step (nested steps are folded into the outer one).

        Yields a progress callback for the kernels' ``progress=`` keyword, or None.
        """
        if self._step is None:
            yield None
        else:
            with self._step(description) as progress:
                yield progress

    # -- inputs
    def cloud(self, name: str) -> Any:
        """The point cloud input `name` (read once)."""
        if name not in self._clouds:
            from ..io import read

            spec = self.config.inputs[name]
            with self.step(f"Reading {spec.path.name}"):
                cloud = read(spec.path)
            if cloud.crs is None and spec.effective_crs is not None:
                cloud.crs = spec.effective_crs
            elif cloud.crs is None:
                cloud.crs = self.crs
            self._clouds[name] = cloud
        return self._clouds[name]

    def segments(self, name: str) -> Any:
        if name not in self._segments:
            from ..io.vector import read_segments

            spec = self.config.inputs[name]
            seg = read_segments(spec.path)
            if seg.crs is None:
                seg.crs = spec.effective_crs or self.crs
            self._segments[name] = seg
        return self._segments[name]

    def points(self, name: str, *, require_z: bool = True) -> Any:
        key = (name, require_z)
        if key not in self._points:
            from ..io.vector import read_points

            spec = self.config.inputs[name]
            pts = read_points(spec.path, require_z=require_z)
            if pts.crs is None:
                pts.crs = spec.effective_crs or self.crs
            self._points[key] = pts
        return self._points[key]

    def select(self, name: str, classes: Any = None, source_id: Any = None) -> Any:
        """A subset of cloud `name` by classes and flight strips (None = all)."""
        cloud = self.cloud(name)
        if classes is None and source_id is None:
            return cloud
        return cloud.select(classes=classes, source_id=source_id)

    def edges(self, cloud: str, classes: Any, source_id: Any, options: dict[str, Any]) -> Any:
        """Edges extracted from a cloud selection (cached on selection + options)."""
        key = (cloud, _norm_ids(classes), _norm_ids(source_id), _freeze(options))
        if key not in self._edges:
            extract_edges = _attr("lidarqa.geometry.edges", "extract_edges", "edges")
            sub = self.select(cloud, classes, source_id)
            label = selection_label(cloud, classes, source_id)
            with self.step(f"Extracting edges ({label}, {len(sub):,} points)"):
                if len(sub) < 3:
                    from ..io.vector import Segments

                    seg = Segments(np.empty(0, dtype=np.int64), np.empty((0, 3)), np.empty((0, 3)))
                else:
                    seg = extract_edges(sub.xyz, **options)
            if getattr(seg, "crs", None) is None:
                seg.crs = sub.crs
            self._edges[key] = seg
        return self._edges[key]

    # -- outputs
    def output_path(self, item: AnalysisItem, filename: str) -> Path:
        """Where an analysis writes an output file (inside the run's temporary folder)."""
        rel = Path("outputs") / item.id / filename
        p = self.work_dir / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        self.outputs.setdefault(item.id, []).append(rel.as_posix())
        return p


def _norm_ids(value: Any) -> tuple[int, ...] | None:
    """A selector (None, int or list of ints) as a sorted tuple, so 706 and [706] share a cache."""
    if value is None:
        return None
    return tuple(sorted(int(v) for v in np.atleast_1d(value)))


def _freeze(value: Any) -> Any:
    if isinstance(value, dict):
        return tuple(sorted((k, _freeze(v)) for k, v in value.items()))
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def selection_label(cloud: str, classes: Any, source_id: Any) -> str:
    parts = [cloud]
    if source_id is not None:
        parts.append("strip " + "+".join(str(s) for s in np.atleast_1d(source_id)))
    if classes is not None:
        parts.append("class " + "+".join(str(c) for c in np.atleast_1d(classes)))
    return ", ".join(parts)


def _write_vector_safe(
    ctx: RunContext, item: AnalysisItem, obj: Any, base: str, fmt: str, notes: list[str]
) -> None:
    """Write a PointSet or Segments in the requested format (CSV when the GIS libraries
    are missing)."""
    from ..errors import MissingDependencyError
    from ..io.vector import PointSet, write_points, write_segments

    write = write_points if isinstance(obj, PointSet) else write_segments
    try:
        write(obj, ctx.output_path(item, f"{base}.{fmt}"), overwrite=True)
    except MissingDependencyError:
        ctx.outputs[item.id].pop()
        write(obj, ctx.output_path(item, f"{base}.csv"), overwrite=True)
        notes.append(f"{base}: written as CSV ({fmt} needs the 'vector' extra)")


# --------------------------------------------------------------------- info


@register("info")
def run_info(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Describe the cloud and show it from above, coloured by class and by flight strip."""
    from ..io.info import describe_cloud
    from . import plots

    name = item.options["cloud"]
    cloud = ctx.cloud(name)
    info = describe_cloud(cloud).to_dict()
    figures = []
    with ctx.step(f"Plotting {name}"):
        if cloud.classification is not None:
            figures.append(
                Figure(
                    "Classes",
                    plots.plot_classes(
                        cloud.xyz[:, :2],
                        cloud.classification,
                        f"{name}: classes",
                        z=cloud.xyz[:, 2],
                    ),
                    "top view, coloured by the file's classification",
                )
            )
        psid = cloud.point_source_id
        if psid is not None and len(np.unique(psid)) > 1:
            figures.append(
                Figure(
                    "Flight strips",
                    plots.plot_categories(
                        cloud.xyz[:, :2],
                        psid,
                        f"{name}: flight strips (point_source_id)",
                        z=cloud.xyz[:, 2],
                    ),
                    "top view, coloured by point_source_id",
                )
            )
        figures.append(
            Figure(
                "Heights",
                plots.plot_values(
                    cloud.xyz[:, :2],
                    cloud.xyz[:, 2],
                    f"{name}: heights",
                    label="z (m)",
                    z=cloud.xyz[:, 2],
                ),
                "top view, coloured by height (1st–99th percentile)",
            )
        )
    b = info["bounds"]
    rows = [
        ["points", info["n_points"]],
        ["x range", f"{b['min_x']:.2f} .. {b['max_x']:.2f}" if info["n_points"] else "–"],
        ["y range", f"{b['min_y']:.2f} .. {b['max_y']:.2f}" if info["n_points"] else "–"],
        ["z range", f"{b['min_z']:.2f} .. {b['max_z']:.2f}" if info["n_points"] else "–"],
        [
            "CRS",
            (info["crs_name"] or "none")
            + (f" (EPSG:{info['crs_epsg']})" if info["crs_epsg"] else ""),
        ],
        ["density (pts/m²)", info["density_per_m2"]],
        [
            "return numbers",
            "valid"
            if info["returns"].get("valid")
            else (
                "absent" if not info["returns"].get("present") else "present, partly invalid/zero"
            ),
        ],
    ]
    from .plots import CLASS_NAMES

    tables = [Table("Cloud", ["property", "value"], rows)]
    if info["classes"]:
        tables.append(
            Table(
                "Classes",
                ["class", "name", "points"],
                [[int(k), CLASS_NAMES.get(int(k), ""), v] for k, v in info["classes"].items()],
            )
        )
    if info["point_source_ids"]:
        tables.append(
            Table(
                "Flight strips",
                ["point_source_id", "points"],
                [[int(k), v] for k, v in info["point_source_ids"].items()],
            )
        )
    dens = info["density_per_m2"]
    headline = (
        f"{info['n_points']:,} points"
        + (f", {dens:.1f} pts/m²" if dens else "")
        + (f", {len(info['point_source_ids'])} flight strips" if info["point_source_ids"] else "")
    )
    info.pop("header", None)
    return SectionResult(results=info, headline=headline, figures=figures, tables=tables)


# -------------------------------------------------------------------- lines


def _lines_params(options: dict) -> dict[str, Any]:
    match_segments = _attr("lidarqa.accuracy.lines", "match_segments", "lines")
    return keyword_defaults(match_segments, exclude=("ground_truth",))


def _edge_params(options: dict) -> dict[str, Any]:
    extract_edges = _attr("lidarqa.geometry.edges", "extract_edges", "edges")
    out = keyword_defaults(extract_edges, exclude=("segmentation", "crs"))
    # extract_edges passes **segment_options to segment_planes: accept those names too.
    with contextlib.suppress(AnalysisUnavailableError):
        segment_planes = _attr("lidarqa.geometry.segmentation", "segment_planes", "edges")
        extra = keyword_defaults(segment_planes)
        for k, v in extra.items():
            if k not in out:
                out[k] = v
                if k in extra.annotations:
                    out.annotations[k] = extra.annotations[k]
    return out


def _segment_source(ctx: RunContext, source: dict, edge_options: dict) -> tuple[Any, str]:
    if "segments" in source:
        return ctx.segments(source["segments"]), source["segments"]
    seg = ctx.edges(source["cloud"], source.get("classes"), source.get("source_id"), edge_options)
    return seg, selection_label(source["cloud"], source.get("classes"), source.get("source_id"))


def _threshold_curve(th: Any, label: str) -> dict[str, Any]:
    k = int(getattr(th, "peak_index", -1))
    return {
        "label": f"{label} (δ = {th.threshold:.3f} m, {th.reason})",
        "sorted": np.asarray(th.sorted_nearest),
        "second_diff": np.asarray(th.second_diff),
        "second_diff_offset": 1,
        "peak_index": (k + 1) if k >= 0 else None,
        "threshold": float(th.threshold),
    }


@register("lines", _lines_params)
def run_lines(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Match test and model segments (Poreba & Goulette modified LHD), both ways."""
    from ..io.vector import Segments
    from . import plots

    match_segments = _attr("lidarqa.accuracy.lines", "match_segments", "lines")
    opts = item.options
    test, tlabel = _segment_source(ctx, opts["test"], opts["edges"])
    model, mlabel = _segment_source(ctx, opts["model"], opts["edges"])
    notes: list[str] = []
    gt = None
    if opts["ground_truth"] is not None:
        from ..accuracy._lines_io import read_pairs

        gt = read_pairs(opts["ground_truth"])
    if len(test) == 0 or len(model) == 0:
        from ..errors import DegenerateGeometryError

        raise DegenerateGeometryError(
            f"no segments to match: {len(test)} test ({tlabel}), {len(model)} model ({mlabel})"
        )
    with ctx.step(f"Matching {len(test):,} × {len(model):,} segments") as progress:
        m = match_segments(test, model, ground_truth=gt, progress=progress, **item.params)
    res = m.to_dict()
    res.update(
        test=tlabel,
        model=mlabel,
        cutoff=m.cutoff,
        gao_leung_tm=m.gao_leung_tm,
        gao_leung_mt=m.gao_leung_mt,
        hausdorff_tm=m.hausdorff_tm,
        hausdorff_mt=m.hausdorff_mt,
        threshold_reason_tm=m.auto_tm.reason,
        threshold_reason_mt=m.auto_mt.reason,
    )
    p, q = m.p, m.q

    # Output files: segments used (when extracted), correspondences both ways.
    fmt = opts["format"]
    for side, seg, src in (("test", test, opts["test"]), ("model", model, opts["model"])):
        if "cloud" in src:
            _write_vector_safe(ctx, item, seg, f"edges_{side}", fmt, notes)
    ti, mi, d = m.pairs_tm()
    best = np.full(p, np.nan)
    best_model = np.full(p, -1, dtype=np.int64)
    if len(ti):
        order = np.lexsort((d, ti))
        first = np.ones(len(order), bool)
        first[1:] = ti[order][1:] != ti[order][:-1]
        sel = order[first]
        best[ti[sel]] = d[sel]
        best_model[ti[sel]] = mi[sel]
    attrs = {
        "matched": np.isfinite(best),
        "model_id": np.array(
            [str(model.ids[j]) if j >= 0 else "" for j in best_model], dtype=object
        ),
        "distance": best,
    }
    matched_test = Segments(test.ids, test.start, test.end, attrs, test.crs)
    _write_vector_safe(ctx, item, matched_test, "matched_test", fmt, notes)
    comp = m.pair_components
    for base, mask, dcol in (
        ("pairs_tm", m.match_tm, comp[:, 3]),
        ("pairs_mt", m.match_mt, m.pair_d_mt),
    ):
        # One row per pair: the test segment's geometry with both ids and the distance parts.
        k = np.flatnonzero(mask)
        ti_k, mi_k = m.pair_test[k], m.pair_model[k]
        pairs = Segments(
            np.arange(len(k)),
            test.start[ti_k],
            test.end[ti_k],
            {
                "test_id": np.array([str(v) for v in test.ids[ti_k]], dtype=object),
                "model_id": np.array([str(v) for v in model.ids[mi_k]], dtype=object),
                "d": dcol[k],
                "d_angle": comp[k, 0],
                "d_parallel": comp[k, 1],
                "d_perpendicular": comp[k, 2],
            },
            test.crs,
        )
        _write_vector_safe(ctx, item, pairs, base, fmt, notes)
        if fmt != "csv":
            _write_vector_safe(ctx, item, pairs, base, "csv", notes)

    figures: list[Figure] = []
    with ctx.step("Plotting line matching"):
        if p * q <= 4_000_000:
            sim = np.full((p, q), np.nan)
            sim[m.pair_test, m.pair_model] = comp[:, 3]
            figures.append(
                Figure(
                    "Similarity matrix",
                    plots.plot_matrix(sim, f"Segment distances d (p = {p}, q = {q})", label="d"),
                    "rows: test segments, columns: model segments; "
                    "blank = pruned pairs (far apart)",
                )
            )
            cor = np.zeros((p, q), dtype=np.int8)
            cor[m.pair_test[m.match_tm], m.pair_model[m.match_tm]] = 1
            figures.append(
                Figure(
                    "Correspondence matrix",
                    plots.plot_matrix(
                        cor, f"Correspondence test → model ({m.n_pairs_tm} pairs)", binary=True
                    ),
                    "a dark cell is a pair with d ≤ δ (test → model)",
                )
            )
        else:
            notes.append(
                f"similarity and correspondence matrices not drawn: {p} × {q} is too large"
            )
        figures.append(
            Figure(
                "Automatic threshold",
                plots.plot_threshold_curve(
                    [
                        _threshold_curve(m.auto_tm, "test → model"),
                        _threshold_curve(m.auto_mt, "model → test"),
                    ]
                ),
                "sorted nearest distances (top) and their second differences (bottom); "
                "circles mark the "
                "chosen peak, dashed lines the thresholds",
            )
        )
        figures.append(
            Figure(
                "Matched segments",
                plots.plot_matched_segments(
                    (test.start, test.end),
                    (model.start, model.end),
                    best,
                    "Test segments coloured by distance to their match",
                ),
                f"test: {tlabel}; model: {mlabel}",
            )
        )
    rows = [
        ["segments p (test) / q (model)", f"{p} / {q}", ""],
        [
            "threshold δ test→model / model→test (m)",
            f"{m.threshold_tm:.4f} / {m.threshold_mt:.4f}",
            f"{m.auto_tm.reason} / {m.auto_mt.reason}",
        ],
        ["pairs test→model / model→test", f"{m.n_pairs_tm} / {m.n_pairs_mt}", ""],
        ["OLHD test→model (m)", m.olhd_tm, ""],
        ["OLHD model→test (m)", m.olhd_mt, ""],
        ["LHD (m)", m.lhd, "max of both directions"],
        [
            "Gao–Leung primary LHD test→model / model→test (m)",
            f"{m.gao_leung_tm:.4f} / {m.gao_leung_mt:.4f}",
            "no threshold",
        ],
    ]
    if m.ground_truth:
        g = m.ground_truth
        rows.append(
            [
                "detection rate test→model / model→test",
                f"{g.get('detection_rate_tm', float('nan')):.4f} / "
                f"{g.get('detection_rate_mt', float('nan')):.4f}",
                "(TP + TN) / (p·q)",
            ]
        )
    tables = [Table("Line matching", ["quantity", "value", "note"], rows)]
    k = np.flatnonzero(m.match_tm)
    k = k[np.argsort(comp[k, 3], kind="stable")]
    tables.append(
        Table(
            "Pairs test → model",
            ["test id", "model id", "d (m)", "angle part", "parallel (m)", "perpendicular (m)"],
            [
                [
                    str(test.ids[m.pair_test[j]]),
                    str(model.ids[m.pair_model[j]]),
                    float(comp[j, 3]),
                    *comp[j, :3].tolist(),
                ]
                for j in k[:50]
            ],
            note=f"{len(k)} pairs"
            + ("; the 50 closest shown, all in the output files" if len(k) > 50 else ""),
        )
    )
    if not (m.threshold_found_tm and m.threshold_found_mt) and item.params.get("threshold") is None:
        notes.append(
            "the automatic threshold fell back to the largest nearest distance in at least one "
            "direction (no clear knee); read the LHD with care"
        )
    headline = f"LHD {m.lhd:.3f} m ({m.n_pairs_tm} pairs; p = {p}, q = {q})"
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=[
            f"Test: {tlabel}. Model: {mlabel}. Distances combine angle, "
            "parallel and perpendicular components (weight W on the angle); "
            "OLHD is the length-weighted mean distance of matched pairs."
        ],
    )


# -------------------------------------------------------------------- edges


@register("edges", _edge_params)
def run_edges(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Extract edges (plane intersections) per flight strip and write them."""
    from . import plots

    opts = item.options
    strips = opts["source_ids"] or [None]
    notes: list[str] = []
    per: dict[str, Any] = {}
    groups = []
    rows = []
    for sid in strips:
        seg = ctx.edges(opts["cloud"], opts["classes"], sid, item.params)
        key = "all" if sid is None else str(sid)
        lengths = seg.lengths if len(seg) else np.empty(0)
        per[key] = {
            "n_edges": len(seg),
            "total_length": float(lengths.sum()),
            "median_length": float(np.median(lengths)) if len(lengths) else None,
        }
        for attr in ("angle_deg", "sigma_line"):
            if attr in seg.attributes and len(seg):
                per[key][f"median_{attr}"] = float(
                    np.nanmedian(np.asarray(seg.attributes[attr], float))
                )
        base = "edges" if sid is None else f"edges_{sid}"
        if len(seg):
            _write_vector_safe(ctx, item, seg, base, opts["format"], notes)
        groups.append((seg.start, seg.end, "all" if sid is None else f"strip {sid}"))
        rows.append(
            [
                key,
                len(seg),
                float(lengths.sum()),
                per[key]["median_length"],
                per[key].get("median_sigma_line"),
            ]
        )
    n_total = sum(v["n_edges"] for v in per.values())
    with ctx.step("Plotting edges"):
        fig = plots.plot_segments(
            groups, "Edges (" + selection_label(opts["cloud"], opts["classes"], None) + ")"
        )
    res = {"n_edges": n_total, "by_source_id": per, "classes": opts["classes"]}
    table = Table(
        "Edges",
        ["strip", "edges", "total length (m)", "median length (m)", "median σ line (m)"],
        rows,
    )
    headline = ", ".join(
        f"{v['n_edges']} edges ({'strip ' + k if k != 'all' else 'all points'})"
        for k, v in per.items()
    )
    return SectionResult(
        results=res,
        headline=headline,
        figures=[Figure("Edges", fig, "top view")],
        tables=[table],
        notes=notes,
    )


# -------------------------------------------------------------- checkpoints


def _checkpoint_params(options: dict) -> dict[str, Any]:
    if options.get("vertical"):
        f = _attr("lidarqa.accuracy.checkpoints", "vertical_check", "checkpoints")
        return keyword_defaults(f, exclude=("classification",))
    f = _attr("lidarqa.accuracy.checkpoints", "assess_checkpoints", "checkpoints")
    return keyword_defaults(f)


def sample_check_points(
    xyz: np.ndarray,
    *,
    n: int,
    seed: int,
    min_spacing: float,
    near: np.ndarray | None = None,
    near_distance: float = 1.0,
) -> np.ndarray:
    """Indices of up to `n` well-spread points (one per `min_spacing` cell, deterministic).

    With `near`, only points within `near_distance` (XY) of a point of `near` qualify
    (so that check points fall where the tested cloud has data).
    """
    cand = np.arange(len(xyz))
    if near is not None and len(near):
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(near[:, :2]).query(xyz[:, :2], k=1, distance_upper_bound=near_distance)
        cand = cand[np.isfinite(dist)]
    if len(cand) == 0:
        return cand
    rng = np.random.default_rng(seed)
    cand = cand[rng.permutation(len(cand))]
    cell = np.floor(xyz[cand, :2] / max(min_spacing, 1e-9)).astype(np.int64)
    _, first = np.unique(cell, axis=0, return_index=True)
    first = np.sort(first)  # keep the random order among cells
    return np.sort(cand[first[:n]])


@register("checkpoints", _checkpoint_params)
def run_checkpoints(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Check points: residuals, RMSE and ASPRS/NSSDA figures (or the vertical check of a cloud)."""
    from ..io.vector import PointSet
    from . import plots

    mod = _import("lidarqa.accuracy.checkpoints", "checkpoints")
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
            from ..errors import InvalidPointsError

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
        _write_vector_safe(ctx, item, check, "check_points", opts["format"], notes)
    if opts["vertical"]:
        tested = ctx.select(opts["measured"], None, opts["source_ids"])
        measured_label = selection_label(opts["measured"], None, opts["source_ids"])
        with ctx.step(f"Vertical check of {measured_label}"):
            rep = mod.vertical_check(
                tested.xyz, check, classification=tested.classification, **item.params
            )
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
        with ctx.step("Comparing check points"):
            rep = mod.assess_checkpoints(measured, check, **item.params)
        residuals = rep.residuals
        xyz = rep.check_xyz
        paragraphs.append(
            f"Measured points: {opts['measured']}; check points: {check_label}. Residual = "
            "(transformed) measured − check."
        )
    res = rep.to_dict()
    res_pts = rep.residual_points()
    res_pts.crs = check.crs if check.crs is not None else ctx.crs  # outputs carry the CRS
    _write_vector_safe(ctx, item, res_pts, "residuals", opts["format"], notes)
    if opts["format"] != "csv":
        _write_vector_safe(ctx, item, res_pts, "residuals", "csv", notes)
    notes.extend(str(w) for w in res.get("warnings", []))
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
    stat_rows = []
    for axis in ("z",) if opts["vertical"] else ("x", "y", "z"):
        stat_rows.append(
            [
                axis,
                res.get(f"mean_{axis}"),
                res.get(f"std_{axis}"),
                res.get(f"rmse_{axis}"),
                res.get(f"max_abs_{axis}"),
            ]
        )
    tables = [
        Table(
            "Residual statistics (m)",
            ["axis", "mean", "std", "RMSE", "max |residual|"],
            stat_rows,
            note=f"{res['n_check']} check points"
            + (f", {res['n_control']} control points" if res.get("n_control") else ""),
        ),
    ]
    acc_rows = [["RMSE horizontal", res.get("rmse_h")], ["RMSE 3D", res.get("rmse_3d")]]
    for k, v in (res.get("nssda") or {}).items():
        if k != "warnings":
            acc_rows.append([f"NSSDA {k}", v])
    for k, v in (res.get("asprs2023") or {}).items():
        if k != "warnings":
            acc_rows.append([f"ASPRS 2023 {k}", v])
    acc_rows = [r for r in acc_rows if r[1] is not None and r[1] == r[1]]  # drop undefined (NaN)
    tables.append(Table("Accuracy figures", ["figure", "value"], acc_rows))
    tr = res.get("transform") or {}
    if tr.get("name") not in (None, "none"):
        tables.append(
            Table(
                f"Transformation: {tr['name']}",
                ["parameter", "value", "σ"],
                [
                    [_with_unit(k), v, (tr.get("sigmas") or {}).get(k)]
                    for k, v in (tr.get("params") or {}).items()
                ],
                note=f"σ0 = {fmt_or_dash(tr.get('sigma0'))} m"
                + (
                    "; tx, ty, tz are the shift of the control-point centroid "
                    + ", ".join(f"{a} {fmt_or_dash(tr['origin'][a])}" for a in "xyz")
                    + " m, about which rotations and scale act"
                    if tr.get("origin")
                    else ""
                ),
            )
        )
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
            note="first 100 points; all in the output files"
            if len(res.get("residuals", [])) > 100
            else "",
            decimals=3,  # metres to the millimetre, heights and residuals alike
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
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        paragraphs=paragraphs,
    )


def _with_unit(key: str) -> str:
    """``"tx (m)"``, ``"kappa_deg"`` stays, ``"scale"`` stays: the unit policy of lidarqa.units."""
    from ..units import param_unit

    unit = param_unit(key)
    return f"{key} ({unit})" if unit and not key.endswith("_deg") else key


def fmt_or_dash(v: Any) -> str:
    from .html import fmt

    return fmt(v)


# ------------------------------------------------------------------ heights


def _heights_params(options: dict) -> dict[str, Any]:
    f = _attr("lidarqa.accuracy.heights", "assess_heights", "heights")
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


@register("heights", _heights_params)
def run_heights(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Height quality (Oude Elberink & Vosselman): predicted map-point σ, w-tests."""
    from ..io.vector import PointSet
    from . import plots

    mod = _import("lidarqa.accuracy.heights", "heights")
    opts = item.options
    notes: list[str] = []
    paragraphs: list[str] = []
    sel = ctx.select(opts["cloud"], opts["classes"], opts["source_ids"])
    label = selection_label(opts["cloud"], opts["classes"], opts["source_ids"])
    laser = sel.xyz
    r = opts["reference"]
    if isinstance(r, str):
        ref_xyz = ctx.points(r).xyz
        ref_label = r
    else:
        rng = np.random.default_rng(r["seed"])
        perm = rng.permutation(len(laser))
        n_ref = int(round(r["fraction"] * len(laser)))
        ref_idx, laser_idx = perm[:n_ref], perm[n_ref:]
        if len(ref_idx) > r["max_points"]:
            ref_idx = rng.choice(ref_idx, size=r["max_points"], replace=False)
        ref_xyz = laser[np.sort(ref_idx)]
        laser = laser[np.sort(laser_idx)]
        ref_label = (
            f"{len(ref_xyz):,} points held apart from {label} (fraction {r['fraction']}, "
            f"seed {r['seed']}); the planes use the other {len(laser):,}"
        )
    m = opts["map"]
    if isinstance(m, str):
        mp = mod.read_map_points(ctx.config.inputs[m].path, spacing=opts["map_spacing"])
        map_xy = mp.xyz[:, :2]
        map_label = f"{len(map_xy)} map points from {m}"
    else:
        map_xy = grid_map_points(laser, m["grid"], min_points=m["min_points"])
        map_label = f"{len(map_xy)} map points on a {m['grid']:g} m grid where laser points exist"
    with ctx.step(f"Heights of {len(map_xy):,} map points, {len(ref_xyz):,} reference points"):
        rep = mod.assess_heights(laser, map_xy, ref_xyz, **item.params)
    res = rep.to_dict()
    mpts = rep.map_points
    sig_cls = plots.sigma_class(np.where(mpts.failed, np.nan, mpts.sigma))
    res["sigma_classes"] = {
        lab: int(np.sum(sig_cls == k)) for k, (_, lab, _) in enumerate(plots.SIGMA_CLASSES)
    }
    res.update(
        n_laser_points=int(len(laser)),
        n_reference=int(len(ref_xyz)),
        n_reference_outside=int(rep.n_outside),
        flags=list(rep.flags),
    )
    paragraphs.append(f"Laser points: {label}. Map points: {map_label}. Reference: {ref_label}.")
    # Outputs.
    mp_set = PointSet(
        ids=np.arange(len(mpts)),
        xyz=np.column_stack([mpts.xy, mpts.height]),
        crs=ctx.crs,
        attributes={
            "sigma": mpts.sigma,
            "sigma_plane": mpts.sigma_plane,
            "sigma_block": mpts.sigma_block,
            "sigma_model": mpts.sigma_model,
            "n_points": mpts.n_points,
            "radius": mpts.radius,
            "failed": mpts.failed,
            "reason": np.asarray(mpts.reason, dtype=object),
        },
    )
    mp_ok = mp_set.subset(~mpts.failed) if mpts.failed.any() else mp_set
    _write_vector_safe(ctx, item, mp_ok, "map_points", opts["format"], notes)
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
    _write_vector_safe(ctx, item, ref_set, "reference_points", opts["format"], notes)
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
                    mpts.xy, np.where(mpts.failed, np.nan, mpts.sigma), background=laser[:, :2]
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
    tables = [
        Table(
            "Map points",
            ["quantity", "value"],
            [
                ["map points", mpd["n"]],
                ["not fitted", mpd["n_failed"]],
                ["mean predicted σ (m)", mpd["sigma_mean"]],
                ["95th percentile σ (m)", mpd["sigma_p95"]],
                *[[f"σ class {k}", v] for k, v in res["sigma_classes"].items()],
            ],
        ),
        Table(
            "Comparison with the reference",
            ["quantity", "value"],
            [[k, v] for k, v in c.items() if not isinstance(v, list | dict)],
        ),
        Table("w-tests", ["quantity", "value"], [[k, v] for k, v in w.items()]),
    ]
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
                        int(i),
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


# ------------------------------------------------------------------- ground


_GROUND_CLASSES = {"segment-ptd": "SegmentPTD", "ptd": "PTD"}


def _ground_params(options: dict) -> dict[str, Any]:
    """classify_ground's keywords plus the chosen filter's parameters (its dataclass fields)."""
    classify_ground = _attr("lidarqa.ground", "classify_ground", "ground")
    out = keyword_defaults(classify_ground, exclude=("method", "evaluate", "ignore_classes"))
    filter_cls = _attr(
        "lidarqa.ground", _GROUND_CLASSES[options.get("method") or "segment-ptd"], "ground"
    )
    fields = dataclass_defaults(filter_cls)
    for k, v in fields.items():
        if k not in out:
            out[k] = v
            if k in fields.annotations:
                out.annotations[k] = fields.annotations[k]
    own = set(keyword_defaults(classify_ground))

    def validate(params: dict[str, Any]) -> None:
        # Building the filter checks every parameter's range (its __post_init__).
        filter_cls(**{k: v for k, v in params.items() if k not in own})
        presets = getattr(_import("lidarqa.ground", "ground"), "PRESETS", None)
        if (
            params.get("preset") is not None
            and presets is not None
            and params["preset"] not in presets
        ):
            raise ConfigError(
                f"key 'preset' must be one of {', '.join(map(repr, presets))}; "
                f"got {params['preset']!r}"
            )

    out.validate = validate
    return out


@register("ground", _ground_params)
def run_ground(ctx: RunContext, item: AnalysisItem) -> SectionResult:
    """Ground filtering (segment-PTD or PTD) and its ISPRS errors against the input's classes."""
    from . import plots

    ground_mod = _import("lidarqa.ground", "ground")
    opts = item.options
    cloud = ctx.cloud(opts["cloud"])
    n = len(cloud)
    notes: list[str] = []
    cls = cloud.classification
    evaluate = bool(opts["evaluate"])
    if evaluate and cls is None:
        notes.append("the cloud has no classification: nothing to evaluate against")
        evaluate = False
    ignore = list(opts["ignore_classes"] or [])
    import warnings

    with (
        ctx.step(f"Ground filtering ({opts['method']}, {n:,} points)") as progress,
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")  # reported through result.warnings instead
        result = ground_mod.classify_ground(
            cloud,
            method=opts["method"],
            evaluate=evaluate,
            ignore_classes=ignore or None,
            progress=progress,
            **item.params,
        )
    ground = np.asarray(result.ground_mask, dtype=bool)
    res = result.to_dict()
    notes.extend(str(w) for w in res.get("warnings", []))
    errors = result.evaluation
    if errors is not None:
        res.update(
            type_i_pct=errors.type_i_pct,
            type_ii_pct=errors.type_ii_pct,
            total_pct=errors.total_pct,
            ignore_classes=ignore,
        )
    if opts["write_cloud"] and cls is not None:
        from ..io import write

        out = cloud.copy()
        out.fields["classification"] = ground_mod.relabel_classification(cls, ground)
        path = ctx.output_path(item, f"{opts['cloud']}_ground.{opts['cloud_format']}")
        with ctx.step("Writing the classified cloud"):
            write(out, path, overwrite=True)
    figures = []
    evaluated = ~np.isin(cls, ignore) if errors is not None else None
    with ctx.step("Plotting ground maps"):
        cmap, emap = plots.plot_ground_maps(
            cloud.xyz[:, :2], ground, (cls == 2) if errors is not None else None, evaluated
        )
        figures.append(Figure("Ground classification", cmap, "top view of the filter's result"))
        if emap is not None:
            figures.append(
                Figure(
                    "Error map",
                    emap,
                    "type I: reference ground rejected; type II: object accepted as ground",
                )
            )
    tables = []
    if errors is not None:
        e = errors
        tables.append(
            Table(
                "Cross table (points)",
                ["reference \\ filter", "ground", "object", "total"],
                [
                    ["ground", e.a, e.b, e.a + e.b],
                    ["object", e.c, e.d, e.c + e.d],
                    ["total", e.a + e.c, e.b + e.d, e.n],
                ],
                note=("classes " + ", ".join(map(str, ignore)) + " not evaluated")
                if ignore
                else "",
            )
        )
        tables.append(
            Table(
                "ISPRS errors",
                ["measure", "value"],
                [
                    ["type I (%)", e.type_i_pct],
                    ["type II (%)", e.type_ii_pct],
                    ["total (%)", e.total_pct],
                    ["Cohen's κ", e.kappa],
                    ["points evaluated", e.n],
                ],
            )
        )
        headline = (
            f"total error {e.total_pct:.2f} % (type I {e.type_i_pct:.2f} %, type II "
            f"{e.type_ii_pct:.2f} %), κ {e.kappa:.3f}"
        )
    else:
        headline = f"{int(ground.sum()):,} of {n:,} points classified as ground"
    tables.append(
        Table(
            "Filter run",
            ["quantity", "value"],
            [
                ["candidate points", res.get("n_candidates")],
                ["ground points", res.get("n_ground")],
                ["return handling", res.get("return_handling")],
                ["noise points excluded", res.get("n_excluded_noise")],
            ],
        )
    )
    return SectionResult(
        results=res,
        headline=headline,
        figures=figures,
        tables=tables,
        notes=notes,
        parameters={"filter": dict(result.parameters)},
        paragraphs=[
            f"Method {opts['method']} on {opts['cloud']} ({n:,} points); the filter decides from "
            "geometry (and return numbers) only; the file's classes are used only to score it."
        ],
    )
