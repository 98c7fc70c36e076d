"""report.json follows the unit policy of lidarqa.units (issue #16)."""

from __future__ import annotations

import json

from lidarqa.units import undefined_units


def test_every_number_in_report_json_has_a_unit(demo_run):
    assert demo_run["result"].exit_code == 0, demo_run["result"].output
    doc = json.loads((demo_run["out"] / "report.json").read_text(encoding="utf-8"))
    assert undefined_units({k: v for k, v in doc.items() if k != "lidarqa_version"}) == []
