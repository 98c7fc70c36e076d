"""Adding an analysis touches one file: the package finds its modules, `order` places them."""

from __future__ import annotations

import pytest

from lidarqa.report import _registry
from lidarqa.report import analyses as analyses_pkg


def test_every_module_of_the_package_registers_its_kind() -> None:
    kinds = list(_registry.specs())
    assert set(analyses_pkg.BUILTIN) <= set(kinds)
    # the report order is the registered order, not the alphabetical module order
    assert kinds[:6] == ["info", "ground", "edges", "lines", "checkpoints", "heights"]


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


def test_order_places_a_new_kind_among_the_sections(probe_kind) -> None:
    from lidarqa.report import config

    @_registry.register(probe_kind, title="Probe", order=15)
    def run_probe(ctx, item):  # pragma: no cover - never run
        """A probe analysis."""

    kinds = list(_registry.specs())
    assert kinds.index("info") < kinds.index(probe_kind) < kinds.index("ground")
    assert probe_kind in config.ANALYSIS_KINDS  # the validator sees it without other edits
    assert _registry.specs()[probe_kind].default_title({}) == "Probe"
