"""The registry of analysis kinds: what each ``[kind]`` table of a config may hold and runs.

An analysis module registers itself in one call::

    @register(
        "swaths",
        params,                      # options -> {library keyword: default}
        keys={"cloud": CLOUD_KEY, ...},   # its framework keys (documented, type-checked)
        targets=targets(Target("rmsdz", ("max_rmsdz",), "max", "worst pair RMSDz", "m")),
        title="Flight strips",
        resolve=None,                # optional: check nested tables / cross references
        order=70,                    # place among the report's sections (built-ins 10..60)
        labels={"max_rmsdz": Label("worst pair RMSDz", "m")},  # report labels of new keys
    )
    def run_swaths(ctx, item) -> SectionResult: ...

in a module of :mod:`lidarqa.report.analyses`, which imports every module of
its package. The config validator (:mod:`lidarqa.report.config`), the run
(:mod:`lidarqa.report.run`) and the generated config reference read everything
else from here, so adding an analysis touches one file.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ._schema import Key, Target
from .labels import Label

__all__ = [
    "AnalysisSpec",
    "ResolveContext",
    "register",
    "specs",
    "library_params",
    "ANALYSES",
    "ANALYSIS_KEYS",
    "ANALYSIS_TARGETS",
    "DEFAULT_TITLES",
    "CLOUD_KEY",
]

#: the ``cloud`` key most analyses share: the name of a point cloud input
CLOUD_KEY = Key("str", required=True, help="name of a cloud in [inputs.clouds]", input=("clouds",))


@dataclass(frozen=True)
class ResolveContext:
    """What a ``resolve`` hook may use to check its nested tables and references."""

    inputs: dict[str, Any]  # name -> InputSpec
    base: Any  # folder of the config file (Path)
    where: str  # "[kind]" or "[[kind]] #2", for messages
    library_params: Callable[[str, dict], dict[str, Any]]


@dataclass(frozen=True)
class AnalysisSpec:
    """One analysis kind: its section function, config keys, targets and default title."""

    kind: str
    run: Callable[..., Any]
    params: Callable[[dict], dict[str, Any]]
    keys: dict[str, Key] = field(default_factory=dict)
    targets: dict[str, Target] = field(default_factory=dict)
    title: str | Callable[[dict], str] = ""
    resolve: Callable[[dict, ResolveContext], None] | None = None
    doc: str = ""
    order: int = 100

    def default_title(self, options: dict) -> str:
        t = self.title(options) if callable(self.title) else self.title
        return t or self.kind.capitalize()


_SPECS: dict[str, AnalysisSpec] = {}
#: kind -> section function ``run(ctx, item) -> SectionResult`` (tests may patch entries)
ANALYSES: dict[str, Callable[..., Any]] = {}
_PARAMS: dict[str, Callable[[dict], dict[str, Any]]] = {}
#: kind -> framework keys / targets (``target_<metric>``) / default section title
ANALYSIS_KEYS: dict[str, dict[str, Key]] = {}
ANALYSIS_TARGETS: dict[str, dict[str, Target]] = {}
DEFAULT_TITLES: dict[str, str] = {}

_BUILTIN = "lidarqa.report.analyses"


def register(
    kind: str,
    params: Callable[[dict], dict[str, Any]] | None = None,
    *,
    keys: dict[str, Key] | None = None,
    targets: dict[str, Target] | None = None,
    title: str | Callable[[dict], str] = "",
    resolve: Callable[[dict, ResolveContext], None] | None = None,
    order: int = 100,
    labels: dict[str, Any] | None = None,
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register the section function of an analysis kind with its config schema.

    Parameters
    ----------
    kind : str
        The config table name (``[kind]`` or ``[[kind]]``).
    params : callable, optional
        ``options -> {name: default}``: the library keyword arguments the
        table accepts besides its framework `keys` (see ``keyword_defaults``).
    keys : dict of str to Key, optional
        Framework keys (``name``, ``title`` and ``enabled`` are added for all).
        A key with ``input=(...)`` names an input; the validator checks it.
    targets : dict, optional
        ``target_<metric>`` keys (see :func:`lidarqa.report._schema.targets`).
    title : str or callable, optional
        Default section title (a callable gets the parsed options).
    resolve : callable, optional
        ``resolve(options, ctx)``: check nested tables and cross references,
        normalising ``options`` in place; raise ``ConfigError``.
    order : int, optional
        Place of the kind among the report's sections and in the config
        reference (ascending; the built-in kinds use 10 to 60, ties by name).
    labels : dict of str to lidarqa.report.labels.Label, optional
        Report labels (with units) of the kind's own parameters and figures
        that :data:`lidarqa.report.labels.LABELS` does not have yet.
    """
    from . import labels as _labels

    # the targets' labels from their own definitions, per kind: swaths' max |dz| is not
    # heights' max |Δh| (a target row is looked up as ``<kind>.targets.<metric>``)
    _labels.add({f"{kind}.targets.{t.metric}": target_label(t) for t in (targets or {}).values()})
    if labels:
        _labels.add(labels)

    def deco(func: Callable[..., Any]) -> Callable[..., Any]:
        spec = AnalysisSpec(
            kind=kind,
            run=func,
            params=params or (lambda options: {}),
            keys=dict(keys or {}),
            targets=dict(targets or {}),
            title=title,
            resolve=resolve,
            doc=(func.__doc__ or "").strip().split("\n")[0],
            order=order,
        )
        _SPECS[kind] = spec
        # keep the registry in report order, whatever order the modules were imported in
        ordered = sorted(_SPECS.values(), key=lambda sp: (sp.order, sp.kind))
        _SPECS.clear()
        _SPECS.update((sp.kind, sp) for sp in ordered)
        ANALYSES[kind] = func
        _PARAMS[kind] = spec.params
        ANALYSIS_KEYS[kind] = spec.keys
        ANALYSIS_TARGETS[kind] = spec.targets
        DEFAULT_TITLES[kind] = title if isinstance(title, str) and title else kind.capitalize()
        return func

    return deco


def target_label(target: Target) -> Label:
    """The report label of a target: ``"target: RMSE z at most"``, with its unit and scale."""
    bound = "at most" if target.direction == "max" else "at least"
    return Label(f"target: {target.label} {bound}", target.unit, target.scale)


def _load_builtin() -> None:
    importlib.import_module(_BUILTIN)


def specs() -> dict[str, AnalysisSpec]:
    """Every registered analysis kind, in report order (loads the built-in ones)."""
    _load_builtin()
    return _SPECS


def library_params(kind: str, options: dict) -> dict[str, Any]:
    """Library keyword arguments (name -> default) an analysis accepts in the config."""
    _load_builtin()
    return _PARAMS[kind](options)
