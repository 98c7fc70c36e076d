"""Segment-PTD's perched-surface test judges a segment it cuts into as a whole.

A flat roof built into a hillside meets the terrain along its uphill edge and stands
on walls elsewhere. The perched-surface test (drops on opposite sides) sees only its
narrow downhill wing; the unsegmented points of the wing's parapet, accepted
point-wise, shielded the roof's border from the raised test (a raised border needs
the nearest ground of another segment to be a storey lower). Once the perched test
has taken the wing and its parapet, the rest of the roof is judged by the raised test
against the ground that remains, and goes with it. A terrace cut into the same
hillside, with the same outline, heights and parapet but embankments (34°) instead of
walls, is never perched and stays ground. The scene is built by hand with known
segments, so the test does not depend on surface growing.
"""

from __future__ import annotations

import numpy as np
import pytest
from handmade import als_filter, assemble, grid

GRADE = 0.3  # the hillside falls by 0.3 m per m in +x (17°)
DEPTH, WIDTH = 28.0, 16.0  # the main body of the outline: downhill depth, width (m)
WING_W, WING_L = 6.0, 12.0  # a narrow wing further downhill
PARAPET = 1.5  # the wing's edge band left unsegmented (m)
TERRAIN, ROOF, WALL, TERRACE, BANK = range(5)


def _terrain(x):
    return -GRADE * x


def _outline(x, y, x0):
    body = (x > x0) & (x < x0 + DEPTH) & (np.abs(y - 25) < WIDTH / 2)
    wing = (x >= x0 + DEPTH) & (x < x0 + DEPTH + WING_L) & (np.abs(y - 25) < WING_W / 2)
    return body | wing


def _walls(x0, z, rng):
    """Sparse points (0.4 per m) on the walls of the roof: all sides but the uphill one."""
    x1, x2 = x0 + DEPTH, x0 + DEPTH + WING_L
    a, b = 25 - WING_W / 2, 25 + WING_W / 2
    lo, hi = 25 - WIDTH / 2, 25 + WIDTH / 2
    sides = [
        (x1, lo, x1, a), (x1, b, x1, hi), (x1, a, x2, a), (x1, b, x2, b), (x2, a, x2, b),
        (x0, lo, x1, lo), (x0, hi, x1, hi),
    ]  # fmt: skip
    out = []
    for i, (xa, ya, xb, yb) in enumerate(sides):
        k = max(1, int(0.4 * np.hypot(xb - xa, yb - ya)))
        t, h = rng.uniform(0, 1, (2, k))
        wx, wy = xa + t * (xb - xa), ya + t * (yb - ya)
        out.append((wx, wy, _terrain(wx) + h * (z - _terrain(wx)), 10 + i, WALL))
    return out


def _top(x0, kind, label, rng):
    """The roof or terrace surface: flat, 0.2 m over the uphill terrain; parapet unsegmented."""
    z = _terrain(x0) + 0.2
    x, y = grid(x0, x0 + DEPTH + WING_L, 0, 50, 1.0, rng)
    m = _outline(x, y, x0)
    inner = np.ones_like(m)
    for dx, dy in ((PARAPET, 0), (-PARAPET, 0), (0, PARAPET), (0, -PARAPET)):
        inner &= _outline(x + dx, y + dy, x0)
    rim = m & ~inner & (x > x0 + DEPTH)
    top = m & ~rim
    return [
        (x[top], y[top], np.full(top.sum(), z), label, kind),
        (x[rim], y[rim], z + rng.uniform(0, 0.3, rim.sum()), -1, kind),
    ]


def _scene(seed: int = 0):
    """A 1 pt/m² hillside with a roof built into it (x from 20) and a terrace (x from 70).

    Labels: 0 terrain, 1 the roof, 3 the terrace, 10-16 the roof's walls, -1 the
    parapets. The terrace's surroundings rise to it at 34° (embankments).
    """
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    x, y = grid(0, 130, 0, 50, 1.0, rng)
    keep = ~_outline(x, y, 20) & ~_outline(x, y, 70)
    x, y = x[keep], y[keep]
    step = 0.25
    gx, gy = np.meshgrid(np.arange(0, 130, step) + step / 2, np.arange(0, 50, step) + step / 2,
                         indexing="ij")  # fmt: skip
    dist = ndimage.distance_transform_edt(~_outline(gx, gy, 70)) * step
    d = dist[np.minimum((x / step).astype(int), gx.shape[0] - 1),
             np.minimum((y / step).astype(int), gx.shape[1] - 1)]  # fmt: skip
    z = np.maximum(_terrain(x), _terrain(70) + 0.2 - d * np.tan(np.radians(34)))
    bank = z > _terrain(x) + 0.05
    parts = [(x[~bank], y[~bank], z[~bank], 0, TERRAIN), (x[bank], y[bank], z[bank], 0, BANK)]
    parts += _top(20.0, ROOF, 1, rng) + _walls(20.0, _terrain(20.0) + 0.2, rng)
    parts += _top(70.0, TERRACE, 3, rng)
    return assemble(parts, 300.0)


def test_without_the_perched_test_roof_and_terrace_are_ground():
    # the scene is a real test: the raised test and the final roof check let the roof in
    pts, labels, kind = _scene()
    g = als_filter(perched_step=0.0).run(pts, labels=labels).ground_mask
    assert g[kind == ROOF].mean() > 0.95
    assert g[kind == TERRACE].mean() > 0.95


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_roof_goes_whole_and_the_terrace_stays(seed):
    pts, labels, kind = _scene(seed)
    off = als_filter(perched_step=0.0).run(pts, labels=labels).ground_mask
    on = als_filter().run(pts, labels=labels).ground_mask
    # the perched cells alone are the wing; the whole roof plane goes with them
    assert not on[labels == 1].any()
    assert on[kind == ROOF].mean() < 0.02
    # the terrace, its embankments and the terrain keep their labels
    for k in (TERRACE, BANK, TERRAIN):
        assert np.array_equal(on[kind == k], off[kind == k]), k
    assert on[kind == TERRACE].mean() > 0.95
