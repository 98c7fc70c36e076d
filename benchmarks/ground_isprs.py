"""ISPRS filter test (Sithole & Vosselman 2004): both lidarqa filters on the 15 labelled samples.

ONE parameter set per method for all samples (no per-sample tuning):
``lidarqa.ground.PRESETS["als"]`` (``ALS_PARAMS`` for point-PTD, ``ALS_SEGMENT_PARAMS``
for segment-PTD) — what ``lidarqa ground --preset als`` runs. Both sets were chosen
on these same 15 samples (there is no held-out labelled ALS data here).
Prints per-sample type I / type II / total
error (%) and Cohen's kappa (%), the means, and the anchors of issue #3.

    python benchmarks/ground_isprs.py [--methods ptd,segment-ptd] [--samples 11,24]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import lidarqa
from lidarqa.ground import PTD, SegmentPTD, filter_errors

DATA = (
    Path(__file__).resolve().parents[1].parent / "shared" / "lidar-data" / "isprs-filtertest-pdal"
)
SAMPLES = ["11", "12", "21", "22", "23", "24", "31", "41", "42", "51", "52", "53", "54", "61", "71"]

from lidarqa.ground import PRESETS  # noqa: E402

ANCHORS = [
    ("PDAL 2.8 SMRF, default parameters (measured)", "5.14", "kappa 83.3"),
    ("PDAL 2.8 PMF, default parameters (measured)", "8.32", ""),
    ("PDAL 2.8 CSF, default parameters (measured)", "19.24", ""),
    ("Axelsson PTD, tuned per sample (published)", "4.82", ""),
    ("CSF, tuned per sample (published)", "4.39", ""),
    ("SMRF, tuned per sample (published)", "2.97", ""),
    ("Mongus & Zalik 2014 (published)", "2.74", ""),
]


def run(method: str, samples: list[str]) -> list[tuple[str, object, float]]:
    cls = PTD if method == "ptd" else SegmentPTD
    filt = cls(**PRESETS["als"][method])
    rows = []
    for s in samples:
        cloud = lidarqa.read(DATA / f"samp{s}-utm.laz")
        t0 = time.perf_counter()
        g = filt.ground_mask(cloud.xyz)
        dt = time.perf_counter() - t0
        rows.append((s, filter_errors(cloud.classification == 2, g), dt))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--methods", default="ptd,segment-ptd")
    ap.add_argument("--samples", default=",".join(SAMPLES))
    a = ap.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA} is not present")
    samples = a.samples.split(",")
    for m in a.methods.split(","):
        print(f"parameters ({m}):", ", ".join(f"{k}={v}" for k, v in PRESETS["als"][m].items()))
    means = {}
    for method in a.methods.split(","):
        rows = run(method, samples)
        print(f"\n{method}")
        print(
            f"{'sample':<8}{'type I %':>10}{'type II %':>11}{'total %':>9}"
            f"{'kappa %':>9}{'time s':>8}"
        )
        for s, e, dt in rows:
            print(
                f"samp{s:<4}{100 * e.type_i:>10.2f}{100 * e.type_ii:>11.2f}{100 * e.total:>9.2f}"
                f"{100 * e.kappa:>9.1f}{dt:>8.1f}"
            )
        m = [
            np.mean([100 * getattr(e, k) for _, e, _ in rows])
            for k in ("type_i", "type_ii", "total", "kappa")
        ]
        means[method] = m
        print(f"{'mean':<8}{m[0]:>10.2f}{m[1]:>11.2f}{m[2]:>9.2f}{m[3]:>9.1f}")
    print("\nmean total error (%) beside the anchors")
    for method, m in means.items():
        print(f"  lidarqa {method:<40}{m[2]:>7.2f}   kappa {m[3]:.1f}")
    for name, tot, extra in ANCHORS:
        print(f"  {name:<48}{tot:>7}   {extra}")


if __name__ == "__main__":
    main()
