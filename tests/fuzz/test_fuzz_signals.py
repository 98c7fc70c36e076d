"""SIGTERM / SIGINT at random moments of a command (subprocess): nothing is left at or
beside the output path, and the exit status says what happened."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.fuzz


def _env() -> dict:
    """The environment of a child `lidarqa`: the package under test (installed in CI; never
    the checkout's src/ behind its back, where numba would write its caches)."""
    import lidarqa

    env = dict(os.environ)
    pkg = str(Path(lidarqa.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (pkg, env.get("PYTHONPATH")) if p)
    env.setdefault("NUMBA_NUM_THREADS", "1")
    return env


@pytest.fixture(scope="module")
def jobs(world, tmp_path_factory):
    """Two commands whose runs are mostly writing: a big CSV (polar) and a LAZ (ground)."""
    d = tmp_path_factory.mktemp("sig")
    rng = np.random.default_rng(0)
    n = 150_000
    obs = d / "obs.csv"
    table = np.column_stack(
        [np.arange(n), rng.uniform(1, 100, n), rng.uniform(0, 360, n), rng.uniform(-30, 30, n)]
    )
    with obs.open("w") as fh:
        fh.write("id,distance,azimuth,elevation\n")
        np.savetxt(fh, table, fmt=["%d", "%.4f", "%.4f", "%.4f"], delimiter=",")
    cmds = {
        "polar": lambda out: ["polar", str(obs), "-o", str(out / "pts.gpkg"),
                              "--json", str(out / "p.json")],
        "ground": lambda out: ["ground", str(world["dir"] / "scene.laz"),
                               "-o", str(out / "g.laz"), "--json", str(out / "g.json")],
        "assess": lambda out: ["assess", str(world["dir"] / "config.toml"),
                               "-o", str(out / "report"), "--json", str(out / "a.json")],
    }
    durations = {}
    for name, argv in cmds.items():
        out = d / f"probe-{name}"
        out.mkdir()
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "lidarqa.cli.main", "-q", *argv(out)],
                              env=_env(), capture_output=True, text=True, timeout=120)
        durations[name] = time.perf_counter() - t0
        assert proc.returncode == 0, proc.stderr
    return cmds, durations


@pytest.mark.slow  # ~25 s: 12 jobs killed mid-run
@settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    name=st.sampled_from(["polar", "ground", "assess"]),
    sig=st.sampled_from([signal.SIGTERM, signal.SIGINT]),
    moment=st.floats(min_value=0.2, max_value=1.1),
)
def test_signal_leaves_nothing(jobs, tmp_path_factory, name, sig, moment):
    cmds, durations = jobs
    out = tmp_path_factory.mktemp("run")
    proc = subprocess.Popen(
        [sys.executable, "-m", "lidarqa.cli.main", "-q", *cmds[name](out)],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    time.sleep(durations[name] * moment)
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"{name} did not stop within 10 s of signal {sig}")
    left = sorted(p.name for p in out.iterdir())
    if proc.returncode == 0:  # the signal came after the outputs were complete
        assert len(left) == 2 and all(not n.startswith(".") for n in left), left
        return
    # 128 + signal from lidarqa's handler; -signal or a KeyboardInterrupt (1) when the signal
    # came while Python was still starting, before lidarqa could install its handler
    assert proc.returncode in (128 + sig, -sig, 1), (proc.returncode, err)
    if proc.returncode == 128 + sig:
        assert "no partial output was left behind" in err, err
    assert left == [], (sig, moment, proc.returncode, left, err[-300:])
