"""Hand-built airborne scenes with known segments, for the segment-PTD pass tests.

Each scene is a list of parts ``(x, y, z, label, kind)``; `assemble` stacks them into
points (offset to realistic projected coordinates), labels and a kind per point.
"""

from __future__ import annotations

import numpy as np

OFFSET = np.array([500000.0, 5400000.0, 0.0])


def grid(x0, x1, y0, y1, spacing, rng):
    """x, y of a grid of `spacing` m over [x0, x1] × [y0, y1], jittered by ±20 %."""
    xs = np.arange(x0 + spacing / 2, x1, spacing)
    ys = np.arange(y0 + spacing / 2, y1, spacing)
    x, y = (a.ravel() for a in np.meshgrid(xs, ys))
    j = rng.uniform(-0.2, 0.2, (2, x.size)) * spacing
    return x + j[0], y + j[1]


def assemble(parts, z0: float):
    """Points (N, 3) shifted by OFFSET and `z0`, labels (N,) int64 and kinds (N,)."""
    pts = np.column_stack([np.concatenate([p[i] for p in parts]) for i in range(3)])
    pts += OFFSET + np.array([0.0, 0.0, z0])
    labels = np.concatenate([np.full(p[0].size, p[3]) for p in parts]).astype(np.int64)
    kind = np.concatenate([np.full(p[0].size, p[4]) for p in parts])
    return pts, labels, kind


def als_filter(**kw):
    """The ALS preset with 20 m seed cells, so each part of a small scene has seeds of its own."""
    from lidarqa.ground import ALS_SEGMENT_PARAMS, SegmentPTD

    return SegmentPTD(**{**ALS_SEGMENT_PARAMS, "cell_size": 20.0, **kw})


def ground_in_both_orders(pts, labels, *, seed: int = 1):
    """Ground masks of `als_filter()` on the scene as given and permuted, in the given order."""
    perm = np.random.default_rng(seed).permutation(len(pts))
    a = als_filter().run(pts, labels=labels).ground_mask
    b = als_filter().run(pts[perm], labels=labels[perm]).ground_mask
    back = np.empty_like(b)
    back[perm] = b
    return a, back
