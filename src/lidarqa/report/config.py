"""Assessment configuration: a TOML file that names inputs, analyses and parameters.

The whole configuration is validated before any work starts: unknown keys
(the message names the key and lists the valid ones), wrong types, missing
input files, references to inputs that are not declared, options the
analysis library does not know, and CRS mismatches between inputs (read from
the file headers only). Every problem is a :class:`~lidarqa.errors.ConfigError`.

Layout::

    title = "Strip repeatability, block 12"     # optional
    crs = "EPSG:2154"                            # optional: every input must match

    [inputs.clouds]                              # point clouds (LAS/LAZ/CSV/PLY)
    tile = "tile.laz"                            # or { path = "...", crs = "EPSG:2154" }
    [inputs.segments]                            # 3D line segments (CSV/GPKG/GeoJSON)
    reference = "ref_edges.gpkg"
    [inputs.points]                              # check points, map points, reference heights
    check = "check.csv"
    [inputs.polygons]                            # map polygons (GPKG/GeoJSON), for heights
    roads = "roads.gpkg"

    [ground]                                     # one analysis (or [[ground]] for several)
    cloud = "tile"
    method = "segment-ptd"
    target_total = 0.05

Analysis kinds: ``info``, ``ground``, ``edges``, ``lines``, ``checkpoints``,
``heights``: one module each under :mod:`lidarqa.report.analyses`, which
registers its keys (see :data:`ANALYSIS_KEYS`). Options other than the
framework keys are passed to the analysis library function under the same
name as its keyword argument (and the CLI option).
"""


from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from . import _registry
from ._registry import ResolveContext
from ._schema import (
    INPUT_KINDS,
    AnalysisItem,
    AnalysisUnavailableError,
    AssessmentConfig,
    ConfigCRSMismatchError,
    InputSpec,
    Key,
    Target,
    check_params,
    check_table,
    describe,
    need_input,
)

__all__ = [
    "ConfigCRSMismatchError",
    "AnalysisUnavailableError",
    "Key",
    "InputSpec",
    "AnalysisItem",
    "Target",
    "AssessmentConfig",
    "INPUT_KINDS",
    "INPUT_KEYS",
    "TOP_KEYS",
    "COMMON_KEYS",
    "load_config",
    "parse_config",
    "check_params",
]

# ANALYSIS_KINDS / ANALYSIS_KEYS / ANALYSIS_TARGETS: the analysis kinds, their keys and
# targets. They come from the registry, which
# loads the analysis modules on first use (so this module imports none).
_LAZY = {
    "ANALYSIS_KINDS": lambda: tuple(_registry.specs()),
    "ANALYSIS_KEYS": lambda: (_registry.specs(), _registry.ANALYSIS_KEYS)[1],
    "ANALYSIS_TARGETS": lambda: (_registry.specs(), _registry.ANALYSIS_TARGETS)[1],
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return _LAZY[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ------------------------------------------------------------------- schema

_INPUT_SUFFIXES = {
    "clouds": {".las", ".laz", ".csv", ".txt", ".xyz", ".pts", ".ply"},
    "segments": {".csv", ".gpkg", ".geojson", ".json"},
    "points": {".csv", ".gpkg", ".geojson", ".json"},
    "polygons": {".gpkg", ".geojson", ".json"},
}
INPUT_KEYS = {
    "path": Key("str", required=True, help="file path, relative to the config file"),
    "crs": Key("crs", help="CRS of a file that declares none"),
}

TOP_KEYS = {
    "title": Key("str", default="LiDAR accuracy assessment"),
    "crs": Key("crs", help="expected CRS of every input"),
    "attribution": Key("str", help="data attribution printed in the report"),
    "inputs": Key("table", required=True, help="[inputs.clouds], [inputs.segments], ..."),
}

COMMON_KEYS = {
    "name": Key("str", help="identifier of this analysis in the report (default: its kind)"),
    "title": Key("str", help="heading of the section"),
    "enabled": Key("bool", default=True),
}


# --------------------------------------------------------------- validation

def load_config(
    path: str | os.PathLike,
    *,
    library_params: Callable[[str, dict], dict[str, Any]] | None = None,
    check_crs: bool = True,
    skip_unavailable: bool = False,
) -> AssessmentConfig:
    """Read and validate an assessment configuration file (TOML).

    Parameters
    ----------
    path : path-like
        The ``.toml`` file. Relative input paths are resolved against its folder.
    library_params : callable, optional
        ``(kind, options) -> {name: default}`` giving the library parameters an
        analysis accepts; by default :func:`lidarqa.report._registry.library_params`.
    check_crs : bool, default True
        Read the inputs' headers and refuse differing CRSs.
    skip_unavailable : bool, default False
        Leave out (and list in ``skipped``) analyses whose library part is not
        installed, instead of refusing the config. ``lidarqa demo`` uses this.

    Raises
    ------
    ConfigError
        Unreadable TOML, unknown key, wrong type, missing input, unknown input
        name, CRS mismatch.
    """
    import tomllib

    p = Path(path)
    try:
        is_file = p.is_file()
        exists = p.exists()
    except (OSError, ValueError) as exc:
        raise ConfigError(f"config {path} cannot be accessed: {exc}") from None
    if not is_file:
        raise ConfigError(
            f"config file {p} does not exist" if not exists else f"config {p} is not a file"
        )
    try:
        with p.open("rb") as fh:
            data = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"config {p} cannot be read: {exc.strerror or exc}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"config {p} is larger than {MAX_CONFIG_BYTES // 1000} kB; not a config")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise ConfigError(f"config {p} is UTF-16 text; save it as UTF-8")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"config {p} is not UTF-8 text (byte {exc.start}: {data[exc.start : exc.start + 1]!r})"
        ) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config {p} is not valid TOML: {exc}") from exc
    except (RecursionError, ValueError, MemoryError) as exc:  # deep nesting, 5,000-digit ints
        raise ConfigError(
            f"config {p} is not a usable TOML file: {' '.join(str(exc).split())[:160]}"
        ) from None
    _check_sane(raw, str(p))
    return parse_config(
        raw,
        base_dir=p.resolve().parent,
        path=p,
        library_params=library_params,
        check_crs=check_crs,
        skip_unavailable=skip_unavailable,
    )


MAX_CONFIG_BYTES = 1_000_000
MAX_CONFIG_DEPTH = 16
MAX_CONFIG_INT = 2**53  # larger integers are not meaningful settings (nor exact as floats)


def _check_sane(raw: Any, where: str) -> None:
    """Refuse absurd structure before validation: deep nesting, huge numbers, NaN."""
    import math

    stack: list[tuple[Any, int, str]] = [(raw, 0, "")]
    while stack:
        value, depth, key = stack.pop()
        if depth > MAX_CONFIG_DEPTH:
            raise ConfigError(
                f"config {where}: {key or 'value'} is nested more than "
                f"{MAX_CONFIG_DEPTH} levels deep"
            )
        if isinstance(value, bool):
            continue
        if isinstance(value, int) and abs(value) > MAX_CONFIG_INT:
            raise ConfigError(f"config {where}: {key or 'value'} is an absurdly large integer")
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"config {where}: {key or 'value'} is {value} (not a finite number)")
        if isinstance(value, Mapping):
            stack.extend((v, depth + 1, f"{key}.{k}" if key else str(k)) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, depth + 1, f"{key}[{i}]") for i, v in enumerate(value))


def parse_config(
    raw: Mapping[str, Any],
    *,
    base_dir: str | os.PathLike | None = None,
    path: Path | None = None,
    library_params: Callable[[str, dict], dict[str, Any]] | None = None,
    check_crs: bool = True,
    skip_unavailable: bool = False,
) -> AssessmentConfig:
    """Validate a configuration already parsed into a dict (see :func:`load_config`)."""
    if not isinstance(raw, Mapping):
        raise ConfigError(f"a config must be a table (dict), got {type(raw).__name__}")
    _check_sane(raw, str(path) if path is not None else "(in memory)")
    specs = _registry.specs()
    if library_params is None:
        library_params = _registry.library_params
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    top_valid = {**TOP_KEYS, **{k: Key("any") for k in specs}}
    top = check_table(raw, top_valid, "the config (top level)")
    crs = _parse_crs(top["crs"], "key 'crs' at the top level") if top["crs"] is not None else None

    inputs = _parse_inputs(top["inputs"], base)

    analyses: list[AnalysisItem] = []
    skipped: list[tuple[str, str, str]] = []
    seen_ids: set[str] = set()
    for kind in specs:
        if kind not in raw:
            continue
        value = raw[kind]
        if isinstance(value, list):
            tables = value
            if not all(isinstance(t, Mapping) for t in tables):
                raise ConfigError(f"[[{kind}]] entries must be tables")
        elif isinstance(value, Mapping):
            tables = [value]
        else:
            raise ConfigError(
                f"key {kind!r} must be a table ([{kind}]) or an array of tables "
                f"([[{kind}]]), got {describe(value)}"
            )
        for i, table in enumerate(tables):
            where = f"[{kind}]" if len(tables) == 1 else f"[[{kind}]] #{i + 1}"
            try:
                item = _parse_analysis(
                    kind, table, where, inputs, base, library_params, i, len(tables)
                )
            except AnalysisUnavailableError as exc:
                if not skip_unavailable:
                    raise
                title = table.get("title") if isinstance(table, Mapping) else None
                skipped.append((kind, str(title or specs[kind].default_title({})), str(exc)))
                continue
            if item is None:
                continue
            if item.id in seen_ids:
                raise ConfigError(
                    f"two analyses are named {item.id!r}; give each a distinct 'name'"
                )
            seen_ids.add(item.id)
            analyses.append(item)
    if not analyses:
        raise ConfigError(
            "the config runs no analysis; add at least one of: "
            + ", ".join(f"[{k}]" for k in specs)
        )
    used = _used_inputs(analyses)
    if check_crs:
        inputs = _check_crs(inputs, crs, used)
    return AssessmentConfig(
        title=top["title"],
        crs=crs,
        attribution=top["attribution"],
        inputs=inputs,
        analyses=analyses,
        raw=_plain(raw),
        path=path,
        base_dir=base,
        skipped=skipped,
    )



def _plain(value: Any) -> Any:
    """TOML values as JSON-compatible plain types (dates become strings)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    return str(value)


def _parse_crs(value: Any, where: str) -> Any:
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        return CRS.from_user_input(value)
    except CRSError as exc:
        raise ConfigError(f"{where}: not a CRS: {value!r}") from exc


_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")


def _parse_inputs(table: Any, base: Path) -> dict[str, InputSpec]:
    groups = check_table(table, {k: Key("table", default={}) for k in INPUT_KINDS}, "[inputs]")
    out: dict[str, InputSpec] = {}
    for kind in INPUT_KINDS:
        for name, value in groups[kind].items():
            where = f"[inputs.{kind}] entry {name!r}"
            if not _NAME_RE.match(name):
                raise ConfigError(
                    f"{where}: input names may only use letters, digits, '_', '-', '.'"
                )
            if name in out:
                raise ConfigError(
                    f"input name {name!r} is used twice ([inputs.{out[name].kind}] and "
                    f"[inputs.{kind}])"
                )
            if isinstance(value, str):
                entry: dict[str, Any] = {"path": value, "crs": None}
            elif isinstance(value, Mapping):
                entry = check_table(value, INPUT_KEYS, where)
            else:
                raise ConfigError(
                    f"key {name!r} in [inputs.{kind}] must be a path string or a table "
                    f"{{ path = ..., crs = ... }}, got {describe(value)}"
                )
            p = Path(os.path.expanduser(entry["path"]))
            if not p.is_absolute():
                p = base / p
            from ..tiling.source import is_catalog_input

            if kind == "clouds" and is_catalog_input(str(p)):  # a folder, glob or .vpc of tiles
                crs = _parse_crs(entry["crs"], where) if entry["crs"] is not None else None
                out[name] = InputSpec(name=name, kind=kind, path=p, crs=crs)
                continue
            if not p.exists():
                raise ConfigError(f"input {name!r} ([inputs.{kind}]): file {p} does not exist")
            if not p.is_file():
                raise ConfigError(f"input {name!r} ([inputs.{kind}]): {p} is not a file")
            suffix = p.suffix.lower()
            if suffix not in _INPUT_SUFFIXES[kind]:
                raise ConfigError(
                    f"input {name!r} ([inputs.{kind}]): cannot read "
                    f"{suffix or 'files without suffix'} "
                    f"as {kind}; expected one of {', '.join(sorted(_INPUT_SUFFIXES[kind]))}"
                )
            crs = _parse_crs(entry["crs"], where) if entry["crs"] is not None else None
            out[name] = InputSpec(name=name, kind=kind, path=p, crs=crs)
    return out



def _parse_analysis(
    kind: str,
    table: Any,
    where: str,
    inputs: Mapping[str, InputSpec],
    base: Path,
    library_params: Callable[[str, dict], dict[str, Any]],
    index: int,
    count: int,
) -> AnalysisItem | None:
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table, got {describe(table)}")
    spec = _registry.specs()[kind]
    keys = {**COMMON_KEYS, **spec.keys}
    targets = spec.targets
    target_keys = {name: Key("float") for name in targets}
    framework = {**keys, **target_keys}
    # Parse framework keys first (method may decide which library params exist).
    fw_only = {k: v for k, v in table.items() if k in framework}
    opts = check_table(fw_only, framework, where)
    if not opts["enabled"]:
        return None
    params_defaults = library_params(kind, opts)
    opts = check_table(table, framework, where, extra=params_defaults)
    for name in target_keys:  # every target is a size, a rate or an error: >= 0
        value = opts.get(name)
        if value is not None and not value >= 0:
            raise ConfigError(f"key {name!r} in {where} must be >= 0, got {value!r}")
    params = check_params(
        {k: v for k, v in table.items() if k not in framework}, params_defaults, where
    )
    validate = getattr(params_defaults, "validate", None)
    if validate is not None:  # cheap value checks by the library itself, before any work
        try:
            validate(params)
        except Exception as exc:  # the library's own OptionError etc.
            reason = " ".join(str(exc).split())
            raise ConfigError(f"{where}: {reason}") from exc

    # Input references (keys with Key.input) and nested tables (the analysis' resolve hook).
    for name, key in spec.keys.items():
        if key.input is not None and isinstance(opts.get(name), str):
            need_input(inputs, opts[name], key.input, where, name)
    if spec.resolve is not None:
        spec.resolve(opts, ResolveContext(dict(inputs), base, where, library_params))
    ident = opts["name"] or (kind if count == 1 else f"{kind}-{index + 1}")
    if not _NAME_RE.match(ident):
        raise ConfigError(f"key 'name' in {where} may only use letters, digits, '_', '-', '.'")
    default_title = spec.default_title(opts)
    if opts["title"]:
        title = opts["title"]
    elif count == 1:
        title = default_title
    elif opts["name"]:
        title = f"{default_title} ({ident})"
    else:
        title = f"{default_title} #{index + 1}"
    tvals = {targets[k].metric: opts.pop(k) for k in list(target_keys) if opts.get(k) is not None}
    for k in target_keys:
        opts.pop(k, None)
    return AnalysisItem(
        kind=kind,
        id=ident,
        title=title,
        options=opts,
        params=params,
        targets=tvals,
        raw=_plain(dict(table)),
    )



def _used_inputs(analyses: list[AnalysisItem]) -> set[str]:
    """Names of the inputs the analyses use (keys with ``Key.input`` and nested tables)."""
    used: set[str] = set()
    specs = _registry.specs()

    def visit(v: Any) -> None:
        if isinstance(v, str):
            used.add(v)
        elif isinstance(v, Mapping):
            for key in ("cloud", "segments", "from_cloud"):
                if isinstance(v.get(key), str):
                    used.add(v[key])

    for a in analyses:
        keys = specs[a.kind].keys if a.kind in specs else {}
        for name, key in keys.items():
            if (key.input is not None or key.type == "ref") and name in a.options:
                visit(a.options[name])
    return used


def read_header_crs(spec: InputSpec) -> Any:
    """The CRS declared by an input file's header (cheap: no points are read)."""
    suffix = spec.path.suffix.lower()
    try:
        from ..tiling.source import is_catalog_input

        if spec.kind == "clouds" and is_catalog_input(str(spec.path)):
            from ..tiling import open_catalog  # refuses mixed CRSs, bad tiles, empty folders

            return open_catalog(str(spec.path)).crs
        if spec.kind == "clouds" and suffix in {".las", ".laz"}:
            from ..io.las import LasReader

            with LasReader(spec.path) as reader:
                return reader.crs
        if suffix in {".gpkg", ".geojson", ".json"}:
            from .._validate import require

            pyogrio = require("pyogrio", "vector")
            info = pyogrio.read_info(str(spec.path))
            wkt = info.get("crs")
            return _parse_crs(wkt, f"input {spec.name!r}") if wkt else None
        from ..io.crs import read_crs_sidecar

        return read_crs_sidecar(spec.path)  # a CSV's .prj sidecar (None without one)
    except ConfigError:
        raise
    except Exception as exc:  # unreadable header: the input is broken, refuse now
        from ..errors import LidarQAError

        reason = " ".join(str(exc).split())
        if isinstance(exc, LidarQAError):
            raise ConfigError(f"input {spec.name!r}: {reason}") from exc
        raise ConfigError(
            f"input {spec.name!r}: cannot read the header of {spec.path}: {reason}"
        ) from exc
    return None


def _check_crs(inputs: dict[str, InputSpec], expected: Any, used: set[str]) -> dict[str, InputSpec]:
    from ..io.crs import crs_name

    def same(a: Any, b: Any) -> bool:
        try:
            return bool(a.equals(b, ignore_axis_order=True))
        except Exception:
            return a == b

    def same_parts(a: Any, b: Any) -> bool:
        # as the commands compare inputs: horizontal and vertical parts apart, so a 2D map
        # matches a cloud whose CRS adds a vertical datum (heights converted to metres)
        from ..errors import CRSMismatchError
        from ..io.crs import ensure_same_crs_parts

        try:
            ensure_same_crs_parts(a, b)
        except CRSMismatchError:
            return False
        return True

    out: dict[str, InputSpec] = {}
    seen: list[tuple[str, Any]] = []
    for name, spec in inputs.items():
        file_crs = read_header_crs(spec)
        if file_crs is not None and spec.crs is not None and not same(file_crs, spec.crs):
            raise ConfigCRSMismatchError(
                f"input {name!r}: its file declares CRS {crs_name(file_crs)}, the config says "
                f"{crs_name(spec.crs)} (key 'crs')"
            )
        spec = InputSpec(spec.name, spec.kind, spec.path, spec.crs, file_crs)
        out[name] = spec
        crs = spec.effective_crs
        if crs is None:
            continue
        if expected is not None and not same_parts(crs, expected):
            raise ConfigCRSMismatchError(
                f"input {name!r} has CRS {crs_name(crs)} but the config's 'crs' is "
                f"{crs_name(expected)}; "
                "reproject it first"
            )
        if name not in used:
            continue
        for other, other_crs in seen:
            if not same_parts(crs, other_crs):
                raise ConfigCRSMismatchError(
                    f"inputs {other!r} ({crs_name(other_crs)}) and {name!r} ({crs_name(crs)}) "
                    "have different CRSs; reproject one of them first"
                )
        seen.append((name, crs))
    return out
