"""Every cloud that can be read can be written (issue #26, part 5).

COPC in gives a plain LAZ out (the COPC info VLR and hierarchy EVLR dropped, everything
else kept); LAS 1.0 in gives LAS 1.2 out (same point format); COPC output is refused
before any work with one line. The PDAL test corpus (shared data) is the oracle of
"every input": each readable file goes through the write path of ``lidarqa ground``
with every point and every dimension but the classification unchanged, and each
deliberately corrupt file is refused with one line.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED

import lidarqa
from lidarqa.errors import LasReadError, WriteError

laspy = pytest.importorskip("laspy")

CORPUS = SHARED / "pdal-corpus"
_FILES = sorted(CORPUS.glob("*.la[sz]")) if CORPUS.is_dir() else []
# The corpus's deliberately broken files (see MANIFEST.md of the shared data): refused.
CORRUPT = {
    "apps__simple-laszip-compressor-version-1.2r0.laz",  # LAZ without a chunk table
    "laz__simple-laszip-compressor-version-1.2r0.laz",
    "ept__lone-star-invalid-tile__ept-data__2-2-2-2.laz",
    "las__1.2-with-color-clipped.las",  # clipped point records
    "las__bad_vlr_count.las",
    "las__garbage_nVariableLength.las",
    "las__permutations__1.2-no-points.las",
}
needs_corpus = pytest.mark.skipif(not _FILES, reason="shared pdal-corpus is not present")


def _vlrs(vlrs) -> list:
    return [
        (v.user_id, v.record_id, bytes(v.record_data_bytes()))
        for v in (vlrs or [])
        if not (str(v.user_id).strip("\x00") == "copc" and v.record_id in (1, 1000))
        and str(v.user_id).strip("\x00") != "laszip encoded"  # the encoding, not the data
    ]


def _relabelled(cloud):
    """What ``lidarqa ground`` writes: the input with a new classification (class 2 = ground)."""
    from lidarqa.ground import relabel_classification

    cls = cloud.fields.get("classification")
    if cls is None:
        cls = np.zeros(len(cloud), np.uint8)
    ground = cloud.z <= np.median(cloud.z) if len(cloud) else np.zeros(0, bool)
    cloud.fields["classification"] = relabel_classification(cls, ground)
    return cloud


def _check_written(path, out, cloud):
    a, b = laspy.read(path), laspy.read(out)
    assert len(b.points) == len(a.points) == len(cloud)
    assert b.header.point_format.id == a.header.point_format.id
    va = str(a.header.version)
    assert str(b.header.version) == ("1.2" if va == "1.0" else va)
    names = [n for n in a.point_format.dimension_names if n != "classification"]
    for n in names:
        x, y = np.asarray(a[n]), np.asarray(b[n])
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), n
    np.testing.assert_array_equal(np.asarray(b.classification), cloud.fields["classification"])
    np.testing.assert_array_equal(b.header.scales, a.header.scales)
    np.testing.assert_array_equal(b.header.offsets, a.header.offsets)
    assert _vlrs(b.header.vlrs) == _vlrs(a.header.vlrs)
    assert _vlrs(getattr(b, "evlrs", None)) == _vlrs(getattr(a, "evlrs", None))
    assert not any(
        str(v.user_id).strip("\x00") == "copc" and v.record_id == 1 for v in b.header.vlrs
    ), "a plain LAZ must not claim to be COPC"


@needs_corpus
@pytest.mark.parametrize("path", _FILES, ids=lambda p: p.name)
def test_corpus_file_is_written_with_every_point(path, tmp_path):
    if path.name in CORRUPT:
        with pytest.raises(LasReadError) as err:
            lidarqa.read(path)
        assert "\n" not in str(err.value) and path.name in str(err.value)
        return
    cloud = _relabelled(lidarqa.read(path))
    out = lidarqa.write(cloud, tmp_path / "out.laz")
    _check_written(path, out, cloud)


@needs_corpus
def test_corpus_counts():
    """105 of the 112 files are readable (the rest are the corrupt ones named above)."""
    assert len(_FILES) == 112
    assert len(CORRUPT) == 7 and CORRUPT <= {p.name for p in _FILES}


@needs_corpus
@pytest.mark.parametrize("name", ["copc__1.2-with-color.copc.laz", "las__permutations__1.0_1.las"])
def test_ground_command_on_copc_and_las10(name, tmp_path):
    from lidarqa.cli.main import cli

    src = CORPUS / name
    out = tmp_path / "out.laz"
    r = CliRunner().invoke(cli, ["ground", str(src), "-o", str(out), "--method", "ptd", "-q"])
    assert r.exit_code == 0, r.output
    a, b = laspy.read(src), laspy.read(out)
    assert len(b.points) == len(a.points)
    for n in ("X", "Y", "Z", "intensity", "return_number", "gps_time"):
        if n in a.point_format.dimension_names:
            assert np.array_equal(np.asarray(a[n]), np.asarray(b[n])), n


@needs_corpus
def test_truly_corrupt_file_gets_one_line(tmp_path):
    from lidarqa.cli.main import cli

    r = CliRunner().invoke(
        cli, ["ground", str(CORPUS / "las__bad_vlr_count.las"), "-o", str(tmp_path / "o.laz")]
    )
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "VLR" in lines[0], r.output
    assert not (tmp_path / "o.laz").exists()


def _copc_like(tmp_path):
    """A LAS 1.4 file carrying COPC info and hierarchy records (written raw, laspy cannot)."""
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = [0, 0, 0]
    header.scales = [0.01, 0.01, 0.01]
    header.vlrs.append(laspy.VLR("copc", 1, "copc info", b"\x00" * 160))
    header.vlrs.append(laspy.VLR("copc", 10000, "other copc record", b"keep me"))
    header.vlrs.append(laspy.VLR("someone", 7, "odd vlr", b"\x01\x02"))
    las = laspy.LasData(header)
    rng = np.random.default_rng(5)
    las.x, las.y, las.z = rng.uniform(0, 10, (3, 200))
    las.classification = np.full(200, 2, np.uint8)
    las.evlrs = laspy.vlrs.vlrlist.VLRList(
        [laspy.VLR("copc", 1000, "hierarchy", b"\x00" * 32), laspy.VLR("someone", 8, "odd", b"x")]
    )
    p = tmp_path / "fake.las"
    las.write(p)
    return p


def test_copc_records_dropped_others_kept(tmp_path):
    src = _copc_like(tmp_path)
    cloud = lidarqa.read(src)
    cloud.fields["classification"] = np.ones(len(cloud), np.uint8)
    out = lidarqa.write(cloud, tmp_path / "o.laz")
    b = laspy.read(out)
    kept = [(str(v.user_id), v.record_id) for v in b.header.vlrs]
    assert ("copc", 1) not in kept and ("copc", 10000) in kept and ("someone", 7) in kept
    assert [(str(v.user_id), v.record_id) for v in b.evlrs] == [("someone", 8)]
    np.testing.assert_array_equal(np.asarray(b.classification), 1)
    # the streaming rewrite of the catalog outputs follows the same rule
    from lidarqa.io.las import rewrite_las_classification

    out2 = rewrite_las_classification(src, tmp_path / "s.laz", lambda s, c: c)
    b2 = laspy.read(out2)
    assert [(str(v.user_id), v.record_id) for v in b2.header.vlrs] == kept
    assert [(str(v.user_id), v.record_id) for v in b2.evlrs] == [("someone", 8)]


def test_las10_written_as_12(tmp_path):
    header = laspy.LasHeader(point_format=1, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.random.default_rng(3).uniform(0, 50, (3, 100))
    las.gps_time = np.arange(100.0)
    p = tmp_path / "v10.las"
    las.write(p)
    raw = bytearray(p.read_bytes())
    raw[25] = 0  # LAS 1.0: same layout for point formats 0/1
    p.write_bytes(bytes(raw))
    cloud = lidarqa.read(p)
    assert str(cloud.source.version) == "1.0"
    out = lidarqa.write(cloud, tmp_path / "o.las")
    back = out.read_bytes()
    assert back[24:26] == bytes([1, 2])
    # every byte but the version is the source's (unchanged cloud: lossless)
    assert back[:24] + back[26:] == bytes(raw[:24] + raw[26:])
    out2 = lidarqa.io.las.rewrite_las_classification(p, tmp_path / "s.las", lambda s, c: c)
    assert out2.read_bytes()[24:26] == bytes([1, 2])
    assert laspy.read(out2).points.array.tobytes() == laspy.read(p).points.array.tobytes()


@pytest.mark.parametrize("name", ["x.copc.laz", "X.COPC.LAZ"])
def test_copc_output_refused_before_work(tmp_path, name):
    cloud = lidarqa.PointCloud(xyz=np.zeros((3, 3)))
    with pytest.raises(WriteError, match="cannot write COPC") as err:
        lidarqa.write(cloud, tmp_path / name)
    assert "\n" not in str(err.value) and ".laz" in str(err.value)
    assert not any(tmp_path.iterdir())
