"""The chunk grid: every point is a core point of exactly one chunk, inside its buffered box."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidarqa.errors import OptionError
from lidarqa.tiling import Catalog, TileInfo, make_chunks, open_catalog, read_chunk
from lidarqa.tiling.chunks import default_chunk_size


def _catalog(tile_points: list[np.ndarray]) -> Catalog:
    tiles = []
    for k, p in enumerate(tile_points):
        mn, mx = p.min(axis=0), p.max(axis=0)
        tiles.append(
            TileInfo(
                f"/t{k:03d}.laz", len(p), (mn[0], mn[1], mx[0], mx[1], 0.0, 1.0), None, 6, "1.4"
            )
        )
    return Catalog(tuple(tiles))


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_tiles=st.integers(1, 4),
    size=st.sampled_from([0.7, 2.5, 10.0, 33.3]),
    buffer=st.sampled_from([0.0, 0.5, 3.0]),
    origin=st.tuples(st.floats(-50, 50), st.floats(-50, 50)),
    quantum=st.sampled_from([0.01, 0.5, 1.0]),
)
def test_every_point_is_core_in_exactly_one_chunk(seed, n_tiles, size, buffer, origin, quantum):
    rng = np.random.default_rng(seed)
    tiles = []
    for _ in range(n_tiles):
        x0, y0 = rng.uniform(-30, 30, 2)
        n = int(rng.integers(1, 100))
        p = np.column_stack([x0 + rng.uniform(0, 8, n), y0 + rng.uniform(0, 8, n)])
        tiles.append(np.round(p / quantum) * quantum)  # points on grid lines happen
    cat = _catalog(tiles)
    chunks = make_chunks(cat, chunk_size=size, buffer=buffer, origin=origin)
    assert len({c.id for c in chunks}) == len(chunks)
    for k, p in enumerate(tiles):
        hits = np.zeros(len(p), dtype=np.int64)
        for c in chunks:
            m = c.core_mask(p)
            if m.any():
                assert k in c.tiles
                b = c.buffered
                q = p[m]
                tol = 1e-6  # the reader widens boxes by this much
                assert (q[:, 0] >= b[0] - tol).all() and (q[:, 0] <= b[2] + tol).all()
                assert (q[:, 1] >= b[1] - tol).all() and (q[:, 1] <= b[3] + tol).all()
                # the half-open core box agrees with the grid-index rule (up to rounding)
                assert (q[:, 0] >= c.core[0] - 1e-9).all() and (q[:, 0] <= c.core[2] + 1e-9).all()
            hits += m
        assert (hits == 1).all()


def test_chunk_ids_are_stable_and_rows_go_south_to_north(scene_tiles):
    _, paths = scene_tiles
    cat = open_catalog(paths)
    a = make_chunks(cat, chunk_size=40.0, buffer=10.0)
    b = make_chunks(open_catalog(list(reversed(paths))), chunk_size=40.0, buffer=10.0)
    assert a == b
    assert a[0].id == "c0000_r0000"
    assert [(c.row, c.col) for c in a] == sorted((c.row, c.col) for c in a)
    with pytest.raises(OptionError):
        make_chunks(cat, chunk_size=0.0)
    with pytest.raises(OptionError):
        make_chunks(cat, chunk_size=10.0, buffer=-1.0)


def test_default_chunk_size_follows_density_and_tiles(scene_tiles):
    _, paths = scene_tiles
    cat = open_catalog(paths)
    size = default_chunk_size(cat)
    tile = cat.tile_size()
    assert tile == 60.0  # nominal 60 m tiles whose data extents are a little smaller
    # a fraction tile/k or a multiple of the tile size
    ratio = size / tile if size >= tile else tile / size
    assert abs(ratio - round(ratio)) < 1e-9
    # buffered chunks stay near the point target at this density
    from lidarqa.tiling.chunks import TARGET_POINTS

    assert (size + 120.0) ** 2 * cat.density >= 0.2 * TARGET_POINTS or size >= tile


def _grid_catalog(tile: float, density: float, n: int = 3) -> Catalog:
    tiles = [
        TileInfo(
            f"/t{i}{j}.laz",
            int(density * tile * tile),
            (i * tile, j * tile, (i + 1) * tile - 0.01, (j + 1) * tile - 0.01, 0.0, 1.0),
            None,
            6,
            "1.4",
        )
        for i in range(n)
        for j in range(n)
    ]
    return Catalog(tuple(tiles))


@pytest.mark.parametrize(
    "target,tile,density,expected,n",
    [
        # the default target (3.5 M points per buffered chunk)
        (None, 1000.0, 25.0, 250.0, 3),  # 1000 / 4: aligned with the tiles, 1 % more work
        (None, 305.0, 25.0, 250.0, 3),  # 305 / 2 would be 46 % more work: not snapped
        (None, 50.0, 25.0, 250.0, 6),  # 5 tiles of 50 m
        (None, 1000.0, 2.0, 1000.0, 3),  # sparse: one tile per chunk (2 would be over the target)
        # the ground job's (6 M)
        (6e6, 1000.0, 25.0, 1000.0 / 3, 3),  # aligned with the tiles, 5 % more work than 370 m
        (6e6, 216.0, 25.0, 360.0, 4),  # 216 m would be 36 % more work: not snapped, 10 m steps
        (6e6, 305.0, 25.0, 305.0, 3),  # one tile per chunk: 11 % more work than 370 m
        (6e6, 50.0, 25.0, 350.0, 9),  # 7 tiles of 50 m
    ],
)
def test_default_chunk_size_snaps_only_when_cheap(target, tile, density, expected, n):
    from lidarqa.tiling.chunks import DEFAULT_BUFFER, SNAP_TOLERANCE, TARGET_POINTS, _work

    cat = _grid_catalog(tile, density, n)
    size = default_chunk_size(cat, target_points=target)
    assert size == pytest.approx(expected)
    raw = ((target or TARGET_POINTS) / cat.density) ** 0.5 - 2 * DEFAULT_BUFFER
    assert size <= raw + 1e-9  # the buffered box never holds more than the target
    assert _work(size, DEFAULT_BUFFER) <= SNAP_TOLERANCE * _work(raw, DEFAULT_BUFFER) or (
        size == pytest.approx(raw // 10 * 10)
    )
    chunks = make_chunks(cat, target_points=target)
    assert chunks and chunks[0].size == pytest.approx(size)


def test_estimated_points_follow_the_overlap():
    from lidarqa.tiling.chunks import estimated_points

    cat = _grid_catalog(100.0, 10.0, n=2)  # 100 000 points per tile
    chunks = make_chunks(cat, chunk_size=100.0, buffer=50.0)
    est = {c.id: estimated_points(cat, c) for c in chunks}
    # a corner chunk's buffered box covers its tile and half of each neighbour, a quarter
    # of the diagonal one: 1 + 0.5 + 0.5 + 0.25 tiles
    assert est["c0000_r0000"] == pytest.approx(225_000, rel=1e-3)
    # symmetric block (tiles are 99.99 m: the 0.01 m gaps shift a few points)
    assert max(est.values()) == pytest.approx(min(est.values()), rel=1e-3)


def test_read_chunk_streams_core_and_buffer(scene_tiles):
    import lidarqa

    scene, paths = scene_tiles
    cat = open_catalog(paths)
    chunks = make_chunks(cat, chunk_size=45.0, buffer=7.5)
    total = 0
    for c in chunks:
        d = read_chunk(cat, c)
        total += d.n_core
        # every point read lies in the buffered box and carries its file and record number
        b = c.buffered
        xyz = d.cloud.xyz
        assert ((xyz[:, 0] >= b[0]) & (xyz[:, 0] <= b[2])).all()
        for t in np.unique(d.tile_index):
            cloud = lidarqa.read(cat.tiles[t].path)
            sel = d.tile_index == t
            np.testing.assert_array_equal(cloud.xyz[d.point_index[sel]], xyz[sel])
            np.testing.assert_array_equal(
                cloud.fields["classification"][d.point_index[sel]],
                d.cloud.fields["classification"][sel],
            )
    assert total == len(scene.points)


def test_points_on_the_catalogs_east_and_north_edge_open_no_extra_chunks():
    # a 50 m tile whose data reach x = 50 and y = 50 exactly (as IGN tiles do)
    g = np.arange(0.0, 50.01, 2.5)
    p = np.column_stack([np.repeat(g, len(g)), np.tile(g, len(g))])
    cat = _catalog([p, p + [50.0, 0.0]])
    chunks = make_chunks(cat, chunk_size=50.0, buffer=5.0)
    assert [c.id for c in chunks] == ["c0000_r0000", "c0001_r0000"]
    for q in (p, p + [50.0, 0.0]):
        hits = sum(c.core_mask(q).astype(int) for c in chunks)
        assert (hits == 1).all()
    # x = 50 is a border between two tiles: those points stay in the east chunk
    west = chunks[0].core_mask(p + [50.0, 0.0])
    assert not west.any()


def test_dense_catalog_chunks_are_a_few_buffers_wide():
    """306 pts/m2 (a TLS scan) with a 60 m buffer: 120 m chunks, not 20 m ones."""
    from lidarqa.tiling.chunks import MIN_BUFFERS, TARGET_POINTS, _work

    cat = _grid_catalog(100.0, 306.0, n=4)
    # the point target alone would give a chunk narrower than two buffers (20 m once)
    assert (TARGET_POINTS / cat.density) ** 0.5 - 2 * 60.0 < MIN_BUFFERS * 60.0
    size = default_chunk_size(cat, buffer=60.0)
    assert size == pytest.approx(MIN_BUFFERS * 60.0)
    assert _work(size, 60.0) <= 4.0 + 1e-9  # was 49 with 20 m chunks
    assert default_chunk_size(cat, buffer=10.0) < size  # a smaller buffer allows smaller chunks


@pytest.mark.parametrize("x0", [515368.60225, 0.0, 59.5, -120.3])
def test_catalog_that_fits_one_chunk_is_one_chunk(x0):
    """A 32 x 41 m scan at 306 pts/m2 anywhere on the grid: one chunk, not 4 or 9."""
    n = int(306 * 32.44 * 40.76)
    tile = TileInfo(
        "/scan.laz", n, (x0, 4918340.36, x0 + 32.44, 4918381.12, 0.0, 1.0), None, 6, "1.4"
    )
    cat = Catalog((tile,))
    for buffer in (60.0, 41.0, 5.0):
        chunks = make_chunks(cat, buffer=buffer)
        assert len(chunks) == 1, buffer
        c = chunks[0]
        assert c.core[0] <= x0 and c.core[2] >= x0 + 32.44
        assert c.size >= 40.76


def test_ground_buffer_is_the_seed_cell_capped_by_the_catalog():
    from lidarqa.tiling.ground import ground_buffer

    assert ground_buffer(cell_size=60.0) == 60.0
    assert ground_buffer(cell_size=25.0) == 25.0  # scales with the filter
    big = _grid_catalog(100.0, 10.0, n=3)  # 300 m across
    assert ground_buffer(big) == 60.0
    small = _grid_catalog(10.0, 10.0, n=2)  # 20 m across: a wider buffer reads nothing more
    assert ground_buffer(small) == pytest.approx(20.0)


def test_ground_buffer_is_two_seed_cells_under_a_canopy():
    from lidarqa.tiling.ground import ground_buffer

    assert ground_buffer(cell_size=60.0, canopy=True) == 120.0
    assert ground_buffer(cell_size=25.0, canopy=True) == 50.0
    big = _grid_catalog(100.0, 10.0, n=3)  # 300 m across
    assert ground_buffer(big, canopy=True) == 120.0
    small = _grid_catalog(10.0, 10.0, n=2)
    assert ground_buffer(small, canopy=True) == pytest.approx(20.0)  # still capped
