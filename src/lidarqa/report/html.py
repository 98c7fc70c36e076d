"""Self-contained HTML report: inline CSS, plots as base64 PNG, no network, phone-friendly.

The page is built with plain string formatting (no template engine); every
text value goes through :func:`html.escape`. Tables sit in horizontally
scrolling wrappers so they stay readable on a narrow screen, and images scale
to the page width.
"""

from __future__ import annotations

import base64
import html
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from .labels import labelled_rows

__all__ = ["Figure", "Table", "Section", "SummaryRow", "Report", "render_html", "fmt", "table_text"]


@dataclass(frozen=True)
class Figure:
    """A plot: PNG bytes, a title and a caption."""

    title: str
    png: bytes
    caption: str = ""


@dataclass(frozen=True)
class Table:
    """A small table: column headers and rows of values (formatted by :func:`fmt`)."""

    title: str
    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    note: str = ""
    #: Fixed decimals for every decimal number (e.g. 3: metres to the mm), else :func:`fmt`.
    decimals: int | None = None
    code_columns: tuple[int, ...] = ()  # columns shown as code (config / JSON keys)


@dataclass(frozen=True)
class SummaryRow:
    """One row of the verdict table."""

    analysis: str
    anchor: str
    headline: str
    verdict: str  # "pass", "fail", "n/a", "error"
    detail: str = ""
    caveats: tuple[str, ...] = ()  # warnings that qualify the verdict (e.g. sample size)


@dataclass
class Section:
    """One analysis in the report."""

    id: str
    title: str
    kind: str
    headline: str = ""
    paragraphs: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)
    error: str | None = None
    verdict: str = "n/a"
    caveats: list[str] = field(default_factory=list)


@dataclass
class Report:
    """Everything the HTML page shows."""

    title: str
    subtitle: str
    summary: list[SummaryRow]
    sections: list[Section]
    parameters: dict[str, Any]
    provenance: list[tuple[str, str]]
    inputs: list[dict[str, Any]]
    versions: dict[str, Any]
    attribution: str | None = None
    config_text: str | None = None
    section_titles: dict[str, str] = field(default_factory=dict)
    #: Figures shown first, above the summary (e.g. ``lidarqa qc``'s block map).
    lead: list[Figure] = field(default_factory=list)


def _is_float(v: Any) -> bool:
    if isinstance(v, bool) or v is None:
        return False
    kind = getattr(getattr(v, "dtype", None), "kind", "")
    return (isinstance(v, float) or kind == "f") and math.isfinite(float(v))


_ID_HEADER = re.compile(r"(^|\b)(id|ids|epsg|strip|source id|point)(\b|$)", re.IGNORECASE)


def fmt(value: Any, digits: int = 4) -> str:
    """A compact, human-readable rendering of a table value."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        if value == 0:
            return "0"
        a = abs(value)
        if a >= 1e9 or a < 1e-4:
            return f"{value:.3e}"
        if a >= 1000:  # coordinates and long distances: to the millimetre, no separators
            return f"{value:.3f}"
        return f"{value:.{digits}g}"
    try:
        import numpy as np

        if isinstance(value, np.integer):
            return fmt(int(value), digits)
        if isinstance(value, np.floating):
            return fmt(float(value), digits)
        if isinstance(value, np.bool_):
            return fmt(bool(value), digits)
    except ImportError:  # pragma: no cover
        pass
    if isinstance(value, list | tuple):
        return ", ".join(fmt(v, digits) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k}: {fmt(v, digits)}" for k, v in value.items())
    return str(value)


_CSS = """
:root { --fg:#1f2933; --muted:#616e7c; --line:#d9e2ec; --bg:#ffffff; --head:#f0f4f8;
        --pass:#1b7f3b; --fail:#c62828; --na:#7b8794; }
* { box-sizing: border-box; }
html { -webkit-text-size-adjust: 100%; }
body { margin: 0; padding: 0 1rem 3rem; font: 15px/1.5 -apple-system, "Segoe UI", Roboto, Helvetica,
       Arial, sans-serif; color: var(--fg); background: var(--bg); }
main { max-width: 60rem; margin: 0 auto; }
header { padding: 1.2rem 0 0.6rem; border-bottom: 2px solid var(--line); margin-bottom: 1rem; }
h1 { font-size: 1.5rem; margin: 0 0 .3rem; }
h2 { font-size: 1.25rem; margin: 2rem 0 .5rem; padding-top: .5rem;
     border-top: 1px solid var(--line); }
h3 { font-size: 1.05rem; margin: 1.2rem 0 .4rem; }
p, li { overflow-wrap: anywhere; }
.sub, .muted, figcaption, .note { color: var(--muted); font-size: .9rem; }
.attribution { font-size: .9rem; margin-top: .4rem; }
nav ul { padding-left: 1.2rem; margin: .3rem 0; }
.table-wrap { width: 100%; overflow-x: auto; -webkit-overflow-scrolling: touch;
              margin: .4rem 0 .8rem; border: 1px solid var(--line); border-radius: 4px; }
table { border-collapse: collapse; width: 100%; font-size: .9rem;
        font-variant-numeric: tabular-nums; }
th, td { padding: .35rem .6rem; border-bottom: 1px solid var(--line); text-align: left;
         vertical-align: top; white-space: nowrap; }
td.wrap { white-space: normal; min-width: 12rem; }
td.name { white-space: normal; min-width: 7rem; max-width: 16rem; }
th { background: var(--head); font-weight: 600; position: sticky; top: 0; }
tr:last-child td { border-bottom: 0; }
td.num { text-align: right; }
.verdict { font-weight: 700; padding: .1rem .45rem; border-radius: 3px; color: #fff;
           font-size: .8rem;
           text-transform: uppercase; letter-spacing: .03em; }
.verdict.pass { background: var(--pass); } .verdict.fail { background: var(--fail); }
.verdict.na { background: var(--na); } .verdict.error { background: #6d1b1b; }
.headline { font-size: 1rem; margin: .2rem 0 .6rem; }
figure { margin: .8rem 0 1.2rem; }
figure img { display: block; max-width: 100%; height: auto;
             border: 1px solid var(--line); }
.figs { display: grid; gap: .8rem;
        grid-template-columns: repeat(auto-fit, minmax(min(100%, 26rem), 1fr)); }
.error-box { border-left: 4px solid var(--fail); background: #fdecea; padding: .5rem .8rem; }
.notes li { color: #8a5a00; }
code, pre { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace;
            font-size: .85rem; }
pre { background: var(--head); padding: .6rem; overflow-x: auto; white-space: pre; }
footer { margin-top: 2.5rem; color: var(--muted); font-size: .85rem; }
#summary-bar { position: sticky; top: 0; z-index: 10; background: var(--bg);
               border-bottom: 1px solid var(--line); padding: .35rem 0; margin: 0 0 .5rem;
               display: flex; flex-wrap: wrap; gap: .2rem .9rem; white-space: nowrap;
               font-size: .85rem; }
#summary-bar a { color: var(--fg); text-decoration: none; display: inline-flex;
                 align-items: center; gap: .25rem; }
#summary-bar .bar-name { display: inline-block; max-width: 10rem; overflow: hidden;
                         text-overflow: ellipsis; vertical-align: middle; }
#summary-bar .bar-title { font-weight: 600; color: var(--muted); }
section { scroll-margin-top: 6rem; }  /* below a summary bar of up to three lines */
details > summary { cursor: pointer; list-style-position: outside; }
details > summary h2 { display: inline; border: 0; margin: 0; padding: 0; }
details.section { border-top: 1px solid var(--line); margin-top: 1.6rem; padding-top: .6rem; }
details.section > summary { font-size: 1.25rem; }
details.section > summary .verdict { margin-left: .6rem; vertical-align: middle; }
details.params { margin: .3rem 0; }
details.params > summary { font-weight: 600; }
.caveat { color: #8a5a00; font-size: .85rem; margin: .2rem 0; white-space: normal; }
.caveat::before { content: "⚠ "; }
td.verdict-cell { white-space: normal; min-width: 7rem; }
@media (max-width: 40rem) { body { font-size: 14px; padding: 0 .6rem 2rem; }
  h1 { font-size: 1.25rem; }
  th, td { padding: .3rem .45rem; }
  #summary-bar { flex-wrap: nowrap; overflow-x: auto; } }
@media print { .table-wrap { overflow: visible; } #summary-bar { position: static; } }
"""


def _e(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _is_num(v: Any) -> bool:
    try:
        import numpy as np

        if isinstance(v, np.number):
            return True
    except ImportError:  # pragma: no cover
        pass
    return isinstance(v, int | float) and not isinstance(v, bool)


def _columns(t: Table) -> tuple[list[bool], list[bool]]:
    """Which columns are numeric (right-aligned) and which hold identifiers (no separators)."""
    ncol = max((len(r) for r in t.rows), default=0)
    numeric_col = [
        any(_is_num(r[j]) for r in t.rows if j < len(r))
        and all(_is_num(r[j]) or r[j] is None for r in t.rows if j < len(r))
        for j in range(ncol)
    ]
    # identifiers (point ids, strip ids, EPSG codes) are names, not quantities: no separators
    id_col = [bool(_ID_HEADER.search(str(c))) for c in t.columns] + [False] * ncol
    return numeric_col, id_col


def _cell(t: Table, v: Any, is_id: bool) -> str:
    """A table value as text: the one formatting of the HTML report and the terminal."""
    is_int = (isinstance(v, int) and not isinstance(v, bool)) or (
        getattr(getattr(v, "dtype", None), "kind", "") in ("i", "u")
    )
    if is_id and is_int:
        return str(v)
    if t.decimals is not None and _is_float(v):
        return f"{float(v):.{t.decimals}f}"
    return fmt(v)


def _table(t: Table, *, numeric_right: bool = True) -> str:
    out = []
    if t.title:
        out.append(f"<h3>{_e(t.title)}</h3>")
    out.append('<div class="table-wrap"><table>')
    out.append(
        "<thead><tr>"
        + "".join(f'<th scope="col">{_e(c)}</th>' for c in t.columns)
        + "</tr></thead><tbody>"
    )
    numeric_col, id_col = _columns(t)
    for row in t.rows:
        cells = []
        for j, v in enumerate(row):
            num = numeric_right and numeric_col[j]
            text = _cell(t, v, id_col[j])
            cls = ' class="num"' if num else (' class="wrap"' if len(text) > 60 else "")
            shown = f"<code>{_e(text)}</code>" if j in t.code_columns else _e(text)
            cells.append(f"<td{cls}>{shown}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table></div>")
    if t.note:
        out.append(f'<p class="note">{_e(t.note)}</p>')
    return "\n".join(out)


def table_text(t: Table) -> str:
    """A table as plain text for the terminal: the report's rows, labels and formatting.

    The columns of report.json keys (``code_columns``) are left out; a two-column
    label/``value`` table is printed without its header.

    Parameters
    ----------
    t : Table
        The table, as a report section builds it.

    Returns
    -------
    str
        The title, the aligned rows (numbers right-aligned) and the note, one per line.
    """
    numeric_col, id_col = _columns(t)
    keep = [j for j in range(len(t.columns)) if j not in t.code_columns]
    rows = [[_cell(t, r[j], id_col[j]) if j < len(r) else "" for j in keep] for r in t.rows]
    plain = len(keep) == 2 and t.columns[keep[1]] == "value"  # label / value: no header
    head = [] if plain else [[str(t.columns[j]) for j in keep]]
    width = [max((len(r[k]) for r in head + rows), default=0) for k in range(len(keep))]
    out = [t.title] if t.title else []
    num = [k > 0 and keep[k] < len(numeric_col) and numeric_col[keep[k]]
           for k in range(len(keep))]  # numeric columns right-aligned (the labels aside)
    for r in head + rows:
        cells = [c.rjust(width[k]) if num[k] else c.ljust(width[k]) for k, c in enumerate(r)]
        out.append(("  " + "  ".join(cells)).rstrip())
    if t.note:
        out.append(f"  ({t.note})")
    return "\n".join(out)


def _figure(f: Figure) -> str:
    data = base64.b64encode(f.png).decode("ascii")
    cap = _e(f.title) + (f" — {_e(f.caption)}" if f.caption else "")
    return (
        f'<figure><img src="data:image/png;base64,{data}" alt="{_e(f.title)}" loading="eager">'
        f"<figcaption>{cap}</figcaption></figure>"
    )


def _verdict(v: str) -> str:
    cls = {"pass": "pass", "fail": "fail", "error": "error"}.get(v, "na")
    label = {"pass": "pass", "fail": "fail", "error": "error", "skipped": "not run"}.get(
        v, "no target"
    )
    return f'<span class="verdict {cls}">{_e(label)}</span>'


def _parameter_rows(params: dict[str, Any]) -> list[list[Any]]:
    """Label rows of one analysis' parameters; a nested copy equal to the top level is dropped.

    Labels are looked up under the analysis kind first (``swaths.targets.max_abs``).
    """
    params = dict(params)
    kind = params.pop("kind", None)
    rows = labelled_rows(params, prefix=kind or "", none="auto")
    if kind:
        rows = [[label, value, path.split(".", 1)[1]] for label, value, path in rows]
    seen = {r[2].split(".")[-1]: r[1] for r in rows if r[2].count(".") == 1}
    out = []
    for label, value, path in rows:
        parts = path.split(".")
        if len(parts) > 2 and parts[0] == "parameters" and seen.get(parts[-1], object()) == value:
            continue  # e.g. parameters.filter.cell_size repeating parameters.cell_size
        if parts[0] == "targets":  # as written in the config
            key = "target_" + ".".join(parts[1:])
        elif parts[0] in ("options", "parameters"):
            key = ".".join(parts[1:])
        else:
            key = path
        out.append([label, value, key])
    return out


def render_html(report: Report) -> str:
    """The complete, self-contained HTML page of a report."""
    parts: list[str] = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        '<meta name="generator" content="lidarqa">',
        f"<title>{_e(report.title)}</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body><main>",
        "<header>",
        f"<h1>{_e(report.title)}</h1>",
        f'<div class="sub">{_e(report.subtitle)}</div>',
    ]
    if report.attribution:
        parts.append(f'<div class="attribution">Data: {_e(report.attribution)}</div>')
    parts.append("</header>")
    if report.lead:
        parts.append('<div class="figs lead">' + "".join(_figure(f) for f in report.lead)
                     + "</div>")

    # A compact summary that stays at the top of the window while scrolling.
    bar = ['<nav id="summary-bar" aria-label="Summary"><span class="bar-title">Summary</span>']
    for row in report.summary:
        mark = ' <span title="see the warnings beside the verdict">⚠</span>' if row.caveats else ""
        bar.append(
            f'<a href="#{_e(row.anchor)}" title="{_e(row.analysis)}">'
            f'<span class="bar-name">{_e(row.analysis)}</span> {_verdict(row.verdict)}{mark}</a>'
        )
    bar.append("</nav>")
    parts.append("".join(bar))

    # Summary verdict table first.
    parts.append('<section id="summary"><h2 style="border-top:0;margin-top:.5rem">Summary</h2>')
    parts.append(
        '<div class="table-wrap"><table class="summary"><thead><tr><th scope="col">Analysis</th>'
        '<th scope="col">Verdict</th><th scope="col">Result</th><th scope="col">Target</th>'
        "</tr></thead><tbody>"
    )
    for row in report.summary:
        caveats = "".join(f'<div class="caveat">{_e(c)}</div>' for c in row.caveats)
        parts.append(
            f'<tr><td class="name"><a href="#{_e(row.anchor)}">{_e(row.analysis)}</a></td>'
            f'<td class="verdict-cell">{_verdict(row.verdict)}{caveats}</td>'
            f'<td class="wrap">{_e(row.headline)}</td>'
            f'<td class="wrap">{_e(row.detail)}</td></tr>'
        )
    parts.append("</tbody></table></div>")
    parts.append(
        "<nav><ul>"
        + "".join(f'<li><a href="#{_e(s.id)}">{_e(s.title)}</a></li>' for s in report.sections)
        + '<li><a href="#parameters">Parameters</a></li>'
        + '<li><a href="#provenance">Provenance</a></li></ul></nav></section>'
    )

    for s in report.sections:
        parts.append(
            f'<section id="{_e(s.id)}" class="analysis"><details class="section" open>'
            f"<summary><h2>{_e(s.title)}</h2>{_verdict(s.verdict)}</summary>"
        )
        if s.headline:
            parts.append(f'<p class="headline"><strong>{_e(s.headline)}</strong></p>')
        for c in s.caveats:  # beside the verdict they qualify
            parts.append(f'<p class="caveat">{_e(c)}</p>')
        if s.error:
            parts.append(f'<p class="error-box">This analysis failed: {_e(s.error)}</p>')
        for p in s.paragraphs:
            parts.append(f"<p>{_e(p)}</p>")
        if s.notes:
            parts.append(
                '<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in s.notes) + "</ul>"
            )
        for t in s.tables:
            parts.append(_table(t))
        if s.figures:
            parts.append('<div class="figs">' + "".join(_figure(f) for f in s.figures) + "</div>")
        if s.outputs:
            parts.append(
                '<p class="muted">Output files: '
                + ", ".join(f'<a href="{_e(o)}"><code>{_e(o)}</code></a>' for o in s.outputs)
                + "</p>"
            )
        parts.append("</details></section>")

    # Parameters and provenance at the end, folded.
    parts.append(
        '<section id="parameters"><details class="section"><summary><h2>Parameters</h2>'
        "</summary>"
        '<p class="muted">Every option and library parameter each analysis ran with, defaults '
        "included. Lengths in metres, angles in degrees; fractions are shown in percent. The key "
        "is the name in the config file and in report.json.</p>"
    )
    for sid, params in report.parameters.items():
        rows = _parameter_rows(params)
        title = report.section_titles.get(sid, sid) if report.section_titles else sid
        parts.append(f'<details class="params"><summary>{_e(title)}</summary>')
        parts.append(
            _table(
                Table("", ["parameter", "value", "key"], rows, code_columns=(2,)),
                numeric_right=False,
            )
        )
        parts.append("</details>")
    parts.append("</details></section>")
    parts.append(
        '<section id="provenance"><details class="section"><summary><h2>Provenance</h2></summary>'
    )
    parts.append(
        _table(
            Table("", ["item", "value"], [list(r) for r in report.provenance]), numeric_right=False
        )
    )
    if report.inputs:
        parts.append(
            _table(
                Table(
                    "Input files",
                    ["name", "kind", "path", "size (bytes)", "sha256", "CRS"],
                    [
                        [
                            i.get("name"),
                            i.get("kind"),
                            i.get("path"),
                            i.get("size"),
                            i.get("sha256"),
                            i.get("crs"),
                        ]
                        for i in report.inputs
                    ],
                ),
                numeric_right=False,
            )
        )
    if report.config_text:
        parts.append(
            "<details><summary>Configuration file</summary><pre>"
            + _e(report.config_text)
            + "</pre></details>"
        )
    parts.append(
        _table(
            Table(
                "Software versions",
                ["package", "version"],
                [[k, v if v is not None else "not installed"] for k, v in report.versions.items()],
            ),
            numeric_right=False,
        )
    )
    parts.append("</details></section>")
    foot = "Generated by lidarqa. This page is self-contained: it needs no network access."
    if report.attribution:
        foot += f" Data: {report.attribution}."
    parts.append(f"<footer>{_e(foot)}</footer>")
    parts.append("</main></body></html>")
    return "\n".join(parts) + "\n"
