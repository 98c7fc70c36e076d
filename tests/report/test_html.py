"""The HTML page: self-contained, escaped, phone-friendly, summary first, parameters last."""

from __future__ import annotations

import re

import numpy as np
import pytest

from lidarqa.report.html import (
    Figure,
    Report,
    Section,
    SummaryRow,
    Table,
    fmt,
    render_html,
    table_text,
)


def _report(**kw) -> Report:
    from lidarqa.report import plots

    png = plots.plot_histogram(np.arange(10.0), "h", xlabel="x")
    base = dict(
        title="QA <script>alert(1)</script>",
        subtitle="sub",
        summary=[
            SummaryRow("Ground", "ground", "total 3 %", "pass", "total ≤ 5 %"),
            SummaryRow("Lines", "lines", "LHD 0.3 m", "fail", "LHD ≤ 0.2 m"),
        ],
        sections=[
            Section(
                id="ground",
                title="Ground",
                kind="ground",
                headline="h",
                tables=[Table("t", ["a", "b"], [[1, "x & y"], [2.5, None]])],
                figures=[Figure("fig", png, "cap")],
            ),
            Section(id="lines", title="Lines", kind="lines", error="boom <b>"),
        ],
        parameters={"ground": {"options": {"cloud": "tile"}, "parameters": {"radius": 2.0}}},
        provenance=[("lidarqa version", "0.1.0")],
        inputs=[
            {
                "name": "tile",
                "kind": "clouds",
                "path": "/x.laz",
                "size": 10,
                "sha256": "ab",
                "crs": "EPSG:2154",
            }
        ],
        versions={"numpy": "2.0", "dask": None},
        attribution="IGN – LiDAR HD",
    )
    base.update(kw)
    return Report(**base)


def test_page_structure_and_order():
    html = render_html(_report())
    assert html.startswith("<!DOCTYPE html>")
    assert '<meta name="viewport" content="width=device-width, initial-scale=1">' in html
    i_summary = html.index('id="summary"')
    i_ground = html.index('<section id="ground"')
    i_params = html.index('id="parameters"')
    i_prov = html.index('id="provenance"')
    assert i_summary < i_ground < i_params < i_prov
    assert 'class="verdict pass"' in html and 'class="verdict fail"' in html
    assert "This analysis failed: boom &lt;b&gt;" in html
    assert "Data: IGN – LiDAR HD" in html
    assert "not installed" in html  # dask: None


def test_text_is_escaped():
    html = render_html(_report())
    assert "<script>" not in html
    assert "QA &lt;script&gt;" in html
    assert "x &amp; y" in html


def test_self_contained_and_scrollable_tables():
    html = render_html(_report())
    srcs = re.findall(r'src="([^"]*)"', html)
    assert srcs and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert "http://" not in html and "https://" not in html
    assert ".table-wrap" in html and "overflow-x: auto" in html
    # every table sits in a scrolling wrapper
    assert html.count("<table>") == html.count('<div class="table-wrap"><table>')
    assert "max-width: 100%" in html


@pytest.mark.parametrize(
    "value, text",
    [
        (None, "–"),
        (True, "yes"),
        (1234567, "1,234,567"),
        (0.0123456, "0.01235"),
        (12.3456, "12.35"),
        (float("nan"), "–"),
        (np.float64(2.0), "2"),
        ([1, 2], "1, 2"),
        (3e-7, "3.000e-07"),
        (770500.05000000005, "770500.050"),  # coordinates to the millimetre (issue #16)
        (1234.5678, "1234.568"),
    ],
)
def test_fmt(value, text):
    assert fmt(value) == text


def test_id_columns_have_no_thousands_separators():
    t = Table(title="Residuals", columns=["id", "dz (m)", "points"], rows=[[12345, 0.01, 12345]])
    sec = Section(id="s", title="s", kind="checkpoints", tables=[t])
    html_text = render_html(
        Report(title="t", subtitle="s", summary=[], sections=[sec], parameters={}, provenance=[],
               inputs=[], versions={})
    )  # fmt: skip
    assert "<td>12345</td>" in html_text.replace(' class="num"', "")
    assert "12,345" in html_text  # a count keeps its separators
    t2 = Table(title="r", columns=["cloud z (m)", "dz (m)"], rows=[[20.9, 0.031694]], decimals=3)
    sec2 = Section(id="s2", title="s2", kind="checkpoints", tables=[t2])
    html2 = render_html(
        Report(title="t", subtitle="s", summary=[], sections=[sec2], parameters={}, provenance=[],
               inputs=[], versions={})
    )  # fmt: skip
    assert "20.900" in html2 and "0.032" in html2 and "0.03169" not in html2



def test_table_text_prints_the_cells_of_the_html_table():
    """The terminal summary of a command is the report's table: same cells, keys left out."""
    rows = [["RMS (m)", 0.012345, "rms"], ["points", 12345, "n"], ["undefined (m)", np.nan, "u"]]
    t = Table("Figures", ["quantity", "value", "key in report.json"], rows, code_columns=(2,),
              note="a note")
    lines = table_text(t).splitlines()
    assert lines[0] == "Figures" and lines[-1] == "  (a note)"
    assert not any("quantity" in ln or ln.endswith(("rms", " n", " u")) for ln in lines)
    page = render_html(_report(sections=[Section(id="s", title="S", kind="k", headline="h",
                                                 tables=[t])]))
    for line, cell in zip(lines[1:4], ("0.01235", "12,345", "–"), strict=True):
        assert line.endswith(cell) and f">{cell}<" in page  # html.fmt's cell, right-aligned
    # identifiers keep no separators; fixed decimals apply; an empty table prints its header
    strips = table_text(Table("S", ["strip", "dz (m)"], [[12345, 0.5]], decimals=3))
    assert strips.splitlines()[2].split() == ["12345", "0.500"]
    assert table_text(Table("E", ["a", "b"], [])).splitlines() == ["E", "  a  b"]
