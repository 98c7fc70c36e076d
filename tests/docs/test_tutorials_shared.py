"""The tutorials' code, run on another real IGN tile from ../shared (skipped without it).

The docs build runs every tutorial on the bundled tile; this test runs the same code
blocks on a neighbouring tile of the same survey (strips 706 and 707, IGN classes),
so the tutorials are not tuned to one file.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest
from datapaths import SHARED, needs_shared

DOCS = Path(__file__).resolve().parents[2] / "docs"
TILE = SHARED / "ign-lidarhd" / "test_data_77060_627760_LA93_IGN69.laz"
TUTORIALS = ("ground", "geometry", "lines", "checkpoints", "heights")


def _blocks(name: str) -> list[str]:
    text = (DOCS / "tutorials" / f"{name}.md").read_text(encoding="utf-8")
    return re.findall(r"```\{lidarqa-run\}\n(.*?)```", text, re.S)


@pytest.mark.parametrize("name", TUTORIALS)
def test_tutorial_blocks_use_the_tile_variable(name: str) -> None:
    blocks = _blocks(name)
    assert blocks, f"tutorial {name} has no executed code"
    assert "path = demo_tile()" in blocks[0]  # the one line a reader replaces by their file


@needs_shared
@pytest.mark.shared
@pytest.mark.parametrize("name", TUTORIALS)
def test_tutorial_runs_on_another_real_tile(name: str, tmp_path, monkeypatch) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not TILE.is_file():
        pytest.skip(f"{TILE.name} is not in ../shared")
    code = "\n".join(_blocks(name)).replace("path = demo_tile()", f"path = {str(TILE)!r}")
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    ns: dict = {}
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, f"tutorials/{name}.md", "exec"), ns)  # noqa: S102
        assert plt.get_fignums(), f"tutorial {name} drew no figure"
    finally:
        plt.close("all")
    printed = out.getvalue()
    assert printed.strip()
    assert str(TILE) == str(ns["path"])
    if name == "ground":
        assert ns["e"].kappa > 0.8  # segment-PTD agrees with IGN's ground on this tile too
    if name == "lines":
        assert len(ns["test"]) > 0 and len(ns["model"]) > 0
