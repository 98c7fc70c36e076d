"""A command's summary is its report section's tables: each figure chosen and formatted once."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from lidarqa.cli.main import cli
from lidarqa.io.vector import PointSet, write_points
from lidarqa.report.analyses.checkpoints import checkpoint_tables
from lidarqa.report.html import table_text


def test_checkpoints_prints_the_report_tables(tmp_path):
    rng = np.random.default_rng(3)
    xyz = rng.uniform(0.0, 100.0, size=(12, 3))
    check = PointSet(ids=np.arange(12), xyz=xyz)
    measured = PointSet(ids=np.arange(12), xyz=xyz + rng.normal(0.0, 0.02, xyz.shape) + 0.05)
    write_points(check, tmp_path / "check.csv")
    write_points(measured, tmp_path / "measured.csv")
    js = tmp_path / "r.json"
    r = CliRunner().invoke(cli, ["checkpoints", str(tmp_path / "measured.csv"),
                                 str(tmp_path / "check.csv"), "--transform", "helmert",
                                 "--control-ids", "0,1,2,3,4", "--json", str(js), "-q"])
    assert r.exit_code == 0, r.output
    results = json.loads(js.read_text())["results"]
    tables = checkpoint_tables(results, vertical=False)
    assert [t.title for t in tables] == ["Residual statistics (m)", "Accuracy figures",
                                         "Transformation: helmert"]
    for t in tables:  # the figures, labels and digits of report.html, from the JSON results
        assert table_text(t) in r.output
    assert "7 check points, 5 control points" in r.output
