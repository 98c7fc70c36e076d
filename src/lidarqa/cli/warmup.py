"""``lidarqa warmup``: compile the numeric kernels ahead of the first real run."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import click

from ._common import Steps, common_options, echo, finish, prepare_outputs, settings


@click.command()
@common_options
def warmup() -> None:
    """Compile the numeric kernels now and store them in numba's cache.

    Runs the bundled demo (as `lidarqa demo` does, into a temporary folder that
    is removed afterwards), so every kernel the demo uses is compiled once and
    cached for later runs of any command. The first run after installing or
    upgrading lidarqa spends 30-60 s compiling; `lidarqa warmup` lets a container
    build or an install script pay that cost ahead of time. It prints where the
    cache went: beside the installed package, in a user cache folder
    (~/.cache/numba) when the package folder is read-only, or in NUMBA_CACHE_DIR
    when that is set. Already warm, it only loads the cached code.
    """
    from .._jitcache import kernel_stats
    from ..errors import AnalysisError, LidarQAError
    from ..report.config import load_config
    from ..report.run import demo_config_path, run_assessment
    from .assess import _demo_kernels_cached

    s = settings()
    prepare_outputs()  # the --json path, before any work
    cold = not _demo_kernels_cached()
    if cold and not s.quiet:
        click.echo("Compiling the numeric kernels (about 30-60 s, once)", err=True)
    steps = Steps()
    before = kernel_stats()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lidarqa-warmup-") as tmp:
        with steps("Checking the demo configuration"):
            cfg = load_config(demo_config_path(), skip_unavailable=True)
        run = run_assessment(cfg, Path(tmp) / "demo", steps=steps, command="demo")
        with steps("Running qc's tile pass on a small synthetic tile"):
            _warm_qc(Path(tmp) / "qc")
    seconds = time.perf_counter() - t0
    stats = kernel_stats().since(before)
    if run.errors:
        raise AnalysisError(
            "the demo did not run completely, some kernels are not compiled: "
            + "; ".join(f"{k}: {v}" for k, v in run.errors.items())
        )
    compiled, loaded = sum(stats.compiled.values()), sum(stats.loaded.values())
    dirs = stats.cache_dirs
    if not dirs:  # cannot happen unless numba changed its layout
        raise LidarQAError("numba reported no cache folder for lidarqa's kernels")
    where = os.path.commonpath(dirs)
    echo(
        f"{compiled} kernel signature(s) compiled, {loaded} loaded from the cache ({seconds:.1f} s)"
    )
    echo(f"Cache: {where}" + (f" ({len(dirs)} folders)" if len(dirs) > 1 else ""))
    finish(
        "warmup",
        inputs={},
        parameters={},
        results={
            "kernels_compiled": compiled,
            "kernels_loaded": loaded,
            "cache_dir": where,
            "cache_dirs": list(dirs),
            "elapsed_s": round(seconds, 3),
        },
    )


def _warm_qc(folder: Path) -> None:
    """Compile qc's per-tile kernels on one small synthetic delivery tile."""
    from ..qc import run_qc
    from ..testing import make_delivery

    d = make_delivery(folder, nx=1, ny=1, tile_size=40.0)
    run_qc(d.paths[0], "usgs-ql2", html=False)  # no `out`: nothing written
