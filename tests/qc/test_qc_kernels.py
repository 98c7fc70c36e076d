"""qc's numba kernels against independent oracles (scipy's morphology; plain NumPy counts)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from lidarqa.qc._kernels import open_square
from lidarqa.qc.density import DensityGrids


@settings(max_examples=60, deadline=None)
@given(ny=st.integers(1, 40), nx=st.integers(1, 40), k=st.sampled_from([1, 3, 5, 9]),
       fill=st.floats(0.3, 0.99), seed=st.integers(0, 2**31))
def test_open_square_is_scipys_opening(ny, nx, k, fill, seed):
    empty = np.random.default_rng(seed).random((ny, nx)) < fill
    e = ndimage.minimum_filter(empty.astype(np.uint8), size=k, mode="constant", cval=0)
    want = ndimage.maximum_filter(e, size=k, mode="constant", cval=0).astype(bool) & empty
    assert np.array_equal(open_square(empty, k), want)


def _fields(rng, n):
    return {
        "return_number": rng.integers(0, 4, n).astype(np.uint8),
        "number_of_returns": rng.integers(1, 4, n).astype(np.uint8),
        "classification": rng.choice(np.array([1, 2, 9, 12], np.uint8), n),
        "withheld": rng.random(n) < 0.05,
        "overlap": rng.random(n) < 0.1,
        "synthetic": rng.random(n) < 0.02,
        "key_point": rng.random(n) < 0.01,
        "point_source_id": rng.choice(np.array([0, 7, 9], np.uint16), n),
        "scan_angle": rng.integers(-3000, 3000, n).astype(np.int16),
    }


def test_scan_counts_equal_numpy_and_do_not_depend_on_the_piece_size():
    rng = np.random.default_rng(4)
    n = 20_000
    xyz = np.column_stack([rng.uniform(0, 50, n), rng.uniform(0, 40, n), rng.normal(10, 3, n)])
    xyz[:50, 0] += 100.0  # outside the header bounds
    f = _fields(rng, n)
    bounds = (0.0, 0.0, 50.0, 40.0)

    def scan(step):
        g = DensityGrids(bounds, cell=1.0, void_cell=0.25, coarse_factor=2)
        for a in range(0, n, step):
            g.scan(xyz[a:a + step], {k: v[a:a + step] for k, v in f.items()}, point_format=6)
        return g

    g = scan(n)
    s = g.stats()
    rn, nr = f["return_number"].astype(int), f["number_of_returns"].astype(int)
    assert s.n == n
    assert s.invalid_returns == int(((rn < 1) | (rn > nr) | (nr > 15)).sum())
    assert s.by_return[:3] == tuple(int((rn == r).sum()) for r in (1, 2, 3))
    assert s.classes[9] == int((f["classification"] == 9).sum())
    assert s.withheld == int(f["withheld"].sum()) and s.overlap == int(f["overlap"].sum())
    assert s.source_ids == {i: int((f["point_source_id"] == i).sum()) for i in (0, 7, 9)}
    assert np.isclose(s.scan_angle_max, f["scan_angle"].max() * 0.006)
    assert s.mins == tuple(xyz.min(axis=0)) and s.maxs == tuple(xyz.max(axis=0))
    first = rn == 1
    usable = first & ~f["withheld"]
    inside = xyz[:, 0] < 50.0 + 1.0
    i = np.floor(xyz[:, 0]).astype(int)
    j = np.floor(xyz[:, 1]).astype(int)
    want = np.zeros((g.fine.ny, g.fine.nx), int)
    np.add.at(want, (j[usable & inside], i[usable & inside]), 1)
    assert np.array_equal(g.firsts.reshape(g.fine.ny, g.fine.nx), want)
    assert g.outside == int((~inside).sum())
    assert g.flagged == int((usable & f["overlap"]).sum())
    counted = first & ~f["withheld"] & ~f["overlap"] & inside
    for sid, row in zip(sorted(g.slots), g.counts, strict=False):
        assert row.sum() == int((counted & (f["point_source_id"] == sid)).sum())
    # pieces of any size give the same tile
    for step in (1_000, 7_777):
        h = scan(step)
        assert h.stats() == s
        assert np.array_equal(h.firsts, g.firsts) and np.array_equal(h.occupied, g.occupied)
        assert all(np.array_equal(a, b) for a, b in zip(h.counts, g.counts, strict=True))
