"""Speed and accuracy of lidarqa.accuracy.roads.reconstruct_roads (issue #15).

Speed goal: 10,000 map points and 2,000,000 laser points in <= 10 s on the
2-core development machine. The scene is the synthetic two-level interchange of
lidarqa.testing.interchange at a density that gives about 2 M points, with the
map point spacing chosen to give about 10,000 map points.

Accuracy goals, per scene (``--seeds N`` scenes with 6, 8, 10 and 14 m decks at
the default 10 m spacing): 100 % of map points on the right level, >= 99 % of
map points within 3 predicted σ of the truth, std of the w-values at the
paint-strip reference points (without outliers) in [0.9, 1.1], map shift within
10 cm. The block offset of the scene is correlated over tens of metres, so
these fractions and std(w) vary from scene to scene: the table shows how much.

Prints tables; run with

    /work/venv/bin/python benchmarks/roads_speed.py [--seeds 20]

Timings on a shared machine are noisy: the CPU column (process time) is less
affected by other jobs than the wall clock.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lidarqa.accuracy.roads import compare_road_heights, reconstruct_roads
from lidarqa.testing.interchange import make_interchange


def _evaluate(scene, spacing):
    t0, c0 = time.perf_counter(), time.process_time()
    rec = reconstruct_roads(scene.points, scene.polygons, spacing=spacing)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    comp = compare_road_heights(rec, scene.reference_xyz)
    mp = rec.map_points
    truth = scene.true_height(mp.xy - scene.map_shift, scene.polygon_road[mp.polygon])
    err = mp.height - truth
    w = comp.w
    return {
        "laser": len(scene.points),
        "map": len(mp),
        "wall": wall,
        "cpu": cpu,
        "shift_err": float(np.max(np.abs(rec.shift + scene.map_shift))),
        "level": float(np.mean(np.abs(err) < 1.0)),  # levels are >= 6 m apart
        "in3": float(np.mean(np.abs(err) <= 3 * mp.sigma)),
        "std_w": float(np.std(w.w[~w.outlier], ddof=1)),
        "n_out": int(w.outlier.sum()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=8, help="scenes in the accuracy table")
    args = ap.parse_args()

    print("speed (goal: 10,000 map points + 2,000,000 laser points <= 10 s)")
    print(f"{'laser pts':>10} {'map pts':>8} {'wall s':>7} {'cpu s':>7}")
    for density, spacing in ((4.0, 10.0), (17.0, 0.14)):
        r = _evaluate(make_interchange(seed=0, density=density), spacing)
        print(f"{r['laser']:>10,} {r['map']:>8,} {r['wall']:>7.2f} {r['cpu']:>7.2f}")

    print()
    print("accuracy per scene (density 4 /m², spacing 10 m)")
    print(
        f"{'seed':>4} {'deck m':>6} {'map pts':>7} {'right lvl':>9} {'<=3σ':>6} "
        f"{'std(w)':>6} {'w out':>5} {'shift err m':>11}"
    )
    rows = []
    for seed in range(args.seeds):
        deck = (6.0, 8.0, 10.0, 14.0)[seed % 4]
        r = _evaluate(make_interchange(seed=seed, density=4.0, deck_height=deck), 10.0)
        rows.append(r)
        print(
            f"{seed:>4} {deck:>6.0f} {r['map']:>7} {r['level']:>9.3f} {r['in3']:>6.3f} "
            f"{r['std_w']:>6.3f} {r['n_out']:>5} {r['shift_err']:>11.3f}"
        )
    lvl = np.array([r["level"] for r in rows])
    in3 = np.array([r["in3"] for r in rows])
    sw = np.array([r["std_w"] for r in rows])
    se = np.array([r["shift_err"] for r in rows])
    print(
        f"scenes with all map points on the right level: {np.sum(lvl == 1)}/{len(rows)}; "
        f">= 99 % within 3σ: {np.sum(in3 >= 0.99)}/{len(rows)} (pooled {np.mean(in3):.4f}); "
        f"std(w) in [0.9, 1.1]: {np.sum((sw >= 0.9) & (sw <= 1.1))}/{len(rows)} "
        f"(mean {sw.mean():.3f}, range {sw.min():.3f}-{sw.max():.3f}); "
        f"shift within 10 cm: {np.sum(se <= 0.10)}/{len(rows)}"
    )


if __name__ == "__main__":
    main()
