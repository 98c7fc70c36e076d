"""Sphinx directives that generate the reference pages and run the tutorials' code.

- ``lidarqa-config-reference``: every key of an assessment config, read from the
  validator's own tables (:mod:`lidarqa.report.config` and the analysis
  registry), so the page cannot drift from what ``lidarqa assess`` accepts.
- ``lidarqa-cli-reference``: every command's usage, help text and options, read
  from the click commands themselves.
- ``lidarqa-run``: run a Python snippet when the docs are built, show it with
  what it printed and embed the matplotlib figures it drew. Snippets of one
  page share a namespace and run in a scratch folder; an exception fails the
  build (the tests build the docs with warnings as errors).
"""

from __future__ import annotations

import base64
import contextlib
import io
import os
import tempfile
import textwrap
import traceback
from typing import Any

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.errors import ExtensionError
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

# ------------------------------------------------------------------ helpers


def _parse_rst(directive: SphinxDirective, lines: list[str]) -> list[nodes.Node]:
    """Parse generated reStructuredText lines into nodes (use these directives in .rst pages)."""
    container = nodes.section()
    container.document = directive.state.document
    content = StringList()
    source = directive.get_source_info()[0]
    for i, line in enumerate(lines):
        content.append(line, source, i)
    nested_parse_with_titles(directive.state, content, container)
    return list(container.children)


def _esc(text: Any) -> str:
    return str(text).replace("*", r"\*").replace("`", r"\`").replace("|", r"\|")


# ---------------------------------------------------------- config reference


def _key_rows(keys: dict[str, Any]) -> list[list[str]]:
    from lidarqa.report._schema import _TYPE_NAMES  # type names of the validator

    rows = []
    for name, key in keys.items():
        kind = _TYPE_NAMES.get(key.type, key.type)
        if key.input:
            kind += " (input name: " + " / ".join(f"[inputs.{k}]" for k in key.input) + ")"
        if key.required:
            default = "required"
        elif key.default is None:
            default = "–"
        else:
            default = f"``{_toml(key.default)}``"
        text = _esc(key.help or "")
        if key.choices:
            text = (text + "; " if text else "") + "one of " + ", ".join(
                f"``{_toml(c)}``" for c in key.choices
            )
        rows.append([f"``{name}``", _esc(kind), default, text or "–"])
    return rows


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return str(value)


def _table(rows: list[list[str]], header: list[str]) -> list[str]:
    out = [".. list-table::", "   :header-rows: 1", "   :widths: auto", ""]
    for row in [header, *rows]:
        out.append("   * - " + (row[0] or "–"))
        for cell in row[1:]:
            out.append("     - " + (cell or "–"))
    out.append("")
    return out


def _library_rows(kind: str, keys: dict[str, Any]) -> list[list[str]]:
    """Library parameters of an analysis, over every variant of its choice/bool keys."""
    from lidarqa.report._registry import library_params
    from lidarqa.report.labels import label_text, lookup

    variants: list[tuple[str, dict]] = [("", {})]
    for name, key in keys.items():
        values = key.choices or ((True, False) if key.type == "bool" else ())
        variants += [(f"{name} = {_toml(v)}", {name: v}) for v in values if v != key.default]
    seen: dict[str, list[str]] = {}
    order: list[str] = []
    for when, options in variants:
        try:
            params = library_params(kind, options)
        except Exception:  # an optional part missing in this installation
            continue
        ann = getattr(params, "annotations", {})
        for name, default in params.items():
            if name in seen:
                continue
            d = "–" if default is None else f"``{_toml(default)}``"
            lab = lookup(name)
            if lab is None:
                meaning = "–"
            elif lab.scale == 100.0:  # the config holds the fraction the report shows in %
                meaning = _esc(f"{lab.text} (fraction, 0.5 = 50 %)")
            else:
                meaning = _esc(label_text(name))
            if when:
                meaning += f" (with ``{when}``)"
            seen[name] = [f"``{name}``", _esc(ann.get(name, type(default).__name__)), d, meaning]
            order.append(name)
    return [seen[n] for n in order]


class ConfigReference(SphinxDirective):
    """Generate the reference of the assessment config from the validator's tables."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from lidarqa.report import _registry, config

        specs = _registry.specs()
        lines: list[str] = []
        lines += ["Top level", "---------", ""]
        lines += _table(
            _key_rows(config.TOP_KEYS), ["key", "type", "default", "meaning"]
        )
        lines += ["Inputs", "------", ""]
        lines += [
            "Each input is ``name = \"path\"`` or ``name = { path = \"...\", crs = \"EPSG:...\" }``"
            " in one of these tables; the name is what the analyses refer to. Paths are"
            " relative to the config file. ``crs`` declares the CRS of a file that has none"
            " (a CSV, a LAS file without a CRS record); a file whose header declares"
            " another CRS is refused. All inputs an assessment uses must share one CRS.",
            "",
        ]
        rows = []
        for kind in config.INPUT_KINDS:
            suffixes = ", ".join(sorted(config._INPUT_SUFFIXES[kind]))
            rows.append([f"``[inputs.{kind}]``", _esc(_INPUT_TEXT.get(kind, "")), suffixes])
        lines += _table(rows, ["table", "holds", "file types"])
        lines += _table(_key_rows(config.INPUT_KEYS), ["key", "type", "default", "meaning"])
        lines += ["Keys of every analysis", "----------------------", ""]
        lines += _table(_key_rows(config.COMMON_KEYS), ["key", "type", "default", "meaning"])
        lines += [
            "An analysis is a table ``[kind]``; several analyses of one kind are an array of"
            " tables ``[[kind]]`` with distinct ``name`` values.",
            "",
        ]
        for kind, spec in specs.items():
            title = f"[{kind}]"
            lines += [title, "-" * len(title), ""]
            if spec.doc:
                lines += [_esc(spec.doc), ""]
            lines += [f"Default section title: *{_esc(spec.default_title({}))}*.", ""]
            lines += _table(_key_rows(spec.keys), ["key", "type", "default", "meaning"])
            for sub_name, sub_keys in _nested_tables(kind):
                lines += [f"Nested table ``{sub_name}``:", ""]
                lines += _table(_key_rows(sub_keys), ["key", "type", "default", "meaning"])
            if spec.targets:
                rows = []
                for key, t in spec.targets.items():
                    unit = "fraction (0.05 = 5 %)" if t.scale == 100.0 else (t.unit or "–")
                    cmp = "at most" if t.direction == "max" else "at least"
                    rows.append([f"``{key}``", _esc(t.label), unit, cmp])
                lines += ["Pass/fail targets (the verdict is *pass* when every target holds):", ""]
                lines += _table(rows, ["key", "metric", "unit", "passes when the value is"])
            rows = _library_rows(kind, spec.keys)
            if rows:
                lines += [
                    "Library parameters (same names and defaults as the Python function and"
                    " the command's options):",
                    "",
                ]
                lines += _table(rows, ["key", "type", "default", "meaning (unit)"])
        return _parse_rst(self, lines)


_INPUT_TEXT = {
    "clouds": "point clouds",
    "segments": "3D line segments (x0, y0, z0, x1, y1, z1 or LineString Z)",
    "points": "points with x, y, z: check points, map points, reference heights",
    "polygons": "map polygons (their boundaries give map points for [heights])",
}


def _nested_tables(kind: str) -> list[tuple[str, dict]]:
    import importlib

    mod = importlib.import_module(f"lidarqa.report.analyses.{kind}")
    names = {
        "SELECTION_KEYS": "test / model = { cloud = ... }",
        "SAMPLE_KEYS": "check = { from_cloud = ... }",
        "GRID_KEYS": "map = { grid = ... }",
        "SPLIT_KEYS": "reference = { from_cloud = true, ... }",
    }
    return [(label, getattr(mod, attr)) for attr, label in names.items() if hasattr(mod, attr)]


# ------------------------------------------------------------- CLI reference


class CliReference(SphinxDirective):
    """Generate the command reference from the click commands."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        import click

        from lidarqa.cli.main import cli

        ctx = click.Context(cli, info_name="lidarqa")
        lines: list[str] = []
        lines += ["lidarqa", "-------", "", ".. code-block:: text", ""]
        lines += ["   " + s for s in cli.get_help(ctx).splitlines()]
        lines += [""]
        for name in cli.list_commands(ctx):
            cmd = cli.get_command(ctx, name)
            if cmd is None:
                continue
            sub = click.Context(cmd, info_name=name, parent=ctx)
            title = f"lidarqa {name}"
            lines += [f".. _cli-{name}:", "", title, "-" * len(title), ""]
            lines += [".. code-block:: text", ""]
            lines += ["   " + s for s in cmd.get_help(sub).splitlines()]
            lines += [""]
        return _parse_rst(self, lines)


# ------------------------------------------------------------ executed code


_SCRATCH: list[str] = []  # scratch folders of this build, removed when it finishes


class RunCode(SphinxDirective):
    """Run the content as Python at build time; show code, output and figures."""

    has_content = True
    option_spec = {"hide-output": directives.flag, "hide-code": directives.flag}

    def run(self) -> list[nodes.Node]:
        env = self.env
        store = env.temp_data.setdefault("lidarqa_run", {})
        state = store.get(env.docname)
        if state is None:
            workdir = tempfile.mkdtemp(prefix="lidarqa-docs-")
            _SCRATCH.append(workdir)
            state = {"ns": {"__name__": "__main__"}, "dir": workdir}
            store[env.docname] = state
        code = "\n".join(self.content)
        out = io.StringIO()
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        plt.close("all")
        cwd = os.getcwd()
        try:
            os.chdir(state["dir"])
            with contextlib.redirect_stdout(out):
                exec(compile(code, f"<{env.docname}>", "exec"), state["ns"])  # noqa: S102
        except Exception as exc:
            raise ExtensionError(
                f"{env.docname}: a lidarqa-run block failed:\n{textwrap.indent(code, '    ')}\n"
                + traceback.format_exc()
            ) from exc
        finally:
            os.chdir(cwd)
        result: list[nodes.Node] = []
        if "hide-code" not in self.options:
            block = nodes.literal_block(code, code)
            block["language"] = "python"
            result.append(block)
        printed = out.getvalue().rstrip()
        if printed and "hide-output" not in self.options:
            block = nodes.literal_block(printed, printed)
            block["language"] = "text"
            block["classes"].append("lidarqa-output")
            result.append(block)
        for num in plt.get_fignums():
            fig = plt.figure(num)
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
            data = base64.b64encode(buf.getvalue()).decode("ascii")
            html = f'<img class="lidarqa-figure" alt="figure" src="data:image/png;base64,{data}"/>'
            result.append(nodes.raw("", html, format="html"))
        plt.close("all")
        return result


def _cleanup(app: Any, exception: Any) -> None:
    """Remove the scratch folders the executed snippets wrote into."""
    import shutil

    while _SCRATCH:
        shutil.rmtree(_SCRATCH.pop(), ignore_errors=True)


def setup(app: Any) -> dict[str, Any]:
    app.connect("build-finished", _cleanup)
    app.add_directive("lidarqa-config-reference", ConfigReference)
    app.add_directive("lidarqa-cli-reference", CliReference)
    app.add_directive("lidarqa-run", RunCode)
    return {"version": "1", "parallel_read_safe": False, "parallel_write_safe": True}
