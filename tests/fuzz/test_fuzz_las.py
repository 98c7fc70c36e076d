"""LAS/LAZ corruption: every header field at extremes, truncation at every field, bit flips.

Property: reading (whole, streamed, described) and ``lidarqa info`` either give
finite numbers or a LasReadError naming the problem, within the time bound.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hostile import LAS_FIELDS, extremes, flip_bits, run_cli, set_field, time_limit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lidarqa.errors import LidarQAError

pytestmark = pytest.mark.fuzz

SOURCES = ["scene.las", "scene.laz"]
_CACHE: dict[str, bytes] = {}


def _source(world, name: str) -> bytes:
    if name not in _CACHE:
        _CACHE[name] = (world["dir"] / name).read_bytes()
    return _CACHE[name]


def _api_property(path) -> None:
    """Every LAS entry point: success with finite values, or a LidarQAError."""
    import lidarqa
    from lidarqa.io.info import describe

    with time_limit(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for fn in (
            lambda: lidarqa.read(path),
            lambda: describe(path),
            lambda: [len(c) for c in lidarqa.open(path).chunks(1000)],
        ):
            try:
                out = fn()
            except LidarQAError:
                continue
            if hasattr(out, "xyz"):
                assert np.isfinite(out.xyz).all()
            if hasattr(out, "to_dict"):
                d = out.to_dict()
                b = d.get("bounds") or {}
                values = b.values() if isinstance(b, dict) else b
                assert all(v is None or math.isfinite(v) for v in values), d
                for v in d.get("header", {}).get("scales", []):
                    assert math.isfinite(v) and v > 0, d


CASES = [
    (src, name, off, fmt, value)
    for src in SOURCES
    for name, off, fmt in LAS_FIELDS
    for value in extremes(fmt)
]


@pytest.mark.parametrize(
    "src,name,off,fmt,value", CASES, ids=[f"{c[0]}-{c[1]}-{c[4]!r}" for c in CASES]
)
def test_header_field_extremes(world, tmp_path, src, name, off, fmt, value):
    p = tmp_path / src
    p.write_bytes(set_field(_source(world, src), off, fmt, value))
    _api_property(p)


@pytest.mark.parametrize("src", SOURCES)
def test_truncated_at_every_header_field(world, tmp_path, src):
    data = _source(world, src)
    cuts = sorted({off for _, off, _ in LAS_FIELDS} | {off + 1 for _, off, _ in LAS_FIELDS}
                  | {375, 376, 430, len(data) - 1, len(data) - 100})
    for cut in cuts:
        p = tmp_path / f"cut{cut}{src[-4:]}"
        p.write_bytes(data[:cut])
        _api_property(p)


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    src=st.sampled_from(SOURCES),
    field=st.sampled_from(LAS_FIELDS),
    raw=st.integers(min_value=0, max_value=2**64 - 1),
    flips=st.lists(st.integers(min_value=0, max_value=375 * 8 - 1), max_size=6),
)
def test_header_random(world, tmp_path_factory, src, field, raw, flips):
    _, off, fmt = field
    data = _source(world, src)
    if fmt.endswith("d"):
        value = np.frombuffer(raw.to_bytes(8, "little"), "<f8")[0].item()
    elif fmt.endswith("s"):
        value = raw.to_bytes(8, "little")[:4]
    else:
        value = raw % (2 ** (8 * int(np.dtype(fmt[-1]).itemsize)))
    data = flip_bits(set_field(data, off, fmt, value), flips)
    p = tmp_path_factory.mktemp("h") / src
    p.write_bytes(data)
    _api_property(p)


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    src=st.sampled_from(SOURCES),
    flips=st.lists(st.integers(min_value=0, max_value=2**40), min_size=1, max_size=20),
    cut=st.one_of(st.none(), st.floats(min_value=0.3, max_value=1.0)),
)
def test_body_corruption(world, tmp_path_factory, src, flips, cut):
    """Bit flips anywhere (VLRs, extra bytes, CRS, LAZ chunks and chunk table) and truncation."""
    data = _source(world, src)
    body = flip_bits(data[375:], flips)
    data = data[:375] + body
    if cut is not None:
        data = data[: int(len(data) * cut)]
    p = tmp_path_factory.mktemp("b") / src
    p.write_bytes(data)
    _api_property(p)


@pytest.mark.parametrize("src", SOURCES)
def test_issue_cases_through_info(world, tmp_path, src):
    """The reported hangs and nonsense: 4,294,967,295 VLRs, LASF + noise, NaN/1e308 scales."""
    data = _source(world, src)
    cases = {
        "vlrs": set_field(data, 100, "<I", 2**32 - 1),
        "noise": b"LASF" + np.random.default_rng(3).bytes(len(data)),
        "nan-scale": set_field(data, 131, "<d", float("nan")),
        "huge-scale": set_field(data, 147, "<d", 1e308),
        "evlr": set_field(set_field(data, 243, "<I", 5), 235, "<Q", 2**63),
        "record-length": set_field(data, 105, "<H", 7),
    }
    for name, blob in cases.items():
        p = tmp_path / f"{name}{src[-4:]}"
        p.write_bytes(blob)
        r = run_cli(["info", p], out_dir=tmp_path / "out")
        assert r.exit_code == 1, (name, r.output)


@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    start=st.floats(min_value=0.0, max_value=0.95),
    length=st.integers(min_value=1, max_value=4096),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_laz_chunk_garbage(world, tmp_path_factory, start, length, seed):
    """Random bytes over the compressed points (layer sizes, chunk table, layers).

    The LAS 1.4 decompressor allocates each layer at its declared size: garbage there
    cost 2 GB of memory on an 11,000-point file before the header layer checked it.
    """
    import resource
    import struct

    data = _source(world, "scene.laz")
    begin = struct.unpack_from("<I", data, 96)[0] + 8
    at = begin + int((len(data) - begin) * start)
    junk = np.random.default_rng(seed).bytes(length)
    blob = data[:at] + junk[: len(data) - at] + data[at + length :]
    p = tmp_path_factory.mktemp("z") / "scene.laz"
    p.write_bytes(blob)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    _api_property(p)
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 500, f"reading a corrupt 70 kB LAZ raised the peak memory by {grown_mb} MB"
