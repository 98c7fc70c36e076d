"""CRS helpers: EPSG codes, vertical units, height conversion, CRS comparison, sidecars.

CSV files carry their CRS in a sidecar file next to them: ``points.csv`` ->
``points.prj``, holding the CRS as WKT (the ESRI/GeoCSV ``.prj`` convention,
which GDAL/OGR's CSV driver and so QGIS read). lidarqa writes it with every
CSV output whose source had a CRS and reads it back with every CSV input.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CRSMismatchError

__all__ = [
    "crs_epsg",
    "crs_name",
    "horizontal_unit",
    "require_metric_xy",
    "vertical_unit",
    "z_to_metres_factor",
    "metre_factors",
    "heights_to_metres",
    "ensure_same_crs_parts",
    "check_map_crs",
    "reproject",
    "ensure_same_crs",
    "parse_crs",
    "crs_label",
    "sidecar_path",
    "read_crs_sidecar",
    "write_crs_sidecar",
    "resolve_crs",
]

#: Suffixes of text tables whose CRS lives in a ``.prj`` sidecar.
SIDECAR_SUFFIXES = {".csv", ".txt", ".xyz", ".pts"}


def parse_crs(value: Any) -> Any:
    """A pyproj CRS from an EPSG int or digits, 'EPSG:xxxx', WKT, a ``.prj`` file or a CRS.

    None stays None; anything else raises :class:`OptionError`.
    """
    if value is None or value == "":
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    from ..errors import OptionError

    if isinstance(value, str) and value.lower().endswith((".prj", ".wkt")):
        p = Path(value)
        if not p.is_file():
            raise OptionError(f"CRS file {value} does not exist")
        value = p.read_text(encoding="utf-8-sig").strip()
    elif isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    try:
        return CRS.from_user_input(value)
    except CRSError as exc:
        raise OptionError(f"not a CRS: {value!r} ({exc})") from exc


def crs_epsg(crs: Any) -> int | None:
    """The EPSG code of `crs` (of a compound CRS as a whole, else None)."""
    if crs is None:
        return None
    try:
        code = crs.to_epsg(min_confidence=70)
    except Exception:
        code = None
    return int(code) if code is not None else None


def crs_name(crs: Any) -> str | None:
    """The CRS's name, or None without a CRS."""
    return None if crs is None else str(crs.name)


def crs_label(crs: Any) -> str:
    """``"RGF93 v1 / Lambert-93 (EPSG:2154)"``, or ``"none"``."""
    if crs is None:
        return "none"
    code = crs_epsg(crs)
    return f"{crs.name} (EPSG:{code})" if code else str(crs.name)


def sidecar_path(path: str | os.PathLike) -> Path:
    """The ``.prj`` sidecar of a text table (``a/b.csv`` -> ``a/b.prj``)."""
    return Path(path).with_suffix(".prj")


def read_crs_sidecar(path: str | os.PathLike) -> Any:
    """The CRS in the ``.prj`` sidecar of `path`, or None when there is none.

    Raises
    ------
    ReadError
        If the sidecar exists but holds no CRS that pyproj understands.
    """
    from ..errors import ReadError

    prj = sidecar_path(path)
    if Path(path).suffix.lower() not in SIDECAR_SUFFIXES or not prj.is_file():
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        text = prj.read_text(encoding="utf-8-sig").strip()
        return CRS.from_user_input(text) if text else None
    except (CRSError, UnicodeDecodeError) as exc:
        raise ReadError(f"{prj} (the CRS of {Path(path).name}) is not a CRS: {exc}") from exc


def write_crs_sidecar(path: str | os.PathLike, crs: Any, *, overwrite: bool = False) -> Path | None:
    """Write (or, when `crs` is None, remove a stale) ``.prj`` sidecar of `path`, atomically."""
    from .._atomic import atomic_path

    prj = sidecar_path(path)
    if crs is None:  # a sidecar left from an earlier version of this file would lie
        if overwrite and prj.is_file():
            prj.unlink()
        return None
    with atomic_path(prj, overwrite=overwrite) as tmp:
        tmp.write_text(crs.to_wkt() + "\n", encoding="utf-8")
    return prj


def resolve_crs(own: Any, given: Any, source: str | os.PathLike) -> Any:
    """The CRS of an input: its own, else the one given (``--crs``).

    An input whose own CRS differs from the given one is an error that names both.
    """
    if given is None:
        return own
    if own is None:
        return given
    try:
        same = own.equals(given, ignore_axis_order=True)
    except Exception:
        same = own == given
    if not same:
        raise CRSMismatchError(
            f"{source} is in {crs_label(own)} but --crs says {crs_label(given)}; "
            "drop --crs or reproject the file"
        )
    return own


def _vertical_axis(crs: Any) -> Any:
    if crs is None:
        return None
    candidates = [crs]
    if crs.is_compound:
        candidates = list(crs.sub_crs_list)
    for c in candidates:
        for axis in c.axis_info:
            if axis.direction in ("up", "down"):
                return axis
    return None


def horizontal_unit(crs: Any) -> tuple[str | None, float | None]:
    """Name and metre factor of the horizontal axes (e.g. ``("US survey foot", 0.3048006)``).

    ``(None, None)`` without a CRS or horizontal axis; a geographic CRS gives
    its angular unit (``("degree", 0.01745...)``, a factor to radians).
    """
    if crs is None:
        return None, None
    for c in list(crs.sub_crs_list) if crs.is_compound else [crs]:
        for axis in c.axis_info:
            if axis.direction in ("east", "north", "west", "south"):
                return str(axis.unit_name), float(axis.unit_conversion_factor)
    return None, None


def require_metric_xy(crs: Any, what: str, needs: str) -> None:
    """Refuse a CRS whose x, y are not metres (feet, degrees), naming it and what `needs` metres.

    A missing CRS is accepted: the user vouches for metres.
    """
    unit, factor = horizontal_unit(crs)
    if unit is not None and (crs.is_geographic or factor is None or abs(factor - 1.0) > 1e-12):
        raise CRSMismatchError(
            f"{what} is in {crs_label(crs)} (x, y unit: {unit}); {needs} a projected CRS in "
            "metres: reproject it first"
        )


def vertical_unit(crs: Any) -> tuple[str | None, float | None]:
    """Name and metre factor of the vertical axis (e.g. ``("US survey foot", 0.3048006)``).

    ``(None, None)`` when the CRS has no vertical axis. A 2D projected CRS is
    assumed to carry heights in its horizontal unit only by :func:`z_to_metres_factor`.
    """
    axis = _vertical_axis(crs)
    if axis is None:
        return None, None
    return str(axis.unit_name), float(axis.unit_conversion_factor)


def z_to_metres_factor(crs: Any) -> float:
    """Factor that turns z values into metres (1.0 when unknown or already metres)."""
    _, factor = vertical_unit(crs)
    return 1.0 if factor is None else factor


def metre_factors(crs: Any) -> tuple[float, float]:
    """Factors that turn x, y and z into metres: ``(horizontal, vertical)``.

    1.0 for metres, for an unknown CRS and for degrees (a geographic CRS is not
    scaled: an angle is no length); the vertical factor is :func:`z_to_metres_factor`.

    Examples
    --------
    >>> metre_factors(parse_crs("EPSG:2263+6360"))  # NY Long Island (US ft) + NAVD88 (US ft)
    (0.30480060960121924, 0.30480060960121924)
    >>> metre_factors(parse_crs("EPSG:2154"))
    (1.0, 1.0)
    """
    if crs is None:
        return 1.0, 1.0
    fh = 1.0
    if not crs.is_geographic:
        fh = float(horizontal_unit(crs)[1] or 1.0)
    return fh, float(z_to_metres_factor(crs))


def heights_to_metres(xyz: np.ndarray, crs: Any) -> np.ndarray:
    """A copy of `xyz` with z converted to metres according to the CRS's vertical unit."""
    out = np.array(xyz, dtype=np.float64, copy=True)
    out[:, 2] *= z_to_metres_factor(crs)
    return out


def ensure_same_crs(
    a: Any, b: Any, *, what: tuple[str, str] = ("test", "reference"), allow_missing: bool = True
) -> None:
    """Raise :class:`CRSMismatchError` if two datasets declare different CRSs.

    A dataset without a CRS is accepted when `allow_missing` (the user vouches
    for it). Equality ignores naming differences (pyproj's ``equals`` with
    ``ignore_axis_order``).
    """
    if a is None or b is None:
        if allow_missing:
            return
        raise CRSMismatchError(f"{what[0 if a is None else 1]} data has no CRS")
    try:
        same = a.equals(b, ignore_axis_order=True)
    except Exception:
        same = a == b
    if not same:
        raise CRSMismatchError(
            f"{what[0]} CRS ({crs_label(a)}) differs from {what[1]} CRS ({crs_label(b)}); "
            "reproject one of them first"
        )


def _horizontal_vertical(crs: Any) -> tuple[Any, Any]:
    if crs is None:
        return None, None
    if crs.is_compound and len(crs.sub_crs_list) >= 2:
        return crs.sub_crs_list[0], crs.sub_crs_list[1]
    return crs, None


def ensure_same_crs_parts(a: Any, b: Any, *, what: tuple[str, str] = ("a", "b")) -> None:
    """:func:`ensure_same_crs` on the horizontal and on the vertical parts of `a` and `b`.

    A compound CRS is compared part by part, so a 2D CRS matches the horizontal part of a
    compound one (a missing part is accepted, as a missing CRS).
    """
    ha, va = _horizontal_vertical(a)
    hb, vb = _horizontal_vertical(b)
    ensure_same_crs(ha, hb, what=what)
    ensure_same_crs(va, vb, what=(what[0] + " vertical", what[1] + " vertical"))


def check_map_crs(cloud_crs: Any, map_crs: Any, polygons: np.ndarray, path: Any) -> None:
    """Cloud and map CRS must agree; say so when a projected map was read as WGS 84.

    A GeoJSON file without a ``crs`` member is WGS 84 by definition, so a map
    digitised in a projected CRS and saved that way reads as longitude/latitude.
    """
    import shapely

    try:
        ensure_same_crs_parts(cloud_crs, map_crs, what=("cloud", "map"))
    except CRSMismatchError as exc:
        x0, y0, x1, y1 = shapely.total_bounds(polygons)
        geographic = bool(getattr(map_crs, "is_geographic", False))
        if geographic and not (-180 <= x0 <= x1 <= 180 and -90 <= y0 <= y1 <= 90):
            raise CRSMismatchError(
                f"{exc}. The map's coordinates are not longitude/latitude: {Path(path).name} "
                "has no CRS of its own (a GeoJSON file without a 'crs' member is WGS 84 by "
                "definition); store the map with its CRS, e.g. as a GeoPackage"
            ) from exc
        raise


def reproject(xyz: np.ndarray, source: Any, target: Any) -> np.ndarray:
    """Transform coordinates between two CRSs (3D when both have a vertical axis).

    Use this explicitly before comparing datasets whose CRSs differ; lidarqa
    never reprojects silently.
    """
    from pyproj import Transformer

    from ..errors import CRSMismatchError

    if source is None or target is None:
        raise CRSMismatchError("cannot reproject: both datasets need a CRS")
    t = Transformer.from_crs(source, target, always_xy=True)
    x, y, z = t.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    out = np.column_stack([x, y, z])
    if not np.isfinite(out).all():
        raise CRSMismatchError(
            "reprojection produced non-finite coordinates (outside the CRS area?)"
        )
    return out
