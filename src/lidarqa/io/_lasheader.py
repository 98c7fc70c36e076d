"""Header sanity checks run on a LAS/LAZ file *before* laspy reads it.

A LAS file describes itself: the public header block gives the number of VLRs,
where the points start, how many there are, how long each record is, and for
LAS 1.4 where the extended VLRs are. A reader that trusts those numbers can be
made to loop over four billion VLRs, allocate terabytes, or print ``nan`` bounds.
:func:`check_las_header` checks every count, offset and extent against the file
size, and scales, offsets and bounds for finiteness, and raises a
:class:`~lidarqa.errors.LasReadError` that names the offending field. It reads
only the headers (public header block, VLR headers, EVLR headers, the LAZ chunk
table pointer), so it costs a few small reads whatever the file size.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

from ..errors import LasReadError

__all__ = ["LasHeaderFacts", "check_las_header", "POINT_RECORD_SIZES"]

# Size in bytes of the standard part of each point data record format (0-10).
POINT_RECORD_SIZES = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
# Minimum public header size per minor version.
_HEADER_SIZES = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
_VLR_HEADER = 54
_EVLR_HEADER = 60
# Limits beyond which a header is taken for corrupt rather than exotic.
MAX_VLRS = 100_000  # real files carry a handful; each VLR header is walked
MAX_SCALE = 1e4  # a coordinate unit coarser than 10 km
MIN_SCALE = 1e-12
MAX_ABS_OFFSET = 1e15
MAX_ABS_BOUND = 1e15
# A compressed point can not shrink below this many bits, so a LAZ file can not
# hold more than ~8 / this * size points; 0.5 bit per point is far beyond any real data.
_MIN_LAZ_BITS_PER_POINT = 0.5


@dataclass(frozen=True)
class LasHeaderFacts:
    """What the checks established about a LAS/LAZ header."""

    version: tuple[int, int]
    point_format: int
    record_length: int
    point_count: int
    offset_to_points: int
    n_vlrs: int
    n_evlrs: int
    compressed: bool
    file_size: int


def _fail(path: Path, field: str, message: str) -> LasReadError:
    return LasReadError(f"input {path}: corrupt LAS header: {field} {message}")


def check_las_header(path: str | Path) -> LasHeaderFacts:
    """Check the header of the LAS/LAZ file at `path` against the file size.

    Raises
    ------
    LasReadError
        Naming the field: signature, version, header size, offset to point data,
        number of VLRs (and each VLR's length), point data format, record length,
        point count, scales, offsets, bounds, EVLR start/count/lengths, LAZ chunk
        table offset.
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            size = fh.seek(0, 2)
            fh.seek(0)
            head = fh.read(375)
            return _check(p, fh, head, size)
    except LasReadError:
        raise
    except OSError as exc:
        raise LasReadError(f"cannot read {p}: {exc.strerror or exc}") from None


def _check(p: Path, fh, head: bytes, size: int) -> LasHeaderFacts:  # noqa: C901, PLR0912, PLR0915
    if len(head) < 4 or head[:4] != b"LASF":
        raise LasReadError(f"cannot read {p} as LAS/LAZ: no 'LASF' signature")
    if len(head) < 227:
        raise _fail(p, "size", f"is {size} bytes, shorter than the 227-byte public header")
    major, minor = head[24], head[25]
    if major != 1 or minor > 4:
        raise _fail(p, "version", f"{major}.{minor} is not a LAS version (1.0-1.4)")
    header_size = struct.unpack_from("<H", head, 94)[0]
    offset = struct.unpack_from("<I", head, 96)[0]
    n_vlrs = struct.unpack_from("<I", head, 100)[0]
    fmt_byte = head[104]
    record_length = struct.unpack_from("<H", head, 105)[0]
    legacy_count = struct.unpack_from("<I", head, 107)[0]
    scales = struct.unpack_from("<3d", head, 131)
    offsets = struct.unpack_from("<3d", head, 155)
    bounds = struct.unpack_from("<6d", head, 179)

    need = _HEADER_SIZES[minor]
    if header_size < need:
        raise _fail(p, "header size", f"{header_size} is below the {need} bytes of LAS 1.{minor}")
    if header_size > size:
        raise _fail(p, "header size", f"{header_size} exceeds the file size ({size} bytes)")
    if len(head) < min(header_size, 375):
        raise _fail(p, "size", f"{size} bytes cannot hold the declared header")
    if offset < header_size:
        raise _fail(
            p, "offset to point data", f"{offset} lies inside the header ({header_size} bytes)"
        )
    if offset > size:
        raise _fail(p, "offset to point data", f"{offset} is beyond the end of file ({size} bytes)")

    # VLRs: the count must fit between the header and the points, and so must each one.
    if n_vlrs > MAX_VLRS or n_vlrs * _VLR_HEADER > offset - header_size:
        raise _fail(
            p,
            "number of VLRs",
            f"{n_vlrs} cannot fit in the {offset - header_size} bytes before the points",
        )
    pos = header_size
    for i in range(n_vlrs):
        fh.seek(pos)
        vh = fh.read(_VLR_HEADER)
        if len(vh) < _VLR_HEADER:
            raise _fail(p, f"VLR {i}", "is truncated")
        length = struct.unpack_from("<H", vh, 20)[0]
        pos += _VLR_HEADER + length
        if pos > offset:
            raise _fail(
                p,
                f"VLR {i} record length",
                f"({length}) runs past the offset to point data ({offset})",
            )

    compressed = bool(fmt_byte & 0x80) or bool(fmt_byte & 0x40)
    fmt = fmt_byte & 0x3F
    if fmt not in POINT_RECORD_SIZES:
        raise _fail(p, "point data format", f"{fmt} is not a LAS point format (0-10)")
    if minor < 4 and fmt > 5:
        raise _fail(p, "point data format", f"{fmt} needs LAS 1.4, the file is 1.{minor}")
    if record_length < POINT_RECORD_SIZES[fmt]:
        raise _fail(
            p,
            "point data record length",
            f"{record_length} is shorter than the {POINT_RECORD_SIZES[fmt]} bytes of format {fmt}",
        )

    for axis, s in zip("xyz", scales, strict=True):
        if not math.isfinite(s) or s <= 0:
            raise _fail(p, f"{axis} scale factor", f"{s!r} is not a finite positive number")
        if not MIN_SCALE <= s <= MAX_SCALE:
            raise _fail(
                p, f"{axis} scale factor", f"{s!r} is outside [{MIN_SCALE:g}, {MAX_SCALE:g}]"
            )
    for axis, o in zip("xyz", offsets, strict=True):
        if not math.isfinite(o) or abs(o) > MAX_ABS_OFFSET:
            raise _fail(
                p, f"{axis} offset", f"{o!r} is not a finite number below {MAX_ABS_OFFSET:g}"
            )
    names = ("max x", "min x", "max y", "min y", "max z", "min z")
    for name, b in zip(names, bounds, strict=True):
        if not math.isfinite(b) or abs(b) > MAX_ABS_BOUND:
            raise _fail(p, name, f"{b!r} is not a finite coordinate")

    count = legacy_count
    n_evlrs = 0
    evlr_start = 0
    if minor >= 3:
        waveform = struct.unpack_from("<Q", head, 227)[0]
        if waveform > size:
            raise _fail(p, "start of waveform data", f"{waveform} is beyond the end of file")
    if minor >= 4:
        evlr_start, n_evlrs = struct.unpack_from("<QI", head, 235)
        count = struct.unpack_from("<Q", head, 247)[0] or legacy_count
        if legacy_count and count != legacy_count:
            raise _fail(
                p,
                "point count",
                f"legacy ({legacy_count}) and LAS 1.4 ({count}) point counts disagree",
            )
        if n_evlrs:
            if evlr_start < offset or evlr_start > size:
                raise _fail(
                    p, "start of first EVLR", f"{evlr_start} is outside the file ({size} bytes)"
                )
            if n_evlrs > MAX_VLRS or n_evlrs * _EVLR_HEADER > size - evlr_start:
                raise _fail(
                    p,
                    "number of EVLRs",
                    f"{n_evlrs} cannot fit in the {size - evlr_start} bytes after {evlr_start}",
                )
            pos = evlr_start
            for i in range(n_evlrs):
                fh.seek(pos)
                eh = fh.read(_EVLR_HEADER)
                if len(eh) < _EVLR_HEADER:
                    raise _fail(p, f"EVLR {i}", "is truncated")
                length = struct.unpack_from("<Q", eh, 20)[0]
                pos += _EVLR_HEADER + length
                if pos > size:
                    raise _fail(p, f"EVLR {i} record length", f"({length}) runs past end of file")

    end_of_points = evlr_start if n_evlrs else size
    available = end_of_points - offset
    if compressed:
        # LAZ: the first 8 bytes of the point data point to the chunk table.
        if count and available < 8:
            raise _fail(p, "point data", "is too short to hold a LAZ chunk table offset")
        if count > available * 8 / _MIN_LAZ_BITS_PER_POINT:
            raise _fail(
                p,
                "point count",
                f"{count} points cannot be compressed into {available} bytes",
            )
        if count:
            fh.seek(offset)
            table = struct.unpack("<q", fh.read(8).ljust(8, b"\0"))[0]
            if table != -1 and not (offset + 8 <= table <= end_of_points - 8):
                raise _fail(
                    p,
                    "LAZ chunk table offset",
                    f"{table} is outside the point data ({offset + 8}..{end_of_points})",
                )
            if table != -1:
                fh.seek(table)
                raw = fh.read(8)
                if len(raw) < 8:
                    raise _fail(p, "LAZ chunk table", "is truncated")
                _version, n_chunks = struct.unpack("<II", raw)
                # each chunk holds at least one point; a compressed entry takes >= 1 bit
                if n_chunks > count + 1 or n_chunks > (end_of_points - table) * 8:
                    raise _fail(
                        p, "LAZ chunk table", f"declares {n_chunks} chunks for {count} points"
                    )
        if count and fmt >= 6:
            _check_laz_layers(p, fh, header_size, n_vlrs, offset, end_of_points, count)
    elif count * record_length > available:
        raise _fail(
            p,
            "point count",
            f"(header declares {count} points) needs {count * record_length} bytes of "
            f"{record_length}-byte records, the file has {available} after the offset to point "
            "data; the file is truncated or its header is wrong",
        )
    return LasHeaderFacts(
        version=(major, minor),
        point_format=fmt,
        record_length=record_length,
        point_count=count,
        offset_to_points=offset,
        n_vlrs=n_vlrs,
        n_evlrs=n_evlrs,
        compressed=compressed,
        file_size=size,
    )


# Layers of the LAS 1.4 ("layered") LAZ items: item type -> number of layers (BYTE14: one
# per byte, given by the item size).
_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}


def _laszip_vlr(fh, header_size: int, n_vlrs: int) -> bytes | None:
    pos = header_size
    for _ in range(n_vlrs):
        fh.seek(pos)
        vh = fh.read(_VLR_HEADER)
        record_id, length = struct.unpack_from("<HH", vh, 18)
        if vh[2:18].rstrip(b"\0") == b"laszip encoded" and record_id == 22204:
            fh.seek(pos + _VLR_HEADER)
            return fh.read(length)
        pos += _VLR_HEADER + length
    return None


def _check_laz_layers(p: Path, fh, header_size: int, n_vlrs: int, offset: int, end: int,
                      count: int) -> None:
    """Check each chunk's layer sizes (LAS 1.4 point formats) against the chunk's bytes.

    A layered LAZ chunk is: the first point raw, the chunk's point count, one 32-bit
    size per layer, then the layers. The decompressor allocates each layer at its
    declared size: garbage there costs gigabytes before the read fails.
    """
    payload = _laszip_vlr(fh, header_size, n_vlrs)
    if payload is None or len(payload) < 34:
        raise _fail(p, "laszip VLR", "is missing or truncated in a compressed file")
    n_items = struct.unpack_from("<H", payload, 32)[0]
    if len(payload) < 34 + 6 * n_items:
        raise _fail(p, "laszip VLR", f"declares {n_items} items but is {len(payload)} bytes")
    items = [struct.unpack_from("<HHH", payload, 34 + 6 * i) for i in range(n_items)]
    if not any(t in _LAYERS or t == 14 for t, _, _ in items):
        return  # not layered (pre-1.4 items)
    n_layers = sum(_LAYERS.get(t, size if t == 14 else 0) for t, size, _ in items)
    raw = sum(size for _, size, _ in items)
    chunks = _chunk_table(fh, payload, offset)
    starts: list[tuple[int, int]] = []  # (start, byte size) of each chunk
    if chunks is None:
        starts = [(offset + 8, end - offset - 8)]  # at least the first chunk
    else:
        pos = offset + 8
        for _n, nbytes in chunks:
            starts.append((pos, nbytes))
            pos += nbytes
    for i, (start, nbytes) in enumerate(starts):
        if start >= end:
            break
        fh.seek(start + raw)
        hdr = fh.read(4 + 4 * n_layers)
        if len(hdr) < 4 + 4 * n_layers:
            raise _fail(p, f"LAZ chunk {i}", "is truncated")
        n_points, *sizes = struct.unpack(f"<I{n_layers}I", hdr)
        if n_points > count:
            raise _fail(p, f"LAZ chunk {i}", f"claims {n_points} points, the file {count}")
        room = min(nbytes, end - start)
        if raw + 4 + 4 * n_layers + sum(sizes) > room:
            raise _fail(
                p, f"LAZ chunk {i}",
                f"declares {sum(sizes)} bytes of compressed layers in {room} bytes",
            )


def _chunk_table(fh, payload: bytes, offset: int) -> list[tuple[int, int]] | None:
    """The (points, bytes) of each chunk, or None if it cannot be read here."""
    try:
        import lazrs
    except ImportError:
        return None
    try:
        fh.seek(offset)
        table = lazrs.read_chunk_table(fh, lazrs.LazVlr(payload))
        return [(int(a), int(b)) for a, b in table] if table is not None else None
    except Exception:  # noqa: BLE001 - no readable table: check the first chunk only
        return None
