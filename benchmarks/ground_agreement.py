"""Label agreement of ``lidarqa ground`` (NO options) between two versions of the code.

A speed change must not change the labels beyond noise (issue #28: >= 99.9 % of the
points keep their label on every file). Run once with the reference version on the
path, saving its ground masks, then with the changed version, comparing:

    PYTHONPATH=/path/to/main/src python benchmarks/ground_agreement.py --save before.npz
    python benchmarks/ground_agreement.py --compare before.npz [--only bcts,oakland]

Files (``../shared/lidar-data``): the IGN tiles, the BC forest tiles, the 8 Oakland
MLS chunks and the 15 ISPRS samples. Prints per file the points, the ground count,
the CPU seconds of the filter and, with ``--compare``, the share of points whose
label is the same and the number that changed; exits 1 when a file is below
``--min`` (default 99.9 %).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import lidarqa
from lidarqa.ground import classify_ground

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "lidar-data"


def files() -> list[Path]:
    """The data files of the check, in a fixed order."""
    return (
        sorted((SHARED / "ign-lidarhd").glob("*.laz"))
        + sorted((SHARED / "lasR-bcts").glob("*.laz"))
        + sorted((SHARED / "oakland-mls").glob("*.laz"))
        + sorted((SHARED / "isprs-filtertest-pdal").glob("samp*.laz"))
    )


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--save", help="write the ground masks to this .npz")
    ap.add_argument("--compare", help="compare with the masks of this .npz")
    ap.add_argument("--only", help="comma-separated substrings of the file names")
    ap.add_argument("--min", type=float, default=99.9, help="least agreement, %% per file")
    a = ap.parse_args()
    todo = files()
    if a.only:
        todo = [f for f in todo if any(k in f.name for k in a.only.split(","))]
    ref = np.load(a.compare) if a.compare else None
    masks = {}
    worst = 100.0
    print(f"{'file':<48}{'points':>10}{'ground':>10}{'CPU s':>8}{'agree %':>10}{'changed':>9}")
    for f in todo:
        cloud = lidarqa.read(f)
        t = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = classify_ground(cloud).ground_mask
        dt = time.process_time() - t
        masks[f.stem] = g
        line = f"{f.stem:<48}{len(cloud):>10,}{int(g.sum()):>10,}{dt:>8.1f}"
        if ref is not None and f.stem in ref:
            same = ref[f.stem] == g
            agree = 100.0 * float(same.mean())
            worst = min(worst, agree)
            line += f"{agree:>10.3f}{int((~same).sum()):>9,}"
        print(line, flush=True)
    if a.save:
        np.savez_compressed(a.save, **masks)
    if ref is not None:
        print(f"lowest agreement {worst:.3f} % (goal >= {a.min} %)")
        return 0 if worst >= a.min else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
