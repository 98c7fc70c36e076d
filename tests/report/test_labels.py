"""The report labels every parameter and figure, and report.json matches its documented schema."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest

from lidarqa.report import labels
from lidarqa.report.run import SCHEMA_VERSION

DOC = Path(__file__).resolve().parents[2] / "docs" / "reference" / "report-json.md"


@pytest.fixture(scope="module")
def demo_doc(demo_run) -> dict:
    assert demo_run["result"].exit_code == 0, demo_run["result"].output
    return json.loads((demo_run["out"] / "report.json").read_text(encoding="utf-8"))


def _leaves(value, prefix=""):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, f"{prefix}.{k}" if prefix else k)
    else:
        yield prefix


def test_every_parameter_of_the_demo_has_a_label(demo_doc) -> None:
    missing = []
    for sid, p in demo_doc["parameters"].items():
        tree = {"options": p["options"], "parameters": p["params"], "targets": p["targets"]}
        missing += [f"{sid}: {k}" for k in _leaves(tree)
                    if labels.lookup(f"{p['kind']}.{k}") is None]
    assert not missing, f"parameters without a label: {missing}"


def test_every_accuracy_figure_has_a_label_and_unit(demo_doc) -> None:
    res = demo_doc["results"]
    figures = {
        "nssda": res["checkpoints"]["nssda"],
        "asprs2023": res["checkpoints"]["asprs2023"],
        "comparison": res["heights"]["comparison"],
        "w": res["heights"]["w"],
    }
    missing = [
        k for k in _leaves(figures) if not k.endswith("warnings") and labels.lookup(k) is None
    ]
    assert not missing, missing
    # lengths carry their unit, fractions are shown in percent
    assert labels.label_text("asprs2023.rmse_v").endswith("(m)")
    assert labels.label_text("w.frac_lt1").endswith("(%)")
    assert labels.display_value("w.frac_lt1", 0.7) == pytest.approx(70.0)


def test_report_page_shows_labels_not_raw_keys(demo_run) -> None:
    page = (demo_run["out"] / "report.html").read_text(encoding="utf-8")
    text = re.sub(r"<code>[^<]*</code>", "", page)  # keys are shown beside labels, as code
    text = re.sub(r"<pre>.*?</pre>", "", text, flags=re.S)  # the config file itself
    for raw in ("frac_lt1", "options.check.min_spacing", "formula_z", "accuracy_z"):
        assert raw not in text, f"raw key {raw!r} shown as a label"
    assert "share of |w| &lt; 1 (68 % expected) (%)" in page
    assert "minimum spacing between check points (m)" in page


def test_sample_size_warning_sits_beside_the_verdict(demo_doc, demo_run) -> None:
    assert demo_doc["verdicts"]["checkpoints"]["verdict"] == "pass"
    n = demo_doc["results"]["checkpoints"]["n_check"]
    assert n < 20  # the demo's vertical check has too few points for the NSSDA
    warnings = demo_doc["warnings"]["checkpoints"]
    assert any("NSSDA" in w and str(n) in w for w in warnings)
    page = (demo_run["out"] / "report.html").read_text(encoding="utf-8")
    row = re.search(r'<tr><td class="name"><a href="#checkpoints">.*?</tr>', page, re.S).group(0)
    assert "NSSDA: only" in row  # in the summary row of the verdict, not further down


def test_report_json_is_versioned_and_documented(demo_doc) -> None:
    assert demo_doc["schema_version"] == SCHEMA_VERSION
    assert re.fullmatch(r"\d+\.\d+", SCHEMA_VERSION)
    doc = DOC.read_text(encoding="utf-8")
    assert f"schema version **{SCHEMA_VERSION}**" in doc
    documented = set(re.findall(r"^\| `([a-z_0-9]+)` \|", doc, re.M))
    undocumented = set(demo_doc) - documented
    assert not undocumented, f"report.json keys missing from the schema page: {undocumented}"


def test_target_lines_use_the_headline_digits(demo_doc, demo_run) -> None:
    # the summary's target column showed "total error 0.8382 %" beside a headline of "0.84 %"
    page = (demo_run["out"] / "report.html").read_text(encoding="utf-8")
    checked = 0
    for sid, v in demo_doc["verdicts"].items():
        for rec in v["targets"]:
            row = re.search(rf'<tr><td class="name"><a href="#{sid}">.*?</tr>', page, re.S).group(0)
            pct = sid == "ground" and rec["metric"] in ("total", "type_i", "type_ii")
            shown = f"{rec['value'] * 100:.2f} %" if pct else f"{rec['value']:.3f} m"
            target_cell = html.unescape(re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)[-1])
            assert f"{shown} ≤" in target_cell, f"{sid}: {target_cell!r} should show {shown!r}"
            checked += 1
    assert checked >= 3


def test_each_target_is_labelled_as_its_analysis_defines_it() -> None:
    """Regression: ``targets.max_abs`` was one label for heights (max |Δh|) and swaths
    (max |dz|), so the swaths target read "max |Δh|"."""
    from lidarqa.report import _registry
    from lidarqa.report.html import _parameter_rows

    specs = _registry.specs()
    rows = {kind: _parameter_rows({"kind": kind, "targets": {"max_abs": 0.1}})
            for kind in ("swaths", "heights")}
    assert rows["swaths"] == [["target: max |dz| at most (m)", 0.1, "target_max_abs"]]
    assert rows["heights"] == [["target: max |Δh| at most (m)", 0.1, "target_max_abs"]]
    for kind, spec in specs.items():  # every target's label is its definition's
        for t in spec.targets.values():
            lab = labels.lookup(f"{kind}.targets.{t.metric}")
            assert lab is not None and t.label in lab.text and lab.unit == t.unit, (kind, t)
