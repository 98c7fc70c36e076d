"""``lidarqa warmup`` compiles (or loads) the demo's kernels and says where numba cached them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from lidarqa._jitcache import KernelStats, kernel_stats, kernels_cached
from lidarqa.cli.main import cli
from lidarqa.units import undefined_units


@pytest.mark.slow  # ~5 s: compiles the demo's kernels
def test_warmup_caches_the_demo_kernels_and_names_the_folder(tmp_path):
    from lidarqa.geometry import _kernels
    from lidarqa.ground import _tin
    from lidarqa.qc import _kernels as qc_kernels

    js = tmp_path / "warmup.json"
    r = CliRunner().invoke(cli, ["-q", "warmup", "--json", str(js)])
    assert r.exit_code == 0, r.output
    doc = json.loads(js.read_text())
    assert undefined_units({k: v for k, v in doc.items() if k != "lidarqa_version"}) == []
    res = doc["results"]
    assert res["kernels_compiled"] >= 0 and res["kernels_loaded"] >= 0
    dirs = [Path(d) for d in res["cache_dirs"]]
    assert dirs and all(d.is_dir() for d in dirs)
    assert all(Path(res["cache_dir"]) in (d, *d.parents) for d in dirs)
    # the ground filter's TIN kernel (the demo's slowest compile) has its index there
    assert any(d.glob("_tin._judge_kernel-*.nbi") for d in dirs), dirs
    assert kernels_cached(_tin._judge_kernel, _kernels.knn_grid, _kernels.surface_growing_kernel)
    # and qc's tile pass (lidarqa qc is the other long job)
    assert kernels_cached(qc_kernels.scan_piece, qc_kernels.open_square)
    assert f"Cache: {res['cache_dir']}" in r.output


def test_kernel_stats_count_compiles_and_cache_loads(tmp_path, monkeypatch):
    """The counts warmup prints: a compile the first time, a cache load in a new process."""
    import importlib.util
    import sys

    src = tmp_path / "lidarqa_jitstats_probe.py"
    src.write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, src)
        mod = importlib.util.module_from_spec(spec)
        monkeypatch.setitem(sys.modules, name, mod)
        spec.loader.exec_module(mod)
        return mod

    # kernel_stats walks lidarqa's modules: a probe module under that name is counted
    mod = load("lidarqa._jitstats_probe")
    before = kernel_stats()
    assert mod.f(1) == 2
    first = kernel_stats().since(before)
    assert first.compiled == {"lidarqa._jitstats_probe.f": 1} and first.loaded == {}
    mod2 = load("lidarqa._jitstats_probe")  # a new process would do the same: load, not compile
    before = kernel_stats()
    assert mod2.f(2) == 3
    second = kernel_stats().since(before)
    assert second.compiled == {} and second.loaded == {"lidarqa._jitstats_probe.f": 1}
    assert isinstance(second, KernelStats)
