"""COPC tiles are read chunk by chunk with spatial queries (issue #26, part 4).

Oracle: the full streaming read of the same file (laspy's chunk iterator, record order).
A catalog of one COPC tile read chunk by chunk must give every point as a core point
exactly once, with its true record number, and each chunk's buffered points must be
those a full read puts in the buffered box, in the same order.
"""

from __future__ import annotations

import numpy as np
import pytest
from datapaths import SHARED

from lidarqa.io.las import read_copc_box, read_las
from lidarqa.tiling import make_chunks, open_catalog, read_chunk
from lidarqa.tiling import reader as reader_mod

CORPUS = SHARED / "pdal-corpus"
COPC_FILES = ["copc__1.2-with-color.copc.laz", "copc__lone-star.copc.laz"]


def _needs(name):
    p = CORPUS / name
    if not p.is_file():
        pytest.skip(f"shared {name} is not present")
    return p


@pytest.mark.parametrize("name", COPC_FILES)
def test_chunked_queries_give_every_point_once(name):
    path = _needs(name)
    full = read_las(path)
    catalog = open_catalog([path])
    assert catalog.tiles[0].is_copc
    x0, y0, x1, y1 = catalog.tiles[0].bounds2d
    size = max(x1 - x0, y1 - y0) / 3.7  # cores cut the file at arbitrary places
    chunks = make_chunks(catalog, chunk_size=size, buffer=size / 4)
    assert len(chunks) >= 9
    streamed = []
    seen = np.zeros(len(full), dtype=np.int64)
    for ch in chunks:
        data = read_chunk(catalog, ch)
        ids = data.point_index
        # true record numbers: coordinates and every field equal the full read's
        np.testing.assert_array_equal(data.cloud.xyz, full.xyz[ids])
        for k, v in full.fields.items() if len(ids) else ():
            np.testing.assert_array_equal(data.cloud.fields[k], v[ids], err_msg=k)
        assert np.all(np.diff(ids) > 0), "points must come in record order"
        # exactly the points of the buffered box (closed, as the streaming reader keeps)
        inside = np.nonzero(reader_mod._in_box(full.xyz, ch.buffered))[0]
        np.testing.assert_array_equal(ids, inside)
        np.add.at(seen, ids[data.core], 1)
        streamed.append(len(ids))
    assert np.all(seen == 1), "each point must be a core point of exactly one chunk"
    assert sum(streamed) > len(full)  # buffers overlap: the queries did read partial boxes


def test_query_is_used_for_partial_boxes(monkeypatch):
    path = _needs("copc__1.2-with-color.copc.laz")
    catalog = open_catalog([path])
    x0, y0, x1, y1 = catalog.tiles[0].bounds2d
    chunks = make_chunks(catalog, chunk_size=(x1 - x0) / 2, buffer=0)
    calls = []

    def spy(p, box, *, tol=0.0):
        calls.append(box)
        return read_copc_box(p, box, tol=tol)

    import lidarqa.io.las as las_mod

    monkeypatch.setattr(las_mod, "read_copc_box", spy)
    n = sum(read_chunk(catalog, c).n_core for c in chunks)
    assert n == catalog.n_points
    assert len(calls) == len(chunks) >= 4


def test_box_query_matches_full_read_on_random_boxes():
    path = _needs("copc__lone-star.copc.laz")
    full = read_las(path)
    rng = np.random.default_rng(26)
    mn, mx = full.xyz[:, :2].min(0), full.xyz[:, :2].max(0)
    for _ in range(4):
        a, b = np.sort(rng.uniform(mn, mx, (2, 2)), axis=0)
        box = (a[0], a[1], b[0], b[1])
        cloud, rec = read_copc_box(path, box)
        x, y = full.x, full.y
        want = np.nonzero((x >= box[0]) & (x <= box[2]) & (y >= box[1]) & (y <= box[3]))[0]
        np.testing.assert_array_equal(rec, want)
        np.testing.assert_array_equal(cloud.xyz, full.xyz[want])


def test_not_copc_is_one_line_error(data_dir):
    from lidarqa.errors import LasReadError

    with pytest.raises(LasReadError, match="as COPC") as err:
        read_copc_box(data_dir / "samp24-utm.laz", (0, 0, 1, 1))
    assert "\n" not in str(err.value)
