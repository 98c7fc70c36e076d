"""Minimal PLY reader (ASCII and binary little/big endian vertex elements)."""

from __future__ import annotations

import os

import numpy as np

from ..errors import InvalidPointsError, ReadError
from .pointcloud import PointCloud

__all__ = ["read_ply"]

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def read_ply(path: str | os.PathLike) -> PointCloud:
    """Read the ``vertex`` element of a PLY file; x, y, z plus scalar properties as fields."""
    from .._atomic import check_input

    p = check_input(path)
    try:
        return _read_ply(p)
    except (ValueError, IndexError, OverflowError, TypeError, UnicodeError) as exc:
        if isinstance(exc, ReadError | InvalidPointsError):
            raise
        raise ReadError(f"input {p} is not a valid PLY file: {str(exc)[:160]}") from None


def _read_ply(p: os.PathLike) -> PointCloud:  # noqa: C901, PLR0912
    size = os.path.getsize(p)
    with open(p, "rb") as fh:  # noqa: PTH123
        if fh.readline().strip() != b"ply":
            raise ReadError(f"input {p} is not a PLY file (no 'ply' magic)")
        fmt = None
        elements: list[tuple[str, int, list[tuple[str, str]]]] = []
        while True:
            line = fh.readline(65536)
            if fh.tell() > 1_000_000:
                raise ReadError(f"input {p}: PLY header longer than 1 MB")
            if not line:
                raise ReadError(f"input {p}: PLY header has no end_header")
            tok = line.decode("ascii", "replace").split()
            if not tok or tok[0] in ("comment", "obj_info"):
                continue
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                count = int(tok[2])
                if count < 0 or count > size:
                    raise ReadError(
                        f"input {p}: PLY element {tok[1]!r} count {count} is impossible"
                    )
                elements.append((tok[1], count, []))
            elif tok[0] == "property":
                if not elements:
                    raise ReadError(f"input {p}: PLY property before any element")
                if tok[1] == "list":
                    if elements and elements[-1][0] == "vertex":
                        raise ReadError(f"input {p}: list properties on vertices are not supported")
                    elements[-1][2].append((tok[-1], "list"))
                else:
                    if tok[1] not in _TYPES:
                        raise ReadError(f"input {p}: unknown PLY type {tok[1]!r}")
                    elements[-1][2].append((tok[2], _TYPES[tok[1]]))
            elif tok[0] == "end_header":
                break
        if not elements or elements[0][0] != "vertex":
            raise ReadError(f"input {p}: the first PLY element must be 'vertex'")
        _, n, props = elements[0]
        names = [name.lower() for name, _ in props]
        if len(set(names)) != len(names):
            raise ReadError(f"input {p}: duplicate vertex property names")
        for c in ("x", "y", "z"):
            if c not in names:
                raise ReadError(f"input {p}: vertex element has no {c!r} property")
        if fmt == "ascii":
            data = np.loadtxt(fh, max_rows=n, ndmin=2)
            if data.shape != (n, len(props)):
                raise ReadError(f"input {p}: expected {n} vertices with {len(props)} values")
            cols = {name: data[:, i] for i, name in enumerate(names)}
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            end = "<" if fmt == "binary_little_endian" else ">"
            dtype = np.dtype(
                [(name, end + t) for name, t in zip(names, (t for _, t in props), strict=True)]
            )
            buf = fh.read(dtype.itemsize * n)
            if len(buf) != dtype.itemsize * n:
                raise ReadError(f"input {p}: truncated PLY (expected {n} vertices)")
            arr = np.frombuffer(buf, dtype=dtype)
            cols = {name: arr[name].astype(arr[name].dtype.newbyteorder("=")) for name in names}
        else:
            raise ReadError(f"input {p}: unsupported PLY format {fmt!r}")
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")]).astype(np.float64)
    if not np.isfinite(xyz).all():
        raise InvalidPointsError(f"input {p} has NaN or infinite coordinates")
    return PointCloud(xyz=xyz, fields=cols, path=str(p))
