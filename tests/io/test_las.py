"""LAS/LAZ reading and lossless writing."""

from __future__ import annotations

import numpy as np
import pytest
from datapaths import HAS_SHARED, SHARED

import lidarqa
from lidarqa.errors import LasReadError, OutputExistsError

laspy = pytest.importorskip("laspy")

# The PDAL corpus (odd versions, COPC, corrupt files) has its own test: test_writers_every_input.
_SHARED_LAS = (
    sorted(p for p in SHARED.glob("*/*.la[sz]") if p.parent.name != "pdal-corpus")
    if HAS_SHARED
    else []
)
# Header fields that describe the data (not the encoding layout, which depends on the LAZ backend).
_HEADER_FIELDS = (
    "version",
    "point_format",
    "scales",
    "offsets",
    "mins",
    "maxs",
    "point_count",
    "system_identifier",
    "generating_software",
    "creation_date",
    "file_source_id",
    "uuid",
    "number_of_points_by_return",
)


def _assert_same_file(a_path, b_path):
    a, b = laspy.read(a_path), laspy.read(b_path)
    assert a.points.array.tobytes() == b.points.array.tobytes(), "point records differ"
    for name in _HEADER_FIELDS:
        va, vb = getattr(a.header, name), getattr(b.header, name)
        if isinstance(va, np.ndarray):
            np.testing.assert_array_equal(va, vb, err_msg=name)
        else:
            assert va == vb, name
    assert a.header.global_encoding.value == b.header.global_encoding.value

    def vlrs(h):
        return [
            (v.user_id, v.record_id, v.description, bytes(v.record_data_bytes())) for v in h.vlrs
        ]

    assert vlrs(a.header) == vlrs(b.header)
    ea, eb = getattr(a, "evlrs", None) or [], getattr(b, "evlrs", None) or []
    assert [(v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in ea] == [
        (v.user_id, v.record_id, bytes(v.record_data_bytes())) for v in eb
    ]


@pytest.mark.parametrize("path", _SHARED_LAS, ids=lambda p: p.name)
def test_shared_files_round_trip(path, tmp_path):
    cloud = lidarqa.read(path)
    out = tmp_path / ("out" + path.suffix)
    lidarqa.write(cloud, out)
    _assert_same_file(path, out)


@pytest.mark.skipif(HAS_SHARED, reason="covered by the shared-data parametrisation")
@pytest.mark.parametrize("name", ["samp24-utm.laz", "autzen-bmx-2010.las"])
def test_bundled_files_round_trip(data_dir, tmp_path, name):
    out = tmp_path / ("out" + name[-4:])
    lidarqa.write(lidarqa.read(data_dir / name), out)
    _assert_same_file(data_dir / name, out)


def test_las_to_laz_and_back_keeps_records(data_dir, tmp_path):
    src = data_dir / "autzen-bmx-2010.las"
    laz = tmp_path / "a.laz"
    lidarqa.write(lidarqa.read(src), laz)
    assert laz.read_bytes()[104] & 0x80, "LAZ point format flag not set"
    assert laspy.read(src).points.array.tobytes() == laspy.read(laz).points.array.tobytes()


def test_reads_fields_and_crs(data_dir):
    cloud = lidarqa.read(data_dir / "samp11-utm.laz")
    assert cloud.xyz.shape == (38010, 3) and cloud.xyz.dtype == np.float64
    assert cloud.crs.to_epsg() == 32632
    assert np.bincount(cloud.classification).tolist()[::2] == [16224, 21786]


def test_changed_classification_only_touches_that_field(data_dir, tmp_path):
    src = data_dir / "samp24-utm.laz"
    cloud = lidarqa.read(src)
    cls = cloud.classification.copy()
    cls[:10] = 6
    cloud.fields["classification"] = cls
    out = tmp_path / "c.laz"
    lidarqa.write(cloud, out)
    a, b = laspy.read(src), laspy.read(out)
    assert np.array_equal(np.asarray(b.classification)[:10], np.full(10, 6))
    assert np.array_equal(np.asarray(a.classification)[10:], np.asarray(b.classification)[10:])
    for dim in ("X", "Y", "Z", "intensity", "point_source_id", "return_number"):
        assert np.array_equal(np.asarray(a[dim]), np.asarray(b[dim])), dim


def test_subset_writes_consistent_header(data_dir, tmp_path):
    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    sub = cloud.select(classes=2)
    out = tmp_path / "g.laz"
    lidarqa.write(sub, out)
    back = laspy.read(out)
    assert back.header.point_count == len(sub) == 5434
    np.testing.assert_allclose(back.header.mins, sub.xyz.min(axis=0))


def test_new_cloud_written_as_las14(tmp_path):
    rng = np.random.default_rng(1234)
    xyz = rng.uniform(0, 100, (500, 3)) + [500000, 5400000, 0]
    cloud = lidarqa.PointCloud(
        xyz=xyz, fields={"classification": np.full(500, 2, np.uint8), "score": rng.normal(size=500)}
    )
    out = tmp_path / "n.laz"
    lidarqa.write(cloud, out)
    back = lidarqa.read(out)
    np.testing.assert_allclose(back.xyz, xyz, atol=0.0006)
    np.testing.assert_allclose(back.fields["score"], cloud.fields["score"])
    assert str(back.source.version) == "1.4"


def test_chunked_reading_matches_whole(data_dir):
    whole = lidarqa.read(data_dir / "samp11-utm.laz")
    with lidarqa.open(data_dir / "samp11-utm.laz") as reader:
        assert reader.n_points == 38010
        parts = list(reader.chunks(10_000))
    assert [len(p) for p in parts] == [10_000, 10_000, 10_000, 8010]
    np.testing.assert_array_equal(np.vstack([p.xyz for p in parts]), whole.xyz)


def test_never_overwrites_without_permission(data_dir, tmp_path):
    cloud = lidarqa.read(data_dir / "samp24-utm.laz")
    out = tmp_path / "o.laz"
    out.write_bytes(b"keep me")
    with pytest.raises(OutputExistsError):
        lidarqa.write(cloud, out)
    assert out.read_bytes() == b"keep me"
    lidarqa.write(cloud, out, overwrite=True)
    assert len(lidarqa.read(out)) == len(cloud)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: None, "does not exist"),
        (lambda p: p.mkdir(), "is a directory"),
        (lambda p: p.write_bytes(b""), "empty"),
        (lambda p: p.write_bytes(np.random.default_rng(0).bytes(5000)), "cannot read"),
    ],
    ids=["missing", "directory", "empty", "random-bytes"],
)
def test_bad_files_raise_read_error(tmp_path, make, message):
    path = tmp_path / "bad.laz"
    make(path)
    with pytest.raises(LasReadError, match=message):
        lidarqa.read(path)


def test_truncated_laz(data_dir, tmp_path):
    raw = (data_dir / "samp11-utm.laz").read_bytes()
    bad = tmp_path / "trunc.laz"
    bad.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(LasReadError):
        lidarqa.read(bad)


@pytest.mark.parametrize("delta", [+7, -7])
def test_las_header_count_disagrees_with_records(data_dir, tmp_path, delta):
    src = tmp_path / "a.las"
    lidarqa.write(lidarqa.read(data_dir / "autzen-bmx-2010.las"), src)
    raw = bytearray(src.read_bytes())
    # LAS 1.4: legacy count at byte 107 (uint32), 64-bit count at byte 247.
    n = int.from_bytes(raw[247:255], "little")
    raw[247:255] = (n + delta).to_bytes(8, "little")
    raw[107:111] = (n + delta).to_bytes(4, "little")
    bad = tmp_path / "count.las"
    bad.write_bytes(bytes(raw))
    with pytest.raises(LasReadError, match="header declares"):
        lidarqa.read(bad)


def test_evlrs_and_extra_bytes_survive(tmp_path):
    """No shared file carries EVLRs, so build a LAS 1.4 file with one (and extra bytes)."""
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dims([laspy.ExtraBytesParams(name="reflectance", type=np.float32),
                           laspy.ExtraBytesParams(name="echo_width", type=np.uint16)])
    header.scales = [0.001, 0.001, 0.001]
    header.offsets = [700000, 6600000, 0]
    las = laspy.LasData(header)
    rng = np.random.default_rng(1234)
    n = 1000
    las.x = 700000 + rng.uniform(0, 50, n)
    las.y = 6600000 + rng.uniform(0, 50, n)
    las.z = rng.uniform(0, 20, n)
    las.reflectance = rng.normal(size=n).astype(np.float32)
    las.echo_width = rng.integers(0, 500, n).astype(np.uint16)
    from laspy.vlrs.vlrlist import VLRList

    las.evlrs = VLRList([laspy.VLR(user_id="lidarqa_test", record_id=42, description="an EVLR",
                                   record_data=b"x" * 70000)])
    src = tmp_path / "evlr.las"
    las.write(src)
    cloud = lidarqa.read(src)
    assert set(cloud.fields) >= {"reflectance", "echo_width"}
    out = tmp_path / "out.laz"
    lidarqa.write(cloud, out)
    _assert_same_file(src, out)
    assert len(laspy.read(out).evlrs) == 1


def _eb_struct(path, name):
    header = laspy.read(path).header
    (vlr,) = [v for v in header.vlrs if v.record_id == 4 and v.user_id == "LASF_Spec"]
    (s,) = [s for s in vlr.extra_bytes_structs if s.format_name() == name]
    return s


@pytest.mark.parametrize("no_data", [None, [255.0]])
def test_extra_bytes_statistics_are_exact_after_a_change(tmp_path, no_data):
    # laspy >= 2.7 tracks extra-dimension min/max from one point (or not at all with a
    # no-data value); the statistics we write must describe every point written.
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.add_extra_dim(laspy.ExtraBytesParams(name="treeID", type=np.float64, no_data=no_data))
    las = laspy.LasData(header)
    rng = np.random.default_rng(7)
    las.x, las.y, las.z = (rng.uniform(0, 10, 50) for _ in range(3))
    tree = rng.integers(3, 40, 50).astype(float)
    tree[0] = 255.0  # the no-data value when one is set
    las.treeID = tree
    src = tmp_path / "src.las"
    las.write(src)

    cloud = lidarqa.read(src)
    cloud.fields["classification"][:] = 2
    tree[1:] += 1  # a changed extra dimension gets new statistics
    cloud.fields["treeID"] = tree.copy()
    out = tmp_path / "out.laz"
    lidarqa.write(cloud, out)
    s = _eb_struct(out, "treeID")
    valid = tree if no_data is None else tree[tree != no_data[0]]
    assert s.min[0] == valid.min() and s.max[0] == valid.max()
    np.testing.assert_array_equal(laspy.read(out).treeID, tree)
