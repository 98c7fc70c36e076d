"""Shared pieces of the analyses: the run context, the section result and helpers.

:class:`RunContext` reads each input once and hands out selections, edges and
output paths; :class:`SectionResult` is what an analysis returns to the report;
:func:`keyword_defaults` / :func:`dataclass_defaults` discover the library
keyword arguments an analysis accepts, so the config uses the API's names.
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

from ._schema import AnalysisItem, AnalysisUnavailableError, AssessmentConfig
from .html import Figure, Table

__all__ = [
    "SectionResult",
    "RunContext",
    "keyword_defaults",
    "dataclass_defaults",
    "ParamDefaults",
    "sha256_file",
    "selection_label",
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
    #: warnings that qualify the verdict (e.g. too few check points for a standard); the report
    #: shows them beside the verdict and report.json lists them under ``warnings``
    caveats: list[str] = field(default_factory=list)



def import_module(module: str, kind: str) -> Any:
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


def library_attr(module: str, name: str, kind: str) -> Any:
    mod = import_module(module, kind)
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

    def add_missing(self, other: ParamDefaults) -> ParamDefaults:
        """Add `other`'s parameters (and annotations) that this one lacks; return self."""
        for k, v in other.items():
            if k not in self:
                self[k] = v
                if k in other.annotations:
                    self.annotations[k] = other.annotations[k]
        return self


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
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
        else:
            out[f.name] = None
    return out


def sha256_file(path: str | Path) -> str:
    """SHA-256 of a file, streamed."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


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
        self._points: dict[Any, Any] = {}
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
    def is_catalog(self, name: str) -> bool:
        """True when cloud input `name` is a catalog (a folder, a glob or a ``.vpc``)."""
        from ..tiling.source import is_catalog_input

        spec = self.config.inputs.get(name)
        return spec is not None and spec.kind == "clouds" and is_catalog_input(str(spec.path))

    def cloud(self, name: str) -> Any:
        """The point cloud input `name` (read once)."""
        if name not in self._clouds:
            from ..io import read
            from ..tiling.source import is_catalog_input, open_source

            spec = self.config.inputs[name]
            with self.step(f"Reading {spec.path.name}"):
                if is_catalog_input(str(spec.path)):  # a catalog in memory: one region
                    cloud = open_source(str(spec.path), z_to_metres=False).read(
                        require_points=False)
                else:
                    cloud = read(spec.path)
            if cloud.crs is None and spec.effective_crs is not None:
                cloud.crs = spec.effective_crs
            elif cloud.crs is None:
                cloud.crs = self.crs
            self._clouds[name] = cloud
        return self._clouds[name]

    def source(self, name: str, classes: Any = None, source_id: Any = None) -> Any:
        """Cloud input `name` as a :class:`~lidarqa.tiling.source.Source` with a selection.

        The one way an analysis reads a cloud, as the CLI does: its CRS, heights converted
        to metres and the selection applied at read time, for a file (the cloud read once,
        one in-memory region) and for a catalog (read chunk by chunk) alike.
        """
        from ..tiling.source import open_source

        spec = self.config.inputs[name]
        src: Any = str(spec.path) if self.is_catalog(name) else self.cloud(name)
        return open_source(src, crs=spec.effective_crs or self.crs, classes=classes,
                           source_id=source_id)

    def segments(self, name: str) -> Any:
        if name not in self._segments:
            from ..io.vector import read_segments

            spec = self.config.inputs[name]
            seg = read_segments(spec.path)
            if seg.crs is None:
                seg.crs = spec.effective_crs or self.crs
            self._segments[name] = seg
        return self._segments[name]

    def points(self, name: str) -> Any:
        if name not in self._points:
            from ..io.vector import read_points

            spec = self.config.inputs[name]
            pts = read_points(spec.path, require_z=True)
            if pts.crs is None:
                pts.crs = spec.effective_crs or self.crs
            self._points[name] = pts
        return self._points[name]

    def select(self, name: str, classes: Any = None, source_id: Any = None) -> Any:
        """A subset of cloud `name` by classes and flight strips (None = all)."""
        cloud = self.cloud(name)
        if classes is None and source_id is None:
            return cloud
        return cloud.select(classes=classes, source_id=source_id)

    def edges(self, cloud: str, classes: Any, source_id: Any, options: dict[str, Any]) -> Any:
        """Edges extracted from a cloud selection (cached on selection + options).

        One job for a file (one region) and a catalog (chunk by chunk, each edge once):
        the same data-driven defaults (the central sample window), the same edges. A cloud
        that is not LAS/LAZ is the cloud read in memory, as one region.
        """
        key = (cloud, _norm_ids(classes), _norm_ids(source_id), _freeze(options))
        if key not in self._edges:
            src: Any = str(self.config.inputs[cloud].path)
            if not (self.is_catalog(cloud) or src.lower().endswith((".las", ".laz"))):
                from ..tiling.source import Source

                src = Source(catalog=None, cloud=self.cloud(cloud))
            label = selection_label(cloud, classes, source_id)
            how = "catalog" if self.is_catalog(cloud) else "one region"
            with self.step(f"Extracting edges ({label}, {how})"):
                self._edges[key] = _catalog_edges(src, classes, source_id, options)
        return self._edges[key]

    # -- outputs
    def output_path(self, item: AnalysisItem, filename: str) -> Path:
        """Where an analysis writes an output file (inside the run's temporary folder)."""
        rel = Path("outputs") / item.id / filename
        p = self.work_dir / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        self.outputs.setdefault(item.id, []).append(rel.as_posix())
        return p


def _catalog_edges(source: Any, classes: Any, source_id: Any, options: dict[str, Any]) -> Any:
    """The edges of a selection of a source (a path or a Source), each edge once."""
    from ..errors import AnalysisError
    from ..tiling.jobs_api import catalog_features

    run = catalog_features(source, kind="edges", classes=classes, source_id=source_id,
                           options=options)
    if run.failed:
        raise AnalysisError(f"edges of the catalog {source}: chunk(s) {', '.join(run.failed)} "
                            "failed")
    return run.value


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
    """The label of `cloud`'s points of `classes` and `source_id` (:meth:`Selection.label`)."""
    from ..tiling.source import Selection

    return Selection.of(classes, source_id).label(cloud)


def write_vector(
    ctx: RunContext, item: AnalysisItem, obj: Any, base: str, fmt: str, notes: list[str]
) -> None:
    """Write a PointSet or Segments in the requested format.

    CSV when the GIS libraries are missing.
    """
    from ..errors import MissingDependencyError
    from ..io.vector import PointSet, write_points, write_segments

    write = write_points if isinstance(obj, PointSet) else write_segments
    try:
        write(obj, ctx.output_path(item, f"{base}.{fmt}"), overwrite=True)
    except MissingDependencyError:
        ctx.outputs[item.id].pop()
        write(obj, ctx.output_path(item, f"{base}.csv"), overwrite=True)
        notes.append(f"{base}: written as CSV ({fmt} needs the 'vector' extra)")
