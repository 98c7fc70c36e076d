"""The numba caches shipped in the package match the sources they were compiled from.

A cache whose source changed is ignored by numba (it compiles again), so a stale one
only costs the first run its speed; this test says which to rebuild with
``python scripts/jit_cache.py``.
"""

from __future__ import annotations

import hashlib
import pickle
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "src" / "lidarqa"


def _shipped_indexes() -> list[Path]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "--", "*.nbi"], cwd=PKG, capture_output=True, text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [PKG / p for p in out.split()]


def test_shipped_caches_are_fresh():
    import numba

    indexes = _shipped_indexes()
    if not indexes:
        pytest.skip("no numba caches are shipped in this checkout")
    stale, other_numba = [], set()
    for idx in indexes:
        with open(idx, "rb") as f:
            version = pickle.load(f)
            stamp, overloads = pickle.loads(f.read())
        if version != numba.__version__:
            other_numba.add(version)
            continue
        module = idx.name.split(".", 1)[0]
        source = idx.parent.parent / f"{module}.py"
        assert source.is_file(), f"{idx} has no source {source}"
        assert overloads, f"{idx} holds no compiled code"
        if stamp != hashlib.sha256(source.read_bytes()).digest():
            stale.append(str(idx.relative_to(ROOT)))
        for data_name in overloads.values():
            assert (idx.parent / data_name).is_file(), f"{idx} names a missing {data_name}"
    assert not stale, f"rebuild with `python scripts/jit_cache.py`: {stale}"
    if other_numba:
        pytest.skip(f"caches built with numba {sorted(other_numba)}, this is {numba.__version__}")


def test_the_demo_kernels_are_shipped():
    names = {p.name.split("-", 1)[0] for p in _shipped_indexes()}
    if not names:
        pytest.skip("no numba caches are shipped in this checkout")
    for kernel in ("_tin._judge_kernel", "_kernels.knn_grid", "_kernels.surface_growing_kernel"):
        assert kernel in names, kernel
