"""Speed of ``lidarqa qc``'s per-tile pass (conformance + density + voids) against laspy.

Writes a synthetic LAS 1.4 delivery (:func:`lidarqa.testing.make_delivery`), then times

- laspy alone reading every point of every tile (the floor: decompressing the data),
- the qc tile task over the same tiles on 1 worker (serial) and on 2 Dask workers,

and prints points per second, the ratio to laspy (the goal: >= 0.5) and the peak memory
of the process for the serial run next to the size of one tile's points (memory is
bounded by one streamed piece plus the tile's grids, not by the block).

Usage: ``python benchmarks/qc_speed.py [--tiles 4] [--size 250] [--density 8]``
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
        t0 = time.perf_counter()
        for p in d.paths:
            with laspy.open(str(p)) as r:
                for pts in r.chunk_iterator(1_000_000):
                    _ = pts.x, pts.y, pts.z  # scaled coordinates, as every reader needs
        t_read = time.perf_counter() - t0
        task = TileTask(get_spec("usgs-ql1"))
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        t0 = time.perf_counter()
        out1 = run_tiles(cat, task, engine=Engine("serial"), progress=False)
        t1 = time.perf_counter() - t0
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        assert all(o.ok for o in out1)
        with Engine(workers=2) as eng:
            run_tiles(cat, task, engine=eng, progress=False)  # warm the workers
            t0 = time.perf_counter()
            out2 = run_tiles(cat, task, engine=eng, progress=False)
            t2 = time.perf_counter() - t0
        assert all(o.ok for o in out2)
        same = all(a.result.checks == b.result.checks for a, b in zip(out1, out2, strict=True))
        per_tile = max(d.n_points.values())
        print(f"{len(d.paths)} tiles ({args.suffix}), {n:,} points, {per_tile:,} per tile")
        print(f"{'run':<22}{'s':>8}{'M pts/s':>10}{'vs laspy':>10}")
        print(f"{'laspy read':<22}{t_read:>8.2f}{n / t_read / 1e6:>10.2f}{1.0:>10.2f}")
        print(f"{'qc, 1 worker':<22}{t1:>8.2f}{n / t1 / 1e6:>10.2f}{t_read / t1:>10.2f}")
        print(f"{'qc, 2 workers':<22}{t2:>8.2f}{n / t2 / 1e6:>10.2f}{t_read / t2:>10.2f}")
        print(f"same verdicts on 1 and 2 workers: {same}")
        print(f"peak RSS serial: {rss1 / 1024:.0f} MB (before the run {rss0 / 1024:.0f} MB); "
              f"one tile's xyz alone is {per_tile * 24 / 2**20:.0f} MB")


if __name__ == "__main__":
    main()
