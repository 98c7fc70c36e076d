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
``heights`` (see :data:`ANALYSIS_KEYS`). Options other than the
framework keys are passed to the analysis library function under the same
name as its keyword argument (and the CLI option).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import ConfigError, CRSMismatchError

__all__ = [
    "ConfigCRSMismatchError",
    "AnalysisUnavailableError",
    "Key",
    "InputSpec",
    "AnalysisItem",
    "Target",
    "AssessmentConfig",
    "ANALYSIS_KINDS",
    "load_config",
    "parse_config",
]


class ConfigCRSMismatchError(ConfigError, CRSMismatchError):
    """Inputs of an assessment declare different CRSs."""


class AnalysisUnavailableError(ConfigError):
    """An analysis needs a part of lidarqa (or an extra) that this installation lacks."""


# ------------------------------------------------------------------ value types

_TYPE_NAMES = {
    "str": "a string",
    "int": "an integer",
    "float": "a number",
    "bool": "true or false",
    "int_list": "an integer or a list of integers",
    "str_list": "a string or a list of strings",
    "table": "a table",
    "crs": "a CRS (EPSG integer or string such as 'EPSG:2154')",
    "any": "any value",
    "ref": "an input name or a table",
}


def _type_ok(kind: str, value: Any) -> bool:
    if kind == "any":
        return True
    if kind == "str":
        return isinstance(value, str)
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "float":
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "int_list":
        items = value if isinstance(value, list) else [value]
        return all(isinstance(v, int) and not isinstance(v, bool) for v in items)
    if kind == "str_list":
        items = value if isinstance(value, list) else [value]
        return all(isinstance(v, str) for v in items)
    if kind == "table":
        return isinstance(value, Mapping)
    if kind == "crs":
        return isinstance(value, str | int) and not isinstance(value, bool)
    if kind == "ref":
        return isinstance(value, str | Mapping)
    raise AssertionError(kind)


def _describe(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, int):
        return f"integer {value}"
    if isinstance(value, float):
        return f"number {value}"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, Mapping):
        return "a table"
    return type(value).__name__


@dataclass(frozen=True)
class Key:
    """One framework key of a configuration table."""

    type: str
    required: bool = False
    default: Any = None
    choices: tuple[Any, ...] | None = None
    help: str = ""


def _check_table(
    table: Any, keys: Mapping[str, Key], where: str, *, extra: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Validate `table` against `keys` (+ `extra` library params name -> default)."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table, got {_describe(table)}")
    extra = dict(extra or {})
    valid = list(keys) + [k for k in extra if k not in keys]
    for name in table:
        if name not in keys and name not in extra:
            import difflib

            close = difflib.get_close_matches(str(name), valid, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ConfigError(
                f"unknown key {name!r} in {where}{hint}; valid keys: {', '.join(sorted(valid))}"
            )
    out: dict[str, Any] = {}
    for name, key in keys.items():
        if name not in table:
            if key.required:
                raise ConfigError(
                    f"missing key {name!r} in {where} ({key.help or _TYPE_NAMES[key.type]})"
                )
            out[name] = key.default
            continue
        value = table[name]
        if not _type_ok(key.type, value):
            raise ConfigError(
                f"key {name!r} in {where} must be {_TYPE_NAMES[key.type]}, got {_describe(value)}"
            )
        if key.type == "int_list" and not isinstance(value, list):
            value = [value]
        if key.type == "str_list" and not isinstance(value, list):
            value = [value]
        if key.type == "float":
            value = float(value)
        if key.choices is not None and value not in key.choices:
            listed = ", ".join(repr(c) for c in key.choices)
            raise ConfigError(f"key {name!r} in {where} must be one of {listed}; got {value!r}")
        out[name] = value
    return out


def check_params(
    table: Mapping[str, Any], defaults: Mapping[str, Any], where: str
) -> dict[str, Any]:
    """Type-check library parameters against their defaults (same names as the API)."""
    out: dict[str, Any] = {}
    annotations = getattr(defaults, "annotations", {})
    for name, value in table.items():
        if name not in defaults:
            continue
        default = defaults[name]
        kind = _kind_of_default(default)
        if kind is None and name in annotations:
            kinds = _kinds_of_annotation(annotations[name])
            if kinds and not any(_type_ok(k, value) for k in kinds):
                expected = " or ".join(_TYPE_NAMES[k] for k in kinds)
                raise ConfigError(
                    f"key {name!r} in {where} must be {expected}, got {_describe(value)}"
                )
            if kinds == ["float"]:
                value = float(value)
            kind = None
        if kind is not None and not _type_ok(kind, value):
            raise ConfigError(
                f"key {name!r} in {where} must be {_TYPE_NAMES[kind]}, got {_describe(value)}"
            )
        if kind == "float":
            value = float(value)
        if isinstance(default, tuple) and isinstance(value, list):
            value = tuple(value)
        out[name] = value
    return out


_ANNOTATION_KINDS = {"float": "float", "int": "int", "bool": "bool", "str": "str"}


def _kinds_of_annotation(annotation: str) -> list[str]:
    """Value kinds allowed by a simple annotation such as ``"float | None"`` ([] = do not check)."""
    kinds = []
    for token in str(annotation).replace("Optional[", "").replace("]", "").split("|"):
        token = token.strip()
        if token in ("None", "NoneType"):
            continue
        if token not in _ANNOTATION_KINDS:
            return []
        kinds.append(_ANNOTATION_KINDS[token])
    if "float" in kinds and "int" in kinds:
        kinds.remove("int")
    return kinds


def _kind_of_default(default: Any) -> str | None:
    if default is None:
        return None
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, int):
        return "int"
    if isinstance(default, float):
        return "float"
    if isinstance(default, str):
        return "str"
    if isinstance(default, list | tuple):
        if default and all(isinstance(v, int) and not isinstance(v, bool) for v in default):
            return "int_list"
        if default and all(isinstance(v, str) for v in default):
            return "str_list"
        return None
    return None


# ------------------------------------------------------------------- schema

INPUT_KINDS = ("clouds", "segments", "points", "polygons")
_INPUT_SUFFIXES = {
    "clouds": {".las", ".laz", ".csv", ".txt", ".xyz", ".pts", ".ply"},
    "segments": {".csv", ".gpkg", ".geojson", ".json"},
    "points": {".csv", ".gpkg", ".geojson", ".json"},
    "polygons": {".gpkg", ".geojson", ".json"},
}
_INPUT_KEYS = {
    "path": Key("str", required=True, help="file path, relative to the config file"),
    "crs": Key("crs", help="CRS of a file that declares none"),
}

_TOP_KEYS = {
    "title": Key("str", default="LiDAR accuracy assessment"),
    "crs": Key("crs", help="expected CRS of every input"),
    "attribution": Key("str", help="data attribution printed in the report"),
    "inputs": Key("table", required=True, help="[inputs.clouds], [inputs.segments], ..."),
}

_COMMON = {
    "name": Key("str", help="identifier of this analysis in the report (default: its kind)"),
    "title": Key("str", help="heading of the section"),
    "enabled": Key("bool", default=True),
}

_FORMAT = Key(
    "str", default="gpkg", choices=("gpkg", "csv", "geojson"), help="vector output format"
)


@dataclass(frozen=True)
class Target:
    """A pass/fail target: ``target_<metric> = value`` in the analysis table."""

    metric: str
    path: tuple[str, ...]  # where the value sits in the analysis results
    direction: str  # "max" (value must be <= target) or "min" (>= target)
    label: str
    unit: str = ""
    scale: float = 1.0  # display factor (e.g. 100 for fractions shown in %)


def _targets(*items: Target) -> dict[str, Target]:
    return {f"target_{t.metric}": t for t in items}


ANALYSIS_TARGETS: dict[str, dict[str, Target]] = {
    "info": {},
    "ground": _targets(
        Target("total", ("total",), "max", "total error", "%", 100.0),
        Target("type_i", ("type_i",), "max", "type I error", "%", 100.0),
        Target("type_ii", ("type_ii",), "max", "type II error", "%", 100.0),
        Target("kappa", ("kappa",), "min", "Cohen's κ", ""),
    ),
    "edges": _targets(Target("n_edges", ("n_edges",), "min", "edges found", "")),
    "lines": _targets(
        Target("lhd", ("lhd",), "max", "LHD", "m"),
        Target("olhd_tm", ("olhd_tm",), "max", "OLHD test→model", "m"),
        Target("olhd_mt", ("olhd_mt",), "max", "OLHD model→test", "m"),
    ),
    "checkpoints": _targets(
        Target("rmse_z", ("rmse_z",), "max", "RMSE z", "m"),
        Target("rmse_h", ("rmse_h",), "max", "RMSE horizontal", "m"),
        Target("rmse_3d", ("rmse_3d",), "max", "RMSE 3D", "m"),
        Target("mean_z", ("mean_z",), "max", "|mean z|", "m"),
    ),
    "heights": _targets(
        Target("rms", ("comparison", "rms"), "max", "RMS Δh", "m"),
        Target("max_abs", ("comparison", "max_abs"), "max", "max |Δh|", "m"),
        Target("sigma_mean", ("map_points", "sigma_mean"), "max", "mean predicted σ", "m"),
    ),
}

ANALYSIS_KEYS: dict[str, dict[str, Key]] = {
    "info": {
        "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
    },
    "ground": {
        "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
        "method": Key("str", default="segment-ptd", choices=("segment-ptd", "ptd")),
        "evaluate": Key("bool", default=True, help="score against the input's classes"),
        "ignore_classes": Key("int_list", default=None, help="classes left out of the evaluation"),
        "write_cloud": Key("bool", default=True, help="write the classified cloud"),
        "cloud_format": Key("str", default="laz", choices=("laz", "las")),
    },
    "edges": {
        "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
        "classes": Key("int_list", default=None, help="classes to use (e.g. [6], buildings)"),
        "source_ids": Key(
            "int_list",
            default=None,
            help="flight strips (point_source_id), each processed separately",
        ),
        "format": _FORMAT,
    },
    "lines": {
        "test": Key(
            "ref",
            required=True,
            help="a segments input name or { cloud = ..., classes = [...], source_id = N }",
        ),
        "model": Key(
            "ref",
            required=True,
            help="a segments input name or { cloud = ..., classes = [...], source_id = N }",
        ),
        "ground_truth": Key(
            "str", help="CSV of true pairs (test_id,model_id), relative to the config"
        ),
        "edges": Key("table", default=None, help="edge-extraction options for cloud inputs"),
        "format": _FORMAT,
    },
    "checkpoints": {
        "measured": Key(
            "str",
            required=True,
            help="a points input name, or a cloud input name with vertical = true",
        ),
        "check": Key(
            "ref",
            required=True,
            help="a points input name or { from_cloud = ..., classes = [...], n = 20, seed = 0 }",
        ),
        "vertical": Key(
            "bool", default=False, help="compare check heights with a TIN of the cloud"
        ),
        "source_ids": Key(
            "int_list", default=None, help="cloud strips of the TIN (vertical check)"
        ),
        "format": _FORMAT,
    },
    "heights": {
        "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
        "classes": Key("int_list", default=[2], help="laser-point classes used for the planes"),
        "source_ids": Key("int_list", default=None, help="laser-point strips used for the planes"),
        "map": Key(
            "ref",
            required=True,
            help="a points/polygons input name, or { grid = 5.0 } for a grid of map points",
        ),
        "reference": Key(
            "ref",
            required=True,
            help="a points input name, or { from_cloud = true, fraction = 0.5, seed = 0 }",
        ),
        "map_spacing": Key(
            "float", default=10.0, help="spacing of map points along polygon boundaries (m)"
        ),
        "format": _FORMAT,
    },
}
ANALYSIS_KINDS = tuple(ANALYSIS_KEYS)

_SELECTION_KEYS = {
    "cloud": Key("str", required=True, help="name of a cloud in [inputs.clouds]"),
    "classes": Key("int_list", default=None),
    "source_id": Key("int_list", default=None),
}
_SAMPLE_KEYS = {  # check points sampled from a cloud
    "from_cloud": Key(
        "any", required=True, help="a cloud input name (or true: the analysis' cloud)"
    ),
    "classes": Key("int_list", default=[2]),
    "source_id": Key("int_list", default=None),
    "n": Key("int", default=20, help="number of points"),
    "seed": Key("int", default=0),
    "min_spacing": Key("float", default=2.0, help="minimum horizontal spacing between samples (m)"),
}
_SPLIT_KEYS = {  # reference heights held apart from the laser points
    "from_cloud": Key("bool", required=True, help="true: hold apart part of the analysis' cloud"),
    "fraction": Key("float", default=0.5, help="share of the selected points held apart"),
    "seed": Key("int", default=0),
    "max_points": Key("int", default=5000, help="at most this many reference points (sampled)"),
}
_GRID_KEYS = {
    "grid": Key("float", required=True, help="spacing of the map-point grid (m)"),
    "min_points": Key("int", default=3, help="laser points needed within grid/2 to keep a node"),
}


# ----------------------------------------------------------------- results


@dataclass(frozen=True)
class InputSpec:
    """A named input file."""

    name: str
    kind: str  # one of INPUT_KINDS
    path: Path
    crs: Any = None  # declared in the config (pyproj CRS) or None
    file_crs: Any = None  # read from the header during validation

    @property
    def effective_crs(self) -> Any:
        return self.file_crs if self.file_crs is not None else self.crs


@dataclass(frozen=True)
class AnalysisItem:
    """One analysis to run: its kind, identifier, framework options and library parameters."""

    kind: str
    id: str
    title: str
    options: dict[str, Any]
    params: dict[str, Any]
    targets: dict[str, float]
    raw: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class AssessmentConfig:
    """A validated assessment configuration."""

    title: str
    crs: Any
    attribution: str | None
    inputs: dict[str, InputSpec]
    analyses: list[AnalysisItem]
    raw: dict[str, Any]
    path: Path | None = None
    base_dir: Path = field(default_factory=Path.cwd)
    skipped: list[tuple[str, str, str]] = field(default_factory=list)  # (kind, title, reason)

    def input(self, name: str) -> InputSpec:
        return self.inputs[name]

    def input_paths(self) -> list[Path]:
        return [spec.path for spec in self.inputs.values()]


# --------------------------------------------------------------- validation

_DEFAULT_TITLES = {
    "info": "Input cloud",
    "ground": "Ground filtering",
    "edges": "Edges",
    "lines": "Line matching",
    "checkpoints": "Check points",
    "heights": "Height quality",
}


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
        analysis accepts; by default :func:`lidarqa.report.analyses.library_params`.
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
    if not p.is_file():
        raise ConfigError(
            f"config file {p} does not exist" if not p.exists() else f"config {p} is not a file"
        )
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"config {p} is not valid TOML: {exc}") from exc
    return parse_config(
        raw,
        base_dir=p.resolve().parent,
        path=p,
        library_params=library_params,
        check_crs=check_crs,
        skip_unavailable=skip_unavailable,
    )


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
    if library_params is None:
        from .analyses import library_params as _lp

        library_params = _lp
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    top_valid = {**_TOP_KEYS, **{k: Key("any") for k in ANALYSIS_KINDS}}
    top = _check_table(raw, top_valid, "the config (top level)")
    crs = _parse_crs(top["crs"], "key 'crs' at the top level") if top["crs"] is not None else None

    inputs = _parse_inputs(top["inputs"], base)

    analyses: list[AnalysisItem] = []
    skipped: list[tuple[str, str, str]] = []
    seen_ids: set[str] = set()
    for kind in ANALYSIS_KINDS:
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
                f"([[{kind}]]), got {_describe(value)}"
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
                skipped.append((kind, str(title or _DEFAULT_TITLES[kind]), str(exc)))
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
            + ", ".join(f"[{k}]" for k in ANALYSIS_KINDS)
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
    groups = _check_table(table, {k: Key("table", default={}) for k in INPUT_KINDS}, "[inputs]")
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
                entry = {"path": value, "crs": None}
            elif isinstance(value, Mapping):
                entry = _check_table(value, _INPUT_KEYS, where)
            else:
                raise ConfigError(
                    f"key {name!r} in [inputs.{kind}] must be a path string or a table "
                    f"{{ path = ..., crs = ... }}, got {_describe(value)}"
                )
            p = Path(os.path.expanduser(entry["path"]))
            if not p.is_absolute():
                p = base / p
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


def _need_input(
    inputs: Mapping[str, InputSpec], name: Any, kinds: tuple[str, ...], where: str, key: str
) -> str:
    if not isinstance(name, str):
        raise ConfigError(f"key {key!r} in {where} must name an input, got {_describe(name)}")
    if name not in inputs:
        declared = [n for n, s in inputs.items() if s.kind in kinds]
        listed = ", ".join(declared) if declared else "none declared"
        raise ConfigError(
            f"key {key!r} in {where} names input {name!r}, which is not declared in "
            f"[inputs.{' / '.join(kinds)}] (declared: {listed})"
        )
    if inputs[name].kind not in kinds:
        raise ConfigError(
            f"key {key!r} in {where}: input {name!r} is in [inputs.{inputs[name].kind}], "
            f"expected [inputs.{' or '.join(kinds)}]"
        )
    return name


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
        raise ConfigError(f"{where} must be a table, got {_describe(table)}")
    keys = {**_COMMON, **ANALYSIS_KEYS[kind]}
    targets = ANALYSIS_TARGETS[kind]
    target_keys = {name: Key("float") for name in targets}
    framework = {**keys, **target_keys}
    # Parse framework keys first (method may decide which library params exist).
    fw_only = {k: v for k, v in table.items() if k in framework}
    opts = _check_table(fw_only, framework, where)
    if not opts["enabled"]:
        return None
    params_defaults = library_params(kind, opts)
    opts = _check_table(table, framework, where, extra=params_defaults)
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

    # Input references and nested tables.
    if kind in ("info", "ground", "edges", "heights"):
        _need_input(inputs, opts["cloud"], ("clouds",), where, "cloud")
    if kind == "lines":
        for side in ("test", "model"):
            opts[side] = _parse_segment_source(opts[side], inputs, where, side)
        if "cloud" in opts["test"] or "cloud" in opts["model"] or opts["edges"] is not None:
            edge_defaults = library_params("edges", {})
            sub = f"{where} key 'edges'"
            _check_table(opts["edges"] or {}, {}, sub, extra=edge_defaults)
            opts["edges"] = check_params(opts["edges"] or {}, edge_defaults, sub)
        else:
            opts["edges"] = {}
        if opts["ground_truth"] is not None:
            gt = Path(opts["ground_truth"])
            gt = gt if gt.is_absolute() else base / gt
            if not gt.is_file():
                raise ConfigError(f"key 'ground_truth' in {where}: file {gt} does not exist")
            opts["ground_truth"] = gt
    if kind == "checkpoints":
        if opts["vertical"]:
            _need_input(inputs, opts["measured"], ("clouds",), where, "measured")
        else:
            _need_input(inputs, opts["measured"], ("points",), where, "measured")
        check = opts["check"]
        if isinstance(check, str):
            _need_input(inputs, check, ("points",), where, "check")
        else:
            sub = _check_table(check, _SAMPLE_KEYS, f"{where} key 'check'")
            src = sub["from_cloud"]
            if src is True:
                if not opts["vertical"]:
                    raise ConfigError(
                        f"key 'check' in {where}: from_cloud = true needs vertical = true "
                        "(or name a cloud input)"
                    )
                src = opts["measured"]
            _need_input(inputs, src, ("clouds",), f"{where} key 'check'", "from_cloud")
            sub["from_cloud"] = src
            if sub["n"] < 1:
                raise ConfigError(f"key 'n' in {where} key 'check' must be >= 1, got {sub['n']}")
            opts["check"] = sub
    if kind == "heights":
        m = opts["map"]
        if isinstance(m, str):
            _need_input(inputs, m, ("points", "polygons"), where, "map")
        else:
            sub = _check_table(m, _GRID_KEYS, f"{where} key 'map'")
            if not sub["grid"] > 0:
                raise ConfigError(f"key 'grid' in {where} key 'map' must be > 0, got {sub['grid']}")
            opts["map"] = sub
        r = opts["reference"]
        if isinstance(r, str):
            _need_input(inputs, r, ("points",), where, "reference")
        else:
            sub = _check_table(r, _SPLIT_KEYS, f"{where} key 'reference'")
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
    ident = opts["name"] or (kind if count == 1 else f"{kind}-{index + 1}")
    if not _NAME_RE.match(ident):
        raise ConfigError(f"key 'name' in {where} may only use letters, digits, '_', '-', '.'")
    default_title = _DEFAULT_TITLES[kind]
    if kind == "checkpoints" and opts["vertical"]:
        default_title = "Vertical check"
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


def _parse_segment_source(
    value: Any, inputs: Mapping[str, InputSpec], where: str, side: str
) -> dict:
    sub_where = f"{where} key {side!r}"
    if isinstance(value, str):
        _need_input(inputs, value, ("segments", "clouds"), where, side)
        if inputs[value].kind == "clouds":
            return {"cloud": value, "classes": None, "source_id": None}
        return {"segments": value}
    if "segments" in value:
        sub = _check_table(value, {"segments": Key("str", required=True)}, sub_where)
        _need_input(inputs, sub["segments"], ("segments",), sub_where, "segments")
        return sub
    sub = _check_table(value, _SELECTION_KEYS, sub_where)
    _need_input(inputs, sub["cloud"], ("clouds",), sub_where, "cloud")
    return sub


def _used_inputs(analyses: list[AnalysisItem]) -> set[str]:
    used: set[str] = set()

    def visit(v: Any) -> None:
        if isinstance(v, str):
            used.add(v)
        elif isinstance(v, Mapping):
            for key in ("cloud", "segments", "from_cloud"):
                if isinstance(v.get(key), str):
                    used.add(v[key])

    for a in analyses:
        for key in ("cloud", "test", "model", "measured", "check", "map", "reference"):
            if key in a.options:
                visit(a.options[key])
    return used


def read_header_crs(spec: InputSpec) -> Any:
    """The CRS declared by an input file's header (cheap: no points are read)."""
    suffix = spec.path.suffix.lower()
    try:
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

    out: dict[str, InputSpec] = {}
    first: tuple[str, Any] | None = None
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
        if expected is not None and not same(crs, expected):
            raise ConfigCRSMismatchError(
                f"input {name!r} has CRS {crs_name(crs)} but the config's 'crs' is "
                f"{crs_name(expected)}; "
                "reproject it first"
            )
        if name not in used:
            continue
        if first is None:
            first = (name, crs)
        elif not same(crs, first[1]):
            raise ConfigCRSMismatchError(
                f"inputs {first[0]!r} ({crs_name(first[1])}) and {name!r} ({crs_name(crs)}) have "
                "different CRSs; reproject one of them first"
            )
    return out
