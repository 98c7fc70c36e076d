"""Catalogs from headers, .vpc round trips and bad catalogs."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.errors import CRSMismatchError, LidarQAError
from lidarqa.tiling import CatalogError, open_catalog


def test_catalog_from_headers_matches_the_points(scene_tiles):
    scene, paths = scene_tiles
    cat = open_catalog(paths[0].parent)
    assert [Path(t.path) for t in cat.tiles] == sorted(p.resolve() for p in paths)
    assert cat.n_points == len(scene.points)
    for t in cat.tiles:
        cloud = lidarqa.read(t.path)
        assert t.n_points == len(cloud)
        mn, mx = cloud.xyz.min(axis=0), cloud.xyz.max(axis=0)
        np.testing.assert_allclose(t.bounds, (mn[0], mn[1], mx[0], mx[1], mn[2], mx[2]), atol=1e-9)
        assert t.point_format == 6 and not t.is_copc
    assert cat.crs is not None and cat.crs.to_epsg() == 2154
    xyz = np.round(scene.points, 3)
    np.testing.assert_allclose(cat.bounds, (*xyz[:, :2].min(0), *xyz[:, :2].max(0)), atol=1e-9)


def test_folder_glob_list_and_vpc_give_the_same_catalog(scene_tiles, tmp_path):
    _, paths = scene_tiles
    folder = paths[0].parent
    a = open_catalog(folder)
    b = open_catalog(str(folder / "*.laz"))
    c = open_catalog([str(p) for p in reversed(paths)])
    vpc = a.write_vpc(tmp_path / "all.vpc")
    d = open_catalog(vpc)
    assert a.tiles == b.tiles == c.tiles == d.tiles
    with pytest.raises(LidarQAError, match="exists"):
        a.write_vpc(vpc)


def test_vpc_structure_is_a_stac_item_collection(scene_tiles, tmp_path):
    _, paths = scene_tiles
    cat = open_catalog(paths)
    (tmp_path / "sub").mkdir()
    vpc = cat.write_vpc(tmp_path / "sub" / "x.vpc")
    doc = json.loads(vpc.read_text())
    assert doc["type"] == "FeatureCollection"
    assert len(doc["features"]) == len(cat.tiles)
    for f, t in zip(doc["features"], cat.tiles, strict=True):
        assert f["type"] == "Feature" and f["stac_version"] == "1.0.0"
        assert any("pointcloud" in e for e in f["stac_extensions"])
        assert any("projection" in e for e in f["stac_extensions"])
        p = f["properties"]
        assert p["pc:count"] == t.n_points and p["pc:type"] == "lidar"
        assert p["proj:epsg"] == 2154 and p["proj:bbox"][0] == t.bounds[0]
        href = f["assets"]["data"]["href"]
        assert not Path(href).is_absolute()
        assert (vpc.parent / href).resolve() == Path(t.path)
        lon, lat = f["bbox"][0], f["bbox"][1]
        assert -180 <= lon <= 180 and -90 <= lat <= 90
    pyogrio = pytest.importorskip("pyogrio")
    meta = pyogrio.read_info(vpc)
    assert meta["features"] == len(cat.tiles)
    assert "Polygon" in meta["geometry_type"]


def _copy_tiles(paths, folder):
    folder.mkdir()
    return [Path(shutil.copy(p, folder / p.name)) for p in paths]


def test_bad_catalogs_name_the_file(scene_tiles, tmp_path):
    _, paths = scene_tiles
    # corrupt tile
    d1 = tmp_path / "corrupt"
    copies = _copy_tiles(paths[:2], d1)
    (d1 / "broken.laz").write_bytes(b"not a las file at all" * 20)
    with pytest.raises(CatalogError, match="broken.laz"):
        open_catalog(d1)
    cat = open_catalog(d1, skip_bad=True)
    assert len(cat.tiles) == 2 and [Path(p).name for p, _ in cat.bad] == ["broken.laz"]
    # truncated LAS (header promises more records)
    las = tmp_path / "t.las"
    lidarqa.write(lidarqa.read(copies[0]), las)
    data = las.read_bytes()
    (d1 / "short.las").write_bytes(data[: len(data) - 100])
    with pytest.raises(CatalogError, match="short.las"):
        open_catalog(d1)
    # empty folder
    (tmp_path / "empty").mkdir()
    with pytest.raises(CatalogError, match="empty"):
        open_catalog(tmp_path / "empty")
    # a .vpc pointing to a missing file
    d2 = tmp_path / "vpc"
    copies2 = _copy_tiles(paths[:2], d2)
    vpc = open_catalog(d2).write_vpc(d2 / "c.vpc")
    copies2[1].unlink()
    with pytest.raises(CatalogError, match=copies2[1].name):
        open_catalog(vpc)
    assert len(open_catalog(vpc, skip_bad=True).tiles) == 1
    # duplicate tiles: the same file twice, or a copy under another name
    with pytest.raises(CatalogError, match="twice"):
        open_catalog([paths[0], paths[0]])
    d3 = tmp_path / "dup"
    _copy_tiles(paths[:2], d3)
    shutil.copy(paths[0], d3 / "zz_copy.laz")
    with pytest.raises(CatalogError, match="zz_copy.laz"):
        open_catalog(d3)
    cat = open_catalog(d3, skip_bad=True)
    assert len(cat.tiles) == 2 and "duplicate" in cat.bad[0][1]


def test_mixed_crs_is_refused_naming_the_files(scene_tiles, tmp_path):
    _, paths = scene_tiles
    d = tmp_path / "crs"
    _copy_tiles(paths[:2], d)
    cloud = lidarqa.read(paths[2])
    from lidarqa.io import PointCloud

    other = PointCloud(cloud.xyz, dict(cloud.fields), crs=lidarqa.io.crs.parse_crs("EPSG:32631"))
    lidarqa.write(other, d / "utm.laz")
    with pytest.raises(CRSMismatchError, match="utm.laz") as info:
        open_catalog(d)
    assert paths[0].name in str(info.value)
    cat = open_catalog(d, skip_bad=True)
    assert len(cat.tiles) == 2 and Path(cat.bad[0][0]).name == "utm.laz"


def test_gaps_and_duplicate_overlaps(scene_tiles, tmp_path):
    from lidarqa.tiling import Catalog, TileInfo

    _, paths = scene_tiles
    full = open_catalog(paths)
    assert full.overlaps() == []
    assert full.gaps() == []  # 2 x 2 tiles whose data extents are a little under 60 m
    # a 3 x 3 block of 100 m tiles without its centre tile: one gap, where the centre was
    tiles = tuple(
        TileInfo(
            f"/t_{i}_{j}.laz",
            10,
            (i * 100.0, j * 100.0, i * 100.0 + 100, j * 100.0 + 100, 0, 1),
            None,
            6,
            "1.4",
        )
        for i in range(3)
        for j in range(3)
        if (i, j) != (1, 1)
    )
    cat = Catalog(tiles)
    assert cat.gaps() == [(100.0, 100.0, 200.0, 200.0)]
    assert Catalog(tiles[:4] + tiles[4:]).overlaps() == []
    # a tile cut from the same area as another, under a different name: a duplicate overlap
    cloud = lidarqa.read(paths[0])
    lidarqa.write(cloud.subset(np.arange(len(cloud)) % 2 == 0), tmp_path / "half.laz")
    cat2 = open_catalog([*paths, tmp_path / "half.laz"])
    ov = cat2.overlaps()
    assert len(ov) == 1 and {Path(p).name for p in ov[0]["tiles"]} == {
        paths[0].name,
        "half.laz",
    }


def test_cli_info_on_a_catalog(scene_tiles, tmp_path):
    from lidarqa.cli.main import cli

    _, paths = scene_tiles
    out = tmp_path / "info.json"
    r = CliRunner().invoke(cli, ["info", str(paths[0].parent), "--json", str(out)])
    assert r.exit_code == 0, r.output
    assert re.search(rf"^  tiles +{len(paths)}$", r.output, re.M)
    doc = json.loads(out.read_text())
    assert doc["results"]["n_points"] == sum(len(lidarqa.read(p)) for p in paths)
    r = CliRunner().invoke(cli, ["info", str(tmp_path / "nothing" / "*.laz")])
    assert r.exit_code == 1 and "matches no" in r.output
    # --strips: points per point source id, streamed from the tiles
    r = CliRunner().invoke(
        cli, ["info", str(paths[0].parent), "--strips", "--json", str(tmp_path / "s.json")]
    )
    assert r.exit_code == 0, r.output
    strips = json.loads((tmp_path / "s.json").read_text())["results"]["strips"]
    ids = np.concatenate([np.asarray(lidarqa.read(p).fields["point_source_id"]) for p in paths])
    u, c = np.unique(ids, return_counts=True)
    assert {int(k): int(v) for k, v in strips.items()} == dict(
        zip(u.tolist(), c.tolist(), strict=True)
    )
    assert re.search(rf"^  {u[0]} +{c[0]:,}$", r.output, re.M)  # the flight strips table
