"""The unit policy of lidarqa: one place for every unit of every number it writes.

Policy
------
- **Lengths and coordinates are metres**, angles are **degrees**, in text, JSON,
  CSV and the report. Inputs in feet (a CRS with a foot axis) are converted to
  metres before any computation, and results say so in a warning.
- **Ratios** (error rates, shares of points) are stored in JSON as **fractions
  between 0 and 1**; text and report show them as percentages. Keys ending in
  ``_pct`` are percentages (0–100).
- **Key names carry their unit** where the name alone would be ambiguous:
  ``_m`` metres, ``_deg`` degrees, ``_m2`` square metres, ``_per_m2`` per square
  metre, ``_s`` seconds, ``_pct`` percent, ``_ppm`` parts per million. Every other
  numeric key of a JSON document has its unit in :data:`KEY_UNITS` below (a test
  walks every command's JSON document and fails on a number whose unit is not
  defined here).
- **Coordinates written to files** keep the precision of their source: a LAS
  file's scale (usually 1 cm or 1 mm); computed coordinates (corners, edges,
  check-point residuals) are written to 0.1 mm, and other decimal numbers to
  at most 10 significant digits, never ``770500.05000000005``.
- **CRS**: every file lidarqa writes carries the CRS of its source. CSV files
  get a sidecar ``<name>.prj`` with the CRS as WKT (ESRI ``.prj`` convention,
  which GDAL/OGR and QGIS read for a CSV) ; lidarqa reads it back when
  ``--crs`` is not given.

The table
---------
:data:`SUFFIX_UNITS` maps key suffixes to units, :data:`KEY_UNITS` maps exact
key names to units ("1" means dimensionless, "count" a number of things,
"fraction" a ratio between 0 and 1, "id" an identifier).
"""

from __future__ import annotations

import re

__all__ = [
    "SUFFIX_UNITS",
    "KEY_UNITS",
    "key_unit",
    "param_unit",
    "COORDINATE_DECIMALS",
    "format_coordinate",
    "format_decimal",
]

#: Unit of a key from its suffix (checked in this order).
SUFFIX_UNITS: dict[str, str] = {
    "_per_m2": "1/m²",
    "_m2": "m²",
    "_m": "m",
    "_deg": "degree",
    "_pct": "percent",
    "_ppm": "ppm",
    "_s": "second",
}

_M = "m"
_D = "degree"
_N = "count"
_F = "fraction"
_1 = "1"

#: Unit of every numeric JSON key without a unit suffix.
KEY_UNITS: dict[str, str] = {
    # coordinates, bounds, lengths (metres)
    **dict.fromkeys(
        (
            "x", "y", "z", "x1", "y1", "z1", "x2", "y2", "z2", "dx", "dy", "dz",
            "min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
            "tx", "ty", "tz", "c", "d", "e",
            "mean_x", "mean_y", "mean_z", "std_x", "std_y", "std_z",
            "rmse_x", "rmse_y", "rmse_z", "rmse_h", "rmse_v", "rmse_3d", "rmse_r",
            "max_abs_x", "max_abs_y", "max_abs_z", "max_abs", "mean", "std", "rmse", "median",
            "accuracy_r", "accuracy_z", "accuracy_h", "accuracy_v", "accuracy_3d",
            "sigma0", "sigma0_h", "sigma0_v", "sigma_x", "sigma_y", "sigma_z", "sigma_line",
            "sigma_point", "sigma_map", "sigma_reference", "sigma_h", "sigma",
            "checkpoint_rmse_h", "checkpoint_rmse_v",
            "max_distance", "max_edge", "radius", "threshold", "cell_size", "spacing",
            "min_spacing", "lhd", "lhd_sym", "lhd_test_model", "lhd_model_test",
            "iter_distance", "max_iter_distance", "distance", "length", "rho", "rms",
            "instrument_height", "height", "offset", "tolerance", "buffer",
            "mean_spacing", "ground_spacing", "sensitivity_m",
        ),
        _M,
    ),
    # angles (degrees)
    **dict.fromkeys(("omega", "phi", "kappa", "iter_angle", "angle", "orientation"), _D),
    # counts
    **dict.fromkeys(
        (
            "n_points", "n_ground", "n_check", "n_control", "n_edges", "n_planes", "n_corners",
            "n_pairs", "n_matched", "n_test", "n_model", "n_map", "n_reference", "n_rejected",
            "n_segments", "n_used", "n_flagged", "dof", "support_a", "support_b", "support_c",
            "count", "points", "min_points", "iterations", "workers", "chunk_size",
        ),
        _N,
    ),
    # ratios 0..1
    **dict.fromkeys(
        (
            "type_i", "type_ii", "total", "kappa_coefficient", "precision", "recall",
            "frac_lt1", "fraction", "correlation", "alpha", "sensitivity", "share",
        ),
        _F,
    ),
    # dimensionless numbers
    **dict.fromkeys(
        ("a", "b", "scale", "weight", "w", "w_test", "critical_value", "k", "factor", "seed"),
        _1,
    ),
}


def key_unit(key: str) -> str | None:
    """The unit of a JSON key by the policy (None when it is not defined).

    Examples
    --------
    >>> key_unit("rmse_z"), key_unit("angle_deg"), key_unit("density_per_m2")
    ('m', 'degree', '1/m²')
    """
    k = key.lower()
    if k in KEY_UNITS:
        return KEY_UNITS[k]
    for suffix, unit in SUFFIX_UNITS.items():
        if k.endswith(suffix):
            return unit
    if re.fullmatch(r"n_\w+", k):
        return _N
    return None


_SHORT = {"m": "m", "degree": "°", "1": "", "count": "", "fraction": "", "ppm": "ppm"}


def param_unit(key: str) -> str:
    """Short unit label of a parameter for text output (``m``, ``°``, or empty)."""
    u = key_unit(key)
    return _SHORT.get(u or "", u or "")


#: Decimals of computed coordinates written to files (0.1 mm).
COORDINATE_DECIMALS = 4


def format_coordinate(value: float, decimals: int = COORDINATE_DECIMALS) -> str:
    """A coordinate for a text file: fixed decimals, no trailing float noise.

    Examples
    --------
    >>> format_coordinate(770500.05000000005), format_coordinate(1.0, 2)
    ('770500.0500', '1.00')
    """
    return f"{float(value):.{decimals}f}"


def format_decimal(value: float) -> str:
    """A non-coordinate decimal for a text file: at most 10 significant digits.

    Examples
    --------
    >>> format_decimal(0.1 + 0.2), format_decimal(1e-12)
    ('0.3', '1e-12')
    """
    return f"{float(value):.10g}"
