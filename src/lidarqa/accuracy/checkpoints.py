"""Point-based accuracy: check points, residual statistics, ASPRS (Ed. 2, 2023) and NSSDA.

Measured points (building corners from :func:`lidarqa.geometry.corners.extract_corners`,
targets picked in a cloud, ...) are matched with surveyed check points, optionally
transformed onto them by least squares from a set of *control* points
(:mod:`lidarqa.accuracy.transforms`), and the residuals of the remaining *check*
points are summarised per axis (mean = bias, standard deviation, RMSE, max ``|residual|``),
horizontally (RMSE_H) and in 3D (RMSE_3D, the P-RMSE of Fang & Huang, :ref:`alg-rmse`).

Residuals are always *measured (after transformation) minus check*: a positive dz
means the data lie above the check point.

Accuracy reports
----------------
ASPRS Positional Accuracy Standards for Digital Geospatial Data, Edition 2,
Version 1.0 (August 2023), §7 (accuracy assessment; the section number and the
exact notation are UNVERIFIED against the primary text). Edition 2 drops the 95 %
confidence figures, requires at least 30 check points for a product accuracy
assessment, and folds the accuracy of the check-point survey itself into the
reported accuracy:

- RMSE_H1 = sqrt(RMSE_x² + RMSE_y²)                (product vs. check points)
- RMSE_H  = sqrt(RMSE_H1² + RMSE_H,GCP²)   (RMSE_H,GCP: horizontal RMSE of the check-point survey)
- RMSE_V  = sqrt(RMSE_V1² + RMSE_V,GCP²)           (RMSE_V1 = RMSE_z)
- RMSE_3D = sqrt(RMSE_H² + RMSE_V²)

(The list of Edition 2 changes, including "consideration of survey checkpoint
accuracy when computing final product accuracy" and the minimum of 30 check
points, is summarised in GPS World, 6 Dec 2023, "ASPRS approves edition 2 of the
ASPRS Positional Accuracy Standards for Digital Geospatial Data".)

NSSDA (FGDC-STD-007.3-1998, Geospatial Positioning Accuracy Standards Part 3,
Appendix 3-A) at 95 % confidence, with at least 20 check points:

- Accuracy_z = 1.9600·RMSE_z
- Accuracy_r = 1.7308·RMSE_r (RMSE_r = sqrt(RMSE_x² + RMSE_y²)) when RMSE_x ≈ RMSE_y,
  taken as RMSE_min/RMSE_max >= 0.6; otherwise 2.4477·½(RMSE_x + RMSE_y).
  The report names the formula used. Both are approximations of the exact 95 %
  radius of a bivariate normal error and coincide (and are exact) for
  RMSE_x = RMSE_y. Note that the NSSDA text itself gives 1.7308·RMSE_r for
  RMSE_x = RMSE_y and 2.4477·½(RMSE_x + RMSE_y) for 0.6 <= RMSE_min/RMSE_max < 1,
  and no approximation below 0.6; in that range the two differ by at most 3 %.
  The rule above is the project's (issue #6). The exact value is always reported
  (``accuracy_r_exact``), and a warning is added when the ratio is below 0.6.

Vertical check of a cloud (LAStools ``lascontrol`` style): :func:`vertical_check`
interpolates a TIN of the cloud's ground points at the check points' XY and
compares heights; points outside the TIN or in sparse areas are flagged and left
out of the statistics.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import MAX_COORDINATE, as_points, check_choice, check_positive
from ..errors import (
    DegenerateGeometryError,
    InvalidPointsError,
    NothingToMeasureError,
    OptionError,
)
from ..io.vector import PointSet, as_pointset
from .transforms import TRANSFORMS, TransformFit, estimate_transform

__all__ = [
    "ASPRS_MIN_CHECKPOINTS",
    "NSSDA_MIN_CHECKPOINTS",
    "ResidualStats",
    "NSSDAAccuracy",
    "ASPRSAccuracy",
    "PointMatch",
    "CheckpointReport",
    "VerticalCheckReport",
    "residual_statistics",
    "rmse_3d",
    "nssda_accuracy",
    "asprs2023_accuracy",
    "match_points",
    "assess_checkpoints",
    "metric_units",
    "scale_points",
    "summarise_vertical",
    "vertical_check",
]

#: ASPRS Ed. 2 (2023): minimum number of check points for a product accuracy assessment.
ASPRS_MIN_CHECKPOINTS = 30
#: NSSDA (1998): minimum number of check points.
NSSDA_MIN_CHECKPOINTS = 20

_NSSDA_RATIO = 0.6
_NSSDA_EQUAL_RATIO = 0.95  # "RMSE_x ≈ RMSE_y": within 5 % of each other


# ============================================================== statistics


@dataclass(frozen=True)
class ResidualStats:
    """Per-axis statistics of residuals (m).

    Attributes
    ----------
    n : int
        Number of residuals.
    mean, std, rmse, max_abs : ndarray of shape (3,)
        Per axis x, y, z: mean (bias), sample standard deviation (n-1),
        root mean square (divisor n - ddof), largest absolute value. NaN for an
        axis without data.
    rmse_h : float
        sqrt(rmse_x² + rmse_y²).
    rmse_3d : float
        sqrt(rmse_x² + rmse_y² + rmse_z²) (the P-RMSE of Fang & Huang).
    """

    n: int
    mean: np.ndarray
    std: np.ndarray
    rmse: np.ndarray
    max_abs: np.ndarray
    rmse_h: float
    rmse_3d: float

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        out: dict[str, Any] = {"n": self.n}
        for i, ax in enumerate("xyz"):
            out[f"rmse_{ax}"] = float(self.rmse[i])
        out["rmse_h"] = self.rmse_h
        out["rmse_3d"] = self.rmse_3d
        for name in ("mean", "std", "max_abs"):
            for i, ax in enumerate("xyz"):
                out[f"{name}_{ax}"] = float(getattr(self, name)[i])
        return out


def residual_statistics(residuals: Any, *, ddof: int = 0) -> ResidualStats:
    """Mean, standard deviation, RMSE and max ``|residual|`` per axis, RMSE_H and RMSE_3D.

    Parameters
    ----------
    residuals : ndarray of shape (n, 3)
        Residuals dx, dy, dz (m). A column that is entirely NaN (e.g. no
        horizontal residuals in a vertical-only check) gives NaN statistics.
    ddof : int, default 0
        RMSE divisor is n - ddof (:ref:`alg-rmse`: n by default).

    Returns
    -------
    ResidualStats

    Examples
    --------
    >>> s = residual_statistics([[0.03, 0.0, 0.1], [-0.03, 0.04, -0.1]])
    >>> [round(float(v), 3) for v in s.rmse], round(s.rmse_h, 3), round(s.rmse_3d, 3)
    ([0.03, 0.028, 0.1], 0.041, 0.108)
    """
    r = np.asarray(residuals, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 3:
        raise InvalidPointsError(f"residuals must have shape (n, 3), got {r.shape}")
    n = len(r)
    mean = np.full(3, np.nan)
    std = np.full(3, np.nan)
    rmse = np.full(3, np.nan)
    mx = np.full(3, np.nan)
    for k in range(3):
        col = r[:, k]
        if n == 0 or np.isnan(col).all():
            continue
        if not np.isfinite(col).all():
            raise InvalidPointsError("residuals contain NaN or infinite values")
        mean[k] = col.mean()
        std[k] = col.std(ddof=1) if n > 1 else np.nan
        rmse[k] = math.sqrt(float(np.sum(col**2)) / (n - ddof)) if n > ddof else np.nan
        mx[k] = np.abs(col).max()
    return ResidualStats(
        n=n,
        mean=mean,
        std=std,
        rmse=rmse,
        max_abs=mx,
        rmse_h=float(math.hypot(rmse[0], rmse[1])),
        rmse_3d=rmse_3d(rmse[0], rmse[1], rmse[2]),
    )


def rmse_3d(rmse_x: float, rmse_y: float, rmse_z: float) -> float:
    """P-RMSE = sqrt(RMSE_E² + RMSE_N² + RMSE_H²) (m), Fang & Huang Tables 1-2.

    Examples
    --------
    >>> round(rmse_3d(0.045, 0.019, 0.010), 5)
    0.04986
    """
    return float(math.sqrt(rmse_x**2 + rmse_y**2 + rmse_z**2))


# ============================================================== NSSDA / ASPRS


@dataclass(frozen=True)
class NSSDAAccuracy:
    """NSSDA accuracy at the 95 % confidence level (m).

    Attributes
    ----------
    accuracy_r : float
        Horizontal (radial) accuracy by the formula named in `formula`.
    accuracy_z : float
        1.9600·RMSE_z.
    formula : str
        The horizontal formula used.
    ratio : float
        RMSE_min / RMSE_max of x and y.
    accuracy_r_exact : float
        95 % radius of a bivariate normal with standard deviations RMSE_x, RMSE_y
        (no approximation).
    n_check : int or None
    warnings : tuple of str
    """

    accuracy_r: float
    accuracy_z: float
    formula: str
    ratio: float
    accuracy_r_exact: float
    n_check: int | None
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "accuracy_r": self.accuracy_r,
            "accuracy_z": self.accuracy_z,
            "formula": self.formula,
            "formula_z": "1.9600*RMSE_z",
            "ratio": self.ratio,
            "accuracy_r_exact": self.accuracy_r_exact,
            "n_check": self.n_check,
            "warnings": list(self.warnings),
        }


def _circular_95(sx: float, sy: float) -> float:
    """Radius R with P(x² + y² <= R²) = 0.95 for independent N(0, sx²), N(0, sy²)."""
    if not (np.isfinite(sx) and np.isfinite(sy)):
        return math.nan
    hi, lo = max(sx, sy), min(sx, sy)
    if hi <= 0:
        return 0.0
    if lo <= 1e-12 * hi:
        return 1.959963984540054 * hi
    from scipy import integrate, optimize, special

    def prob(r: float) -> float:
        def f(x: float) -> float:
            return math.exp(-0.5 * (x / hi) ** 2) * special.erf(
                math.sqrt(max(r * r - x * x, 0.0)) / (lo * math.sqrt(2))
            )

        val, _ = integrate.quad(f, -r, r, limit=200)
        return val / (hi * math.sqrt(2 * math.pi))

    return float(
        optimize.brentq(lambda r: prob(r) - 0.95, 1.9 * lo, 2.5 * hi + 2.5 * lo, xtol=1e-12)
    )


def nssda_accuracy(
    rmse_x: float, rmse_y: float, rmse_z: float, *, n_check: int | None = None
) -> NSSDAAccuracy:
    """NSSDA 95 % horizontal and vertical accuracy (FGDC-STD-007.3-1998).

    Parameters
    ----------
    rmse_x, rmse_y, rmse_z : float
        Per-axis RMSE (m); NaN where an axis was not tested.
    n_check : int, optional
        Number of check points; a warning is added below 20.

    Returns
    -------
    NSSDAAccuracy

    Notes
    -----
    Following FGDC-STD-007.3-1998 Appendix 3-A: when RMSE_x ≈ RMSE_y
    (RMSE_min/RMSE_max >= 0.95 here), Accuracy_r = 1.7308·RMSE_r; otherwise the
    NSSDA approximation 2.4477·½(RMSE_x + RMSE_y), which the standard states for
    0.6 <= RMSE_min/RMSE_max <= 1. Both coincide for RMSE_x = RMSE_y. Below 0.6
    the NSSDA gives no formula: the approximation is still reported (as the
    issue asks) with a warning, beside ``accuracy_r_exact``, the exact radius of
    the 95 % circle for independent normal x, y errors. Accuracy_z = 1.9600·RMSE_z.

    Examples
    --------
    >>> a = nssda_accuracy(0.03, 0.03, 0.05)
    >>> round(a.accuracy_r, 5), round(a.accuracy_z, 3)
    (0.07343, 0.098)
    """
    warn: list[str] = []
    if n_check is not None and n_check < NSSDA_MIN_CHECKPOINTS:
        warn.append(
            f"NSSDA: only {n_check} check points "
            f"(the NSSDA asks for at least {NSSDA_MIN_CHECKPOINTS})"
        )
    acc_z = 1.9600 * rmse_z if np.isfinite(rmse_z) else math.nan
    if np.isfinite(rmse_x) and np.isfinite(rmse_y):
        big = max(rmse_x, rmse_y)
        ratio = min(rmse_x, rmse_y) / big if big > 0 else 1.0
        if ratio >= _NSSDA_EQUAL_RATIO:
            acc_r = 1.7308 * math.hypot(rmse_x, rmse_y)
            formula = "1.7308*RMSE_r (RMSE_x ~ RMSE_y: RMSE_min/RMSE_max >= 0.95)"
        else:
            acc_r = 2.4477 * 0.5 * (rmse_x + rmse_y)
            formula = f"2.4477*0.5*(RMSE_x+RMSE_y) (RMSE_min/RMSE_max = {ratio:.2f})"
        if ratio < _NSSDA_RATIO:
            warn.append(
                f"NSSDA: RMSE_min/RMSE_max = {ratio:.2f} < 0.6, outside the range of the NSSDA "
                "approximations; see accuracy_r_exact"
            )
        exact = _circular_95(rmse_x, rmse_y)
    else:
        acc_r, ratio, exact = math.nan, math.nan, math.nan
        formula = "not tested (no horizontal residuals)"
    return NSSDAAccuracy(
        accuracy_r=float(acc_r),
        accuracy_z=float(acc_z),
        formula=formula,
        ratio=float(ratio),
        accuracy_r_exact=float(exact),
        n_check=n_check,
        warnings=tuple(warn),
    )


@dataclass(frozen=True)
class ASPRSAccuracy:
    """Accuracy per the ASPRS Positional Accuracy Standards, Edition 2 (2023), in m.

    Attributes
    ----------
    rmse_h : float
        sqrt(RMSE_H1² + RMSE_H,GCP²), RMSE_H1 = sqrt(RMSE_x² + RMSE_y²).
    rmse_v : float
        sqrt(RMSE_V1² + RMSE_V,GCP²), RMSE_V1 = RMSE_z.
    rmse_3d : float
        sqrt(RMSE_H² + RMSE_V²).
    rmse_h1, rmse_v1 : float
        The product's RMSE against the check points alone.
    checkpoint_rmse_h, checkpoint_rmse_v : float
        RMSE_H,GCP and RMSE_V,GCP: accuracy of the check-point survey.
    n_check : int
    warnings : tuple of str
    """

    rmse_h: float
    rmse_v: float
    rmse_3d: float
    rmse_h1: float
    rmse_v1: float
    checkpoint_rmse_h: float
    checkpoint_rmse_v: float
    n_check: int
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "rmse_h": self.rmse_h,
            "rmse_v": self.rmse_v,
            "rmse_3d": self.rmse_3d,
            "rmse_h1": self.rmse_h1,
            "rmse_v1": self.rmse_v1,
            "checkpoint_rmse_h": self.checkpoint_rmse_h,
            "checkpoint_rmse_v": self.checkpoint_rmse_v,
            "n_check": self.n_check,
            "warnings": list(self.warnings),
            "standard": "ASPRS Positional Accuracy Standards for Digital Geospatial Data, "
            "Ed. 2 (2023)",
        }


def asprs2023_accuracy(
    rmse_x: float,
    rmse_y: float,
    rmse_z: float,
    *,
    n_check: int,
    checkpoint_rmse_h: float = 0.0,
    checkpoint_rmse_v: float = 0.0,
) -> ASPRSAccuracy:
    """ASPRS Edition 2 (2023) accuracy with the check-point survey accuracy folded in.

    Parameters
    ----------
    rmse_x, rmse_y, rmse_z : float
        RMSE of the product against the check points (m); NaN where not tested.
    n_check : int
        Number of check points; a warning is added below 30 (Ed. 2 minimum).
    checkpoint_rmse_h : float, default 0
        RMSE_H,GCP: horizontal (radial) RMSE of the check-point survey (m).
    checkpoint_rmse_v : float, default 0
        RMSE_V,GCP: vertical RMSE of the check-point survey (m).

    Returns
    -------
    ASPRSAccuracy
        RMSE_H = sqrt(RMSE_H1² + RMSE_H,GCP²), RMSE_V = sqrt(RMSE_V1² + RMSE_V,GCP²),
        RMSE_3D = sqrt(RMSE_H² + RMSE_V²) (ASPRS Ed. 2, 2023, §7).

    Examples
    --------
    >>> a = asprs2023_accuracy(0.03, 0.04, 0.12, n_check=30, checkpoint_rmse_v=0.05)
    >>> round(a.rmse_h, 3), round(a.rmse_v, 3), round(a.rmse_3d, 3)
    (0.05, 0.13, 0.139)
    """
    ch = check_positive(checkpoint_rmse_h, "checkpoint_rmse_h", allow_zero=True)
    cv = check_positive(checkpoint_rmse_v, "checkpoint_rmse_v", allow_zero=True)
    h1 = math.hypot(rmse_x, rmse_y)
    h = math.hypot(h1, ch)
    v = math.hypot(rmse_z, cv)
    warn = []
    if n_check < ASPRS_MIN_CHECKPOINTS:
        warn.append(
            f"ASPRS Ed. 2: only {n_check} check points (at least {ASPRS_MIN_CHECKPOINTS} are "
            "required for a product accuracy assessment)"
        )
    missing = [
        n
        for n, val, tested in (
            ("checkpoint_rmse_h", ch, np.isfinite(h1)),
            ("checkpoint_rmse_v", cv, np.isfinite(rmse_z)),
        )
        if tested and val == 0
    ]
    if missing:
        warn.append(
            "ASPRS Ed. 2: the check-point survey accuracy is not included "
            f"({' and '.join(missing)} = 0)"
        )
    return ASPRSAccuracy(
        rmse_h=float(h),
        rmse_v=float(v),
        rmse_3d=float(math.hypot(h, v)),
        rmse_h1=float(h1),
        rmse_v1=float(rmse_z),
        checkpoint_rmse_h=ch,
        checkpoint_rmse_v=cv,
        n_check=int(n_check),
        warnings=tuple(warn),
    )


# ================================================================ matching


def metric_units(measured_crs: Any, check_crs: Any) -> tuple[Any, float, float, list[str]]:
    """The CRS measured and check points share, its factors to metres, and notes.

    The one unit rule of ``lidarqa checkpoints`` and the report's check points: the
    CRS is MEASURED's, else CHECK's (a missing one is taken to share the other's);
    x, y are scaled by the horizontal unit and z by the vertical unit to metres.

    Returns
    -------
    crs : pyproj.CRS or None
    fh, fv : float
        Horizontal and vertical factors to metres (1.0 for metres).
    notes : list of str
        What was converted (empty for metres).

    Raises
    ------
    CRSMismatchError
        The two CRSs differ, or the shared one is geographic (degrees).
    """
    from ..errors import CRSMismatchError
    from ..io.crs import ensure_same_crs, horizontal_unit, metre_factors, vertical_unit

    ensure_same_crs(measured_crs, check_crs, what=("MEASURED", "CHECK"))
    crs = measured_crs if measured_crs is not None else check_crs
    if crs is None:
        return None, 1.0, 1.0, []
    h_name, _ = horizontal_unit(crs)
    if h_name is not None and (h_name.lower().startswith("deg") or crs.is_geographic):
        raise CRSMismatchError(
            f"{'MEASURED' if measured_crs is not None else 'CHECK'} is in a geographic CRS "
            f"({crs.name}, degrees): reproject it to a projected CRS in metres first")
    v_name, _ = vertical_unit(crs)
    fh, fv = metre_factors(crs)
    notes = []
    if fv != 1.0 or fh != 1.0:
        notes.append(f"coordinates converted to metres (horizontal unit: {h_name or 'metre'}, "
                     f"vertical unit: {v_name or 'metre'})")
        if measured_crs is None or check_crs is None:
            notes.append("one input has no CRS and is taken to share the other's CRS and units")
    return crs, fh, fv, notes


def scale_points(points: PointSet, fh: float, fv: float) -> PointSet:
    """`points` with x, y multiplied by `fh` and z by `fv` (a copy; ids and attributes kept).

    Parameters
    ----------
    points : PointSet
    fh, fv : float
        Horizontal and vertical factors (e.g. from :func:`metric_units`).

    Returns
    -------
    PointSet
    """
    xyz = np.array(points.xyz, dtype=np.float64, copy=True)
    xyz[:, :2] *= fh
    xyz[:, 2] *= fv
    return PointSet(points.ids, xyz, dict(points.attributes), crs=points.crs)


def _keys(ids: np.ndarray) -> np.ndarray:
    out = []
    for v in np.asarray(ids).tolist():
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        out.append(str(v).strip())
    return np.array(out, dtype=object)


def _natural_key(key: str) -> tuple:
    parts = re.split(r"(\d+)", key)
    return tuple(int(p) if i % 2 else p for i, p in enumerate(parts))


def _sort_order(keys: np.ndarray) -> np.ndarray:
    """Canonical order of id keys: natural order ("C2" before "C10", -1 before 2)."""
    try:
        nums = np.array([int(k) for k in keys], dtype=np.int64)
        return np.argsort(nums, kind="stable")
    except ValueError:
        return np.array(
            sorted(range(len(keys)), key=lambda i: (_natural_key(str(keys[i])), str(keys[i]))),
            dtype=np.int64,
        )


def _check_ids(keys: np.ndarray, name: str) -> None:
    u, c = np.unique(keys.astype(str), return_counts=True)
    if (c > 1).any():
        dup = ", ".join(u[c > 1][:5])
        raise InvalidPointsError(f"{name} has duplicate id(s): {dup}")


def _check_finite(ps: PointSet, name: str, *, need_z: bool = True) -> None:
    cols = ps.xyz if need_z else ps.xyz[:, :2]
    bad = ~np.isfinite(cols).all(axis=1)
    if bad.any():
        ids = ", ".join(str(v) for v in ps.ids[bad][:5])
        raise InvalidPointsError(
            f"{name} has {int(bad.sum())} point(s) with NaN or infinite coordinates (id {ids})"
        )
    huge = (np.abs(cols) > MAX_COORDINATE).any(axis=1)
    if huge.any():  # squared distances of such values overflow: corrupt data, not coordinates
        ids = ", ".join(str(v) for v in ps.ids[huge][:5])
        raise InvalidPointsError(
            f"{name} has {int(huge.sum())} point(s) with coordinates beyond "
            f"±{MAX_COORDINATE:g} (id {ids})"
        )


@dataclass(frozen=True)
class PointMatch:
    """Pairs of measured and check points.

    Attributes
    ----------
    measured_index, check_index : ndarray of shape (m,)
        Row indices of matched pairs, ordered by check id.
    distance : ndarray of shape (m,)
        3D distance between the pair before any transformation (m).
    unmatched_measured, unmatched_check : list
        Ids left without a partner.
    method : str
        ``"id"`` or ``"nearest"``.
    """

    measured_index: np.ndarray
    check_index: np.ndarray
    distance: np.ndarray
    unmatched_measured: list
    unmatched_check: list
    method: str

    def __len__(self) -> int:
        return len(self.check_index)


def match_points(
    measured: Any, check: Any, *, match: str = "id", max_distance: float | None = None
) -> PointMatch:
    """Pair measured points with check points by id or by nearest neighbour.

    Parameters
    ----------
    measured, check : PointSet or ndarray of shape (N, 3)
    match : {"id", "nearest"}, default "id"
        ``"id"``: equal ids (compared as text, so 7 and "7" match).
        ``"nearest"``: one-to-one pairing by increasing 3D distance (greedy,
        ties by check then measured id order), each pair within `max_distance`.
    max_distance : float, optional
        Largest pair distance (m). With ``"id"`` matching, pairs farther apart
        are rejected as unmatched too.

    Returns
    -------
    PointMatch

    Raises
    ------
    InvalidPointsError
        Duplicate ids, NaN coordinates, or no pair at all.
    """
    check_choice(match, ("id", "nearest"), "match")
    if max_distance is not None:
        max_distance = check_positive(max_distance, "max_distance")
    mp = as_pointset(measured, "measured")
    cp = as_pointset(check, "check")
    if len(mp) == 0 or len(cp) == 0:
        raise InvalidPointsError(f"no points to match (measured: {len(mp)}, check: {len(cp)})")
    mk, ck = _keys(mp.ids), _keys(cp.ids)
    _check_ids(mk, "measured")
    _check_ids(ck, "check")
    _check_finite(mp, "measured")
    _check_finite(cp, "check")
    corder = _sort_order(ck)
    if match == "id":
        pos = {k: i for i, k in enumerate(mk.tolist())}
        ci = np.array([i for i in corder if ck[i] in pos], dtype=np.int64)
        mi = np.array([pos[ck[i]] for i in ci], dtype=np.int64)
        if len(ci) == 0:
            raise InvalidPointsError(
                "no ids in common between measured (e.g. "
                + ", ".join(mk[_sort_order(mk)][:3])
                + ") and check points (e.g. "
                + ", ".join(ck[corder][:3])
                + "); match by position with "
                "match='nearest' (--match nearest)"
            )
    else:
        from scipy.spatial import cKDTree

        origin = cp.xyz.min(axis=0)
        tree = cKDTree(mp.xyz - origin)
        k = min(8, len(mp))
        ub = np.inf if max_distance is None else max_distance + 1e-12 * max(1.0, max_distance)
        dist, idx = tree.query(cp.xyz - origin, k=k, distance_upper_bound=ub)
        dist, idx = dist.reshape(len(cp), k), idx.reshape(len(cp), k)
        rank_c = np.empty(len(cp), dtype=np.int64)
        rank_c[corder] = np.arange(len(cp))
        rank_m = np.empty(len(mp), dtype=np.int64)
        rank_m[_sort_order(mk)] = np.arange(len(mp))
        ok = np.isfinite(dist)
        cc = np.repeat(np.arange(len(cp)), k).reshape(len(cp), k)[ok]
        mm, dd = idx[ok], dist[ok]
        order = np.lexsort((rank_m[mm], rank_c[cc], dd))
        used_c = np.zeros(len(cp), bool)
        used_m = np.zeros(len(mp), bool)
        pairs = []
        for o in order:
            c, m = cc[o], mm[o]
            if not used_c[c] and not used_m[m]:
                used_c[c] = used_m[m] = True
                pairs.append((rank_c[c], c, m))
        pairs.sort()
        ci = np.array([p[1] for p in pairs], dtype=np.int64)
        mi = np.array([p[2] for p in pairs], dtype=np.int64)
        if len(ci) == 0:
            lim = "" if max_distance is None else f" within max_distance {max_distance:g} m"
            raise InvalidPointsError(f"no measured point lies near any check point{lim}")
    d = np.linalg.norm(mp.xyz[mi] - cp.xyz[ci], axis=1) if len(ci) else np.empty(0)
    if match == "id" and max_distance is not None:
        keep = d <= max_distance + 1e-12 * max(1.0, max_distance)
        ci, mi, d = ci[keep], mi[keep], d[keep]
        if len(ci) == 0:
            raise InvalidPointsError(
                f"all pairs with equal ids are farther apart than max_distance {max_distance:g} m"
            )
    um = np.setdiff1d(np.arange(len(mp)), mi)
    uc = np.setdiff1d(np.arange(len(cp)), ci)
    um = um[np.argsort(_sort_order(mk).argsort()[um], kind="stable")]
    uc = uc[np.argsort(corder.argsort()[uc], kind="stable")]
    return PointMatch(
        measured_index=mi,
        check_index=ci,
        distance=d,
        unmatched_measured=[
            mp.ids[i].item() if hasattr(mp.ids[i], "item") else mp.ids[i] for i in um
        ],
        unmatched_check=[cp.ids[i].item() if hasattr(cp.ids[i], "item") else cp.ids[i] for i in uc],
        method=match,
    )


# ============================================================== assessment


def _jsonable_id(v: Any) -> Any:
    return v.item() if hasattr(v, "item") else v


@dataclass(frozen=True)
class CheckpointReport:
    """Result of :func:`assess_checkpoints`.

    Attributes
    ----------
    n_check, n_control : int
        Points judged / points used to estimate the transformation.
    transform : TransformFit
        The transformation (``name == "none"`` without one).
    stats : ResidualStats
        Statistics of the check-point residuals.
    control_stats : ResidualStats or None
        Statistics of the control-point residuals (fit residuals).
    nssda : NSSDAAccuracy
    asprs2023 : ASPRSAccuracy
    ids : ndarray of shape (m,)
        Check-file ids of the matched points (ordered by id).
    measured_ids : ndarray of shape (m,)
    check_xyz : ndarray of shape (m, 3)
        Check-point coordinates.
    residuals : ndarray of shape (m, 3)
        Transformed measured minus check (m).
    role : ndarray of shape (m,) of str
        ``"check"``, ``"control"`` or ``"control+check"`` (used for both, when no
        control points were named).
    match : PointMatch
    warnings : tuple of str
    """

    n_check: int
    n_control: int
    transform: TransformFit
    stats: ResidualStats
    control_stats: ResidualStats | None
    nssda: NSSDAAccuracy
    asprs2023: ASPRSAccuracy
    ids: np.ndarray
    measured_ids: np.ndarray
    check_xyz: np.ndarray
    residuals: np.ndarray
    role: np.ndarray
    match: PointMatch
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def residual_points(self) -> PointSet:
        """The matched check points with ``dx, dy, dz, role, measured_id`` attributes (for -o)."""
        return PointSet(
            ids=self.ids,
            xyz=self.check_xyz,
            attributes={
                "measured_id": np.array([str(v) for v in self.measured_ids], dtype=object),
                "dx": self.residuals[:, 0],
                "dy": self.residuals[:, 1],
                "dz": self.residuals[:, 2],
                "role": self.role.astype(object),
            },
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``results`` of ``lidarqa checkpoints``."""
        out: dict[str, Any] = {
            "n_check": self.n_check,
            "n_control": self.n_control,
            "transform": self.transform.to_dict(),
        }
        s = self.stats.to_dict()
        s.pop("n")
        out.update(s)
        out["nssda"] = self.nssda.to_dict()
        out["asprs2023"] = self.asprs2023.to_dict()
        if self.control_stats is not None:
            cs = self.control_stats.to_dict()
            out["control"] = {
                k: cs[k] for k in ("n", "rmse_x", "rmse_y", "rmse_z", "rmse_h", "rmse_3d")
            }
        out["residuals"] = [
            {
                "id": _jsonable_id(i),
                "measured_id": _jsonable_id(m),
                "dx": float(r[0]),
                "dy": float(r[1]),
                "dz": float(r[2]),
                "role": str(ro),
            }
            for i, m, r, ro in zip(
                self.ids, self.measured_ids, self.residuals, self.role, strict=True
            )
        ]
        out["match"] = {
            "method": self.match.method,
            "n_matched": len(self.match),
            "unmatched_measured": [_jsonable_id(v) for v in self.match.unmatched_measured],
            "unmatched_check": [_jsonable_id(v) for v in self.match.unmatched_check],
        }
        out["warnings"] = list(self.warnings)
        return out


def assess_checkpoints(
    measured: Any,
    check: Any,
    *,
    transform: str = "none",
    control_ids: Any = None,
    match: str = "id",
    max_distance: float | None = None,
    include_control: bool = False,
    checkpoint_rmse_h: float = 0.0,
    checkpoint_rmse_v: float = 0.0,
    ddof: int = 0,
) -> CheckpointReport:
    """Compare measured points with check points, optionally after a least-squares transformation.

    Parameters
    ----------
    measured : PointSet or ndarray of shape (N, 3)
        Points measured in the data (e.g. building corners), m.
    check : PointSet or ndarray of shape (M, 3)
        Surveyed check points (m), same CRS as `measured`.
    transform : {"none", "similarity2d", "helmert", "helmert-fixed-scale"}, default "none"
        Transformation from measured to check coordinates, estimated on the
        control points (:mod:`lidarqa.accuracy.transforms`).
    control_ids : sequence, optional
        Check-point ids used as control (to estimate the transformation). They
        are excluded from the accuracy statistics unless `include_control`. When
        a transformation is asked for without control ids, every matched point
        is used for both, and a warning says the RMSE is then an (optimistic)
        fit residual.
    match : {"id", "nearest"}, default "id"
        How measured and check points are paired (:func:`match_points`).
    max_distance : float, optional
        Largest distance of a pair before transformation (m).
    include_control : bool, default False
        Also count the control points as check points.
    checkpoint_rmse_h, checkpoint_rmse_v : float, default 0
        Accuracy (RMSE, m) of the check-point survey, folded into the ASPRS Ed. 2 figures.
    ddof : int, default 0
        RMSE divisor n - ddof.

    Returns
    -------
    CheckpointReport

    Raises
    ------
    InvalidPointsError
        Duplicate ids, NaN coordinates, no matching pair, unknown control ids,
        no check point left.
    DegenerateGeometryError
        Too few or degenerate (collinear, coincident) control points for the transformation.
    OptionError
        Unknown `transform` or `match`, negative accuracies.

    Examples
    --------
    >>> from lidarqa.io.vector import PointSet
    >>> chk = PointSet(ids=np.array([1, 2, 3]), xyz=np.array([[0, 0, 0], [10, 0, 0], [0, 10, 1.]]))
    >>> xyz = np.array([[0, 10, 1.1], [10, 0, 0.1], [0, 0, 0.1]])
    >>> mea = PointSet(ids=np.array([3, 2, 1]), xyz=xyz)
    >>> round(float(assess_checkpoints(mea, chk).stats.rmse[2]), 3)
    0.1
    """
    check_choice(transform, TRANSFORMS, "transform")
    if int(ddof) != ddof or ddof < 0:
        raise OptionError(f"ddof must be a non-negative integer, got {ddof!r}")
    mp = as_pointset(measured, "measured")
    cp = as_pointset(check, "check")
    pm = match_points(mp, cp, match=match, max_distance=max_distance)
    ci, mi = pm.check_index, pm.measured_index
    m = len(ci)
    keys = _keys(cp.ids[ci])
    warn: list[str] = []
    if match == "nearest" and max_distance is None:
        warn.append(
            "nearest matching without max_distance: pairs are accepted however far apart "
            f"(largest pair distance {float(pm.distance.max()):.3f} m)"
        )
    if pm.unmatched_measured or pm.unmatched_check:
        warn.append(
            f"{len(pm.unmatched_check)} check point(s) and {len(pm.unmatched_measured)} measured "
            "point(s) were not matched"
        )
    is_control = np.zeros(m, dtype=bool)
    if control_ids is not None:
        wanted = _keys(np.asarray(list(control_ids), dtype=object))
        known = set(keys.tolist())
        missing = [k for k in wanted.tolist() if k not in known]
        if missing:
            raise InvalidPointsError(
                "control id(s) not among the matched check points: " + ", ".join(missing[:5])
            )
        is_control = np.isin(keys.astype(str), wanted.astype(str))
        if transform == "none":
            warn.append(
                "control points named but transform is 'none': "
                "they are only left out of the statistics"
            )
    mxyz = mp.xyz[mi]
    cxyz = cp.xyz[ci]
    if transform == "none":
        fit = estimate_transform(mxyz, cxyz, method="none")
        role = np.where(is_control, "control", "check")
        is_check = ~is_control | include_control
    else:
        if control_ids is None:
            is_control[:] = True
            is_check = np.ones(m, dtype=bool)
            role = np.full(m, "control+check")
            warn.append(
                "no independent check points: every point was used to estimate the transformation, "
                "so the RMSE is a fit residual (optimistic); name control points to get an "
                "independent check"
            )
        else:
            is_check = ~is_control | include_control
            role = np.where(is_control, "control+check" if include_control else "control", "check")
        fit = estimate_transform(mxyz[is_control], cxyz[is_control], method=transform)
    if include_control and control_ids is not None and transform != "none":
        warn.append(
            "control points are counted as check points (include_control): the RMSE is optimistic"
        )
    residuals = fit.apply(mxyz) - cxyz if transform != "none" else mxyz - cxyz
    n_check = int(is_check.sum())
    if n_check == 0:
        raise InvalidPointsError(f"no check points left: all {m} matched points are control points")
    stats = residual_statistics(residuals[is_check], ddof=ddof)
    n_control = int(is_control.sum()) if (transform != "none" or control_ids is not None) else 0
    control_stats = (
        residual_statistics(residuals[is_control], ddof=ddof) if is_control.any() else None
    )
    nssda = nssda_accuracy(*stats.rmse, n_check=n_check)
    asprs = asprs2023_accuracy(
        *stats.rmse,
        n_check=n_check,
        checkpoint_rmse_h=checkpoint_rmse_h,
        checkpoint_rmse_v=checkpoint_rmse_v,
    )
    warn.extend(fit.notes)
    warn.extend(nssda.warnings)
    warn.extend(asprs.warnings)
    return CheckpointReport(
        n_check=n_check,
        n_control=n_control,
        transform=fit,
        stats=stats,
        control_stats=control_stats,
        nssda=nssda,
        asprs2023=asprs,
        ids=cp.ids[ci],
        measured_ids=mp.ids[mi],
        check_xyz=cxyz,
        residuals=residuals,
        role=np.asarray(role, dtype=str),
        match=pm,
        warnings=tuple(warn),
    )


# ========================================================== vertical check

_FLAGS = ("ok", "outside_tin", "sparse_tin", "no_ground_nearby")


def _barycentric(tri_xy: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric weights (n, 3) of points p (n, 2) in triangles (n, 3, 2); NaN if area < EPS."""
    a = tri_xy[:, 0]
    v0 = tri_xy[:, 1] - a
    v1 = tri_xy[:, 2] - a
    v2 = p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    ok = np.abs(den) >= 2 * 1e-9
    den = np.where(ok, den, 1.0)
    wb = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    wc = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    w = np.column_stack([1.0 - wb - wc, wb, wc])
    w[~ok] = np.nan
    return w


def _xy_ordered(simplices: np.ndarray, vxy: np.ndarray) -> np.ndarray:
    """Each triangle's vertex indices sorted by the vertices' (x, y).

    The arithmetic on a triangle (weights relative to its first vertex, the sum
    of weighted heights) then does not depend on the order Qhull listed the
    vertices in, which changes with the point subset that was triangulated.
    """
    s = np.asarray(simplices)
    if s.size == 0:
        return s
    xy = vxy[s]
    order = np.lexsort((xy[..., 1], xy[..., 0]), axis=-1)
    return np.take_along_axis(s, order, axis=-1)


def _locate(
    simplices: np.ndarray, vxy: np.ndarray, pxy: np.ndarray, k: int = 12
) -> tuple[np.ndarray, np.ndarray]:
    """Triangle containing each point (-1 if none) and its barycentric weights.

    Candidates are the triangles incident to the k TIN vertices nearest to the
    point (the containing triangle's vertices are among them unless the triangle
    is very large), then every triangle for the points still unresolved. Among
    several containing triangles (a point on an edge) the one with the largest
    smallest weight wins, ties by triangle index.
    """
    from scipy.spatial import cKDTree

    n_tri = len(simplices)
    flat = simplices.ravel()
    order = np.argsort(flat, kind="stable")
    tri_of = order // 3
    starts = np.searchsorted(flat[order], np.arange(len(vxy) + 1))
    _, near = cKDTree(vxy).query(pxy, k=min(k, len(vxy)))
    near = np.asarray(near).reshape(len(pxy), -1)
    cand_p, cand_t = [], []
    for i, vs in enumerate(near):
        tris = np.unique(np.concatenate([tri_of[starts[v] : starts[v + 1]] for v in vs]))
        cand_p.append(np.full(len(tris), i))
        cand_t.append(tris)
    simp = np.full(len(pxy), -1, dtype=np.int64)
    weights = np.full((len(pxy), 3), np.nan)

    def pick(cp: np.ndarray, ct: np.ndarray) -> None:
        w = _barycentric(vxy[simplices[ct]], pxy[cp])
        wmin = np.nan_to_num(w.min(axis=1), nan=-np.inf)
        good = wmin >= -1e-9
        cp, ct, w, wmin = cp[good], ct[good], w[good], wmin[good]
        best = np.lexsort((ct, -wmin, cp))  # per point: largest min weight, then smallest index
        cp, ct, w = cp[best], ct[best], w[best]
        first = np.r_[True, cp[1:] != cp[:-1]] if len(cp) else np.zeros(0, bool)
        simp[cp[first]] = ct[first]
        weights[cp[first]] = w[first]

    if len(pxy):
        pick(np.concatenate(cand_p), np.concatenate(cand_t))
    rest = np.flatnonzero(simp < 0)
    for i_rest in rest:  # rare: huge triangles; brute force over all triangles
        pick(np.full(n_tri, i_rest), np.arange(n_tri))
    return simp, weights


@dataclass(frozen=True)
class VerticalCheckReport:
    """Result of :func:`vertical_check`.

    Attributes
    ----------
    ids : ndarray of shape (m,)
        Check-point ids, ordered by id.
    check_xyz : ndarray of shape (m, 3)
    tin_z : ndarray of shape (m,)
        Height of the ground TIN at each check point's XY (m); NaN outside the TIN.
    dz : ndarray of shape (m,)
        tin_z - check z (m): positive when the cloud lies above the check point.
    flag : ndarray of shape (m,) of str
        ``"ok"``, ``"outside_tin"``, ``"sparse_tin"`` (longest edge of the containing
        triangle > `max_edge`; tin_z is NaN when that edge exceeds 2·`max_edge`) or
        ``"no_ground_nearby"`` (no ground point within
        `search_radius`). Only ``"ok"`` points enter the statistics.
    longest_edge : ndarray of shape (m,)
        Longest XY edge of the containing triangle (m); NaN outside.
    n_check : int
        Number of ``"ok"`` points.
    n_ground : int
        Ground points used for the TIN (after merging exact XY duplicates).
    max_edge, search_radius : float
        Thresholds used (m).
    stats : ResidualStats
        Statistics of dz over the ``"ok"`` points (x and y are NaN).
    nssda : NSSDAAccuracy
    asprs2023 : ASPRSAccuracy
    warnings : tuple of str
    """

    ids: np.ndarray
    check_xyz: np.ndarray
    tin_z: np.ndarray
    dz: np.ndarray
    flag: np.ndarray
    longest_edge: np.ndarray
    n_check: int
    n_ground: int
    max_edge: float
    search_radius: float
    stats: ResidualStats
    nssda: NSSDAAccuracy
    asprs2023: ASPRSAccuracy
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def residual_points(self) -> PointSet:
        """Check points with ``tin_z, dz, flag, longest_edge`` attributes (for -o)."""
        return PointSet(
            ids=self.ids,
            xyz=self.check_xyz,
            attributes={
                "tin_z": self.tin_z,
                "dz": self.dz,
                "flag": self.flag.astype(object),
                "longest_edge": self.longest_edge,
            },
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON ``results`` in the layout of :meth:`CheckpointReport.to_dict` (x, y untested)."""
        out: dict[str, Any] = {
            "n_check": self.n_check,
            "n_control": 0,
            "transform": {"name": "none", "params": {}, "sigmas": {}, "sigma0": None},
        }
        s = self.stats.to_dict()
        s.pop("n")
        out.update(s)
        out["nssda"] = self.nssda.to_dict()
        out["asprs2023"] = self.asprs2023.to_dict()
        out["vertical"] = {
            "n_points": len(self.ids),
            "n_ground": self.n_ground,
            "max_edge": self.max_edge,
            "search_radius": self.search_radius,
            "flags": {f: int(np.sum(self.flag == f)) for f in _FLAGS},
        }
        out["residuals"] = [
            {
                "id": _jsonable_id(i),
                "dx": None,
                "dy": None,
                "dz": float(d),
                "tin_z": float(t),
                "role": "check" if f == "ok" else "flagged",
                "flag": str(f),
            }
            for i, d, t, f in zip(self.ids, self.dz, self.tin_z, self.flag, strict=True)
        ]
        out["warnings"] = list(self.warnings)
        return out


def vertical_check(
    points: Any,
    check: Any,
    *,
    classification: Any = None,
    classes: Any = (2,),
    max_edge: float | None = None,
    search_radius: float | None = None,
    checkpoint_rmse_v: float = 0.0,
) -> VerticalCheckReport:
    """Vertical accuracy of a cloud at check points, LAStools ``lascontrol`` style.

    A Delaunay TIN of the ground points is interpolated linearly at each check
    point's XY and compared with the check point's height.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        The cloud (m).
    check : PointSet or ndarray of shape (M, 3)
        Check points (m).
    classification : ndarray of shape (N,), optional
        Point classes; without it every point is taken as ground.
    classes : sequence of int, default (2,)
        Classes forming the ground TIN.
    max_edge : float, optional
        A check point whose containing triangle has an XY edge longer than this
        (m) is flagged ``"sparse_tin"``. Default: 6 × the nominal ground point
        spacing 1/sqrt(density), with the density measured from the 16 nearest
        ground points of each check point (median over the check points).
    search_radius : float, optional
        A check point with no ground point within this XY radius (m) is flagged
        ``"no_ground_nearby"``. Default: `max_edge` / 2.
    checkpoint_rmse_v : float, default 0
        Vertical RMSE of the check-point survey (m), for the ASPRS Ed. 2 figure.

    Returns
    -------
    VerticalCheckReport

    Raises
    ------
    InvalidPointsError
        NaN coordinates, duplicate check ids, classification of the wrong length.
    DegenerateGeometryError
        Fewer than 3 ground points, or ground points all collinear in XY.
    NothingToMeasureError
        No check point could be compared (all outside the TIN or in sparse ground).

    Notes
    -----
    Exact XY duplicates among the ground points are merged (mean z) and the
    points are sorted before triangulating, so the TIN does not depend on the
    input order. Only ground points within 2·`max_edge` of a check point are
    triangulated: a Delaunay triangle of all ground points remains a Delaunay
    triangle of any subset that holds its vertices, so every triangle with edges
    up to 2·`max_edge` around a check point is the one of the full TIN.
    """
    from scipy.spatial import Delaunay, QhullError, cKDTree

    pts = as_points(points, "points")
    cp = as_pointset(check, "check")
    ck = _keys(cp.ids)
    _check_ids(ck, "check")
    _check_finite(cp, "check")
    if len(cp) == 0:
        raise InvalidPointsError("no check points")
    if classification is not None:
        cls = np.asarray(classification)
        if cls.shape != (len(pts),):
            raise InvalidPointsError(
                f"classification must have shape ({len(pts)},), got {cls.shape}"
            )
        classes_t = tuple(int(c) for c in np.atleast_1d(classes))
        ground = pts[np.isin(cls, classes_t)]
        what = f"class {', '.join(map(str, classes_t))}"
    else:
        ground = pts
        what = "the cloud"
    if len(ground) < 3:
        raise DegenerateGeometryError(
            f"vertical check needs at least 3 ground points ({what}), got {len(ground)}"
        )
    origin = np.array([ground[:, 0].min(), ground[:, 1].min(), 0.0])
    g = ground - origin
    c = cp.xyz - origin
    # merge exact XY duplicates (mean z): order-free
    uxy, inv = np.unique(g[:, :2], axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    uz = np.bincount(inv, weights=g[:, 2]) / np.bincount(inv)
    g = np.column_stack([uxy, uz])
    if len(g) < 3:
        raise DegenerateGeometryError(
            f"vertical check needs at least 3 ground points with distinct XY, got {len(g)}"
        )
    tree = cKDTree(g[:, :2])
    if max_edge is None:
        # local density from the 16 nearest ground points of each check point
        kk = min(16, len(g))
        dk, _ = tree.query(c[:, :2], k=kk)
        rk = np.asarray(dk).reshape(len(c), kk)[:, -1]
        spacing = float(np.median(rk * math.sqrt(math.pi / kk)))  # 1/sqrt(density)
        max_edge = 6.0 * spacing
        if not max_edge > 0:
            raise DegenerateGeometryError("ground points around the check points have zero spacing")
    else:
        max_edge = check_positive(max_edge, "max_edge")
    search_radius = (
        max_edge / 2 if search_radius is None else check_positive(search_radius, "search_radius")
    )
    # local subset around the check points
    balls = tree.query_ball_point(c[:, :2], r=2.0 * max_edge)
    sub = np.unique(
        np.concatenate([np.asarray(b, dtype=np.int64) for b in balls] + [np.empty(0, np.int64)])
    )
    m = len(cp)
    tin_z = np.full(m, np.nan)
    longest = np.full(m, np.nan)
    flag = np.full(m, "outside_tin", dtype=object)
    if len(sub) >= 3:
        gs = g[sub]
        try:
            tri = Delaunay(gs[:, :2])
        except QhullError as exc:
            if len(sub) == len(g):
                raise DegenerateGeometryError(
                    f"cannot triangulate the ground points (collinear in XY?): "
                    f"{str(exc).splitlines()[0]}"
                ) from None
            tri = None
        if tri is not None:
            # each triangle's vertices in XY order: the weights and the interpolated height are
            # then the same bits whatever subset (chunk) was triangulated or its origin
            simplices = _xy_ordered(tri.simplices, gs[:, :2])
            simp, w = _locate(simplices, gs[:, :2], c[:, :2])
            inside = simp >= 0
            if inside.any():
                verts = simplices[simp[inside]]
                tin_z[inside] = np.sum(w[inside] * gs[verts, 2], axis=1)
                vxy = gs[verts, :2]
                edges = np.stack(
                    [
                        np.linalg.norm(vxy[:, 0] - vxy[:, 1], axis=1),
                        np.linalg.norm(vxy[:, 1] - vxy[:, 2], axis=1),
                        np.linalg.norm(vxy[:, 2] - vxy[:, 0], axis=1),
                    ],
                    axis=1,
                )
                longest[inside] = edges.max(axis=1)
                flag[inside] = "ok"
    unresolved = flag == "outside_tin"
    if unresolved.any():
        # not in the local TIN: inside the hull of all ground points means a triangle with an edge
        # longer than 2·max_edge (sparse), else truly outside
        from scipy.spatial import ConvexHull

        try:
            eq = ConvexHull(g[:, :2]).equations
            inside_hull = np.all(c[unresolved, :2] @ eq[:, :2].T + eq[:, 2] <= 1e-9, axis=1)
        except QhullError:
            inside_hull = np.zeros(int(unresolved.sum()), dtype=bool)
        idx = np.flatnonzero(unresolved)[inside_hull]
        flag[idx] = "sparse_tin"
    dnear, _ = tree.query(c[:, :2], k=1)
    tol = 1e-12 * max(1.0, max_edge)
    flag[(flag == "ok") & (longest > max_edge + tol)] = "sparse_tin"
    flag[(flag == "ok") & (dnear > search_radius + tol)] = "no_ground_nearby"
    flag = flag.astype(str)
    dz = tin_z - c[:, 2]
    return summarise_vertical(
        cp, tin_z, dz, flag, longest, n_ground=len(g), max_edge=float(max_edge),
        search_radius=float(search_radius), checkpoint_rmse_v=checkpoint_rmse_v,
    )


def summarise_vertical(
    check: PointSet,
    tin_z: np.ndarray,
    dz: np.ndarray,
    flag: np.ndarray,
    longest_edge: np.ndarray,
    *,
    n_ground: int,
    max_edge: float,
    search_radius: float,
    checkpoint_rmse_v: float = 0.0,
) -> VerticalCheckReport:
    """The summary half of :func:`vertical_check`: figures from per-check-point values.

    The per-point values (TIN height, dz, flag, longest triangle edge) come from
    one region (an in-memory run) or are merged from the chunks of a catalog
    run; either way the report is made here, so both give the same figures.

    Parameters
    ----------
    check : PointSet
        All check points (m), in any order.
    tin_z, dz, flag, longest_edge : ndarray of shape (M,)
        Per check point, in the order of `check`; ``flag == "ok"`` marks the
        points compared.
    n_ground : int
        Distinct ground points (XY) of the TIN.
    max_edge, search_radius : float
        The thresholds used (m).
    checkpoint_rmse_v : float, default 0
        Vertical RMSE of the check-point survey (m).

    Returns
    -------
    VerticalCheckReport

    Raises
    ------
    NothingToMeasureError
        No check point could be compared.
    """
    m = len(check)
    ck = _keys(check.ids)
    flag = np.asarray(flag).astype(str)
    order = _sort_order(ck)
    ok = flag[order] == "ok"
    n_ok = int(ok.sum())
    warn = []
    n_flag = m - n_ok
    if n_flag:
        warn.append(
            f"{n_flag} of {m} check point(s) flagged (outside the TIN or in sparse ground) "
            "and left out"
        )
    if n_ok == 0:
        # Nothing to measure is an error, never an RMSE of NaN over 0 check points.
        kinds, counts = np.unique(flag, return_counts=True)
        why = ", ".join(f"{c} {k}" for k, c in zip(kinds.tolist(), counts.tolist(), strict=True))
        raise NothingToMeasureError(
            f"none of the {m} check point(s) could be compared with the ground TIN ({why}); "
            "do the check points lie inside the cloud, in the same CRS?"
        )
    res = np.column_stack([np.full(n_ok, np.nan), np.full(n_ok, np.nan), dz[order][ok]])
    stats = residual_statistics(res)
    nssda = nssda_accuracy(math.nan, math.nan, float(stats.rmse[2]), n_check=n_ok)
    asprs = asprs2023_accuracy(
        math.nan, math.nan, float(stats.rmse[2]), n_check=n_ok, checkpoint_rmse_v=checkpoint_rmse_v
    )
    warn.extend(nssda.warnings)
    warn.extend(asprs.warnings)
    return VerticalCheckReport(
        ids=check.ids[order],
        check_xyz=check.xyz[order],
        tin_z=tin_z[order],
        dz=dz[order],
        flag=flag[order],
        longest_edge=longest_edge[order],
        n_check=n_ok,
        n_ground=int(n_ground),
        max_edge=float(max_edge),
        search_radius=float(search_radius),
        stats=stats,
        nssda=nssda,
        asprs2023=asprs,
        warnings=tuple(warn),
    )
