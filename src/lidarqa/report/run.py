"""Assessment runs: validated config in, ``report.html`` + ``report.json`` + outputs out.

Everything is written into a temporary folder inside the output folder and
moved into place at the very end (``report.html`` last), so an interrupted
run (Ctrl-C) leaves no partial report at the final paths. The JSON records
every analysis's ``results``, the parameters actually used (library defaults
filled in), SHA-256 hashes of the inputs and the versions of lidarqa and its
dependencies.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._version import __version__
from ..errors import LidarQAError
from . import _registry
from .config import AnalysisItem, AssessmentConfig, load_config
from .html import Report, Section, SummaryRow, fmt, render_html

__all__ = [
    "AssessmentRun",
    "run_assessment",
    "check_out_dir",
    "demo_config_path",
    "assess",
    "SCHEMA_VERSION",
    "REPORT_HTML",
    "REPORT_JSON",
    "OUTPUTS_DIR",
]

#: version of the report.json layout (docs: Reference, report.json): MINOR for new keys, MAJOR
#: for removed or renamed keys or changed units
SCHEMA_VERSION = "1.0"
REPORT_HTML = "report.html"
REPORT_JSON = "report.json"
OUTPUTS_DIR = "outputs"


@dataclass
class AssessmentRun:
    """What a run produced (also the content of ``report.json``)."""

    out_dir: Path
    html_path: Path
    json_path: Path
    document: dict[str, Any]
    summary: list[SummaryRow] = field(default_factory=list)
    errors: dict[str, str] = field(default_factory=dict)

    @property
    def results(self) -> dict[str, Any]:
        """The ``results`` of the JSON document, by analysis."""
        return self.document["results"]


def demo_config_path() -> Path:
    """The bundled demo configuration (``lidarqa/data/demo.toml``)."""
    from importlib import resources

    return Path(str(resources.files("lidarqa.data") / "demo.toml"))


def check_out_dir(out_dir: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Refuse an output folder that already holds a report (unless `overwrite`).

    Raises :class:`OutputExistsError` when ``report.html``, ``report.json`` or
    ``outputs/`` exist and `overwrite` is false, and :class:`WriteError` when
    the path is a file.
    """
    from .._atomic import check_output_folder

    return check_output_folder(out_dir, (REPORT_HTML, REPORT_JSON, OUTPUTS_DIR),
                               overwrite=overwrite)


class _Progress:
    """Wraps :class:`lidarqa.cli._common.Steps` so nested steps do not nest live displays."""

    def __init__(self, steps: Any) -> None:
        self.steps = steps
        self.depth = 0

    @contextlib.contextmanager
    def __call__(self, description: str) -> Iterator[Any]:
        """Yield the step's progress callback (a no-op for nested steps)."""
        outer = self.steps is not None and self.depth == 0
        self.depth += 1
        try:
            with self.steps(description) if outer else contextlib.nullcontext() as progress:
                yield progress if callable(progress) else _no_progress
        finally:
            self.depth -= 1


def _no_progress(fraction: float) -> None:
    """Progress callback of a step that shows nothing."""


def _lookup(results: dict[str, Any], path: tuple[str, ...]) -> Any:
    v: Any = results
    for k in path:
        if not isinstance(v, dict) or k not in v:
            return None
        v = v[k]
    return v


def _measured(value: float | None, unit: str) -> str:
    """A measured value with the digits the section headlines use: mm for metres, 0.01 for %."""
    if value is None or value != value:
        return "–"
    if unit == "%":
        return f"{value:.2f}"
    if unit == "" and float(value).is_integer():
        return f"{int(value)}"  # counts (edges found)
    return f"{value:.3f}"  # metres to the mm; κ to three decimals


def _verdict(item: AnalysisItem, results: dict[str, Any]) -> tuple[str, str, list[dict[str, Any]]]:
    """The verdict (pass / fail / n/a) against the targets, a text and the per-target records."""
    if not item.targets:
        return "n/a", "", []
    specs = {t.metric: t for t in _registry.specs()[item.kind].targets.values()}
    records = []
    texts = []
    missing: list[str] = []
    ok_all = True
    for metric, target in item.targets.items():
        t = specs[metric]
        value = _lookup(results, t.path)
        try:
            value_f = float(value) if value is not None else None
        except (TypeError, ValueError):
            value_f = None
        if metric == "mean_z" and value_f is not None:
            value_f = abs(value_f)
        if value_f is None or value_f != value_f:
            # Nothing to measure (0 check points, no matched pair): an error, not a NaN verdict.
            missing.append(t.label)
            ok = False
        elif t.direction == "max":
            ok = value_f <= target
        else:
            ok = value_f >= target
        ok_all &= ok
        op = "≤" if t.direction == "max" else "≥"
        unit = f" {t.unit}" if t.unit else ""
        shown = None if value_f is None else value_f * t.scale
        texts.append(
            f"{t.label} {_measured(shown, t.unit)}{unit} {op} {fmt(target * t.scale)}{unit}: "
            f"{'pass' if ok else 'FAIL'}"
        )
        records.append(
            {
                "metric": metric,
                "value": value_f,
                "target": target,
                "direction": t.direction,
                "passed": ok,
            }
        )
    if missing:
        return (
            "error",
            f"nothing to measure: {', '.join(missing)} could not be computed",
            records,
        )
    return ("pass" if ok_all else "fail"), "; ".join(texts), records


def catalog_record(name: str, spec: Any) -> dict[str, Any]:
    """The report's input record of a catalog: tiles, points and a fingerprint.

    Hashing every byte of a delivery would read it all; the fingerprint is the
    SHA-256 of the sorted tile names, sizes and header bounds instead.
    """
    from ..io.crs import crs_epsg, crs_name
    from ..tiling import open_catalog

    cat = open_catalog(str(spec.path))
    h = hashlib.sha256()
    for t in cat.tiles:
        size = Path(t.path).stat().st_size if Path(t.path).exists() else -1
        h.update(f"{Path(t.path).name}|{size}|{t.n_points}|{t.bounds}\n".encode())
    crs = spec.effective_crs or cat.crs
    return {"name": name, "kind": spec.kind, "path": str(spec.path), "catalog": True,
            "n_tiles": len(cat.tiles), "n_points": int(cat.n_points),
            "size": int(sum(Path(t.path).stat().st_size for t in cat.tiles
                            if Path(t.path).exists())),
            "sha256": h.hexdigest(), "fingerprint": "tile names, sizes, point counts, bounds",
            "crs_epsg": crs_epsg(crs), "crs_name": crs_name(crs)}


def _input_records(config: AssessmentConfig, progress: _Progress) -> dict[str, dict[str, Any]]:
    from ..io.crs import crs_epsg, crs_name
    from ..tiling.source import is_catalog_input
    from ._context import sha256_file

    out = {}
    with progress("Hashing inputs"):
        for name, spec in config.inputs.items():
            if spec.kind == "clouds" and is_catalog_input(str(spec.path)):
                out[name] = catalog_record(name, spec)
                continue
            crs = spec.effective_crs
            out[name] = {
                "name": name,
                "kind": spec.kind,
                "path": str(spec.path),
                "size": spec.path.stat().st_size,
                "sha256": sha256_file(spec.path),
                "crs_epsg": crs_epsg(crs),
                "crs_name": crs_name(crs),
            }
    return out


def _resolved_params(item: AnalysisItem) -> dict[str, Any]:
    from ._registry import library_params

    try:
        defaults = library_params(item.kind, item.options)
    except LidarQAError:
        defaults = {}
    return {**defaults, **item.params}


def _options_for_json(options: dict[str, Any]) -> dict[str, Any]:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in options.items() if v is not None}


def run_assessment(
    config: AssessmentConfig | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    overwrite: bool = False,
    steps: Any = None,
    command: str = "assess",
) -> AssessmentRun:
    """Run every analysis of `config` and write the report into `out_dir`.

    Parameters
    ----------
    config : AssessmentConfig or path-like
        A validated config (:func:`lidarqa.report.config.load_config`) or the TOML path.
    out_dir : path-like
        Output folder (created if needed). Receives ``report.html``,
        ``report.json`` and ``outputs/<analysis>/...``.
    overwrite : bool, default False
        Replace an existing report in `out_dir`.
    steps : lidarqa.cli._common.Steps, optional
        Progress display; None shows nothing.

    Returns
    -------
    AssessmentRun

    Notes
    -----
    An analysis that fails with an error is reported as such (verdict
    "error", message in the report and the JSON ``errors``); the others still
    run. ``KeyboardInterrupt`` aborts the run and removes the temporary folder,
    leaving `out_dir` as it was.
    """
    from .. import show_versions
    from ._context import RunContext
    from ._registry import ANALYSES, specs

    specs()  # load the analysis modules

    if not isinstance(config, AssessmentConfig):
        config = load_config(config)
    out = check_out_dir(out_dir, overwrite=overwrite)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    from .._atomic import note_created, register_temp, unregister_temp

    if created:
        note_created(out)  # removed with everything in it if the command fails or is stopped
    progress = _Progress(steps)
    started = _dt.datetime.now(_dt.UTC)
    t0 = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix=".lidarqa-run-", dir=out))
    register_temp(work)  # removed by the signal handler too
    try:
        inputs = _input_records(config, progress)
        ctx = RunContext(config, work, step=progress)
        sections: list[Section] = []
        summary: list[SummaryRow] = []
        results: dict[str, Any] = {}
        parameters: dict[str, Any] = {}
        errors: dict[str, str] = {}
        tracebacks: dict[str, str] = {}
        verdicts: dict[str, Any] = {}
        caveats: dict[str, list[str]] = {}
        timings: dict[str, float] = {}
        for item in config.analyses:
            ta = time.perf_counter()
            params = _resolved_params(item)
            section = Section(id=item.id, title=item.title, kind=item.kind)
            try:
                with progress(item.title):
                    res = ANALYSES[item.kind](ctx, item)
            except (KeyboardInterrupt, SystemExit):
                raise
            except Exception as exc:  # one failing analysis must not lose the others
                message = " ".join(str(exc).split()) or type(exc).__name__
                if not isinstance(exc, LidarQAError):
                    message = f"{type(exc).__name__}: {message}"
                    tracebacks[item.id] = traceback.format_exc()
                errors[item.id] = message
                section.error = message
                results[item.id] = None
                summary.append(SummaryRow(item.title, item.id, "failed: " + message, "error", ""))
                verdicts[item.id] = {"verdict": "error", "targets": []}
                section.verdict = "error"
            else:
                params = {**params, **res.parameters}
                results[item.id] = res.results
                section.headline = res.headline
                section.paragraphs = res.paragraphs
                section.tables = res.tables
                section.figures = res.figures
                section.notes = res.notes
                section.outputs = ctx.outputs.get(item.id, [])
                verdict, detail, records = _verdict(item, res.results)
                if verdict == "error":
                    errors[item.id] = detail
                    section.error = detail
                section.verdict = verdict
                section.caveats = list(res.caveats)
                if res.caveats:
                    caveats[item.id] = list(res.caveats)
                summary.append(
                    SummaryRow(
                        item.title, item.id, res.headline, verdict, detail, tuple(res.caveats)
                    )
                )
                verdicts[item.id] = {"verdict": verdict, "targets": records}
            timings[item.id] = round(time.perf_counter() - ta, 3)
            parameters[item.id] = {
                "kind": item.kind,
                "title": item.title,
                "options": _options_for_json(item.options),
                "params": params,
                "targets": dict(item.targets),
            }
            sections.append(section)

        for _kind, title, reason in config.skipped:
            summary.append(SummaryRow(title, "summary", "not run: " + reason, "skipped", ""))
        duration = time.perf_counter() - t0
        versions = show_versions()
        attribution = config.attribution
        if attribution is None and _uses_demo_tile(config):
            from ..data import DEMO_TILE_ATTRIBUTION

            attribution = DEMO_TILE_ATTRIBUTION
        config_record: dict[str, Any] = {"content": config.raw}
        if config.path is not None:
            from ._context import sha256_file

            config_record.update(path=str(config.path), sha256=sha256_file(config.path))
        doc = {
            "schema_version": SCHEMA_VERSION,
            "lidarqa_version": __version__,
            "command": command,
            "title": config.title,
            "attribution": attribution,
            "started_utc": started.isoformat(timespec="seconds"),
            "duration_s": round(duration, 3),
            "config": config_record,
            "inputs": inputs,
            "parameters": parameters,
            "results": results,
            "verdicts": verdicts,
            "warnings": caveats,
            "errors": errors,
            "skipped": [{"kind": k, "title": t, "reason": r} for k, t, r in config.skipped],
            "outputs": {k: v for k, v in ctx.outputs.items()},
            "timings_s": timings,
            "versions": versions,
            "argv": list(sys.argv),
        }
        if tracebacks:
            doc["tracebacks"] = tracebacks

        provenance = [
            ("lidarqa version", __version__),
            ("command", command),
            ("started (UTC)", started.isoformat(timespec="seconds")),
            ("duration", f"{duration:.1f} s"),
            ("config", str(config.path) if config.path else "(in memory)"),
            ("config sha256", config_record.get("sha256", "–")),
            ("output folder", str(out.resolve())),
        ]
        n_fail = sum(r.verdict == "fail" for r in summary)
        n_err = len(errors)
        n_pass = sum(r.verdict == "pass" for r in summary)
        subtitle = (
            f"{len(summary)} analyses · {n_pass} passed · {n_fail} failed"
            + (f" · {n_err} errors" if n_err else "")
            + (f" · {len(config.skipped)} not available" if config.skipped else "")
            + f" · generated {started.strftime('%Y-%m-%d %H:%M UTC')} by lidarqa {__version__}"
        )
        report = Report(
            title=config.title,
            subtitle=subtitle,
            summary=summary,
            sections=sections,
            parameters={
                pid: {
                    "kind": p["kind"],
                    "options": p["options"],
                    "parameters": p["params"],
                    **({"targets": p["targets"]} if p["targets"] else {}),
                }
                for pid, p in parameters.items()
            },
            provenance=provenance,
            inputs=[
                {**rec, "crs": (f"EPSG:{rec['crs_epsg']}" if rec["crs_epsg"] else rec["crs_name"])}
                for rec in inputs.values()
            ],
            versions=versions,
            attribution=attribution,
            section_titles={item.id: item.title for item in config.analyses},
            config_text=(
                config.path.read_text(encoding="utf-8") if config.path is not None else None
            ),
        )
        with progress("Writing the report"):
            from .._json import to_jsonable

            (work / REPORT_JSON).write_text(
                json.dumps(to_jsonable(doc), indent=2, allow_nan=False) + "\n", encoding="utf-8"
            )
            (work / REPORT_HTML).write_text(render_html(report), encoding="utf-8")
            _commit(work, out, overwrite=overwrite)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        if created:  # leave no trace of an interrupted or failed run
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
        unregister_temp(work)
    return AssessmentRun(
        out_dir=out,
        html_path=out / REPORT_HTML,
        json_path=out / REPORT_JSON,
        document=doc,
        summary=summary,
        errors=errors,
    )


def _uses_demo_tile(config: AssessmentConfig) -> bool:
    from ..data import demo_tile

    try:
        tile = demo_tile().resolve()
    except Exception:
        return False
    return any(spec.path.resolve() == tile for spec in config.inputs.values())


def _commit(work: Path, out: Path, *, overwrite: bool) -> None:
    """Move the finished run from `work` into `out`: outputs first, then JSON, then HTML."""
    check_out_dir(out, overwrite=overwrite)  # something may have appeared meanwhile
    src_outputs = work / OUTPUTS_DIR
    dst_outputs = out / OUTPUTS_DIR
    if dst_outputs.exists():
        trash = work / ".old-outputs"
        os.replace(dst_outputs, trash)
    if src_outputs.exists():
        os.replace(src_outputs, dst_outputs)
    from ..io import atomic_path

    for name in (REPORT_JSON, REPORT_HTML):  # the HTML last: it marks a complete report
        with atomic_path(out / name, overwrite=overwrite) as tmp:
            os.replace(work / name, tmp)


def assess(
    config: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    overwrite: bool = False,
    steps: Any = None,
) -> AssessmentRun:
    """Validate `config` (TOML path) and run it into `out_dir`: ``lidarqa assess`` as a function."""
    cfg = load_config(config)
    check_out_dir(out_dir, overwrite=overwrite)
    return run_assessment(cfg, out_dir, overwrite=overwrite, steps=steps)
