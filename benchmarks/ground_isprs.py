"""ISPRS filter test (Sithole & Vosselman 2004) and forest/bridge checks with NO options.

What a user gets from ``lidarqa ground IN -o OUT`` (``preset="auto"``: parameters
chosen from figures measured on each cloud) for both methods on the 15 labelled
ISPRS samples, the two lidR forest plots (vendor ground labels) and the IGN tile
with a bridge (classes 2,3,4,5,6,17 evaluated; bridge points labelled ground
reported). Prints per-sample type I / type II / total error (%) and Cohen's kappa
(%), the means, and published / measured anchors.

Leave-one-site-out (``--loso``), over EVERY constant of the sparse airborne preset
(``PRESETS["als"][method]``, 16 for segment-PTD): each constant in turn is tried at
0.75x, 1x and 1.25x its preset value (integers rounded, booleans both ways), the
others held at the preset. For each ISPRS site (1–7: CSite1–4, FSite5–7) the value
with the lowest mean total error on the samples of the *other* sites is chosen
(ties keep the preset value) and the held-out site is scored with it. Per constant it
prints the all-sample mean at each value, at how many sites the held-out choice
differs from the preset, and the LOSO mean; then the joint LOSO (every constant at its
held-out choice at once, one run per held-out sample). A LOSO mean well above the
all-sample mean says the preset value is fitted to these 15 samples. Cost: 1 + 2 per
constant configurations of the 15 samples (33 x 15 = 495 filter runs for segment-PTD,
about 20–30 min on one core) plus 15 joint runs. ``--loso-pair`` keeps the older joint
3 x 3 grid over the iteration angle and distance.

    python benchmarks/ground_isprs.py [--methods segment-ptd,ptd] [--samples 11,24]
        [--loso] [--loso-pair]
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


def _variants(value):
    """The values a constant is tried at: its preset value, 0.75x and 1.25x (both for a bool)."""
    if isinstance(value, bool):
        return [value, not value]
    if isinstance(value, int):
        return sorted({max(1, round(0.75 * value)), value, round(1.25 * value)})
    return sorted({0.75 * value, value, 1.25 * value})


def loso_all(method: str, clouds: dict, only=None) -> None:
    """Leave-one-site-out over every constant of the sparse preset, one constant at a time."""
    from lidarqa.ground import PRESETS

    preset = PRESETS["als"][method]
    if only:
        preset = {k: v for k, v in preset.items() if k in only}
    t0 = time.perf_counter()
    base = {s: 100 * _score(cloud, method, preset="als")[0].total for s, cloud in clouds.items()}
    sites = sorted({s[0] for s in clouds})
    at_preset = np.mean(list(base.values()))
    print(
        f"\nleave-one-site-out over every constant of the sparse preset ({method}, "
        f"{len(preset)} constants; all-sample mean at the preset {at_preset:.2f} %)"
    )
    print(
        f"{'constant':<22}{'preset':>8}  {'all-sample mean total % per value':<44}"
        f"{'sites moved':>12}{'LOSO mean %':>12}"
    )
    chosen: dict[str, dict[str, object]] = {site: {} for site in sites}
    for k, v in preset.items():
        tot = {(v, s): t for s, t in base.items()}
        values = _variants(v)
        for x in values:
            if x == v:
                continue
            for s, cloud in clouds.items():
                tot[x, s] = 100 * _score(cloud, method, preset="als", **{k: x})[0].total
        held = {}
        moved = 0
        for site in sites:
            train = [s for s in clouds if s[0] != site]
            # lowest training mean; ties keep the preset value
            best = min(values, key=lambda x: (np.mean([tot[x, s] for s in train]), x != v))
            chosen[site][k] = best
            moved += best != v
            for s in clouds:
                if s[0] == site:
                    held[s] = tot[best, s]
        per_value = ", ".join(
            f"{x:g}: {np.mean([tot[x, s] for s in clouds]):.2f}" for x in values
        )
        print(
            f"{k:<22}{v!s:>8}  {per_value:<44}{moved:>8}/{len(sites)}"
            f"{np.mean(list(held.values())):>12.2f}"
        )
    joint = {}
    for site in sites:
        moved = {k: x for k, x in chosen[site].items() if x != preset[k]}
        for s, cloud in clouds.items():
            if s[0] == site:
                joint[s] = (
                    100 * _score(cloud, method, preset="als", **moved)[0].total
                    if moved
                    else base[s]
                )
        print(f"  site {site}: held-out choice differs from the preset in {moved or 'nothing'}")
    print(
        f"  joint LOSO (every constant re-chosen without the held-out site): mean total "
        f"{np.mean(list(joint.values())):.2f} %, max {max(joint.values()):.2f} %; "
        f"preset on all samples {np.mean(list(base.values())):.2f} %, "
        f"max {max(base.values()):.2f} %  ({time.perf_counter() - t0:.0f} s)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--methods", default="segment-ptd,ptd")
    ap.add_argument("--samples", default=",".join(SAMPLES))
    ap.add_argument("--loso", action="store_true", help="LOSO over every preset constant")
    ap.add_argument("--loso-pair", action="store_true", help="LOSO 3x3 grid, angle x distance")
    ap.add_argument("--constants", default=None, help="--loso: only these constants (comma list)")
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
            loso_all(method, clouds, a.constants.split(",") if a.constants else None)
        if a.loso_pair:
            loso(method, clouds)
    print("\nmean total error (%) beside the anchors")
    for method, (m, worst) in means.items():
        name = f"{method} (no options)"
        print(f"  lidarqa {name:<40}{m[2]:>7.2f}   kappa {m[3]:.1f}, worst {worst:.2f}")
    for name, tot, extra in ANCHORS:
        print(f"  {name:<48}{tot:>7}   {extra}")


if __name__ == "__main__":
    main()
