"""Text point clouds: XYZ / CSV / TXT with a header naming the columns."""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_path, check_input, check_output
from ..errors import InvalidPointsError, ReadError
from .crs import read_crs_sidecar, resolve_crs, sidecar_path, write_crs_sidecar
from .pointcloud import PointCloud

__all__ = ["read_text", "write_text", "sniff_header", "dialect_hint", "DECIMAL_COMMA"]

#: A number written with a decimal comma (``770500,05``, ``-0,3``).
DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d+,\d+\s*$")


def _header_commas(text: str) -> int:
    for ln in text.splitlines():
        if ln.strip() and not ln.startswith("#"):
            return ln.count(",")
    return 0


def dialect_hint(path: str | os.PathLike) -> str:
    """A hint on a text table's dialect, for error messages ("" when nothing stands out).

    Recognises the usual spreadsheet exports that are not plain CSV: UTF-16
    ("Unicode text"), ';'-separated with decimal commas (European locales),
    text that is not UTF-8 (Latin-1/Windows-1252), and a byte-order mark.
    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read(8192)
    except OSError:
        return ""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return (
            " (the file is UTF-16, 'Unicode text' in spreadsheets: save it as 'CSV UTF-8' with "
            "',' between values and '.' as decimal point)"
        )
    hints = []
    text = raw.decode("utf-8-sig", errors="replace")
    if "\ufffd" in text:
        hints.append("it is not UTF-8 (Latin-1/Windows-1252?): save it as 'CSV UTF-8'")
    lines = [ln for ln in text.splitlines()[1:20] if ln.strip() and not ln.startswith("#")]
    if any(";" in ln for ln in lines):
        tokens = [t for ln in lines for t in ln.split(";")]
        if any(DECIMAL_COMMA.match(t) for t in tokens):
            hints.append(
                "it looks like ';'-separated with decimal commas, which lidarqa reads; "
                "check for thousands separators or text columns with commas"
            )
    elif any(DECIMAL_COMMA.match(t) for ln in lines for t in ln.split("\t")) and "\t" in text:
        hints.append("it looks like tab-separated with decimal commas")
    elif lines and any(ln.count(",") > _header_commas(text) for ln in lines):
        hints.append(
            "there are more commas than columns: decimal commas in a ','-separated file? "
            "Export with ';' between values or '.' as decimal point"
        )
    if raw.startswith(b"\xef\xbb\xbf") and not hints:
        return ""  # a UTF-8 byte-order mark is read fine
    return f" ({'; '.join(hints)})" if hints else ""


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def sniff_header(path: str | os.PathLike) -> tuple[list[str] | None, str | None]:
    """Column names (lower-cased, quotes stripped) and delimiter of a text table.

    Returns ``(None, delimiter)`` when the first line is all numbers (no header).
    A delimiter of None means runs of white space.
    """
    p = check_input(path)
    with p.open("r", encoding="utf-8-sig", errors="replace") as fh:
        first = ""
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                first = line.strip()
                break
    if not first:
        raise ReadError(f"input {p} has no data lines")
    delim: str | None = None
    for cand in (",", ";", "\t", "|"):
        if cand in first:
            delim = cand
            break
    tokens = next(csv.reader([first], delimiter=delim)) if delim else first.split()
    tokens = [t.strip().strip('"').strip("'") for t in tokens]
    if all(_is_number(t) for t in tokens):
        return None, delim
    return [t.lower() for t in tokens], delim


def read_text(path: str | os.PathLike, *, crs: Any = None) -> PointCloud:
    """Read an XYZ/CSV/TXT point table.

    The first line names the columns (``x, y, z`` required, case-insensitive;
    every other numeric column becomes a field). A file whose first line is all
    numbers has no header: its first three columns are x, y, z. The CRS comes
    from a ``.prj`` sidecar next to the file, else from `crs` (a pyproj CRS);
    a sidecar that differs from `crs` raises :class:`CRSMismatchError`.

    Raises
    ------
    ReadError
        Missing or empty file, no x/y/z columns, non-numeric values.
    InvalidPointsError
        NaN or infinite coordinates.
    """
    p = check_input(path)
    names, delim = sniff_header(p)
    skip = 0 if names is None else 1
    extra: dict[str, Any] = {}
    if delim in (";", "\t") and "decimal commas" in dialect_hint(p):
        extra["converters"] = lambda v: float(v.replace(",", "."))
    try:
        data = np.loadtxt(
            p,
            delimiter=delim,
            skiprows=skip,
            comments="#",
            ndmin=2,
            dtype=np.float64,
            encoding="utf-8-sig",
            quotechar='"',
            **extra,
        )
    except ValueError as exc:
        raise ReadError(
            f"cannot read {p} as a numeric table: {str(exc).splitlines()[0][:160]}"
            + dialect_hint(p)
        ) from exc
    if names is None:
        if data.shape[1] < 3:
            raise ReadError(f"input {p} needs at least 3 columns (x, y, z), found {data.shape[1]}")
        names = ["x", "y", "z"] + [f"col{i}" for i in range(3, data.shape[1])]
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise ReadError(
            f"input {p} has no column(s) {', '.join(missing)}; header is: {', '.join(names)}"
        )
    if data.shape[1] != len(names):
        raise ReadError(f"input {p}: header has {len(names)} columns but rows have {data.shape[1]}")
    cols = {name: data[:, i] for i, name in enumerate(names)}
    xyz = np.column_stack([cols.pop("x"), cols.pop("y"), cols.pop("z")])
    if not np.isfinite(xyz).all():
        bad = int((~np.isfinite(xyz)).any(axis=1).sum())
        raise InvalidPointsError(f"input {p} has {bad} row(s) with NaN or infinite coordinates")
    fields = {}
    for name, col in cols.items():
        if (
            np.all(np.isfinite(col))
            and np.all(col == np.round(col))
            and col.size
            and np.abs(col).max() < 2**31
        ):
            fields[name] = col.astype(np.int64)
        else:
            fields[name] = col
    own = resolve_crs(read_crs_sidecar(p), crs, p)
    return PointCloud(xyz=xyz, fields=fields, crs=own, source=None, path=str(p))


def _decimals(cloud: PointCloud) -> list[int]:
    """Decimals of x, y, z: those of the LAS scale the cloud came from, else mm."""
    scales = getattr(cloud.source, "scales", None)
    if scales is None:
        return [3, 3, 3]
    out = []
    for sc in np.asarray(scales, dtype=float):
        d = int(np.ceil(-np.log10(sc) - 1e-9)) if 0 < sc < 1 else 0
        out.append(min(max(d, 0), 9))
    return out


def write_text(cloud: PointCloud, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a cloud as CSV with a header ``x,y,z,<fields>``, atomically.

    Coordinates keep the precision of the cloud's source (the LAS scale, e.g.
    0.01 m -> 2 decimals), else 1 mm; integer fields are written as integers,
    other decimals with 15 significant digits (what a float64 holds without
    noise: GPS time keeps its microseconds). The CRS goes to a ``.prj``
    sidecar (WKT) that GDAL/QGIS and :func:`read_text` read.
    """
    names = ["x", "y", "z", *cloud.fields]
    cols = [cloud.x, cloud.y, cloud.z, *(np.asarray(v) for v in cloud.fields.values())]
    fmts = [f"%.{d}f" for d in _decimals(cloud)]
    for c in cols[3:]:
        fmts.append("%d" if c.dtype.kind in "iub" else "%.15g")
    replacing = Path(path).exists()
    if cloud.crs is not None:
        check_output(sidecar_path(path), overwrite=overwrite or replacing)
    with atomic_path(path, overwrite=overwrite) as tmp:
        with tmp.open("w", encoding="utf-8", newline="") as fh:
            fh.write(",".join(names) + "\n")
            if len(cloud):
                table = np.empty(len(cloud), dtype=[(f"c{i}", c.dtype) for i, c in enumerate(cols)])
                for i, c in enumerate(cols):
                    table[f"c{i}"] = c
                np.savetxt(fh, table, delimiter=",", fmt=fmts)
        write_crs_sidecar(path, cloud.crs, overwrite=replacing or overwrite)
    return Path(path)
