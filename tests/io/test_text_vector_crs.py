"""Text clouds, PLY, vector I/O, CRS helpers and polar observations."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import CRS

import lidarqa
from lidarqa.errors import CRSMismatchError, InvalidPointsError, OutputExistsError, ReadError
from lidarqa.io.crs import crs_epsg, ensure_same_crs, reproject, vertical_unit, z_to_metres_factor
from lidarqa.io.polar import Station, polar_to_cartesian, read_polar_csv
from lidarqa.io.vector import (
    PointSet,
    Segments,
    read_points,
    read_segments,
    write_points,
    write_segments,
)


def test_csv_header_any_case_and_extra_columns(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text('"X","Y","Z","Intensity","Classification"\n1,2,3,10,2\n4,5,6.5,11,1\n')
    cloud = lidarqa.read(p)
    np.testing.assert_array_equal(cloud.xyz, [[1, 2, 3], [4, 5, 6.5]])
    assert cloud.fields["classification"].tolist() == [2, 1]
    assert cloud.fields["intensity"].dtype.kind == "i"


def test_whitespace_xyz_without_header(tmp_path):
    p = tmp_path / "c.xyz"
    p.write_text("1 2 3\n4 5 6\n")
    assert lidarqa.read(p).xyz.shape == (2, 3)


def test_csv_without_xyz_columns(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(ReadError, match="no column"):
        lidarqa.read(p)


def test_csv_with_nan_coordinates(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z\n1,2,3\n4,nan,6\n")
    with pytest.raises(InvalidPointsError, match="NaN"):
        lidarqa.read(p)


def test_unknown_extension(tmp_path):
    p = tmp_path / "c.dat"
    p.write_text("x")
    with pytest.raises(ReadError, match="format"):
        lidarqa.read(p)


def test_csv_round_trip(tmp_path):
    cloud = lidarqa.PointCloud(
        xyz=np.array([[0.1, 0.2, 0.3], [1e6, 5e6, 12.5]]),
        fields={"classification": np.array([2, 6])},
    )
    lidarqa.write(cloud, tmp_path / "o.csv")
    back = lidarqa.read(tmp_path / "o.csv")
    np.testing.assert_array_equal(back.xyz, cloud.xyz)
    assert back.fields["classification"].tolist() == [2, 6]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply(tmp_path, fmt):
    xyz = np.array([[0, 0, 0], [1, 2, 3.5]], dtype=np.float64)
    head = (
        f"ply\nformat {fmt} 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
        "property double z\nproperty uchar label\nend_header\n"
    )
    p = tmp_path / "c.ply"
    if fmt == "ascii":
        p.write_text(head + "0 0 0 1\n1 2 3.5 7\n")
    else:
        rec = np.zeros(2, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("label", "u1")])
        rec["x"], rec["y"], rec["z"], rec["label"] = xyz[:, 0], xyz[:, 1], xyz[:, 2], [1, 7]
        p.write_bytes(head.encode() + rec.tobytes())
    cloud = lidarqa.read(p)
    np.testing.assert_array_equal(cloud.xyz, xyz)
    assert cloud.fields["label"].tolist() == [1, 7]


@pytest.mark.parametrize("ext", ["csv", "gpkg", "geojson"])
def test_segments_round_trip(tmp_path, ext):
    pytest.importorskip("pyogrio")
    seg = Segments(
        ids=np.array([3, 9]),
        start=[[0, 0, 0], [1e5, 2e6, 10]],
        end=[[1, 0, 0], [1e5 + 3, 2e6 + 4, 10.5]],
        attributes={"angle_deg": np.array([90.0, 45.0])},
        crs=CRS.from_epsg(2154),
    )
    path = tmp_path / f"s.{ext}"
    write_segments(seg, path)
    back = read_segments(path)
    assert back.ids.tolist() == [3, 9]
    np.testing.assert_allclose(back.start, seg.start)
    np.testing.assert_allclose(back.end, seg.end)
    np.testing.assert_allclose(back.attributes["angle_deg"], [90, 45])
    if ext != "csv":
        assert crs_epsg(back.crs) == 2154


@pytest.mark.parametrize("ext", ["csv", "gpkg", "geojson"])
def test_points_round_trip(tmp_path, ext):
    pytest.importorskip("pyogrio")
    pts = PointSet(ids=np.array(["P1", "P2"]), xyz=[[1, 2, 3], [4, 5, 6]])
    write_points(pts, tmp_path / f"p.{ext}")
    back = read_points(tmp_path / f"p.{ext}")
    assert back.ids.tolist() == ["P1", "P2"]
    np.testing.assert_allclose(back.xyz, pts.xyz)


def test_points_duplicate_ids_and_missing_columns(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("id,x,y,z\n1,0,0,0\n1,1,1,1\n")
    with pytest.raises(ReadError, match="duplicate"):
        read_points(p)
    p.write_text("id,x,y\n1,0,0\n")
    with pytest.raises(ReadError, match="lacks"):
        read_points(p)
    assert np.isnan(read_points(p, require_z=False).xyz[0, 2])


def test_segments_reject_nan_and_refuse_overwrite(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("id,x1,y1,z1,x2,y2,z2\n1,0,0,0,nan,1,1\n")
    with pytest.raises(InvalidPointsError):
        read_segments(p)
    seg = Segments(ids=np.array([1]), start=[[0, 0, 0]], end=[[1, 1, 1]])
    with pytest.raises(OutputExistsError):
        write_segments(seg, p)


def test_compound_crs_vertical_unit(data_dir):
    cloud = lidarqa.read(data_dir / "autzen-bmx-2010.las")
    name, factor = vertical_unit(cloud.crs)
    assert "foot" in name.lower()
    assert factor == pytest.approx(1200 / 3937)
    assert z_to_metres_factor(cloud.crs) == pytest.approx(0.3048006096)
    metres = lidarqa.read(data_dir / "autzen-bmx-2010.las", z_to_metres=True)
    np.testing.assert_allclose(metres.z, cloud.z * 1200 / 3937)
    np.testing.assert_array_equal(metres.xyz[:, :2], cloud.xyz[:, :2])  # XY already metres


def test_crs_mismatch_is_refused_and_reprojection_is_explicit():
    a, b = CRS.from_epsg(2154), CRS.from_epsg(32631)
    ensure_same_crs(a, CRS.from_epsg(2154))
    with pytest.raises(CRSMismatchError, match="differs"):
        ensure_same_crs(a, b)
    xyz = np.array([[700000.0, 6600000.0, 100.0]])
    there = reproject(xyz, a, b)
    back = reproject(there, b, a)
    np.testing.assert_allclose(back, xyz, atol=1e-6)


def test_polar_spec_vectors():
    np.testing.assert_allclose(polar_to_cartesian([10], [90], [0]), [[10, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(polar_to_cartesian([10], [0], [30]), [[0, 8.660254, 5]], atol=1e-6)
    # zenith 60 deg = elevation 30 deg; 100 gon = 90 deg
    np.testing.assert_allclose(
        polar_to_cartesian([10], [0], [60], vertical_kind="zenith"), [[0, 8.660254, 5]], atol=1e-6
    )
    np.testing.assert_allclose(
        polar_to_cartesian([10], [100], [0], angle_unit="gon"), [[10, 0, 0]], atol=1e-12
    )


def test_polar_station_and_csv(tmp_path):
    p = tmp_path / "obs.csv"
    p.write_text("id,distance,hz,zenith\nA,10,0,90\nB,5,90,90\n")
    ids, xyz = read_polar_csv(
        p, station=Station(100, 200, 50, orientation=90, instrument_height=1.5)
    )
    assert ids.tolist() == ["A", "B"]
    np.testing.assert_allclose(xyz, [[110, 200, 51.5], [100, 195, 51.5]], atol=1e-9)
    with pytest.raises(InvalidPointsError):
        polar_to_cartesian([-1], [0], [0])
