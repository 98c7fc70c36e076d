"""Adding an analysis touches one file: the package finds its modules, `order` places them."""

from __future__ import annotations

import pytest

from lidarqa.report import _registry, labels
from lidarqa.report import analyses as analyses_pkg


def test_every_module_of_the_package_registers_its_kind() -> None:
    kinds = list(_registry.specs())
    assert set(analyses_pkg.BUILTIN) <= set(kinds)
    # the report order is the registered order, not the alphabetical module order
    assert kinds[:6] == ["info", "ground", "edges", "lines", "checkpoints", "heights"]


def test_the_package_holds_the_analyses_only() -> None:
    """Regression (issue #26): it re-exported the old ``analyses.py`` names, a second path to
    the registry and the run context that nothing used."""
    public = {k for k in vars(analyses_pkg) if not k.startswith("__")}
    assert public - {"annotations", "importlib", "pkgutil", "_name"} == \
        {"BUILTIN", *analyses_pkg.BUILTIN}


@pytest.fixture
def probe_kind():
    kind = "zz_probe"
    yield kind
    for table in (
        _registry._SPECS,
        _registry.ANALYSES,
        _registry._PARAMS,
        _registry.ANALYSIS_KEYS,
        _registry.ANALYSIS_TARGETS,
        _registry.DEFAULT_TITLES,
    ):
        table.pop(kind, None)
    labels.LABELS.pop("zz_probe_offset", None)


def test_order_places_a_new_kind_among_the_sections(probe_kind) -> None:
    from lidarqa.report import config

    offset = labels.Label("probe offset", "m")

    @_registry.register(
        probe_kind, title="Probe", order=15, labels={"zz_probe_offset": offset}
    )
    def run_probe(ctx, item):  # pragma: no cover - never run
        """A probe analysis."""

    kinds = list(_registry.specs())
    assert kinds.index("info") < kinds.index(probe_kind) < kinds.index("ground")
    assert probe_kind in config.ANALYSIS_KINDS  # the validator sees it without other edits
    assert _registry.specs()[probe_kind].default_title({}) == "Probe"
    assert labels.label_text("results.zz_probe_offset") == "probe offset (m)"


def test_a_label_cannot_change_meaning() -> None:
    with pytest.raises(ValueError, match="already labelled"):
        labels.add({"cloud": labels.Label("something else")})
    labels.add({"cloud": labels.lookup("cloud")})  # the same label again is fine


def test_every_key_and_parameter_of_every_kind_has_a_label() -> None:
    # the demo report walks one config; this covers every kind and each variant of its
    # choice/bool keys (ground method = "ptd", checkpoints vertical = true, ...)
    missing = []
    for kind, spec in _registry.specs().items():
        variants = [{}]
        for name, key in spec.keys.items():
            values = key.choices or ((True, False) if key.type == "bool" else ())
            variants += [{name: v} for v in values if v != key.default]
        names = set(spec.keys)
        for options in variants:
            try:
                names |= set(_registry.library_params(kind, options))
            except Exception:  # an optional part missing in this installation
                continue
        missing += [f"[{kind}] {n}" for n in sorted(names) if labels.lookup(n) is None]
        missing += [
            f"[{kind}] {t}" for t in spec.targets
            if labels.lookup(f"{kind}.targets.{t[7:]}") is None
        ]
    assert not missing, f"keys without a report label: {missing}"
