"""Strip relative accuracy: σ calibration by Monte Carlo, speed/memory, real IGN tiles.

Run:  /work/venv/bin/python benchmarks/swaths_bench.py calibration [--runs 1000]
      /work/venv/bin/python benchmarks/swaths_bench.py speed        (1 km², 4 strips, ~1 M points)
      /work/venv/bin/python benchmarks/swaths_bench.py real         (needs ../shared/lidar-data)

Prints tables; timing goals live here, never in the unit tests. CPU time is printed
next to wall time because the machine may be shared.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

SHARED = Path(__file__).resolve().parents[2] / "shared" / "lidar-data" / "ign-lidarhd"


def calibration(runs: int) -> None:
    from lidarqa.accuracy.swaths import assess_swaths
    from lidarqa.testing.strips import make_strip_scene

    truth = np.array([[0.0, 0.0, 0.0], [0.03, -0.02, 0.02], [-0.02, 0.04, -0.01]])
    est, sig, rms = [], [], []
    for seed in range(runs):
        scene = make_strip_scene(
            3, offsets=truth, noise=0.03, length=50.0, strip_width=40.0, seed=20_000 + seed
        )
        rep = assess_swaths(
            scene.points, scene.strip, cell_size=1.0, return_grids=False, reference_strip=1
        )
        net = {o.strip_b: o for o in rep.network_offsets}
        est.append([[net[s].dx, net[s].dy, net[s].dz] for s in (2, 3)])
        sig.append([[net[s].sigma_dx, net[s].sigma_dy, net[s].sigma_dz] for s in (2, 3)])
        rms.append([p.rmsdz for p in rep.pairs])
    est, sig = np.array(est), np.array(sig)
    print(f"{runs} three-strip scenes, network offsets relative to strip 1 (noise 3 cm)")
    print(
        f"{'strip':>5} {'param':>5} {'true':>8} {'mean':>9} {'emp. sd':>9} {'mean σ':>9} "
        f"{'ratio':>6}"
    )
    for k, s in enumerate((2, 3)):
        for p, name in enumerate(("dx", "dy", "dz")):
            e, sg = est[:, k, p], sig[:, k, p]
            ratio = sg.mean() / e.std(ddof=1)
            print(
                f"{s:>5} {name:>5} {truth[s - 1, p]:8.4f} {e.mean():9.5f} {e.std(ddof=1):9.5f} "
                f"{sg.mean():9.5f} {ratio:6.3f}"
            )


def speed() -> None:
    from lidarqa.accuracy.swaths import assess_swaths
    from lidarqa.testing.strips import make_strip_scene

    off = [[0, 0, 0], [0.03, -0.02, 0.02], [-0.02, 0.04, -0.01], [0.01, 0.01, 0.03]]
    # 1 km x 1 km, 4 strips of 400 m with 100 m side overlap, ~1 M points in all
    scene = make_strip_scene(
        4, offsets=off, density=0.84, length=1000.0, strip_width=400.0, overlap=0.25, seed=1
    )
    print(f"{len(scene.points):,} points, 4 strips, 1 km²")
    for rot in (False, True):
        t0, c0 = time.perf_counter(), time.process_time()
        rep = assess_swaths(scene.points, scene.strip, rotations=rot)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(
            f"rotations={rot!s:5}  cell {rep.cell_size:g} m  wall {wall:6.2f} s  cpu {cpu:6.2f} s  "
            f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.0f} MB  "
            f"pairs {len(rep.pairs)}"
        )
    # The whole command: read the LAZ, compare, write rasters, maps and tables.
    import subprocess
    import tempfile

    import lidarqa
    from lidarqa.io import PointCloud

    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "block.laz"
        fields = {
            "classification": np.full(len(scene.points), 2, dtype=np.uint8),
            "point_source_id": scene.strip.astype(np.uint16),
        }
        lidarqa.write(
            PointCloud(xyz=scene.points + [650_000.0, 6_860_000.0, 0.0], fields=fields), f
        )
        t0 = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "lidarqa.cli.main",
                "swaths",
                str(f),
                "--by-source-id",
                "-o",
                str(Path(d) / "out"),
                "-q",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        wall = time.perf_counter() - t0
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        print(
            f"lidarqa swaths (LAZ in, GeoTIFF/PNG/CSV out): wall {wall:6.2f} s  cpu "
            f"{ru.ru_utime + ru.ru_stime:6.2f} s  peak RSS {ru.ru_maxrss / 1024:7.0f} MB"
        )


def real() -> None:
    from lidarqa.accuracy.swaths import assess_swaths, last_return_mask, surface_class_mask
    from lidarqa.io import read

    files = sorted(SHARED.glob("*.laz"))
    if not files:
        sys.exit(f"no data in {SHARED}")
    for f in files:
        pc = read(f)
        keep = last_return_mask(pc.fields, len(pc)) & surface_class_mask(pc.classification, len(pc))
        sid = np.asarray(pc.point_source_id)
        keep &= sid != 0
        t0 = time.perf_counter()
        rep = assess_swaths(pc.xyz[keep], sid[keep].astype(np.int64))
        dt = time.perf_counter() - t0
        print(
            f"\n{f.name}: {keep.sum():,} points, cell {rep.cell_size:g} m, {dt:.2f} s, E4 "
            f"{rep.e4 * 100:.1f} cm"
        )
        print(
            f"  {'pair':>9} {'overlap m2':>10} {'area m2':>8} {'RMSDz':>7} {'mean':>7} "
            f"{'max':>7} pass"
        )
        for p in rep.pairs:
            print(
                f"  {p.strip_a:>4}-{p.strip_b:<4} {p.overlap_area:10.0f} {p.area:8.0f} "
                f"{p.rmsdz:7.3f} {p.mean:7.3f} {p.max_abs:7.3f} {p.passed}"
            )
        for o in rep.pair_offsets:
            print(
                f"  offset {o.strip_a}->{o.strip_b} (robust σ {_cm3(o.sigma_robust)}): "
                f"dx {o.dx:+.3f}±{o.sigma_dx:.3f} dy "
                f"{o.dy:+.3f}±{o.sigma_dy:.3f} dz {o.dz:+.3f}±{o.sigma_dz:.3f} (n {o.n_obs})"
            )
        for r in rep.repeatability:
            print(
                f"  strip {r.strip}: RMSE {r.rmse:.3f} median range {r.median_range:.3f} "
                f"area {r.area:.0f}"
            )


def _cm3(v):
    return "n/a" if v is None else "/".join(f"{x:.3f}" for x in v)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("calibration", "speed", "real"))
    ap.add_argument("--runs", type=int, default=1000)
    a = ap.parse_args()
    {"calibration": lambda: calibration(a.runs), "speed": speed, "real": real}[a.what]()


if __name__ == "__main__":
    main()
