"""Synthetic scenes: determinism, density, noise and exactness of the truth."""

from __future__ import annotations

import numpy as np
import pytest

import lidarqa
from lidarqa.errors import InvalidPointsError, OptionError
from lidarqa.testing import (
    BuildingSpec,
    Scene,
    cases,
    make_building_scene,
    make_scene,
    make_terrain_scene,
    plane_area,
    rigid_motion,
    rotation_matrix,
)
from lidarqa.testing._shapes import in_rectangle

NOISE = 0.02


@pytest.fixture(scope="module")
def buildings() -> Scene:
    return make_building_scene(seed=3, roofs=("flat", "gable") * 3)


@pytest.fixture(scope="module")
def full() -> Scene:
    return make_scene(seed=5, size=(120.0, 100.0), embankment=True, outliers=20, returns=True)


def _assert_truth_exact(scene: Scene, tol: float) -> None:
    pl = scene.planes
    a = scene.edges.attributes
    for s, e, pa, pb in zip(scene.edges.start, scene.edges.end, a["plane_a"], a["plane_b"],
                            strict=True):
        for k in (pa, pb):
            assert np.abs(pl[k].distance(np.array([s, e]))).max() < tol
    c = scene.corners.attributes
    for xyz, *ids in zip(scene.corners.xyz, c["plane_a"], c["plane_b"], c["plane_c"], strict=True):
        for k in ids:
            assert abs(pl[k].distance(xyz[None])[0]) < tol


def _assert_points_on_planes(scene: Scene, noise: float) -> None:
    on = scene.plane_id >= 0
    normals = np.array([p.normal for p in scene.planes])
    rho = np.array([p.rho for p in scene.planes])
    pid = scene.plane_id[on]
    d = np.einsum("ij,ij->i", scene.points[on], normals[pid]) - rho[pid]
    assert np.abs(d).max() < 6.5 * noise
    assert np.mean(np.abs(d) < 4 * noise) > 0.999


# --------------------------------------------------------------------- determinism


def test_same_seed_same_scene() -> None:
    a = make_scene(seed=11, size=(60.0, 60.0))
    b = make_scene(seed=11, size=(60.0, 60.0))
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.classification, b.classification)
    np.testing.assert_array_equal(a.plane_id, b.plane_id)
    np.testing.assert_array_equal(a.edges.start, b.edges.start)
    assert a.params == b.params
    c = make_scene(seed=12, size=(60.0, 60.0))
    assert len(c) != len(a) or not np.array_equal(c.points, a.points)


def test_contract_fields(full: Scene) -> None:
    n = len(full)
    assert full.points.shape == (n, 3) and full.points.dtype == np.float64
    assert full.classification.dtype == np.uint8
    assert full.is_ground.dtype == bool and full.object_id.dtype == np.int64
    assert full.plane_id.dtype == np.int64
    assert set(np.unique(full.classification)) <= {1, 2, 3, 4, 5, 6, 7}
    assert {1, 2, 5, 6, 7} <= set(np.unique(full.classification).tolist())
    np.testing.assert_array_equal(full.is_ground, full.classification == 2)
    assert full.plane_id.max() < len(full.planes)
    for p in full.planes:
        assert abs(np.linalg.norm(p.normal) - 1) < 1e-12 and p.normal[2] >= 0
    assert set(full.edges.attributes) >= {"plane_a", "plane_b", "kind"}
    assert set(full.corners.attributes) >= {"plane_a", "plane_b", "plane_c"}
    assert np.all(full.edges.attributes["plane_a"] < full.edges.attributes["plane_b"])
    assert (full.classification == 7).sum() == 20
    # objects: every building/car point has an object id, terrain has none
    assert np.all(full.object_id[np.isin(full.classification, [1, 6])] >= 0)
    assert np.all(full.object_id[full.is_ground] == -1)


# --------------------------------------------------------------------- density and noise


def test_ground_density_and_noise() -> None:
    s = make_terrain_scene(seed=2, size=(80.0, 60.0), curbs=0, embankment=False, undulation=0.0)
    g = s.is_ground
    assert abs(g.sum() / (80 * 60) / 20.0 - 1) < 0.10
    d = s.points[g, 2] - s.ground_z(s.points[g, :2])
    # planar terrain: noise along the normal, so z residual = noise / n_z
    nz = s.planes[0].normal[2]
    assert abs(np.std(d) * nz / NOISE - 1) < 0.10
    assert abs(np.mean(d)) < 3 * NOISE / np.sqrt(g.sum()) * 3


def test_roof_and_wall_density_and_noise(buildings: Scene) -> None:
    for i, p in enumerate(buildings.planes):
        if p.kind == "ground":
            continue
        on = buildings.plane_id == i
        area = plane_area(p)
        if p.kind == "roof":  # per horizontal m^2
            expected = 20.0 * area * p.normal[2]
        else:
            expected = 20.0 * area
        assert abs(on.sum() / expected - 1) < 0.10 + 3 / np.sqrt(expected)
        d = p.distance(buildings.points[on])
        assert abs(np.std(d) / NOISE - 1) < 0.10
    # all planes together: the std is exact to a few percent
    on = buildings.plane_id >= 0
    d = np.concatenate([buildings.planes[k].distance(buildings.points[buildings.plane_id == k])
                        for k in range(len(buildings.planes))])
    assert abs(np.std(d) / NOISE - 1) < 0.02
    assert on.sum() == len(d)


def test_wall_density_option() -> None:
    s = make_building_scene(seed=1, roofs=("flat",), wall_density=5.0)
    for i, p in enumerate(s.planes):
        if p.kind == "wall":
            expected = 5.0 * plane_area(p)
            assert abs((s.plane_id == i).sum() / expected - 1) < 0.10 + 3 / np.sqrt(expected)


# --------------------------------------------------------------------- truth


def test_points_lie_on_their_planes(buildings: Scene, full: Scene) -> None:
    _assert_points_on_planes(buildings, NOISE)
    _assert_points_on_planes(full, NOISE)


def test_edges_and_corners_exact(buildings: Scene, full: Scene) -> None:
    _assert_truth_exact(buildings, 1e-9)
    _assert_truth_exact(full, 1e-9)
    assert len(full.edges) > 20 and len(full.corners) > 10


def test_known_building_topology() -> None:
    flat = BuildingSpec("flat", (20.0, 20.0), 16.0, 10.0, 30.0, 6.0)
    gable = BuildingSpec("gable", (60.0, 20.0), 14.0, 9.0, -20.0, 4.0, 35.0)
    s = make_building_scene(seed=0, buildings=[flat, gable])
    kinds = s.edges.attributes["kind"]
    oid = s.edges.attributes["object_id"]
    f, g = (oid == 0), (oid == 1)
    assert sorted(kinds[f]) == ["eave"] * 4 + ["foot"] * 4 + ["wall"] * 4
    expected = ["eave"] * 2 + ["foot"] * 4 + ["ridge"] + ["verge"] * 4 + ["wall"] * 4
    assert sorted(kinds[g]) == expected
    ck = s.corners.attributes["kind"]
    co = s.corners.attributes["object_id"]
    assert sorted(ck[co == 0]) == ["eave"] * 4 + ["foot"] * 4
    assert sorted(ck[co == 1]) == ["eave"] * 4 + ["foot"] * 4 + ["ridge"] * 2
    # the ridge: 14 m long, at 4 + 4.5 tan(35 deg) above the flat ground
    ridge = s.edges.subset(kinds == "ridge")
    assert ridge.lengths[0] == pytest.approx(14.0, abs=1e-12)
    assert ridge.start[0, 2] == pytest.approx(4.0 + 4.5 * np.tan(np.deg2rad(35.0)), abs=1e-12)
    mid = 0.5 * (ridge.start[0] + ridge.end[0])
    np.testing.assert_allclose(mid[:2], [60.0, 20.0], atol=1e-12)
    # the flat roof: 16 x 10 m at z = 6
    roof = next(p for p in s.planes if p.kind == "roof" and p.object_id == 0)
    assert roof.rho == pytest.approx(6.0) and plane_area(roof) == pytest.approx(160.0)
    _assert_truth_exact(s, 1e-9)


def test_unobserved_planes_give_no_edges() -> None:
    s = make_building_scene(seed=4, roofs=("gable", "flat"), wall_density=0.0)
    assert set(s.edges.attributes["kind"].tolist()) == {"ridge"}
    assert len(s.corners) == 0
    observed = np.array([p.n_points >= 10 for p in s.planes])
    assert observed[s.edges.attributes["plane_a"]].all()
    assert observed[s.edges.attributes["plane_b"]].all()


def test_no_ground_under_footprints(full: Scene) -> None:
    g = full.points[full.is_ground, :2]
    specs = full.params["buildings"] + full.params["cars"]
    assert len(full.params["buildings"]) >= 3 and len(full.params["cars"]) >= 5
    for b in specs:
        inside = in_rectangle(g, np.asarray(b["center"]), b["length"], b["width"], b["azimuth_deg"])
        assert not inside.any()


def test_cars_touch_the_ground(full: Scene) -> None:
    assert any(p.kind == "car_side" for p in full.planes)
    cars = full.classification == 1
    oids = np.unique(full.object_id[cars])
    for oid in oids:
        pts = full.points[full.object_id == oid]
        gz = full.ground_z(pts[:, :2])
        # the lowest side points reach the ground; the top is ~1.5 m above it
        assert np.min(pts[:, 2] - gz) < 0.1
        assert 1.2 < np.max(pts[:, 2] - gz) < 2.0


def test_terrain_ground_z_and_curbs() -> None:
    s = make_terrain_scene(seed=7, size=(80.0, 80.0), curb_height=0.25)
    g = s.is_ground
    d = s.points[g, 2] - s.ground_z(s.points[g, :2])
    # noise plus the curb faces (0..0.25 m above the lower side)
    assert np.mean(np.abs(d) < 4 * NOISE) > 0.99
    curb_face = (d > 4 * NOISE) | (d < -0.3)
    assert 0 < curb_face.sum() < 0.01 * g.sum()
    assert len(s.planes) == 0 and len(s.edges) == 0
    bl = s.breaklines()
    assert bl.attributes["kind"].tolist().count("curb") == 2
    # the curb-face points lie on a curb line (within the horizontal noise)
    curbs = bl.subset(bl.attributes["kind"] == "curb")
    face = s.points[g][curb_face & (d > 0)]
    u = (curbs.end - curbs.start)[:, :2]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = face[:, None, :2] - curbs.start[None, :, :2]
    dist = np.abs(w[..., 0] * u[:, 1] - w[..., 1] * u[:, 0]).min(axis=1)
    assert np.quantile(dist, 0.99) < 4 * NOISE
    zz = s.ground_z(s.points[g, :2])
    assert np.ptp(zz) > 2.0  # slope + embankment


def test_returns_and_strips() -> None:
    s = make_scene(seed=9, size=(50.0, 50.0), returns=True, strips=2, strip_offset=(0.0, 0.0, 0.1),
                   n_buildings=1, roofs=("flat",))
    rn, nr = s.fields["return_number"], s.fields["number_of_returns"]
    assert np.all((rn >= 1) & (rn <= nr))
    assert (nr == 2).any()
    last = (rn == 2)
    assert np.all(s.is_ground[last])
    psid = s.fields["point_source_id"]
    n1, n2 = (psid == 1).sum(), (psid == 2).sum()
    assert abs(n1 / n2 - 1) < 0.05
    roof = next(i for i, p in enumerate(s.planes) if p.kind == "roof")
    for k, shift in ((1, 0.0), (2, 0.1)):
        m = (s.plane_id == roof) & (psid == k)
        assert s.planes[roof].distance(s.points[m]).mean() == pytest.approx(shift, abs=0.005)


def test_origin_shift_keeps_truth_exact() -> None:
    o = (500_000.0, 5_400_000.0, 120.0)
    a = make_building_scene(seed=2)
    b = make_building_scene(seed=2, origin=o)
    np.testing.assert_allclose(b.points - np.asarray(o), a.points, atol=1e-8)
    np.testing.assert_allclose(b.edges.start - np.asarray(o), a.edges.start, atol=1e-8)
    _assert_truth_exact(b, 1e-6)
    _assert_points_on_planes(b, NOISE)
    xy = b.points[b.is_ground, :2]
    np.testing.assert_allclose(b.ground_z(xy), 120.0, atol=1e-9)


def test_rigid_motion_moves_points_and_truth(buildings: Scene) -> None:
    m = rigid_motion(buildings, rotation_deg=(10.0, -25.0, 130.0), translation=(3.0, -7.0, 100.0))
    rot = rotation_matrix((10.0, -25.0, 130.0))
    np.testing.assert_allclose(m.points, buildings.points @ rot.T + [3.0, -7.0, 100.0], atol=1e-9)
    _assert_truth_exact(m, 1e-8)
    _assert_points_on_planes(m, NOISE)
    assert all(p.normal[2] >= 0 for p in m.planes)
    assert m.terrain is None and len(m.params["motions"]) == 1
    # a rotation about z keeps the terrain model
    mz = rigid_motion(buildings, rotation_deg=(0, 0, 40.0), translation=(1.0, 2.0, 3.0))
    g = mz.is_ground
    assert np.abs(mz.points[g, 2] - mz.ground_z(mz.points[g, :2])).max() < 6 * NOISE
    # arrays, Segments and PointSet move the same way; center= rotates about a point
    np.testing.assert_allclose(rigid_motion(buildings.points, (10.0, -25.0, 130.0),
                                            (3.0, -7.0, 100.0)), m.points)
    np.testing.assert_allclose(rigid_motion(buildings.edges, (10.0, -25.0, 130.0),
                                            (3.0, -7.0, 100.0)).end, m.edges.end)
    c = np.array([5.0, 5.0, 5.0])
    np.testing.assert_allclose(rigid_motion(c[None], (0, 0, 90.0), center=c), c[None], atol=1e-12)


def test_to_cloud_writes_las(tmp_path, buildings: Scene) -> None:
    s = make_building_scene(seed=8, roofs=("gable",), density=5.0, strips=2)
    cloud = s.to_cloud(include_truth=True, crs="EPSG:2154")
    path = lidarqa.write(cloud, tmp_path / "scene.las")
    back = lidarqa.read(path)
    assert back.crs is not None and back.crs.to_epsg() == 2154
    assert len(back) == len(s)
    np.testing.assert_allclose(back.xyz, s.points, atol=0.0006)
    np.testing.assert_array_equal(back.fields["classification"], s.classification)
    np.testing.assert_array_equal(back.fields["point_source_id"], s.fields["point_source_id"])
    np.testing.assert_array_equal(back.fields["plane_id"], s.plane_id)


def test_subset_keeps_truth(buildings: Scene) -> None:
    sub = buildings.subset(buildings.classification == 6)
    assert len(sub) == (buildings.classification == 6).sum()
    assert len(sub.edges) == len(buildings.edges)
    assert not sub.is_ground.any()


def test_bad_options() -> None:
    with pytest.raises(OptionError):
        make_scene(density=0)
    with pytest.raises(OptionError):
        make_scene(roofs=("dome",))
    with pytest.raises(OptionError):
        make_building_scene(strips=0)
    with pytest.raises(OptionError):
        BuildingSpec("gable", pitch_deg=95.0)
    with pytest.raises(OptionError):
        make_scene(size=(10.0,))


@pytest.mark.slow
def test_two_million_point_scene() -> None:
    s = make_scene(seed=0, size=(316.0, 316.0))
    assert len(s) > 2_000_000
    assert s.params["counts"]["buildings"] >= 30
    _assert_truth_exact(s, 1e-9)


# --------------------------------------------------------------------- cases


def test_cases_groups() -> None:
    from lidarqa._validate import as_points

    for name, arr in cases.point_cases("invalid").items():
        with pytest.raises(InvalidPointsError):
            as_points(arr)
        del name
    deg = cases.point_cases("degenerate")
    assert deg["empty"].shape == (0, 3) and len(deg["one_point"]) == 1
    assert np.linalg.matrix_rank(deg["collinear"] - deg["collinear"][0]) == 1
    assert np.ptp(deg["single_z"][:, 2]) == 0
    num = cases.point_cases("numeric")
    assert num["float32_plane"].dtype == np.float32
    assert num["utm_plane"][:, 1].min() > 5e6
    a = cases.point_cases()
    a["collinear"][:] = 0
    assert cases.point_cases()["collinear"].any()
    with pytest.raises(OptionError):
        cases.point_cases("bogus")


def test_planar_terrain_gives_ground_plane_and_foot_edges() -> None:
    s = make_scene(seed=13, size=(80.0, 80.0), slope_deg=4.0, undulation=0.0, curbs=0,
                   n_trees=3, n_shrubs=0, outliers=0)
    ground = [i for i, p in enumerate(s.planes) if p.kind == "ground"]
    assert ground == [0]
    assert np.degrees(np.arccos(s.planes[0].normal[2])) == pytest.approx(4.0)
    kinds = s.edges.attributes["kind"]
    assert (kinds == "foot").sum() == 4 * s.params["counts"]["buildings"]
    assert (kinds == "car").sum() == 12 * s.params["counts"]["cars"]  # 4 top, 4 vertical, 4 foot
    _assert_truth_exact(s, 1e-9)
    _assert_points_on_planes(s, NOISE)


def test_undulating_terrain_noise_in_z() -> None:
    s = make_terrain_scene(seed=14, size=(60.0, 60.0), curbs=0, embankment=False, undulation=1.0)
    g = s.is_ground
    d = s.points[g, 2] - s.ground_z(s.points[g, :2])
    assert abs(np.std(d) / NOISE - 1) < 0.10
    assert s.planes == [] and np.all(s.plane_id == -1)


def test_overhang_keeps_truth_and_hides_ground() -> None:
    spec = BuildingSpec("gable", (20.0, 20.0), 12.0, 8.0, 15.0, 5.0, 40.0, overhang=0.8)
    s = make_building_scene(seed=1, buildings=[spec])
    _assert_truth_exact(s, 1e-9)
    _assert_points_on_planes(s, NOISE)
    ridge = s.edges.subset(s.edges.attributes["kind"] == "ridge")
    assert ridge.lengths[0] == pytest.approx(12.0 + 2 * 0.8)
    g = s.points[s.is_ground, :2]
    assert not in_rectangle(g, np.array([20.0, 20.0]), 12.0 + 1.6, 8.0 + 1.6, 15.0).any()
    # the eaves stay where the walls meet the roof (z = 5), the roof reaches lower
    eaves = s.edges.subset(s.edges.attributes["kind"] == "eave")
    np.testing.assert_allclose(eaves.start[:, 2], 5.0)
    roof = s.points[np.isin(s.plane_id, [i for i, p in enumerate(s.planes) if p.kind == "roof"])]
    assert roof[:, 2].min() < 5.0 - 0.8 * np.tan(np.deg2rad(40.0)) + 0.1


def test_jittered_pattern_is_even() -> None:
    from scipy.spatial import cKDTree

    r = make_building_scene(seed=6, roofs=("flat", "gable"))
    j = make_building_scene(seed=6, roofs=("flat", "gable"), pattern="jittered")
    for i, p in enumerate(j.planes):
        if p.kind == "ground":
            open_area = np.prod(j.params["size"]) - sum(b["length"] * b["width"]
                                                       for b in j.params["buildings"])
            assert abs((j.plane_id == i).sum() / (20.0 * open_area) - 1) < 0.01
            continue
        expected = 20.0 * plane_area(p) * (p.normal[2] if p.kind == "roof" else 1.0)
        assert abs((j.plane_id == i).sum() / expected - 1) < 0.05
    _assert_truth_exact(j, 1e-9)
    _assert_points_on_planes(j, NOISE)

    def nn(s: Scene) -> np.ndarray:
        g = s.points[s.plane_id == 0, :2]
        return cKDTree(g).query(g, k=2)[0][:, 1]

    # a scanner-like layout has far fewer near-coincident points
    assert np.quantile(nn(j), 0.01) > 2 * np.quantile(nn(r), 0.01)
    with pytest.raises(OptionError):
        make_scene(pattern="spiral")


@pytest.mark.parametrize("angle", [20.0, 90.0, 160.0])
def test_plane_pair(angle: float) -> None:
    from lidarqa.testing import make_plane_pair

    s = make_plane_pair(angle_deg=angle, length=8.0, rotation_deg=(10.0, 20.0, 30.0),
                        translation=(100.0, 200.0, 5.0))
    assert len(s.planes) == 2 and len(s.edges) == 1 and len(s.corners) == 0
    cos = abs(s.planes[0].normal @ s.planes[1].normal)
    assert cos == pytest.approx(abs(np.cos(np.deg2rad(angle))), abs=1e-12)
    assert s.edges.lengths[0] == pytest.approx(8.0)
    np.testing.assert_allclose(s.edges.start[0], [100.0, 200.0, 5.0])
    _assert_truth_exact(s, 1e-9)
    _assert_points_on_planes(s, NOISE)
    with pytest.raises(OptionError):
        make_plane_pair(angle_deg=180.0)


def test_corner() -> None:
    from lidarqa.testing import make_corner

    s = make_corner(size=4.0, rotation_deg=(0.0, 0.0, 45.0), translation=(1.0, 1.0, 1.0))
    assert len(s.planes) == 3 and len(s.edges) == 3 and len(s.corners) == 1
    np.testing.assert_allclose(s.corners.xyz[0], [1.0, 1.0, 1.0], atol=1e-12)
    assert abs(np.linalg.det(np.array([p.normal for p in s.planes]))) == pytest.approx(1.0)
    assert all(abs((s.plane_id == k).sum() / (20.0 * 16.0) - 1) < 0.2 for k in range(3))
    _assert_truth_exact(s, 1e-9)
    _assert_points_on_planes(s, NOISE)
