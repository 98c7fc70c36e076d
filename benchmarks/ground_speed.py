"""Speed and peak memory of ``lidarqa ground`` (read + filter + write) against the CSF wheel.

Runs every measurement in a fresh subprocess so that peak RSS (ru_maxrss) and CPU
time (user + sys of the process and its threads) are that run's own. Datasets
(``--only``, comma-separated; default ``fsite5,2m``):

- ``fsite5``: the unlabelled ISPRS site file FSite5_orig-utm.laz (628 k points);
- ``2m``: a 2 M-point synthetic scene (lidarqa.testing.make_scene, 20 pts/m²);
- ``bcts2``: the BC forest tile lasR-bcts/bcts_2 (824 k points);
- ``oakland``: the 8 Oakland mobile-scanning chunks, one after the other in one
  process (the set is timed as a whole);
- ``sites``: FSite5 and three CSite files.

CSF = cloth-simulation-filter (``pip install cloth-simulation-filter``), on the last
(and single) returns like PDAL ``filters.csf``, noise classes 7 and 18 left out:

- ``csf`` runs PDAL ``filters.csf``'s defaults (cloth resolution 1.0 m, rigidness 3,
  time step 0.65, class threshold 0.5, slope smoothing on, 500 iterations): what a
  PDAL user gets, and the reference of the speed goal;
- ``csf05`` the same with a 0.5 m cloth on the dense synthetic scene (slower).

Times are read + filter + write (the imports the run needs included, not the
interpreter start); the summary also gives the median CPU seconds per phase (the start,
the filter's imports, reading with the reader's imports, filtering with its first calls,
writing). Both methods
run after ``import lidarqa``, which sets ``OMP_WAIT_POLICY=PASSIVE``: CSF's OpenMP
threads then sleep between parallel regions too (on 2 shared cores that took a quarter
to a half of CSF's CPU time off on bcts_2 and the Oakland set), so the CPU ratio
compares the two without spinning threads.
Every module loads from bytecode, as in an installed package (``_peers.timed_env``;
without it each lidarqa process compiled lidarqa's source again, 0.07 CPU-s of its
2.0 s on bcts_2), and one untimed run of each method on each dataset comes first, so
the bytecode and numba's compiled kernels are in place when the timing starts.
The methods run interleaved, ``--repeat`` rounds, each run in its own process, and
the ratios use the median per method, of wall time and of CPU time (the machine may
be shared: wall times are noisy, compare CPU seconds).

    python benchmarks/ground_speed.py [--methods segment-ptd,csf,csf05] [--only 2m,bcts2,oakland]
        [--repeat 3]

A method may name a preset: ``segment-ptd@als`` runs ``--preset als``; without one
the default (``auto``) runs.
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "lidar-data" / "isprs-filtertest-pdal" / "FSite5_orig-utm.laz"
DATA = REPO.parent / "shared" / "lidar-data"


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _csf(cloud, cloth: float):
    """CSF at PDAL filters.csf defaults on the last returns, noise left out."""
    from _peers import csf_ground

    return csf_ground(cloud, cloth=cloth)


def one(method: str, src: str, out: str, cloth: float = 0.5) -> dict:
    """Read, filter and write every file of `src` (``;``-separated) with `method`."""
    import warnings

    import numpy as np

    c0 = _cpu()
    t0 = time.perf_counter()
    if not method.startswith("csf"):  # what the console script does first
        from lidarqa._malloc import tune_process

        tune_process()
    import lidarqa

    times = {"read_s": 0.0, "filter_s": 0.0, "write_s": 0.0}
    # CPU seconds per phase: the start (lidarqa), the filter's imports, then reading (the
    # LAS reader's imports on the first file), filtering (its first calls included) and
    # writing, summed over the files
    cpu = {"start": _cpu() - c0, "imports": 0.0, "read": 0.0, "filter": 0.0, "write": 0.0}
    c1 = _cpu()
    if method.startswith("csf"):
        import CSF  # noqa: F401  (the wheel; imported by _peers.csf_ground)
    else:
        from lidarqa.ground import classify_ground
    cpu["imports"] = _cpu() - c1
    n = n_ground = 0
    for k, path in enumerate(src.split(";")):
        t1 = time.perf_counter()
        c1 = _cpu()
        cloud = lidarqa.read(path)
        t2 = time.perf_counter()
        c2 = _cpu()
        if method.startswith("csf"):
            ground = _csf(cloud, 0.5 if method == "csf05" else 1.0)
        else:
            name, _, preset = method.partition("@")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ground = classify_ground(cloud, method=name, preset=preset or "auto").ground_mask
        t3 = time.perf_counter()
        c3 = _cpu()
        from _peers import relabel

        cls = cloud.fields.get("classification", np.zeros(len(cloud), dtype=np.uint8))
        cloud.fields["classification"] = relabel(cls, ground)
        lidarqa.write(cloud, out.replace(".laz", f"-{k}.laz"), overwrite=True)
        t4 = time.perf_counter()
        cpu["read"] += c2 - c1
        cpu["filter"] += c3 - c2
        cpu["write"] += _cpu() - c3
        times["read_s"] += t2 - t1
        times["filter_s"] += t3 - t2
        times["write_s"] += t4 - t3
        n += len(cloud)
        n_ground += int(ground.sum())
    return {
        "method": method,
        "n": n,
        **times,
        "total_s": time.perf_counter() - t0,
        "cpu_s": _cpu() - c0,
        "cpu_phases": cpu,
        "n_ground": n_ground,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def make_2m(path: Path) -> None:
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.testing import make_scene

    sc = make_scene(seed=0, size=(300.0, 300.0), density=20.0, origin=(500000.0, 5400000.0, 100.0))
    import numpy as np

    cloud = PointCloud(sc.points, fields={"classification": sc.classification.astype(np.uint8)})
    lidarqa.write(cloud, path, overwrite=True)


def main() -> None:
    from _peers import timed_env, warm_up

    ap = argparse.ArgumentParser()
    ap.add_argument("--one", nargs=4, metavar=("METHOD", "SRC", "OUT", "CLOTH"))
    ap.add_argument("--methods", default="segment-ptd,csf,csf05")
    ap.add_argument("--only", default=None)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    if a.one:
        print(json.dumps(one(a.one[0], a.one[1], a.one[2], float(a.one[3]))))
        return
    tmp = Path(tempfile.mkdtemp(prefix="lidarqa-ground-speed-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)  # the scene and the outputs
    datasets: list[tuple[str, str, float]] = []
    only = (a.only or "fsite5,2m").split(",")
    if SHARED.exists() and ("fsite5" in only or "sites" in only):
        datasets.append(("FSite5_orig (628 k)", str(SHARED), 1.0))
    if SHARED.exists() and "sites" in only:
        for site in ("CSite2_orig", "CSite3_orig", "CSite4_orig"):
            f = SHARED.parent / f"{site}-utm.laz"
            if f.exists():
                datasets.append((site, str(f), 1.0))
    if "2m" in only:
        syn = tmp / "synthetic-2m.laz"
        make_2m(syn)
        datasets.append(("synthetic 2 M", str(syn), 0.5))
    bcts = DATA / "lasR-bcts" / "bcts_2.laz"
    if "bcts2" in only and bcts.exists():
        datasets.append(("bcts_2 (forest)", str(bcts), 1.0))
    oak = sorted((DATA / "oakland-mls").glob("*.laz"))
    if "oakland" in only and oak:
        datasets.append((f"Oakland MLS ({len(oak)})", ";".join(map(str, oak)), 1.0))
    methods = a.methods.split(",")
    print(
        f"{'dataset':<22}{'method':<16}{'points':>10}{'read s':>8}{'filter s':>10}{'write s':>9}"
        f"{'total s':>9}{'CPU s':>8}{'peak MB':>9}{'ground':>10}"
    )
    for name, src, cloth in datasets:
        res: dict[str, list[dict]] = {}
        for m in methods:  # untimed: bytecode and numba's cache in place (see timed_env)
            warm_up([sys.executable, __file__, "--one", m, src, str(tmp / "warm.laz"), str(cloth)],
                    timed_env())
        for _ in range(a.repeat):
            for m in methods:  # interleaved: every method once per round
                out = tmp / f"out-{m}.laz"
                p = subprocess.run(
                    [sys.executable, __file__, "--one", m, src, str(out), str(cloth)],
                    capture_output=True,
                    text=True,
                    env=timed_env(),
                )
                if p.returncode != 0:
                    print(f"{name:<22}{m:<16} FAILED: {p.stderr.strip().splitlines()[-1:]}")
                    continue
                r = json.loads(p.stdout.strip().splitlines()[-1])
                res.setdefault(m, []).append(r)
                print(
                    f"{name:<22}{m:<16}{r['n']:>10,}{r['read_s']:>8.1f}{r['filter_s']:>10.1f}"
                    f"{r['write_s']:>9.1f}{r['total_s']:>9.1f}{r['cpu_s']:>8.1f}{r['peak_rss_mb']:>9.0f}"
                    f"{r['n_ground']:>10,}   load {os.getloadavg()[0]:.1f}",
                    flush=True,
                )
        med = {m: statistics.median(r["total_s"] for r in rs) for m, rs in res.items()}
        cpu = {m: statistics.median(r["cpu_s"] for r in rs) for m, rs in res.items()}
        for m in med:
            print(f"{'':<22}{m}: median wall {med[m]:.2f} s, median CPU {cpu[m]:.2f} s")
            phases = ", ".join(
                f"{ph} {statistics.median(r['cpu_phases'][ph] for r in res[m]):.2f}"
                for ph in res[m][0]["cpu_phases"]
            )
            print(f"{'':<24}median CPU s per phase: {phases}")
        for ref in ("csf", "csf05"):
            if ref not in med:
                continue
            for m, t in med.items():
                if not m.startswith("csf"):
                    print(
                        f"{'':<22}{m} / {ref} median ratio: wall {t / med[ref]:.2f}, "
                        f"CPU {cpu[m] / cpu[ref]:.2f}"
                        + ("   (PDAL filters.csf defaults)" if ref == "csf" else "   (0.5 m cloth)")
                    )


if __name__ == "__main__":
    main()
