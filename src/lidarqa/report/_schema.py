"""The vocabulary of assessment configs, below the analyses and the validator.

Value types and :class:`Key` (one documented key of a config table), the
table and parameter checks, :class:`Target` (a pass/fail target), the
validated config records (:class:`InputSpec`, :class:`AnalysisItem`,
:class:`AssessmentConfig`) and the errors. Analysis modules and
:mod:`lidarqa.report.config` both build on this module; it imports neither.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import AnalysisUnavailableError, ConfigCRSMismatchError, ConfigError

__all__ = [
    "ConfigCRSMismatchError",
    "AnalysisUnavailableError",
    "Key",
    "Target",
    "targets",
    "InputSpec",
    "AnalysisItem",
    "AssessmentConfig",
    "INPUT_KINDS",
    "FORMAT_KEY",
    "check_table",
    "check_params",
    "need_input",
    "describe",
]



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


def describe(value: Any) -> str:
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
    #: for a key naming an input: the input kinds it may name (checked by the validator)
    input: tuple[str, ...] | None = None



def check_table(
    table: Any, keys: Mapping[str, Key], where: str, *, extra: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Validate `table` against `keys` (+ `extra` library params name -> default)."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table, got {describe(table)}")
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
                f"key {name!r} in {where} must be {_TYPE_NAMES[key.type]}, got {describe(value)}"
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
                    f"key {name!r} in {where} must be {expected}, got {describe(value)}"
                )
            if kinds == ["float"]:
                value = float(value)
            kind = None
        if kind is not None and not _type_ok(kind, value):
            raise ConfigError(
                f"key {name!r} in {where} must be {_TYPE_NAMES[kind]}, got {describe(value)}"
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



INPUT_KINDS = ("clouds", "segments", "points", "polygons")

FORMAT_KEY = Key(
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


def targets(*items: Target) -> dict[str, Target]:
    return {f"target_{t.metric}": t for t in items}



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



def need_input(
    inputs: Mapping[str, InputSpec], name: Any, kinds: tuple[str, ...], where: str, key: str
) -> str:
    if not isinstance(name, str):
        raise ConfigError(f"key {key!r} in {where} must name an input, got {describe(name)}")
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


