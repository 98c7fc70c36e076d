"""Rebuild the numba caches shipped in the package (run after changing a numba kernel).

    python scripts/jit_cache.py

Deletes every numba cache file (``*.nbi`` index, ``*.nbc`` code) under src/lidarqa,
runs ``lidarqa demo`` on the package of this checkout (its kernels are compiled with
``cache=True`` and write their caches next to their sources, in ``__pycache__``), then
stages the new files with ``git add -f`` (``__pycache__`` is otherwise git-ignored; the
wheel takes them through the build hook in hatch_build.py).

numba keys a cache by the source file's content, the numba version, the Python version
and the CPU: a user whose four match loads the compiled code on the first run; anyone
else compiles on first use, exactly as without shipped caches.
tests/test_jit_cache.py fails when a shipped index no longer matches its source.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "src" / "lidarqa"


def _cache_files() -> list[Path]:
    return sorted([*PKG.rglob("__pycache__/*.nbi"), *PKG.rglob("__pycache__/*.nbc")])


def main() -> None:
    old = _cache_files()
    for p in old:
        p.unlink()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT / "src"), env.get("PYTHONPATH")) if p)
    env.pop("NUMBA_CACHE_DIR", None)  # the caches must land next to the sources
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [sys.executable, "-m", "lidarqa.cli.main", "-q", "demo", "--out", str(Path(tmp) / "d")],
            env=env, check=True,
        )
    new = _cache_files()
    subprocess.run(["git", "add", "-A", "-f", "--", "src/lidarqa/*.nbi", "src/lidarqa/*.nbc"],
                   cwd=ROOT, check=True)
    size = sum(p.stat().st_size for p in new)
    print(f"{len(old)} old cache files removed; {len(new)} staged ({size / 2**20:.1f} MB)")


if __name__ == "__main__":
    main()
