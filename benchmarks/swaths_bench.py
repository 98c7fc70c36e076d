"""Strip relative accuracy: σ calibration by Monte Carlo, speed/memory, real IGN tiles.

Run:  /work/venv/bin/python benchmarks/swaths_bench.py calibration [--runs 1000]
      /work/venv/bin/python benchmarks/swaths_bench.py speed        (1 km², 4 strips, ~1 M points)
      /work/venv/bin/python benchmarks/swaths_bench.py real         (needs ../shared/lidar-data)
      /work/venv/bin/python benchmarks/swaths_bench.py lines        (strip-pair lines per
                                                  50 m tile and on St-Barth)

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


def lines() -> None:
    """Strip-to-strip line pairs per IGN 50 m tile and on St-Barth, four edge/threshold set-ups."""
    from lidarqa import read
    from lidarqa.accuracy.lines import match_segments, match_strips
    from lidarqa.accuracy.lines_io import with_point_spacing
    from lidarqa.geometry.edges import extract_edges
    from lidarqa.geometry.segmentation import segment_planes

    tiles = sorted(SHARED.glob("test_data_770*_6277*_LA93_IGN69.laz"))
    sb = SHARED / "St_Barth_RGAF09_UTM20N_IGN_1988_SB_subset_100m.laz"
    setups = {"edges, knee": ({}, "knee"), "edges, band": ({}, "sampling"),
              "edges+steps, knee": ({"steps": True}, "knee"),
              "edges+steps, band": ({"steps": True}, "sampling")}
    sets: dict = {}
    for path in [*tiles, sb]:
        cloud = read(path).select(classes=[6])
        sid = cloud.point_source_id
        name = path.name[10:22] if path.name.startswith("test_data") else "St-Barth"
        pair = (706, 707) if name != "St-Barth" else (4320, 4330)
        for s in pair:
            xyz = cloud.xyz[sid == s]
            seg = segment_planes(xyz)
            for label, (opts, _) in setups.items():
                e = with_point_spacing(extract_edges(xyz, segmentation=seg, **opts), xyz)
                sets.setdefault((label, name), []).append(e)
    print(f"{'set-up':<20}{'tile':<14}{'p':>5}{'q':>5}{'<=0.5 m':>9}{'pairs':>11}"
          f"{'δ T→M':>8}{'δ M→T':>8}{'LHD':>7}")
    for label, (_, auto) in setups.items():
        deltas = []
        for name in [p.name[10:22] for p in tiles] + ["St-Barth"]:
            a, b = sets[(label, name)]
            if min(len(a), len(b)) == 0:
                print(f"{label:<20}{name:<14}{len(a):>5}{len(b):>5}   no edges in one strip")
                continue
            r = match_strips(a, b, auto=auto)
            near = match_segments(a, b, threshold=0.5)
            if name != "St-Barth":
                deltas += [r["threshold_tm"], r["threshold_mt"]]
            print(f"{label:<20}{name:<14}{r['p']:>5}{r['q']:>5}"
                  f"{min(near.n_pairs_tm, near.n_pairs_mt):>9}"
                  f"{str(r['n_pairs_tm']) + '/' + str(r['n_pairs_mt']):>11}"
                  f"{r['threshold_tm']:>8.2f}{r['threshold_mt']:>8.2f}{r['lhd']:>7.3f}")
        print(f"{label:<20}{'six tiles':<14} thresholds {min(deltas):.2f}-{max(deltas):.2f} m "
              f"(x{max(deltas) / min(deltas):.2f})")


def _cm3(v):
    return "n/a" if v is None else "/".join(f"{x:.3f}" for x in v)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("calibration", "speed", "real", "lines"))
    ap.add_argument("--runs", type=int, default=1000)
    a = ap.parse_args()
    {"calibration": lambda: calibration(a.runs), "speed": speed, "real": real,
     "lines": lines}[a.what]()


if __name__ == "__main__":
    main()
