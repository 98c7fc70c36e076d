"""No compiled code in the repository or the wheel (issue #29).

numba compiles the kernels on first use into its own cache (``lidarqa warmup`` does
it ahead of time): nothing machine-specific is tracked by git or put in the wheel,
and the wheel is built from the tracked sources alone, so two builds are identical.
"""

from __future__ import annotations

import re
import subprocess
import tomllib

import pytest
from datapaths import REPO

COMPILED = re.compile(r"(^|/)__pycache__/|\.(nbi|nbc|pyc|pyo|so|pyd|dll|dylib)$")


def test_git_tracks_no_compiled_code():
    try:
        out = subprocess.run(
            ["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    tracked = out.splitlines()
    assert tracked, "git lists no file"
    assert [p for p in tracked if COMPILED.search(p)] == []


def test_the_wheel_takes_only_the_package_sources():
    """No build hook, force-include or artifact can add untracked (ignored) files."""
    path = REPO / "pyproject.toml"
    if not path.is_file():
        pytest.skip("not a source checkout")
    build = tomllib.loads(path.read_text(encoding="utf-8"))["tool"]["hatch"]["build"]
    wheel = build["targets"]["wheel"]
    assert wheel == {"packages": ["src/lidarqa"]}, wheel
    assert not (REPO / "hatch_build.py").exists()
    assert "__pycache__/" in (REPO / ".gitignore").read_text(encoding="utf-8").split()
