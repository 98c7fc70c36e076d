"""Put the shipped numba caches (``src/lidarqa/**/__pycache__/*.nbi|*.nbc``) in the wheel.

hatchling never walks into ``__pycache__`` folders, where numba looks for its caches
next to the sources; ``force_include`` names each cache file instead (never a whole
folder: the builder's ``.pyc`` files stay out). Editable installs read the caches
from the source tree and need nothing. See scripts/jit_cache.py.
"""

from __future__ import annotations

from pathlib import Path

from hatchling.builders.hooks.plugin.interface import BuildHookInterface


class NumbaCacheHook(BuildHookInterface):
    def initialize(self, version: str, build_data: dict) -> None:
        if self.target_name != "wheel" or version == "editable":
            return
        src = Path(self.root) / "src"
        for pattern in ("lidarqa/**/__pycache__/*.nbi", "lidarqa/**/__pycache__/*.nbc"):
            for path in sorted(src.glob(pattern)):
                build_data["force_include"][str(path)] = path.relative_to(src).as_posix()
