"""3D line segments and point lists: CSV, GeoPackage, GeoJSON.

CSV is handled with the standard library; GeoPackage and GeoJSON need the
``vector`` extra (shapely + pyogrio), imported lazily.

- Segments CSV: ``id,x1,y1,z1,x2,y2,z2`` then any attribute columns.
- Points CSV: ``id,x,y,z`` (``z`` optional where noted) then attributes.
- GeoPackage/GeoJSON: LineString Z / Point Z features with an ``id`` field.

CRS: GeoPackage/GeoJSON carry it inside; a CSV carries it in a ``.prj``
sidecar (WKT, read by GDAL/QGIS), written with the CSV and read back with it.
Every reader takes ``crs=`` for inputs without one (an input whose own CRS
differs is an error naming both). CSV coordinates are written to 0.1 mm and
other decimals to 10 significant digits (see :mod:`lidarqa.units`).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_path, check_input, check_output
from .._validate import MAX_COORDINATE
from ..errors import InvalidPointsError, ReadError, WriteError
from ..units import format_coordinate, format_decimal
from .crs import read_crs_sidecar, resolve_crs, sidecar_path, write_crs_sidecar
from .text import DECIMAL_COMMA, dialect_hint

__all__ = [
    "Segments",
    "metric_lengths",
    "heights_in_metres",
    "PointSet",
    "as_pointset",
    "read_segments",
    "write_segments",
    "read_points",
    "write_points",
    "read_features",
    "VECTOR_SUFFIXES",
]

VECTOR_SUFFIXES = {".csv", ".gpkg", ".geojson", ".json"}


@dataclass(eq=False)
class Segments:
    """A set of 3D line segments.

    Attributes
    ----------
    ids : ndarray of shape (n,)
        Identifiers (int or str).
    start, end : ndarray of shape (n, 3)
        Endpoints.
    attributes : dict of str to ndarray of shape (n,)
    crs : pyproj.CRS or None
    """

    ids: np.ndarray
    start: np.ndarray
    end: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    crs: Any = None

    def __post_init__(self) -> None:
        self.start = np.asarray(self.start, dtype=np.float64).reshape(-1, 3)
        self.end = np.asarray(self.end, dtype=np.float64).reshape(-1, 3)
        self.ids = np.asarray(self.ids)
        n = len(self.start)
        if self.end.shape != (n, 3) or self.ids.shape != (n,):
            raise InvalidPointsError("segments: ids, start and end must have the same length")
        for k, v in self.attributes.items():
            if len(v) != n:
                raise InvalidPointsError(
                    f"segments: attribute {k!r} has {len(v)} values for {n} segments"
                )

    def __len__(self) -> int:
        return len(self.start)

    @property
    def lengths(self) -> np.ndarray:
        """Length of each segment, in metres."""
        return np.linalg.norm(self.end - self.start, axis=1)

    @property
    def endpoints(self) -> np.ndarray:
        """(n, 2, 3) array of endpoint pairs."""
        return np.stack([self.start, self.end], axis=1)

    def subset(self, index: Any) -> Segments:
        """The segments selected by `index` (a mask, indices or a slice)."""
        return Segments(
            self.ids[index],
            self.start[index],
            self.end[index],
            {k: np.asarray(v)[index] for k, v in self.attributes.items()},
            self.crs,
        )


def heights_in_metres(segments: Segments) -> Segments:
    """`segments` with heights in metres, from the vertical unit of their CRS (a copy).

    Line matching measures distances in metres: edges given back in a cloud's own
    vertical unit (US survey feet, say) or a segment file in feet are compared in
    metres. The CRS is kept (x, y are not scaled); metres are returned as they are.

    Parameters
    ----------
    segments : Segments

    Returns
    -------
    Segments
    """
    from .crs import z_to_metres_factor

    f = z_to_metres_factor(segments.crs)
    if f == 1.0:
        return segments
    start = np.array(segments.start, dtype=np.float64, copy=True)
    end = np.array(segments.end, dtype=np.float64, copy=True)
    start[:, 2] *= f
    end[:, 2] *= f
    return Segments(segments.ids, start, end, dict(segments.attributes), crs=segments.crs)


def metric_lengths(segments: Segments) -> np.ndarray:
    """Length of each segment in metres, whatever the unit of its heights.

    Edges are extracted in metres and their heights written back in the cloud's
    vertical unit (e.g. US survey feet); the ``length`` attribute the extraction
    measured is then the length in metres, while :attr:`Segments.lengths` measures
    the stored coordinates. Without that attribute, :attr:`Segments.lengths`.

    Parameters
    ----------
    segments : Segments

    Returns
    -------
    ndarray of shape (n,)
    """
    if len(segments) == 0:
        return np.zeros(0)
    if "length" in segments.attributes:
        return np.asarray(segments.attributes["length"], dtype=np.float64)
    return segments.lengths


@dataclass(eq=False)
class PointSet:
    """Named 3D points (check points, corners, map points). z may be NaN when unknown."""

    ids: np.ndarray
    xyz: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    crs: Any = None

    def __post_init__(self) -> None:
        self.xyz = np.asarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        self.ids = np.asarray(self.ids)
        n = len(self.xyz)
        if self.ids.shape != (n,):
            raise InvalidPointsError("points: ids and xyz must have the same length")
        for k, v in self.attributes.items():
            if len(v) != n:
                raise InvalidPointsError(
                    f"points: attribute {k!r} has {len(v)} values for {n} points"
                )

    def __len__(self) -> int:
        return len(self.xyz)

    def subset(self, index: Any) -> PointSet:
        """The points selected by `index` (a mask, indices or a slice)."""
        return PointSet(
            self.ids[index],
            self.xyz[index],
            {k: np.asarray(v)[index] for k, v in self.attributes.items()},
            self.crs,
        )


def as_pointset(obj: Any, name: str = "points") -> PointSet:
    """`obj` as a :class:`PointSet`: a PointSet as it is, an ``(N, 3)`` array numbered 0..N-1.

    Parameters
    ----------
    obj : PointSet or array_like of shape (N, 3)
        Named points, or bare coordinates (x, y, z; m).
    name : str, default "points"
        What `obj` is, for the error message.

    Returns
    -------
    PointSet
        `obj` itself when it is a PointSet (not copied), else new points with
        ids ``0..N-1`` and no CRS.

    Raises
    ------
    InvalidPointsError
        `obj` is neither a PointSet nor an ``(N, 3)`` array.
    """
    if isinstance(obj, PointSet):
        return obj
    xyz = np.asarray(obj, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InvalidPointsError(
            f"{name} must be a PointSet or an (N, 3) array, got shape {xyz.shape}"
        )
    return PointSet(ids=np.arange(len(xyz)), xyz=xyz)


# --------------------------------------------------------------------- helpers


def _suffix(path: str | os.PathLike) -> str:
    s = Path(path).suffix.lower()
    if s not in VECTOR_SUFFIXES:
        raise ReadError(f"unsupported vector format {s!r} for {path}: use .csv, .gpkg or .geojson")
    return s


def _convert_column(values: list[str]) -> np.ndarray:
    try:
        arr = np.array([float(v) if v.strip() != "" else np.nan for v in values], dtype=np.float64)
    except ValueError:
        # decimal commas (';'-separated European exports): every value a number with a comma
        if values and all(DECIMAL_COMMA.match(v) or _is_float(v) for v in values if v.strip()):
            return _convert_column([v.replace(",", ".") for v in values])
        return np.array(values, dtype=object)
    if (
        arr.size
        and np.all(np.isfinite(arr))
        and np.all(arr == np.round(arr))
        and np.abs(arr).max() < 2**53
    ):
        return arr.astype(np.int64)
    return arr


MAX_CSV_BYTES = 2_000_000_000  # a vector table beyond 2 GB is not a point or segment list


def _decode(p: Path) -> str:
    """The text of a CSV file: UTF-8 (with or without BOM), UTF-16 with BOM, else Latin-1.

    Coordinates are ASCII in every one of these, so only free-text columns
    (names, comments) depend on the guess; a Latin-1 fallback is announced.
    """
    import codecs
    import warnings

    from ..errors import DataQualityWarning

    size = p.stat().st_size
    if size > MAX_CSV_BYTES:
        raise ReadError(f"input {p} is {size / 1e9:.1f} GB; too large for a vector table")
    data = p.read_bytes()
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise ReadError(f"input {p} is not valid UTF-16 text: {exc.reason}") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        warnings.warn(
            f"{p} is not UTF-8 (byte {data[exc.start:exc.start + 1]!r} at offset {exc.start}); "
            "read as Latin-1",
            DataQualityWarning,
            stacklevel=4,
        )
        return data.decode("latin-1")


def _read_csv_table(p: Path) -> dict[str, np.ndarray]:
    import io

    text = _decode(p)
    if "\x00" in text:
        raise ReadError(f"input {p} contains NUL bytes: not a text table")
    sample = text[:4096]
    delim = ";" if sample.count(";") > sample.count(",") else ","
    try:
        rows = [
            r
            for r in csv.reader(io.StringIO(text, newline=""), delimiter=delim)
            if r and not r[0].lstrip().startswith("#")
        ]
    except csv.Error as exc:  # a field beyond csv's size limit, a stray quote, ...
        raise ReadError(f"input {p} is not a readable CSV table: {exc}") from None
    if not rows:
        raise ReadError(f"input {p} has no rows")
    header = [h.strip().lower() for h in rows[0]]
    seen: set[str] = set()
    for h in header:
        if h in seen:
            raise ReadError(f"input {p}: column {h!r} appears more than once in the header")
        seen.add(h)
    if "" in seen:
        # a trailing delimiter gives an unnamed, empty column: drop it; refuse one with values
        k = header.index("")
        if any(len(r) > k and r[k].strip() for r in rows[1:]):
            raise ReadError(f"input {p}: column {k + 1} has values but no name in the header")
        rows = [r[:k] + r[k + 1 :] for r in rows]
        header = header[:k] + header[k + 1 :]
    body = rows[1:]
    for i, r in enumerate(body, start=2):
        if len(r) != len(header):
            raise ReadError(
                f"input {p} line {i}: {len(r)} values for {len(header)} columns"
                + dialect_hint(p)
            )
    cols = list(zip(*body, strict=True)) if body else [() for _ in header]
    return {h: _convert_column(list(c)) for h, c in zip(header, cols, strict=True)}


def _is_float(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _need(table: dict, names: tuple[str, ...], p: Path) -> None:
    missing = [n for n in names if n not in table]
    if missing:
        raise ReadError(f"input {p} lacks column(s) {', '.join(missing)}; has: {', '.join(table)}")


def _floats(table: dict, name: str, p: Path) -> np.ndarray:
    col = table[name]
    if col.dtype == object:
        bad = next((str(v) for v in col if not _is_float(str(v))), "")
        raise ReadError(
            f"input {p}: column {name!r} is not numeric (e.g. {bad!r})" + dialect_hint(p)
        )
    return col.astype(np.float64)


def _ids(table: dict, n: int) -> np.ndarray:
    if "id" in table:
        return table["id"]
    return np.arange(n)


def _check_unique(ids: np.ndarray, p: Path) -> None:
    u, c = np.unique(ids.astype(str), return_counts=True)
    if (c > 1).any():
        raise ReadError(f"input {p}: duplicate id(s) {', '.join(u[c > 1][:5])}")


def read_features(path: str | os.PathLike) -> tuple[Any, list[str], np.ndarray, list]:
    """Every feature of a GeoPackage/GeoJSON layer: CRS, field names, geometries, field values.

    Parameters
    ----------
    path : str or path-like
        A vector file GDAL/OGR reads (its first layer is read).

    Returns
    -------
    crs : pyproj.CRS or None
        The layer's CRS (None when it declares none or it is not understood).
    names : list of str
        The attribute field names, lower-cased.
    geometries : ndarray of shape (F,) object
        Shapely geometries (None for a feature without one).
    fields : list of ndarray
        One array of F values per name, in the order of `names`.

    Raises
    ------
    ReadError
        The file cannot be read.
    MissingDependencyError
        pyogrio or shapely is not installed (the ``vector`` extra).
    """
    pyogrio, shapely = _gis()
    try:
        meta, _, wkb, field_data = pyogrio.raw.read(str(path))
    except Exception as exc:
        raise ReadError(f"cannot read {path}: {exc}") from exc
    names = [n.lower() for n in meta["fields"]]
    return _crs_from_meta(meta), names, shapely.from_wkb(wkb), field_data


def _gis():
    from .._validate import require

    return require("pyogrio", "vector"), require("shapely", "vector")


# --------------------------------------------------------------------- segments


def read_segments(path: str | os.PathLike, *, crs: Any = None) -> Segments:
    """Read 3D line segments from CSV (``id,x1,y1,z1,x2,y2,z2``), GeoPackage or GeoJSON.

    Multi-vertex LineStrings are split into their consecutive segments (ids
    ``<id>.<k>``). Raises :class:`ReadError` for a missing/empty file, missing
    columns or 2D geometry, and :class:`InvalidPointsError` for NaN coordinates.
    `crs` (a pyproj CRS) is the CRS of a file that declares none; a file whose
    own CRS (embedded, or a CSV's ``.prj`` sidecar) differs raises
    :class:`CRSMismatchError`.
    """
    p = check_input(path)
    suffix = _suffix(p)
    given, crs = crs, None
    if suffix == ".csv":
        crs = read_crs_sidecar(p)
        table = _read_csv_table(p)
        _need(table, ("x1", "y1", "z1", "x2", "y2", "z2"), p)
        start = np.column_stack([_floats(table, c, p) for c in ("x1", "y1", "z1")])
        end = np.column_stack([_floats(table, c, p) for c in ("x2", "y2", "z2")])
        ids = _ids(table, len(start))
        attrs = {
            k: v for k, v in table.items() if k not in {"id", "x1", "y1", "z1", "x2", "y2", "z2"}
        }
    else:
        crs, names, geoms, field_data = read_features(p)
        starts, ends, ids_l, rows = [], [], [], []
        base_ids = field_data[names.index("id")] if "id" in names else np.arange(len(geoms))
        for i, g in enumerate(geoms):
            if g is None or g.is_empty:
                continue
            if g.geom_type not in ("LineString", "MultiLineString"):
                raise ReadError(
                    f"input {p}: feature {base_ids[i]} is a {g.geom_type}; line segments need "
                    "LineString Z features"
                )
            if not g.has_z:
                raise ReadError(
                    f"input {p}: feature {base_ids[i]} has no z (LineString Z expected)"
                )
            parts = list(getattr(g, "geoms", [g]))
            k = 0
            for part in parts:
                c = np.asarray(part.coords)
                for a, b in zip(c[:-1], c[1:], strict=True):
                    starts.append(a)
                    ends.append(b)
                    single = len(parts) == 1 and len(c) == 2
                    ids_l.append(base_ids[i] if single else f"{base_ids[i]}.{k}")
                    rows.append(i)
                    k += 1
        start = np.asarray(starts, dtype=float).reshape(-1, 3)
        end = np.asarray(ends, dtype=float).reshape(-1, 3)
        ids = np.asarray(ids_l) if ids_l else np.empty(0, dtype=np.int64)
        rows_a = np.asarray(rows, dtype=np.int64)
        attrs = {n: np.asarray(field_data[j])[rows_a] for j, n in enumerate(names) if n != "id"}
    if len(start) and not (np.isfinite(start).all() and np.isfinite(end).all()):
        raise InvalidPointsError(f"input {p} has segments with NaN or infinite coordinates")
    if len(start) and max(np.abs(start).max(), np.abs(end).max()) > MAX_COORDINATE:
        raise InvalidPointsError(f"input {p} has coordinates beyond ±{MAX_COORDINATE:g}")
    _check_unique(ids, p)
    crs = resolve_crs(crs, given, p)
    return Segments(ids=ids, start=start, end=end, attributes=attrs, crs=crs)


def write_segments(
    segments: Segments, path: str | os.PathLike, *, overwrite: bool = False, layer: str = "segments"
) -> Path:
    """Write segments as CSV, GeoPackage or GeoJSON (LineString Z), atomically."""
    suffix = Path(path).suffix.lower()
    if suffix not in VECTOR_SUFFIXES:
        raise WriteError(f"cannot write segments as {suffix!r}: use .csv, .gpkg or .geojson")
    if len(segments) and not (
        np.isfinite(segments.start).all() and np.isfinite(segments.end).all()
    ):
        raise WriteError("refusing to write segments with NaN coordinates")
    if suffix == ".csv":
        cols = {"id": segments.ids}
        for i, c in enumerate(("x1", "y1", "z1")):
            cols[c] = segments.start[:, i]
        for i, c in enumerate(("x2", "y2", "z2")):
            cols[c] = segments.end[:, i]
        cols.update(segments.attributes)
        return _write_csv(cols, path, overwrite=overwrite, crs=segments.crs)
    _, shapely = _gis()
    geoms = shapely.linestrings(segments.endpoints) if len(segments) else np.empty(0, dtype=object)
    return _write_ogr(
        geoms,
        {"id": segments.ids, **segments.attributes},
        segments.crs,
        path,
        overwrite=overwrite,
        layer=layer,
        geometry_type="LineString Z",
    )


# ----------------------------------------------------------------------- points


def read_points(path: str | os.PathLike, *, require_z: bool = True, crs: Any = None) -> PointSet:
    """Read a point list from CSV (``id,x,y,z``), GeoPackage or GeoJSON (Point Z).

    With ``require_z=False`` a missing z column / 2D geometry gives z = NaN.
    `crs` (a pyproj CRS) is the CRS of a file that declares none; a file whose
    own CRS (embedded, or a CSV's ``.prj`` sidecar) differs raises
    :class:`CRSMismatchError`.
    """
    p = check_input(path)
    suffix = _suffix(p)
    given, crs = crs, None
    if suffix == ".csv":
        crs = read_crs_sidecar(p)
        table = _read_csv_table(p)
        _need(table, ("x", "y") + (("z",) if require_z else ()), p)
        x, y = _floats(table, "x", p), _floats(table, "y", p)
        z = _floats(table, "z", p) if "z" in table else np.full(len(x), np.nan)
        xyz = np.column_stack([x, y, z])
        ids = _ids(table, len(xyz))
        attrs = {k: v for k, v in table.items() if k not in {"id", "x", "y", "z"}}
    else:
        crs, names, geoms, field_data = read_features(p)
        if len(geoms) and not all(g is not None and g.geom_type == "Point" for g in geoms):
            raise ReadError(f"input {p}: expected Point features")
        if require_z and len(geoms) and not all(g.has_z for g in geoms):
            raise ReadError(f"input {p}: points have no z (Point Z expected)")
        xyz = _gis()[1].get_coordinates(geoms, include_z=True) if len(geoms) else np.empty((0, 3))
        ids = field_data[names.index("id")] if "id" in names else np.arange(len(xyz))
        attrs = {n: np.asarray(field_data[j]) for j, n in enumerate(names) if n != "id"}
    finite = np.isfinite(xyz[:, :2]).all() and (not require_z or np.isfinite(xyz[:, 2]).all())
    if len(xyz) and not finite:
        raise InvalidPointsError(f"input {p} has points with NaN or infinite coordinates")
    if len(xyz) and np.nanmax(np.abs(xyz)) > MAX_COORDINATE:
        raise InvalidPointsError(f"input {p} has coordinates beyond ±{MAX_COORDINATE:g}")
    _check_unique(np.asarray(ids), p)
    crs = resolve_crs(crs, given, p)
    return PointSet(ids=np.asarray(ids), xyz=xyz, attributes=attrs, crs=crs)


def write_points(
    points: PointSet, path: str | os.PathLike, *, overwrite: bool = False, layer: str = "points"
) -> Path:
    """Write a point list as CSV, GeoPackage or GeoJSON (Point Z), atomically."""
    suffix = Path(path).suffix.lower()
    if suffix not in VECTOR_SUFFIXES:
        raise WriteError(f"cannot write points as {suffix!r}: use .csv, .gpkg or .geojson")
    if suffix == ".csv":
        cols = {
            "id": points.ids,
            "x": points.xyz[:, 0],
            "y": points.xyz[:, 1],
            "z": points.xyz[:, 2],
        }
        cols.update(points.attributes)
        return _write_csv(cols, path, overwrite=overwrite, crs=points.crs)
    _, shapely = _gis()
    geoms = shapely.points(points.xyz) if len(points) else np.empty(0, dtype=object)
    no_z = ~np.isfinite(points.xyz[:, 2])
    if suffix in {".geojson", ".json"} and no_z.any():
        # GeoJSON has no NaN: a point without a height is written as [x, y]
        geoms = np.array(
            [
                shapely.to_wkb(g, output_dimension=2 if flat else 3)
                for g, flat in zip(geoms, no_z, strict=True)
            ],
            dtype=object,
        )
    return _write_ogr(
        geoms,
        {"id": points.ids, **points.attributes},
        points.crs,
        path,
        overwrite=overwrite,
        layer=layer,
        geometry_type="Point Z",
    )


# ------------------------------------------------------------------- writers


#: CSV columns holding coordinates and coordinate differences in metres (written to 0.1 mm).
COORDINATE_COLUMNS = frozenset(
    {"x", "y", "z", "x1", "y1", "z1", "x2", "y2", "z2", "dx", "dy", "dz", "dh"}
)


def _fmt(v: Any, coordinate: bool = False) -> str:
    if isinstance(v, float | np.floating):
        if not np.isfinite(v):
            return ""
        return format_coordinate(float(v)) if coordinate else format_decimal(float(v))
    if isinstance(v, bool | np.bool_):
        return "true" if v else "false"
    return str(v)


def _write_csv(
    cols: dict[str, Any], path: str | os.PathLike, *, overwrite: bool, crs: Any = None
) -> Path:
    names = list(cols)
    arrays = [np.asarray(cols[n]) for n in names]
    is_coord = [n in COORDINATE_COLUMNS for n in names]
    replacing = Path(path).exists()
    if crs is not None:
        check_output(sidecar_path(path), overwrite=overwrite or replacing)
    with atomic_path(path, overwrite=overwrite) as tmp:
        with tmp.open("w", encoding="utf-8", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for row in zip(*arrays, strict=True):
                w.writerow([_fmt(v, c) for v, c in zip(row, is_coord, strict=True)])
        # the sidecar belongs to the CSV: replaced with it, removed if now stale
        write_crs_sidecar(path, crs, overwrite=replacing or overwrite)
    return Path(path)


def _write_ogr(
    geoms: Any,
    fields: dict[str, Any],
    crs: Any,
    path: str | os.PathLike,
    *,
    overwrite: bool,
    layer: str,
    geometry_type: str,
) -> Path:
    pyogrio, shapely = _gis()
    suffix = Path(path).suffix.lower()
    driver = "GPKG" if suffix == ".gpkg" else "GeoJSON"
    names = list(fields)
    arrays = []
    for n in names:
        a = np.asarray(fields[n])
        if a.dtype == object or a.dtype.kind in "US":
            a = a.astype(str).astype(object)
        elif a.dtype == bool:
            a = a.astype(np.int32)
        arrays.append(a)
    if len(geoms) and isinstance(geoms[0], bytes):  # already WKB (mixed dimensions)
        wkb = geoms
    else:
        wkb = (
            shapely.to_wkb(geoms, output_dimension=3) if len(geoms) else np.empty(0, dtype=object)
        )
    crs_wkt = crs.to_wkt() if crs is not None else None
    import warnings

    with atomic_path(path, overwrite=overwrite) as tmp:
        target = tmp.with_suffix(suffix)  # drivers pick the format from the extension
        try:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*'crs' was not provided.*")
                pyogrio.raw.write(
                    str(target),
                    wkb,
                    geometry_type=geometry_type,
                    field_data=arrays,
                    fields=names,
                    crs=crs_wkt,
                    driver=driver,
                    layer=layer,
                    encoding="UTF-8",
                )
            os.replace(target, tmp)
        finally:
            if target.exists():
                target.unlink()
    return Path(path)


def _crs_from_meta(meta: dict) -> Any:
    wkt = meta.get("crs")
    if not wkt:
        return None
    from pyproj import CRS

    try:
        return CRS.from_user_input(wkt)
    except Exception:
        return None
