"""The README's Python example per method runs as written, on the bundled tile."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_python_examples_per_method_run(tmp_path, monkeypatch) -> None:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    example = next((b for b in blocks if "classify_ground" in b), None)
    assert example is not None, "README lost its Python example per method"
    for name in ("classify_ground", "extract_edges", "match_segments", "vertical_check",
                 "assess_heights"):
        assert name in example
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    ns: dict = {}
    with contextlib.redirect_stdout(out):
        exec(compile("import lidarqa\n" + example, "README.md", "exec"), ns)  # noqa: S102
    printed = out.getvalue().splitlines()
    assert len(printed) == 4
    total_pct, kappa = (float(v) for v in printed[0].split())
    assert total_pct < 5 and kappa > 0.9  # ground filter against IGN's classes
    assert 0.0 < float(printed[1]) < 1.0  # LHD of two strips' roof edges (m)
    assert 0.0 < ns["rep"].to_dict()["rmse_z"] < 0.2  # strip vs strip heights (m)
    assert 0.0 < ns["h"].to_dict()["w"]["std"] < 3.0
