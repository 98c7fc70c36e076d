"""ISPRS filter test (Sithole & Vosselman 2004) and forest/bridge checks with NO options.

What a user gets from ``lidarqa ground IN -o OUT`` (``preset="auto"``: parameters
chosen from figures measured on each cloud) for both methods on the 15 labelled
ISPRS samples, the two lidR forest plots (vendor ground labels) and the IGN tile
with a bridge (classes 2,3,4,5,6,17 evaluated; bridge points labelled ground
reported). Prints per-sample type I / type II / total error (%) and Cohen's kappa
(%), the means, and published / measured anchors.

Leave-one-site-out (``--loso``): the sparse airborne set's two most influential
values (iteration angle and distance) are re-chosen from a small grid on the
samples of the *other* ISPRS sites (1–8: CSite1–4, FSite5–7, no site 8 sample)
and the held-out site is scored with that choice. The LOSO mean beside the
all-sample mean shows whether the fixed values are fitted to these 15 samples.

    python benchmarks/ground_isprs.py [--methods segment-ptd,ptd] [--samples 11,24] [--loso]
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

import lidarqa
from lidarqa.ground import classify_ground, filter_errors

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "lidar-data"
DATA = SHARED / "isprs-filtertest-pdal"
SAMPLES = ["11", "12", "21", "22", "23", "24", "31", "41", "42", "51", "52", "53", "54", "61", "71"]
EXTRA = [
    ("Megaplot", SHARED / "lidR-extdata" / "Megaplot.laz", None),
    ("MixedConifer", SHARED / "lidR-extdata" / "MixedConifer.laz", None),
    (
        "IGN semis 0299_6802",
        SHARED / "ign-lidarhd" / "test_semis_2023_0299_6802_LA93_IGN69.laz",
        (2, 3, 4, 5, 6, 17),
    ),
]
GRID = {"iter_angle": (12.0, 16.0, 20.0), "iter_distance": (0.5, 0.7, 0.9)}

ANCHORS = [
    ("PDAL 2.8 SMRF, default parameters (measured)", "5.14", "kappa 83.3"),
    ("PDAL 2.8 PMF, default parameters (measured)", "8.32", ""),
    ("PDAL 2.8 CSF, default parameters (measured)", "19.24", ""),
    ("Axelsson PTD, tuned per sample (published)", "4.82", ""),
    ("CSF, tuned per sample (published)", "4.39", ""),
    ("SMRF, tuned per sample (published)", "2.97", ""),
    ("Mongus & Zalik 2014 (published)", "2.74", ""),
]


def _score(cloud, method: str, keep_classes=None, **params):
    cls = np.asarray(cloud.classification)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        r = classify_ground(cloud, method=method, **params)
        dt = time.perf_counter() - t0
    keep = np.ones(cls.size, bool) if keep_classes is None else np.isin(cls, keep_classes)
    e = filter_errors(cls[keep] == 2, r.ground_mask[keep])
    bridge = r.ground_mask[cls == 17].mean() if keep_classes and (cls == 17).any() else None
    return e, dt, r, bridge


def _row(name, e, dt, extra=""):
    print(
        f"{name:<22}{100 * e.type_i:>9.2f}{100 * e.type_ii:>10.2f}{100 * e.total:>9.2f}"
        f"{100 * e.kappa:>9.1f}{dt:>8.1f}  {extra}"
    )


def _header():
    print(
        f"{'sample':<22}{'type I %':>9}{'type II %':>10}{'total %':>9}{'kappa %':>9}{'time s':>8}"
    )


def loso(method: str, clouds: dict) -> None:
    """Leave-one-site-out over the sparse set's iteration angle and distance."""
    combos = list(itertools.product(*GRID.values()))
    tot = {}  # (combo, sample) -> total error %
    for c in combos:
        p = dict(zip(GRID, c, strict=True))
        for s, cloud in clouds.items():
            e, _, _, _ = _score(cloud, method, preset="als", **p)
            tot[c, s] = 100 * e.total
    sites = sorted({s[0] for s in clouds})
    held = {}
    print(f"\nleave-one-site-out ({method}; grid {GRID}, preset als + the grid values)")
    for site in sites:
        train = [s for s in clouds if s[0] != site]
        best = min(combos, key=lambda c: (np.mean([tot[c, s] for s in train]), c))
        for s in clouds:
            if s[0] == site:
                held[s] = tot[best, s]
        print(f"  site {site}: chosen {dict(zip(GRID, best, strict=True))}")
    allbest = min(combos, key=lambda c: (np.mean([tot[c, s] for s in clouds]), c))
    print(
        f"  LOSO mean total {np.mean(list(held.values())):.2f} %, max {max(held.values()):.2f} %;"
        f" best single choice on all samples {dict(zip(GRID, allbest, strict=True))}: "
        f"{np.mean([tot[allbest, s] for s in clouds]):.2f} %"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--methods", default="segment-ptd,ptd")
    ap.add_argument("--samples", default=",".join(SAMPLES))
    ap.add_argument("--loso", action="store_true")
    ap.add_argument("--no-extra", action="store_true")
    a = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA} is not present")
    samples = a.samples.split(",")
    clouds = {s: lidarqa.read(DATA / f"samp{s}-utm.laz") for s in samples}
    means = {}
    for method in a.methods.split(","):
        print(f"\n{method}, no options (preset auto)")
        _header()
        rows = []
        for s, cloud in clouds.items():
            e, dt, r, _ = _score(cloud, method)
            rows.append(e)
            _row(f"samp{s}", e, dt, f"{r.regime}")
        keys = ("type_i", "type_ii", "total", "kappa")
        m = [np.mean([100 * getattr(e, k) for e in rows]) for k in keys]
        worst = max(100 * e.total for e in rows)
        means[method] = (m, worst)
        print(
            f"{'mean':<22}{m[0]:>9.2f}{m[1]:>10.2f}{m[2]:>9.2f}{m[3]:>9.1f}   "
            f"(worst sample {worst:.2f} %)"
        )
        if not a.no_extra:
            for name, path, keep in EXTRA:
                if path.exists():
                    e, dt, r, br = _score(lidarqa.read(path), method, keep)
                    extra = r.regime
                    if br is not None:
                        extra += f", bridge (17) as ground {100 * br:.1f} %"
                    _row(name, e, dt, extra)
        if a.loso:
            loso(method, clouds)
    print("\nmean total error (%) beside the anchors")
    for method, (m, worst) in means.items():
        name = f"{method} (no options)"
        print(f"  lidarqa {name:<40}{m[2]:>7.2f}   kappa {m[3]:.1f}, worst {worst:.2f}")
    for name, tot, extra in ANCHORS:
        print(f"  {name:<48}{tot:>7}   {extra}")


if __name__ == "__main__":
    main()
