"""lidarqa qc block checks: relative accuracy (swaths judged with the profile's limits) and
ground consistency (the delivery's class 2 against lidarqa's ground filter)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lidarqa.io.las import read_las, write_las
from lidarqa.qc import run_qc
from lidarqa.testing import make_delivery


def _edit(path, fn):
    """Rewrite one tile in place with `fn(cloud)` applied (keeps its header and format)."""
    c = read_las(path)
    fn(c)
    write_las(c, path, overwrite=True)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return make_delivery(tmp_path_factory.mktemp("clean") / "tiles", nx=2, ny=1,
                         tile_size=100, density=4.0, seed=3)


@pytest.fixture(scope="module")
def shifted(tmp_path_factory):
    """Swath 2 raised by 0.25 m: over the QL2 RMSDz (0.08 m) and max |dz| (0.16 m)."""
    d = make_delivery(tmp_path_factory.mktemp("shifted") / "tiles", nx=2, ny=1,
                      tile_size=100, density=4.0, seed=3)

    def raise_swath2(c):
        c.xyz[np.asarray(c.fields["point_source_id"]) == 2, 2] += 0.25

    for p in d.paths:
        _edit(p, raise_swath2)
    return d


def test_relative_accuracy_passes_a_clean_block_and_fails_a_shifted_swath(clean, shifted,
                                                                          tmp_path):
    ok = run_qc(clean.paths[0].parent, "usgs-ql2", relative_accuracy=True).block
    bad = run_qc(shifted.paths[0].parent, "usgs-ql2", relative_accuracy=True).block
    ra, rb = ok["relative_accuracy"], bad["relative_accuracy"]
    assert ra["status"] == "pass" and ra["n_pairs"] >= 1, ra
    assert ra["value"] < 0.02
    assert rb["status"] == "fail", rb
    # the pair difference is the planted shift (flat synthetic ground, no noise in z)
    assert rb["value"] == pytest.approx(0.25, abs=0.03)
    assert rb["limit"] == 0.08 and rb["limits"]["max_abs_dz_m"] == 0.16
    # a looser profile of one's own (QL3: 0.16 / 0.32 m) still fails RMSDz, not max |dz|
    b3 = run_qc(shifted.paths[0].parent, "usgs-ql3", relative_accuracy=True).block
    assert b3["relative_accuracy"]["status"] == "fail"
    assert "largest |dz|" not in b3["relative_accuracy"]["message"]


def test_relative_accuracy_without_strips_is_not_assessed(clean, tmp_path):
    def one_strip(c):
        c.fields["point_source_id"][:] = 1

    d = make_delivery(tmp_path / "tiles", nx=1, ny=1, tile_size=60, density=3.0, seed=5)
    _edit(d.paths[0], one_strip)
    b = run_qc(d.paths[0].parent, "usgs-ql2", relative_accuracy=True).block
    assert b["relative_accuracy"]["status"] == "warn"
    assert b["relative_accuracy"]["message"].startswith("not assessed")


@pytest.mark.slow  # ~6 s: the ground filter on a whole delivery
def test_ground_consistency_maps_ground_the_delivery_left_unclassified(clean, tmp_path):
    """Class 2 wiped in the western 40 m of the block: the disagreement is there, its size
    is the number of wiped ground points, and it is information (the verdict holds)."""
    d = make_delivery(tmp_path / "tiles", nx=2, ny=1, tile_size=100, density=4.0, seed=3)
    x0 = 500_000.0  # make_delivery's default origin
    x_cut = x0 + 40.0
    wiped = 0

    def wipe(c):
        nonlocal wiped
        cls = c.fields["classification"]
        m = (c.xyz[:, 0] < x_cut) & (cls == 2)
        wiped += int(m.sum())
        cls[m] = 1

    for p in d.paths:
        _edit(p, wipe)
    base = run_qc(clean.paths[0].parent, "usgs-ql2", ground_consistency=True)
    res = run_qc(d.paths[0].parent, "usgs-ql2", ground_consistency=True,
                 out=tmp_path / "out")
    g0, g = base.block["ground_consistency"], res.block["ground_consistency"]
    assert g0["value"] > 0.99 and g0["n_areas"] == 0
    assert g["status"] == "pass"  # information, never a verdict
    assert g["n_filter_only"] == pytest.approx(wiped, rel=0.02)
    assert g["value"] == pytest.approx(1 - wiped / g["n_compared"], abs=0.01)
    polys = res.ground["polygons"]
    assert polys and all(k == "filter ground only" for _, k in polys)
    area = sum(p.area for p, _ in polys)
    assert area == pytest.approx(40.0 * 100.0, rel=0.15)
    minx = min(p.bounds[0] for p, _ in polys)
    maxx = max(p.bounds[2] for p, _ in polys)
    assert minx <= x0 + 5 and maxx <= x_cut + 5
    doc = json.loads((tmp_path / "out" / "qc.json").read_text())
    assert doc["results"]["block"]["ground_consistency"]["n_filter_only"] == g["n_filter_only"]
    assert (tmp_path / "out" / "ground_consistency.tif").is_file()
    import pyogrio

    layers = [n for n, _ in pyogrio.list_layers(tmp_path / "out" / "qc.gpkg")]
    assert "ground_disagreement" in layers


def test_block_map_draws_every_void_ring_as_one_path():
    """The block map's voids are one compound path (a patch per void made a site with
    10k voids take minutes): every ring is in it once, holes included, shifted by x0, y0."""
    import shapely
    from matplotlib.path import Path as MplPath

    from lidarqa.qc.outputs import _void_path

    boxes = [shapely.box(100 + 3 * i, 50, 102 + 3 * i, 52) for i in range(5000)]
    holed = shapely.Polygon([(0, 0), (10, 0), (10, 10), (0, 10)],
                            [[(2, 2), (4, 2), (4, 4), (2, 4)]])
    multi = shapely.MultiPolygon([shapely.box(20, 20, 21, 21), shapely.box(30, 30, 31, 31)])
    p = _void_path([*boxes, holed, multi], 100.0, 50.0)
    assert np.count_nonzero(p.codes == MplPath.MOVETO) == 5000 + 2 + 2
    assert np.count_nonzero(p.codes == MplPath.CLOSEPOLY) == 5000 + 2 + 2
    assert len(p.vertices) == 5 * (5000 + 2 + 2)
    assert p.vertices[:5, 0].min() == 0.0 and p.vertices[:5, 1].min() == 0.0
    assert _void_path([], 0.0, 0.0) is None
