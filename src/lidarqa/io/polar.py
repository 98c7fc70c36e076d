"""Raw scanner / total-station observations: polar to Cartesian (Fang & Huang eq. 5).

In the instrument frame, with slope distance S, azimuth α measured from +Y
towards +X and elevation β above the horizon::

    X = S cos β sin α,   Y = S cos β cos α,   Z = S sin β

The station's position (X0, Y0, Z0), its orientation (the azimuth of the
instrument's zero direction in the target frame, added to α) and the
instrument height are applied afterwards.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .._validate import check_choice
from ..errors import InvalidPointsError, ReadError

__all__ = ["Station", "polar_to_cartesian", "read_polar_csv"]

_ANGLE = {"deg": np.pi / 180.0, "gon": np.pi / 200.0, "rad": 1.0}


@dataclass(frozen=True)
class Station:
    """Instrument set-up: position (m), orientation (angle unit) and instrument height (m)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    orientation: float = 0.0
    instrument_height: float = 0.0


def polar_to_cartesian(
    distance: np.ndarray,
    azimuth: np.ndarray,
    vertical: np.ndarray,
    *,
    station: Station | None = None,
    angle_unit: str = "deg",
    vertical_kind: str = "elevation",
) -> np.ndarray:
    """Convert polar observations to Cartesian coordinates (Fang & Huang eq. 5).

    Parameters
    ----------
    distance : ndarray of shape (N,)
        Slope distances S (m), >= 0.
    azimuth : ndarray of shape (N,)
        Horizontal angle α from +Y towards +X (clockwise seen from above).
    vertical : ndarray of shape (N,)
        Elevation β above the horizon, or zenith angle when ``vertical_kind="zenith"``.
    station : Station, optional
        Position, orientation (same unit as the angles) and instrument height.
    angle_unit : {"deg", "gon", "rad"}, default "deg"
    vertical_kind : {"elevation", "zenith"}, default "elevation"

    Returns
    -------
    ndarray of shape (N, 3)

    Examples
    --------
    >>> polar_to_cartesian([10.0], [90.0], [0.0]).round(9).tolist()
    [[10.0, 0.0, 0.0]]
    >>> polar_to_cartesian([10.0], [0.0], [30.0]).round(6).tolist()
    [[0.0, 8.660254, 5.0]]
    """
    check_choice(angle_unit, _ANGLE, "angle_unit")
    check_choice(vertical_kind, ("elevation", "zenith"), "vertical_kind")
    s = np.asarray(distance, dtype=np.float64).ravel()
    a = np.asarray(azimuth, dtype=np.float64).ravel()
    v = np.asarray(vertical, dtype=np.float64).ravel()
    if not (len(s) == len(a) == len(v)):
        raise InvalidPointsError("distance, azimuth and vertical angle must have the same length")
    if not (np.isfinite(s).all() and np.isfinite(a).all() and np.isfinite(v).all()):
        raise InvalidPointsError("polar observations contain NaN or infinite values")
    if (s < 0).any():
        raise InvalidPointsError("slope distances must be >= 0")
    st = station or Station()
    k = _ANGLE[angle_unit]
    alpha = (a + st.orientation) * k
    beta = v * k
    if vertical_kind == "zenith":
        beta = np.pi / 2.0 - beta
    cb = np.cos(beta)
    out = np.empty((len(s), 3))
    out[:, 0] = st.x + s * cb * np.sin(alpha)
    out[:, 1] = st.y + s * cb * np.cos(alpha)
    out[:, 2] = st.z + st.instrument_height + s * np.sin(beta)
    return out


_DIST = ("distance", "slope_distance", "s", "sd", "range")
_AZ = ("azimuth", "alpha", "hz", "horizontal_angle")
_EL = ("elevation", "beta", "vertical_angle")
_ZEN = ("zenith", "zenith_angle", "v")


def read_polar_csv(
    path: str | os.PathLike,
    *,
    station: Station | None = None,
    angle_unit: str = "deg",
) -> tuple[np.ndarray, np.ndarray]:
    """Read polar observations from CSV and convert them; returns ``(ids, xyz)``.

    Columns are found by name (case-insensitive): distance (``distance``,
    ``slope_distance``, ``s``, ``sd``, ``range``), azimuth (``azimuth``, ``alpha``,
    ``hz``), and either an elevation (``elevation``, ``beta``, ``vertical_angle``)
    or a zenith angle (``zenith``, ``zenith_angle``, ``v``). An ``id`` column is kept.
    """
    from .._atomic import check_input
    from .vector import _read_csv_table

    p = check_input(path)
    table = _read_csv_table(p)

    def pick(cands: tuple[str, ...]) -> str | None:
        return next((c for c in cands if c in table), None)

    d, az, el, zen = pick(_DIST), pick(_AZ), pick(_EL), pick(_ZEN)
    if d is None or az is None or (el is None and zen is None):
        raise ReadError(
            f"input {p} needs distance, azimuth and elevation (or zenith) columns; "
            f"has: {', '.join(table)}"
        )
    cols = []
    for name in (d, az, el or zen):
        assert name is not None  # checked above
        col = table[name]
        if col.dtype == object:
            raise ReadError(f"input {p}: column {name!r} is not numeric")
        cols.append(col.astype(np.float64))
    xyz = polar_to_cartesian(
        *cols, station=station, angle_unit=angle_unit, vertical_kind="elevation" if el else "zenith"
    )
    ids = table["id"] if "id" in table else np.arange(len(xyz))
    return np.asarray(ids), xyz
