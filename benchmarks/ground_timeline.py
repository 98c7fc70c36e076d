"""Per-process CPU timeline of ``lidarqa ground BLOCK -o OUT --workers N``: where time goes.

Run:  /work/venv/bin/python benchmarks/ground_timeline.py BLOCK OUT N [extra lidarqa options]

Samples every process of the run (the CLI process, the Dask workers) every 0.1 s and
prints, per process, its start, end and CPU seconds and one digit per wall-clock second:
the tenths of a core it used in that second (9 = busy, . = idle). One thread per
library per process, as in ``benchmarks/catalog_scale.py``.
"""

from __future__ import annotations

import subprocess
import sys
import time

import psutil


def main() -> None:
    block, out, workers, *extra = sys.argv[1:]
    from _peers import timed_env, warm_up

    env = timed_env()
    warm_up([sys.executable, "-c", "import lidarqa.cli.main, lidarqa.ground, lidarqa.tiling, "
             "distributed"], env)  # untimed: the bytecode in place (see timed_env)
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                "RAYON_NUM_THREADS"):
        env[var] = "1"
    cmd = [sys.executable, "-m", "lidarqa.cli.main", "ground", block, "-o", out,
           "--workers", workers, "--json", out + ".json", "-q", "--overwrite", *extra]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env)
    root = psutil.Process(p.pid)
    samples: dict[int, list[tuple[float, float]]] = {}
    names: dict[int, str] = {}
    while p.poll() is None:
        t = time.perf_counter() - t0
        try:
            procs = [root, *root.children(recursive=True)]
        except psutil.Error:
            break
        for q in procs:
            try:
                c = q.cpu_times()
                samples.setdefault(q.pid, []).append((t, c.user + c.system))
                names.setdefault(q.pid, " ".join(q.cmdline()[1:4])[-40:])
            except psutil.Error:
                pass
        time.sleep(0.1)
    wall = time.perf_counter() - t0
    print(f"workers={workers} wall={wall:.2f}s rc={p.returncode}")
    total = 0.0
    for pid, s in samples.items():
        total += s[-1][1]
        per_s: dict[int, float] = {}
        prev = 0.0
        for t, c in s:
            per_s[int(t)] = per_s.get(int(t), 0.0) + c - prev
            prev = c
        line = "".join(
            str(min(9, round(per_s.get(b, 0.0) * 10))) if per_s.get(b, 0.0) > 0.05 else "."
            for b in range(int(wall) + 1)
        )
        span = f"start {s[0][0]:5.1f} end {s[-1][0]:5.1f} cpu {s[-1][1]:5.1f}"
        print(f"{pid:>7} {span}  {names.get(pid, '?')}")
        print("        " + line)
    print(f"total CPU (sampled) {total:.1f} s")


if __name__ == "__main__":
    main()
