"""The "first run: compiling kernels" notice asks numba's cache whether code is ready."""

from __future__ import annotations

import importlib.util
import os
import sys

from lidarqa._jitcache import kernels_cached


def _load(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_cached_only_after_compiling_and_until_the_source_changes(tmp_path):
    src = tmp_path / "jitmod_firstrun.py"
    src.write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    mod = _load(src, "jitmod_firstrun")
    assert not kernels_cached(mod.f)
    assert mod.f(1) == 2
    assert kernels_cached(mod.f)
    # an upgrade changes the source stamp: the old index no longer counts
    st = src.stat()
    src.write_text(src.read_text() + "# upgraded\n")
    os.utime(src, (st.st_atime, st.st_mtime + 10))
    mod2 = _load(src, "jitmod_firstrun")
    assert not kernels_cached(mod2.f)
    del sys.modules["jitmod_firstrun"]


def test_objects_without_a_numba_cache_count_as_cached():
    assert kernels_cached(len, object())
