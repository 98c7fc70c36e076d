"""Speed and memory of line-segment matching (issue 5): p × q segments matched both ways.

Run: /work/venv/bin/python benchmarks/lines_speed.py [--sizes 1000,10000,30000] [--repeat 3]

Each scenario runs in a fresh process and prints one row: the synthetic scene
(grid spacing of the segments in m, and the offset between the sets in m), p and
q, the candidate pairs evaluated, the pairs matched test→model, the wall time of
``match_segments`` (best of `repeat`, after a warm-up that loads the numba
kernels), the peak NumPy memory of the call (tracemalloc) and the process's peak
RSS (including Python, NumPy, SciPy and numba themselves, about 150 MB).
Rows up to --dense-check also compare with the dense p × q computation.
Goal: 10,000 × 10,000 in ≤ 2 s and ≤ 1 GB (beyond: ≤ 0.5 s).
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
import tracemalloc

import numpy as np


def sets(n: int, *, spacing: float, shift: float, seed: int = 0):
    from lidarqa.accuracy._lines_synthetic import make_segment_sets

    s = make_segment_sets(
        n_model=n,
        seed=seed,
        spacing=spacing,
        translation=(shift * 0.8, shift * 0.6, 0.03),
        origin=(770000.0, 6277000.0, 0.0),
    )
    rng = np.random.default_rng(seed)
    keep = np.sort(rng.choice(len(s.test), size=min(n, len(s.test)), replace=False))
    return s.test.subset(keep), s.model


def one(n: int, spacing: float, shift: float, repeat: int, dense_check: int) -> str:
    from lidarqa.accuracy.lines import match_segments, segment_distances

    t, m = sets(200, spacing=spacing, shift=shift)
    match_segments(t, m)  # warm-up: numba cache load
    t, m = sets(n, spacing=spacing, shift=shift)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = match_segments(t, m)
        best = min(best, time.perf_counter() - t0)
    tracemalloc.start()
    r = match_segments(t, m)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    same = "-"
    if n <= dense_check:
        d = segment_distances(t, m)[3]
        # same nearest distances; same pairs up to rounding at the threshold (1e-9 m)
        lo = int((d <= r.threshold_tm - 1e-9).sum())
        hi = int((d <= r.threshold_tm + 1e-9).sum())
        near_ok = np.allclose(d.min(axis=1), r.nearest_tm, rtol=0, atol=1e-9) and np.allclose(
            d.min(axis=0), r.nearest_mt, rtol=0, atol=1e-9
        )
        same = str(bool(near_ok and lo <= r.n_pairs_tm <= hi))
    return (
        f"{spacing:>7.0f} {shift:>6.1f} {len(t):>7} {len(m):>7} {len(r.pair_test):>11} "
        f"{r.n_pairs_tm:>9} {r.threshold_tm:>7.3f} {best:>8.3f} {peak / 2**20:>10.1f} {rss:>8.0f} "
        f"{same:>8}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="1000,10000,30000")
    ap.add_argument(
        "--spacings", default="12,4", help="grid spacing of the segments (m); small = dense"
    )
    ap.add_argument("--shifts", default="0.1,3", help="offset between test and model (m)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dense-check", type=int, default=1000)
    ap.add_argument("--one", nargs=3, type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        n, spacing, shift = args.one
        print(one(int(n), spacing, shift, args.repeat, args.dense_check), flush=True)
        return
    print(
        f"{'spacing':>7} {'shift':>6} {'p':>7} {'q':>7} {'candidates':>11} {'pairs_tm':>9} "
        f"{'delta':>7} {'time_s':>8} {'numpy_MB':>10} {'rss_MB':>8} {'==dense':>8}",
        flush=True,
    )
    for spacing in args.spacings.split(","):
        for shift in args.shifts.split(","):
            for n in args.sizes.split(","):
                cmd = [
                    sys.executable,
                    __file__,
                    "--one",
                    n,
                    spacing,
                    shift,
                    "--repeat",
                    str(args.repeat),
                    "--dense-check",
                    str(args.dense_check),
                ]
                subprocess.run(cmd, check=True)


if __name__ == "__main__":
    main()
