"""Speed of lidarqa.accuracy.roads.reconstruct_roads (issue #15).

Goal: 10,000 map points and 2,000,000 laser points in <= 10 s on the 2-core
development machine. The scene is the synthetic two-level interchange of
lidarqa.testing.interchange at a density that gives about 2 M points, with the
map point spacing chosen to give about 10,000 map points. Prints a table; run
with

    /work/venv/bin/python benchmarks/roads_speed.py

Timings on a shared machine are noisy; run it when the machine is quiet.
"""

from __future__ import annotations

import time

import numpy as np

from lidarqa.accuracy.roads import compare_road_heights, reconstruct_roads
from lidarqa.testing.interchange import make_interchange


def main() -> None:
    rows = []
    for density, spacing in ((4.0, 10.0), (17.0, 0.14)):
        scene = make_interchange(seed=0, density=density)
        t0 = time.perf_counter()
        rec = reconstruct_roads(scene.points, scene.polygons, spacing=spacing)
        t1 = time.perf_counter()
        comp = compare_road_heights(rec, scene.reference_xyz)
        t2 = time.perf_counter()
        mp = rec.map_points
        truth = scene.true_height(mp.xy - scene.map_shift, scene.polygon_road[mp.polygon])
        err = mp.height - truth
        rows.append(
            (
                len(scene.points),
                len(mp),
                t1 - t0,
                t2 - t1,
                float(np.hypot(*(rec.shift + scene.map_shift))),
                float(np.mean(np.abs(err) < 1.0)),
                float(np.mean(np.abs(err) <= 3 * mp.sigma)),
                float(np.std(comp.w.w[~comp.w.outlier], ddof=1)),
            )
        )
    print(
        f"{'laser pts':>10} {'map pts':>8} {'recon s':>8} {'w-test s':>8} {'shift err':>9} "
        f"{'right lvl':>9} {'<=3σ':>6} {'std(w)':>6}"
    )
    for n, m, tr, tw, se, rl, w3, sw in rows:
        print(f"{n:>10,} {m:>8,} {tr:>8.2f} {tw:>8.2f} {se:>9.3f} {rl:>9.3f} {w3:>6.3f} {sw:>6.3f}")
    print("goal: 10,000 map points + 2,000,000 laser points <= 10 s")


if __name__ == "__main__":
    main()
