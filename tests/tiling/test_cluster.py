"""A real Dask cluster (``dask scheduler`` + two ``dask worker`` processes on 127.0.0.1).

Same outputs as the serial and LocalCluster runs; a worker killed mid-run does not lose
the job (the scheduler moves its chunks to the other worker, or ``--resume`` finishes
the missing chunks). Every process started here is shut down, in bounded time.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

import lidarqa
from lidarqa.tiling.ground import WORK_DIR, ground_catalog

pytest.importorskip("distributed")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env() -> dict[str, str]:
    env = dict(os.environ)
    src = str(Path(lidarqa.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    env.setdefault("NUMBA_NUM_THREADS", "1")
    return env


def _dask_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "dask", *args]  # `dask scheduler` / `dask worker`


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + 6
    for p in procs:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=max(deadline - time.monotonic(), 0.1))
        if p.poll() is None:
            p.kill()
            p.wait(timeout=5)


@pytest.fixture
def cluster(tmp_path):
    """(address, [scheduler, worker1, worker2]) of a fresh local cluster."""
    from distributed import Client

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = _env()
    log = (tmp_path / "dask.log").open("wb")
    procs = [
        subprocess.Popen(
            _dask_cmd("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"),
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    ]
    try:
        for k in range(2):
            procs.append(
                subprocess.Popen(
                    _dask_cmd(
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--no-nanny",
                        "--no-dashboard",
                        "--memory-limit",
                        "1GB",
                        "--name",
                        f"w{k}",
                        "--death-timeout",
                        "60",
                    ),
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            )
        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(address, timeout="5s") as c:
                    c.wait_for_workers(2, timeout=60)
                break
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        yield address, procs
    finally:
        _stop(procs[::-1])
        log.close()


def _digests(paths) -> list[str]:
    return [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths]


@pytest.mark.slow  # ~30 s: a scheduler, two workers, one killed
def test_cluster_outputs_equal_local_runs_and_survive_a_killed_worker(
    scene_tiles, small_runs, cluster, tmp_path
):
    _, paths = scene_tiles
    address, procs = cluster
    serial, local = small_runs["serial"], small_runs["two"]  # LocalCluster: 2 workers
    remote = ground_catalog(paths, tmp_path / "remote", scheduler=address, **small_runs["opts"])
    assert _digests(remote.outputs) == _digests(local.outputs) == _digests(serial.outputs)

    # the command line against the cluster, one worker killed as soon as a chunk is done
    out = tmp_path / "killed"
    doc = tmp_path / "killed.json"
    cmd = [sys.executable, "-m", "lidarqa.cli.main", "ground", str(paths[0].parent)]
    cmd += ["-o", str(out), "--scheduler", address, "--json", str(doc), "-q"]
    cmd += ["--chunk-size", "60", "--buffer", "10", "--cell-size", "20"]
    run = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not list((out / WORK_DIR).glob("*.npz")) and run.poll() is None:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        killed_mid_run = run.poll() is None
        procs[1].kill()  # one worker dies (no nanny to restart it)
        procs[1].wait(timeout=10)
        stdout, stderr = run.communicate(timeout=180)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(timeout=10)
    if run.returncode != 0:
        # the job lost chunks with the worker: --resume completes only the missing ones
        done = len(list((out / WORK_DIR).glob("*.npz")))
        rerun = subprocess.run(
            [*cmd, "--resume", "--overwrite"], env=_env(), capture_output=True, timeout=180
        )
        assert rerun.returncode == 0, rerun.stderr.decode()
        res = json.loads(doc.read_text())["results"]
        assert res["n_chunks_resumed"] == done and res["n_chunks_run"] == res["n_chunks"] - done
    else:
        assert killed_mid_run or stdout
    assert _digests(sorted(out.glob("*.laz"))) == _digests(sorted(serial.outputs))
