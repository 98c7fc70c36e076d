"""Speed of ``lidarqa qc``'s per-tile pass (conformance + density + voids) against laspy.

Writes a synthetic LAS 1.4 delivery (:func:`lidarqa.testing.make_delivery`), then times

- laspy alone reading every point of every tile (the floor: decompressing the data),
- the qc tile task over the same tiles on 1 worker (serial) and on 2 Dask workers,

and prints points per second, the ratio to laspy (the goal: >= 0.5) and the peak memory
of the process for the serial run next to the size of one tile's points (memory is
bounded by one streamed piece plus the tile's grids, not by the block).

laspy and qc runs alternate (``--rounds``) and each ratio is taken against the laspy run
just before, so a busy shared machine slows both alike.

Usage: ``python benchmarks/qc_speed.py [--tiles 4] [--size 250] [--density 8] [--rounds 3]``
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tiles", type=int, default=4, help="tiles across and up (n x n)")
    ap.add_argument("--size", type=float, default=250.0, help="tile side (m)")
    ap.add_argument("--density", type=float, default=8.0, help="pulses per m² per swath")
    ap.add_argument("--suffix", default=".laz")
    ap.add_argument("--rounds", type=int, default=3, help="alternating laspy/qc rounds")
    args = ap.parse_args()

    import laspy

    from lidarqa.qc import get_spec
    from lidarqa.qc._task import TileTask
    from lidarqa.testing import make_delivery
    from lidarqa.tiling import Engine, open_catalog, run_tiles

    with tempfile.TemporaryDirectory() as tmp:
        d = make_delivery(Path(tmp) / "tiles", nx=args.tiles, ny=args.tiles,
                          tile_size=args.size, density=args.density, suffix=args.suffix)
        n = sum(d.n_points.values())
        cat = open_catalog(d.paths[0].parent)

        def laspy_read() -> float:
            t0 = time.perf_counter()
            for p in d.paths:
                with laspy.open(str(p)) as r:
                    for pts in r.chunk_iterator(1_000_000):
                        _ = pts.x, pts.y, pts.z  # scaled coordinates, as every reader needs
            return time.perf_counter() - t0

        task = TileTask(get_spec("usgs-ql1"))

        def qc(engine: Engine) -> tuple[float, list]:
            t0 = time.perf_counter()
            out = run_tiles(cat, task, engine=engine, progress=False)
            return time.perf_counter() - t0, out

        # the machine may be shared: laspy and qc alternate, and each round's ratio is
        # taken against the laspy run just before it; the median round is reported
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        rows1, rows2 = [], []
        out1 = out2 = None
        with Engine(workers=2) as eng:
            run_tiles(cat, task, engine=eng, progress=False)  # warm the workers
            for _ in range(args.rounds):
                tr = laspy_read()
                t1, out1 = qc(Engine("serial"))
                rows1.append((tr, t1))
                tr = laspy_read()
                t2, out2 = qc(eng)
                rows2.append((tr, t2))
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        assert all(o.ok for o in out1) and all(o.ok for o in out2)
        same = all(a.result.checks == b.result.checks for a, b in zip(out1, out2, strict=True))
        per_tile = max(d.n_points.values())
        print(f"{len(d.paths)} tiles ({args.suffix}), {n:,} points, {per_tile:,} per tile, "
              f"{args.rounds} alternating round(s)")
        print(f"{'run':<16}{'laspy s':>9}{'qc s':>8}{'qc M pts/s':>12}{'qc/laspy speed':>16}")
        for name, rows in (("qc, 1 worker", rows1), ("qc, 2 workers", rows2)):
            ratios = sorted(tr / tq for tr, tq in rows)
            tr, tq = sorted(rows, key=lambda r: r[0] / r[1])[len(rows) // 2]
            print(f"{name:<16}{tr:>9.2f}{tq:>8.2f}{n / tq / 1e6:>12.2f}{tr / tq:>16.2f}"
                  f"   (rounds: {', '.join(f'{r:.2f}' for r in ratios)})")
        print(f"same verdicts on 1 and 2 workers: {same}")
        print(f"peak RSS: {rss1 / 1024:.0f} MB (before the runs {rss0 / 1024:.0f} MB); "
              f"one tile's xyz alone is {per_tile * 24 / 2**20:.0f} MB")


if __name__ == "__main__":
    main()
