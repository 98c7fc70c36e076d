"""Scale of ``lidarqa ground`` on a catalog: wall time, throughput and peak RSS per worker.

A synthetic block of tiles is generated with ``lidarqa.testing.write_block`` (one
seeded scene per tile: terrain, buildings, trees, returns) into a temporary folder,
then ``lidarqa ground BLOCK -o OUT`` runs with 1 worker (serial, in process) and with
2 workers (this process and a Dask LocalCluster of one), and the CSF wheel
(``cloth-simulation-filter``) runs tile by tile as PDAL's ``filters.csf`` runs it by
default (last and single returns, noise left out, cloth resolution 1.0, rigidness 3,
time step 0.65, class threshold 0.5, slope smoothing on, 500 iterations:
``_peers.csf_ground``), reading each tile and writing it classified, as a PDAL pipeline
``readers.las -> filters.csf -> writers.las`` does and as ``ground_speed.py`` times the
peers: both sides of the table pay the same decompression and compression.

Run:  /work/venv/bin/python benchmarks/catalog_scale.py                # 50 tiles x 2 M points
      /work/venv/bin/python benchmarks/catalog_scale.py --small        # 8 tiles x 250 k points
      [--tiles N] [--points P] [--density D] [--workers 1,2] [--no-csf] [--keep DIR]

Peak RSS is sampled (psutil, every 0.2 s) for every process of a run; "worker" is the
largest peak of any single process doing chunk work: the CLI process (which runs chunks
too: of N local workers it is one) and the Dask worker processes. Targets (issue #12):
peak RSS per worker <= 2 GB whatever the block size, 2-worker wall time <= 0.55 x the
1-worker time. Timings on a shared machine are noisy:
the CPU column shows how much CPU the run actually got.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def _env() -> dict[str, str]:
    from _peers import timed_env

    env = timed_env()
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    return env


class _RssSampler:
    """Peak RSS of a process and all its descendants, per process, sampled in a thread."""

    def __init__(self, pid: int, every: float = 0.2) -> None:
        import psutil

        self.root = psutil.Process(pid)
        self.every = every
        self.peaks: dict[int, float] = {}
        self.cpu: dict[int, float] = {}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        import psutil

        while not self._stop.is_set():
            try:
                procs = [self.root, *self.root.children(recursive=True)]
            except psutil.Error:
                break
            for p in procs:
                try:
                    rss = p.memory_info().rss / 2**20
                    t = p.cpu_times()
                    self.cpu[p.pid] = t.user + t.system
                except psutil.Error:
                    continue
                self.peaks[p.pid] = max(self.peaks.get(p.pid, 0.0), rss)
            time.sleep(self.every)

    def stop(self) -> None:
        self._stop.set()
        self._t.join(timeout=5)


def make_block(folder: Path, n_tiles: int, points: int, density: float, seed: int = 0) -> list:
    from lidarqa.testing import write_block

    # a scene has about density x area points on terrain and roofs, plus walls/trees
    side = math.sqrt(points / (density * 1.08))
    nx = math.ceil(math.sqrt(n_tiles))
    ny = math.ceil(n_tiles / nx)
    paths = write_block(
        folder,
        nx=nx,
        ny=ny,
        tile_size=round(side, 1),
        density=density,
        seed=seed,
        returns=True,
    )
    # keep exactly n_tiles (the last row may be partial)
    for p in paths[n_tiles:]:
        Path(p).unlink()
    return paths[:n_tiles]


def run_ground(block: Path, out: Path, workers: int, chunk_size: float | None) -> dict:
    doc = out.with_suffix(".json")
    cmd = [sys.executable, "-m", "lidarqa.cli.main", "ground", str(block), "-o", str(out)]
    cmd += ["--workers", str(workers), "--json", str(doc), "-q", "--overwrite"]
    if chunk_size:
        cmd += ["--chunk-size", str(chunk_size)]
    t0 = time.perf_counter()
    env = _env()
    # 1 worker = 1 core, as each Dask worker: no kernel or LAZ-codec threads beyond it
    for var in (
        "NUMBA_NUM_THREADS",
        "OMP_NUM_THREADS",
        "OPENBLAS_NUM_THREADS",
        "RAYON_NUM_THREADS",
    ):
        env[var] = "1"
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    sampler = _RssSampler(p.pid)
    stdout, stderr = p.communicate()
    wall = time.perf_counter() - t0
    sampler.stop()
    if p.returncode != 0:
        raise SystemExit(f"lidarqa ground failed: {stderr.decode()[-2000:]}")
    res = json.loads(doc.read_text())["results"]
    peaks = dict(sampler.peaks)
    main = peaks.pop(p.pid, 0.0)
    # every process runs chunks: the CLI process (serial, or one of the local workers
    # beside the Dask worker processes) and the worker processes
    worker_peak = max([main, *peaks.values()])
    return {
        "workers": workers,
        "wall_s": wall,
        "cpu_s": sum(sampler.cpu.values()),
        "n_points": res["n_points"],
        "n_chunks": res["n_chunks"],
        "chunk_size": res["chunk_size"],
        "buffer": res["buffer"],
        "peak_worker_mb": worker_peak,
        "peak_client_mb": main,
    }


class _quiet_stdout:
    """Silence the CSF library's progress lines (printed by C++ on file descriptor 1)."""

    def __enter__(self) -> None:
        sys.stdout.flush()
        self._saved = os.dup(1)
        self._null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self._null, 1)

    def __exit__(self, *exc: object) -> None:
        os.dup2(self._saved, 1)
        os.close(self._saved)
        os.close(self._null)


def run_csf(paths: list, out: Path) -> dict:
    """The CSF wheel per tile, at PDAL's defaults (``_peers.csf_ground``): read, filter, write."""
    import resource

    from _peers import csf_ground, relabel

    import lidarqa

    out.mkdir(parents=True, exist_ok=True)
    n = 0
    t0 = time.perf_counter()
    c0 = time.process_time()
    for path in paths:
        cloud = lidarqa.read(path)
        with _quiet_stdout():
            ground = csf_ground(cloud)
        cloud.fields["classification"] = relabel(cloud.fields["classification"], ground)
        lidarqa.write(cloud, out / Path(path).name, overwrite=True)
        n += len(cloud)
    return {
        "wall_s": time.perf_counter() - t0,
        "cpu_s": time.process_time() - c0,
        "n_points": n,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tiles", type=int, default=50)
    ap.add_argument("--points", type=int, default=2_000_000, help="points per tile")
    ap.add_argument("--density", type=float, default=20.0, help="points per m2")
    ap.add_argument(
        "--small", action="store_true", help="8 tiles x 250 k points, one chunk per tile"
    )
    ap.add_argument("--chunk-size", type=float, default=None, help="default: lidarqa's")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--no-csf", action="store_true")
    ap.add_argument("--keep", default=None, help="keep the block and outputs in this folder")
    a = ap.parse_args()
    if a.small:
        a.tiles, a.points = 8, 250_000
        a.chunk_size = a.chunk_size or "tile"
    tmp = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="lidarqa-catalog-scale-"))
    tmp.mkdir(parents=True, exist_ok=True)
    block = tmp / "block"
    try:
        t0 = time.perf_counter()
        if block.is_dir() and any(block.glob("*.laz")):
            paths = sorted(block.glob("*.laz"))
        else:
            paths = make_block(block, a.tiles, a.points, a.density)
        from lidarqa.tiling import open_catalog

        cat = open_catalog(block)
        print(
            f"block: {len(cat.tiles)} tiles, {cat.n_points / 1e6:.1f} M points, "
            f"{cat.density:.1f} pts/m2, tile {cat.tile_size():.0f} m "
            f"(made in {time.perf_counter() - t0:.0f} s) in {block}"
        )
        chunk = cat.tile_size() if a.chunk_size == "tile" else a.chunk_size
        peer = None if a.no_csf else run_csf(paths, tmp / "out-csf")
        from _peers import warm_up

        # untimed: the bytecode of what the CLI and its workers import (see timed_env)
        warm_up([sys.executable, "-c", "import lidarqa.cli.main, lidarqa.ground, "
                 "lidarqa.tiling, distributed"], _env())
        rows = []
        for w in [int(v) for v in a.workers.split(",")]:
            rows.append(run_ground(block, tmp / f"out-{w}", w, chunk))
        print()
        print(
            f"{'run':<22}{'points':>10}{'chunks':>8}{'wall s':>9}{'CPU s':>9}{'M pts/min':>11}"
            f"{'peak/worker MB':>16}{'client MB':>11}"
        )
        if peer is not None:  # the peer first
            mpm = peer["n_points"] / 1e6 / (peer["wall_s"] / 60)
            print(
                f"{'CSF wheel, per tile':<22}{peer['n_points']:>10,}{len(paths):>8}"
                f"{peer['wall_s']:>9.1f}{peer['cpu_s']:>9.1f}{mpm:>11.2f}"
                f"{peer['peak_mb']:>16.0f}{'':>11}"
            )
        for r in rows:
            mpm = r["n_points"] / 1e6 / (r["wall_s"] / 60)
            name = f"lidarqa ground x{r['workers']}"
            print(
                f"{name:<22}{r['n_points']:>10,}{r['n_chunks']:>8}{r['wall_s']:>9.1f}"
                f"{r['cpu_s']:>9.1f}{mpm:>11.2f}{r['peak_worker_mb']:>16.0f}"
                f"{r['peak_client_mb']:>11.0f}"
            )
        if peer is not None:
            print()
            for r in rows:  # points per CPU-second, lidarqa / CSF (issue #28: >= 1/3)
                rel = (r["n_points"] / r["cpu_s"]) / (peer["n_points"] / peer["cpu_s"])
                print(
                    f"points per CPU-second, lidarqa x{r['workers']} / CSF: {rel:.2f} "
                    f"(1/{1 / rel:.1f}; target >= 1/3)"
                )
        by = {r["workers"]: r for r in rows}
        if 1 in by and 2 in by:
            ratio = by[2]["wall_s"] / by[1]["wall_s"]
            print()
            print(f"2-worker / 1-worker wall time: {ratio:.2f} (target <= 0.55)")
            print(
                f"peak RSS per worker: {max(r['peak_worker_mb'] for r in rows):.0f} MB "
                "(target <= 2048 MB)"
            )
            print(
                f"chunks: {rows[0]['chunk_size']:g} m + {rows[0]['buffer']:g} m buffer "
                + ("(defaults from the density)" if chunk is None else "(--chunk-size)")
            )
        print(f"CPU cores: {os.cpu_count()}; the machine is shared, timings are noisy.")
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
