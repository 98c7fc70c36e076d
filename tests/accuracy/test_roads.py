"""3D roads from a 2D map on the right height level (issue #15)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, needs_shared

from lidarqa.accuracy.roads import (
    compare_road_heights,
    read_road_polygons,
    reconstruct_roads,
    smooth_segments,
)
from lidarqa.cli.main import cli
from lidarqa.errors import DegenerateGeometryError, InvalidPointsError, OptionError
from lidarqa.testing.interchange import make_interchange

shapely = pytest.importorskip("shapely")

DATA = __import__("pathlib").Path(__file__).parents[1] / "data"
REAL = SHARED / "ign-lidarhd" / "test_semis_2023_0299_6802_LA93_IGN69.laz"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def scene():
    return make_interchange(seed=1, density=4.0, deck_height=8.0)


@pytest.fixture(scope="module")
def recon(scene):
    return reconstruct_roads(scene.points, scene.polygons, ids=scene.polygon_ids)


def _errors(scene, rec):
    mp = rec.map_points
    truth = scene.true_height(mp.xy - scene.map_shift, scene.polygon_road[mp.polygon])
    return mp.height - truth


def _done_when_scene(scene, rec):
    """Per-scene checks of issue #15; returns (|err| <= 3σ per map point, w without outliers)."""
    # the estimated shift moves the map back onto the laser data
    assert np.all(np.abs(rec.shift + scene.map_shift) <= 0.10)
    mp = rec.map_points
    assert not mp.failed.any()
    err = _errors(scene, rec)
    assert np.all(np.abs(err) < 1.0)  # every map point on its own level (levels >= 6 m apart)
    comp = compare_road_heights(rec, scene.reference_xyz)
    assert np.all(comp.road >= 0)
    # each reference point is compared with its own road's level
    road_of_polygon = {
        int(r): int(scene.polygon_road[np.flatnonzero(rec.polygon_road == r)[0]])
        for r in np.unique(rec.polygon_road)
    }
    assert np.all(np.array([road_of_polygon[r] for r in comp.road]) == scene.reference_road)
    return np.abs(err) <= 3 * mp.sigma, comp.w.w[~comp.w.outlier]


def test_interchange_done_when(scene, recon):
    # The laser block offset is common to tens of metres, so one scene's 138 map points
    # and 975 w-values hold only a few independent block offsets: the fractions are
    # checked over three scenes (8, 6 and 14 m decks) together, each scene on its own
    # for levels and shift (benchmarks/roads_speed.py shows the spread over 20 scenes).
    within, ws = [], []
    for s in (
        scene,
        make_interchange(seed=21, density=3.0, deck_height=6.0),
        make_interchange(seed=22, density=3.0, deck_height=14.0, map_shift=(-0.9, 0.3)),
    ):
        rec = recon if s is scene else reconstruct_roads(s.points, s.polygons)
        a, w = _done_when_scene(s, rec)
        within.append(a)
        ws.append(w)
    assert np.mean(np.concatenate(within)) >= 0.99
    assert 0.9 <= np.std(np.concatenate(ws), ddof=1) <= 1.1


@pytest.mark.parametrize(("deck_height", "seed"), [(6.0, 11), (14.0, 12)])
def test_interchange_deck_heights(deck_height, seed):
    s = make_interchange(seed=seed, density=3.0, deck_height=deck_height, map_shift=(-0.8, 0.5))
    rec = reconstruct_roads(s.points, s.polygons)
    assert np.all(np.abs(rec.shift + s.map_shift) <= 0.10)
    err = _errors(s, rec)
    assert np.all(np.abs(err) < 1.0)
    assert np.mean(np.abs(err) <= 3 * rec.map_points.sigma) >= 0.99


def test_three_levels():
    s = make_interchange(seed=2, density=3.0, third_level=True, map_shift=(0.4, 0.7))
    rec = reconstruct_roads(s.points, s.polygons, ids=s.polygon_ids)
    assert np.all(np.abs(rec.shift + s.map_shift) <= 0.10)
    # three roads, each polygon on its own level (A at 0 m, B at 8 m, C at 14 m over the crossing)
    for truth in range(3):
        assert len(set(rec.polygon_road[s.polygon_road == truth])) == 1
    assert rec.n_roads == 3
    err = _errors(s, rec)
    assert np.all(np.abs(err) < 1.0)
    assert np.mean(np.abs(err) <= 3 * rec.map_points.sigma) >= 0.98
    comp = compare_road_heights(rec, s.reference_xyz)
    road_truth = {
        int(r): int(s.polygon_road[np.flatnonzero(rec.polygon_road == r)[0]])
        for r in np.unique(rec.polygon_road)
    }
    assert np.all(np.array([road_truth[r] for r in comp.road]) == s.reference_road)


def test_interchange_levels_and_growing(scene, recon):
    ids = list(scene.polygon_ids)
    a_mid, b_deck = ids.index("A_mid"), ids.index("B_deck")
    # A_mid is mostly covered by the deck: its deck points are another level, not used
    assert recon.polygon_other[a_mid] > recon.polygon_points[a_mid]
    assert recon.polygon_level[a_mid] < 1.0 and recon.polygon_level[b_deck] > 7.0
    # polygons of one road are merged, the two roads stay apart
    assert len(set(recon.polygon_road[scene.polygon_road == 0])) == 1
    assert len(set(recon.polygon_road[scene.polygon_road == 1])) == 1
    assert recon.n_roads == 2
    # map points of A under the deck carry the lower level
    mp = recon.map_points
    under = (mp.polygon == a_mid) & (np.abs(mp.xy_laser[:, 0]) < 6)
    assert under.any() and np.all(mp.height[under] < 1.0)
    # cars are dropped as small segments or lie on another level: never assigned to a road
    assert np.all(recon.assigned[scene.classification == 1] == -1)
    assert np.mean(recon.labels[scene.classification == 1] == -1) > 0.5
    # the TIN stays within one road per triangle
    tri = recon.triangles
    assert len(tri) and np.all(mp.road[tri] == mp.road[tri[:, :1]])


def test_no_shift_is_not_invented():
    s = make_interchange(seed=4, density=2.0, map_shift=(0.0, 0.0))
    rec = reconstruct_roads(s.points, s.polygons)
    assert np.all(np.abs(rec.shift) <= 0.10)
    # a flat plane shows no edges: the map stays where it is, and says so
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 100, (20_000, 2))
    pts = np.column_stack([xy, 0.01 * xy[:, 0] + rng.normal(0, 0.05, len(xy))])
    rec = reconstruct_roads(pts, [shapely.box(20, 20, 80, 40)])
    assert np.all(rec.shift == 0) and "shift_not_significant" in rec.flags


def test_known_shift_and_order_independence(scene):
    rng = np.random.default_rng(5)
    perm = rng.permutation(len(scene.points))
    a = reconstruct_roads(scene.points, scene.polygons, shift=-scene.map_shift)
    b = reconstruct_roads(scene.points[perm], scene.polygons, shift=-scene.map_shift)
    assert not a.shift_estimated
    np.testing.assert_allclose(a.map_points.height, b.map_points.height, atol=1e-9)
    np.testing.assert_allclose(a.map_points.sigma, b.map_points.sigma, atol=1e-9)


def test_polygon_order_does_not_matter(scene, recon):
    order = np.arange(len(scene.polygons))[::-1]
    rev = reconstruct_roads(
        scene.points, [scene.polygons[i] for i in order], ids=scene.polygon_ids[order]
    )
    np.testing.assert_allclose(rev.shift, recon.shift, atol=1e-9)

    def table(rec):
        mp = rec.map_points
        truth = (
            scene.polygon_road[np.argsort(order)][mp.polygon]
            if rec is rev
            else (scene.polygon_road[mp.polygon])
        )
        key = np.round(mp.xy, 6)
        rows = np.lexsort((truth, key[:, 1], key[:, 0]))
        return key[rows], mp.height[rows], mp.sigma[rows]

    a, b = table(recon), table(rev)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_allclose(a[1], b[1], atol=1e-9)
    np.testing.assert_allclose(a[2], b[2], atol=1e-9)


def test_polygon_without_points_grows_from_neighbour(scene):
    keep = scene.points[:, 0] < 140.0 + scene.map_shift[0]
    pts = scene.points[keep]
    sx, sy = scene.map_shift
    extra = [
        shapely.box(150 + sx, -5 + sy, 170 + sx, 5 + sy),  # beyond the data, touches A_east
        shapely.box(-60 + sx, 40 + sy, -40 + sx, 60 + sy),  # a terrain patch: its own level
        shapely.box(400, 400, 420, 420),  # far outside the cloud
    ]
    polys = list(scene.polygons) + extra
    rec = reconstruct_roads(pts, polys, shift=-scene.map_shift)
    mp = rec.map_points
    grown = len(scene.polygons)
    assert rec.polygon_status[grown] == "grown_from_neighbour"
    rows = mp.polygon == grown
    # heights extrapolated from road A, with a model error that grows with the distance
    assert np.all(np.isfinite(mp.height[rows])) and np.all(mp.sigma_model[rows] > 0)
    far = rows & (mp.xy_laser[:, 0] > 165)
    mid = rows & (mp.xy_laser[:, 0] < 162)
    assert far.any() and mid.any()
    assert np.all(mp.sigma_model[far] > mp.sigma_model[mid].max())
    assert rec.polygon_status[-1] == "no_points"
    assert np.all(mp.failed[mp.polygon == len(polys) - 1])
    assert set(mp.reason[mp.polygon == len(polys) - 1]) == {"no_points"}
    assert "polygons_outside_cloud" in rec.flags and "polygons_without_points" in rec.flags


def test_multipolygon_feature(scene, tmp_path):
    pytest.importorskip("pyogrio")
    from lidarqa.accuracy.roads import write_roads

    polys = list(scene.polygons)
    both = shapely.MultiPolygon([polys[0], polys[2]])  # A_west and A_east as one feature
    rec = reconstruct_roads(scene.points, [both, *polys[1:2], *polys[3:]], shift=-scene.map_shift)
    # split into its parts, which keep the feature's id and each get their level
    assert len(rec.polygons) == len(polys) and list(rec.polygon_ids[:2]) == [0, 0]
    p3 = rec.polygons_3d()
    assert all(g.has_z for g in p3)
    z = shapely.get_coordinates(p3[:2], include_z=True)[:, 2]
    assert np.all(np.abs(z) < 1.0)  # road A's level
    write_roads(rec, tmp_path / "m.gpkg")
    assert (tmp_path / "m.gpkg").stat().st_size > 0


def test_bad_input(scene):
    with pytest.raises(InvalidPointsError, match="empty"):
        reconstruct_roads(scene.points, [])
    bowtie = shapely.Polygon([(0, 0), (10, 10), (10, 0), (0, 10)])
    with pytest.raises(DegenerateGeometryError, match="Self-intersection"):
        reconstruct_roads(scene.points, [bowtie])
    with pytest.raises(OptionError, match="no map polygon overlaps"):
        reconstruct_roads(scene.points, [shapely.box(1e5, 1e5, 1e5 + 10, 1e5 + 10)])
    with pytest.raises(InvalidPointsError, match="LineString"):
        reconstruct_roads(scene.points, [shapely.LineString([(0, 0), (1, 1)])])


def test_smooth_segments_separate_levels_and_drop_cars():
    g = np.stack(np.meshgrid(np.arange(0, 30, 0.5), np.arange(0, 30, 0.5)), -1).reshape(-1, 2)
    road = np.column_stack([g, 0.01 * g[:, 0]])
    deck = np.column_stack([g[g[:, 0] < 10], np.full((g[:, 0] < 10).sum(), 7.0)])
    roof = g[(g[:, 0] > 20) & (g[:, 0] < 22) & (g[:, 1] < 4)]
    car = np.column_stack([roof, np.full(len(roof), 1.5)])
    lab = smooth_segments(np.vstack([road, deck, car]), min_area=20.0)
    n1, n2 = len(road), len(road) + len(deck)
    assert len(set(lab[:n1])) == 1 and len(set(lab[n1:n2])) == 1 and lab[0] != lab[n1]
    assert np.all(lab[n2:] == -1)


@needs_shared
def test_real_bridge_lower_level():
    from lidarqa.io import read

    pc = read(REAL).select(classes=[2, 17])
    polys, ids, crs = read_road_polygons(DATA / "ign-bridge-roads.geojson")
    assert crs.to_epsg() == 2154
    rec = reconstruct_roads(pc.xyz, polys, ids=ids, spacing=2.0)
    mp = rec.map_points
    names = np.asarray(ids).astype(str)
    deck_poly = polys[list(names).index("bridge_deck")]
    lower = names[mp.polygon] == "lower_road"
    under = lower & shapely.contains_xy(deck_poly.buffer(1.0), mp.xy[:, 0], mp.xy[:, 1])
    deck_pts = pc.xyz[pc.classification == 17]
    deck_pts = deck_pts[shapely.contains_xy(deck_poly, deck_pts[:, 0], deck_pts[:, 1])]
    assert len(deck_pts) >= 20
    deck_z = float(np.median(deck_pts[:, 2]))
    assert under.sum() >= 8 and not mp.failed.any()
    # every map point of the lower road under the bridge gets the lower level
    assert np.all(mp.height[under] < deck_z - 4.0)
    # and matches the ground of the cutting next to it
    ground = pc.xyz[pc.classification == 2]
    for x, y, h in zip(mp.xy_laser[under, 0], mp.xy_laser[under, 1], mp.height[under], strict=True):
        d = np.hypot(ground[:, 0] - x, ground[:, 1] - y)
        near = ground[(d < 12) & (np.abs(ground[:, 2] - h) < 3), 2]
        assert near.size >= 3 and abs(np.median(near) - h) < 0.5
    on_deck = names[mp.polygon] == "bridge_deck"
    assert np.all(np.abs(mp.height[on_deck] - deck_z) < 0.5)
    assert np.all(mp.sigma[~mp.failed] < 0.5)


@needs_shared
def test_cli_roads_real(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    out, doc = tmp_path / "roads3d.gpkg", tmp_path / "roads.json"
    r = run("roads", REAL, DATA / "ign-bridge-roads.geojson", "-o", out, "--json", doc, "-q")
    assert r.exit_code == 0, r.output
    layers = {name for name, _ in pyogrio.list_layers(out)}
    assert layers == {"map_points", "polygons_3d", "tin"}
    res = json.loads(doc.read_text())["results"]
    assert res["n_roads"] == 2 and res["n_failed"] == 0 and res["n_triangles"] > 0
    meta, _, wkb, fields = pyogrio.raw.read(str(out), layer="polygons_3d")
    geoms = shapely.from_wkb(wkb)
    assert all(shapely.has_z(geoms))
    # refuses to overwrite
    r = run("roads", REAL, DATA / "ign-bridge-roads.geojson", "-o", out, "-q")
    assert r.exit_code == 1 and "exists" in r.output


@needs_shared
def test_cli_roads_crs_mismatch(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    path = tmp_path / "wgs84.geojson"
    pyogrio.raw.write(
        str(path),
        shapely.to_wkb(np.array([shapely.box(2.1, 48.9, 2.2, 49.0)], dtype=object)),
        geometry_type="Polygon",
        field_data=[np.array([1])],
        fields=["id"],
        crs="EPSG:4326",
        driver="GeoJSON",
    )
    r = run("roads", REAL, path, "-o", tmp_path / "o.gpkg", "-q")
    assert r.exit_code == 1 and "CRS" in r.output and "Traceback" not in r.output


@pytest.fixture(scope="module")
def scene_files(tmp_path_factory):
    """The synthetic interchange as a LAS file, a polygon GeoPackage and a reference CSV."""
    pyogrio = pytest.importorskip("pyogrio")
    from pyproj import CRS

    import lidarqa
    from lidarqa.io import PointCloud

    d = tmp_path_factory.mktemp("roads")
    s = make_interchange(seed=3, density=2.0)
    off = np.array([650_000.0, 6_860_000.0, 100.0])
    pc = PointCloud(
        xyz=s.points + off, fields={"classification": s.classification}, crs=CRS.from_epsg(2154)
    )
    lidarqa.write(pc, d / "cloud.las")
    moved = [shapely.transform(g, lambda c: c + off[:2]) for g in s.polygons]
    pyogrio.raw.write(
        str(d / "map.gpkg"),
        shapely.to_wkb(np.array(moved, dtype=object)),
        geometry_type="Polygon",
        field_data=[s.polygon_ids.astype(str).astype(object)],
        fields=["id"],
        crs="EPSG:2154",
        driver="GPKG",
    )
    with open(d / "ref.csv", "w") as fh:
        fh.write("id,x,y,z\n")
        for i, (x, y, z) in enumerate(s.reference_xyz + off):
            fh.write(f"{i},{x:.3f},{y:.3f},{z:.3f}\n")
    return d, s


def test_cli_heights_with_polygons_tests_each_level(scene_files):
    d, s = scene_files
    out = d / "h.json"
    r = run(
        "heights",
        d / "cloud.las",
        d / "map.gpkg",
        d / "ref.csv",
        "--classes",
        "2,17",
        "--json",
        out,
        "-o",
        d / "h.gpkg",
        "-q",
    )
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())["results"]
    assert res["comparison"]["n"] == len(s.reference_xyz)
    assert res["roads"]["n_roads"] == 2
    assert np.allclose(res["roads"]["shift"], -s.map_shift, atol=0.1)
    # a reference point compared with the wrong level would be a w of ~80
    assert res["w"]["n_outliers"] <= 2 and 0.85 <= res["w"]["std_without_outliers"] <= 1.15


def test_cli_roads_synthetic_and_bad_input(scene_files, tmp_path):
    d, s = scene_files
    r = run(
        "roads",
        d / "cloud.las",
        d / "map.gpkg",
        "-o",
        tmp_path / "r.gpkg",
        "--json",
        tmp_path / "r.json",
        "-q",
    )
    assert r.exit_code == 0, r.output
    res = json.loads((tmp_path / "r.json").read_text())["results"]
    assert res["n_roads"] == 2 and res["n_failed"] == 0
    # a self-intersecting polygon: one clear line, no traceback
    pyogrio = pytest.importorskip("pyogrio")
    bowtie = shapely.Polygon(
        [(650_000, 6_860_000), (650_010, 6_860_010), (650_010, 6_860_000), (650_000, 6_860_010)]
    )
    bad = tmp_path / "bad.geojson"
    pyogrio.raw.write(
        str(bad),
        shapely.to_wkb(np.array([bowtie], dtype=object)),
        geometry_type="Polygon",
        field_data=[np.array([1])],
        fields=["id"],
        crs="EPSG:2154",
        driver="GeoJSON",
    )
    r = run("roads", d / "cloud.las", bad, "-o", tmp_path / "b.gpkg", "-q")
    assert r.exit_code == 1 and "Self-intersection" in r.output and "Traceback" not in r.output
    empty = tmp_path / "empty.geojson"
    empty.write_text('{"type": "FeatureCollection", "features": []}')
    r = run("roads", d / "cloud.las", empty, "-o", tmp_path / "e.gpkg", "-q")
    assert r.exit_code == 1 and "empty" in r.output and "Traceback" not in r.output
    far = tmp_path / "far.geojson"
    pyogrio.raw.write(
        str(far),
        shapely.to_wkb(np.array([shapely.box(0, 0, 10, 10)], dtype=object)),
        geometry_type="Polygon",
        field_data=[np.array([1])],
        fields=["id"],
        crs="EPSG:2154",
        driver="GeoJSON",
    )
    r = run("roads", d / "cloud.las", far, "-o", tmp_path / "f.gpkg", "-q")
    assert r.exit_code == 1 and "no map polygon overlaps" in r.output


@needs_shared
def test_assess_roads_section(tmp_path):
    cfg = tmp_path / "roads.toml"
    cfg.write_text(
        'crs = "EPSG:2154"\n[inputs.clouds]\n'
        f'tile = "{REAL.as_posix()}"\n[inputs.polygons]\n'
        f'bridge = "{(DATA / "ign-bridge-roads.geojson").as_posix()}"\n'
        '[roads]\ncloud = "tile"\nmap = "bridge"\ntarget_sigma_mean = 0.2\n'
    )
    r = run("assess", cfg, "--out", tmp_path / "rep", "-q")
    assert r.exit_code == 0, r.output
    rep = json.loads((tmp_path / "rep" / "report.json").read_text())
    text = json.dumps(rep)
    assert '"n_roads": 2' in text and "roads3d.gpkg" in text


def test_planar_partition_gives_two_heights_where_levels_cross(scene):
    # a planar map: the area under the deck belongs to the deck polygon only, so the corners of
    # road A at the deck edge lie on both roads' boundaries and get one height per level
    sx, sy = scene.map_shift
    box = [
        shapely.box(-150 + sx, -5 + sy, -6 + sx, 5 + sy),
        shapely.box(6 + sx, -5 + sy, 150 + sx, 5 + sy),
        shapely.box(-6 + sx, -175 + sy, 6 + sx, -25 + sy),
        shapely.box(-6 + sx, -25 + sy, 6 + sx, 25 + sy),
        shapely.box(-6 + sx, 25 + sy, 6 + sx, 175 + sy),
    ]
    rec = reconstruct_roads(scene.points, box, shift=-scene.map_shift)
    mp = rec.map_points
    true_road = np.array([0, 0, 1, 1, 1])
    # the two parts of road A are not neighbours: they are separate roads at the same level
    assert len(set(rec.polygon_road[true_road == 1])) == 1
    corner = np.all(np.abs(np.abs(mp.xy - [sx, sy]) - [6, 5]) < 1e-6, axis=1)
    assert corner.sum() == 8  # 4 corners x 2 levels
    for x, y in {(round(a, 6), round(b, 6)) for a, b in mp.xy[corner]}:
        rows = corner & (np.abs(mp.xy[:, 0] - x) < 1e-6) & (np.abs(mp.xy[:, 1] - y) < 1e-6)
        assert rows.sum() == 2
        h = np.sort(mp.height[rows])
        truth = np.sort(scene.true_height([[x - sx, y - sy]] * 2, [0, 1]))
        assert np.all(np.abs(h - truth) <= 3 * np.sort(mp.sigma[rows])[::-1] + 0.05)
        assert h[1] - h[0] > 6


def test_cli_projected_geojson_without_crs(scene_files, tmp_path):
    # a GeoJSON without a 'crs' member is WGS 84 by definition: a map digitised in
    # Lambert-93 and saved that way must be refused with a message that says why
    d, s = scene_files
    feats = [
        {"type": "Feature", "properties": {"id": i}, "geometry": json.loads(shapely.to_geojson(g))}
        for i, g in enumerate(s.polygons)
    ]
    off = np.array([650_000.0, 6_860_000.0])
    for f in feats:
        f["geometry"]["coordinates"] = [
            (np.asarray(ring) + off).tolist() for ring in f["geometry"]["coordinates"]
        ]
    path = tmp_path / "nocrs.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    for cmd in (
        ["roads", d / "cloud.las", path, "-o", tmp_path / "o.gpkg", "-q"],
        ["heights", d / "cloud.las", path, d / "ref.csv", "-q"],
    ):
        r = run(*cmd)
        assert r.exit_code == 1 and "Traceback" not in r.output
        assert "not longitude/latitude" in r.output and "'crs' member" in r.output


def test_seed_density_no_failed_map_points():
    # about one point per 9 m² as in the seed's interchange: the grid segments get small,
    # so map points fall back to all of their road's points instead of failing
    s = make_interchange(seed=1, density=0.11, under_deck_density=0.11 / 3)
    rec = reconstruct_roads(s.points, s.polygons)
    mp = rec.map_points
    assert not mp.failed.any()
    err = _errors(s, rec)
    assert np.all(np.abs(err) < 1.0)
    assert np.mean(np.abs(err) <= 3 * mp.sigma) >= 0.98
    assert np.all(np.abs(rec.shift + s.map_shift) <= 0.15)
