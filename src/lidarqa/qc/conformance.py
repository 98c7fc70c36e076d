"""Conformance of a tile to a profile: its header and its points, in one streaming pass.

:class:`PointStats` summarises a tile's points (filled piece by piece by the one pass
of :meth:`lidarqa.qc.density.DensityGrids.scan`, so the result does not depend on the
piece size); :func:`header_checks` and :func:`point_checks` turn a header's facts
(:func:`lidarqa.io.las.las_header_facts`) and the merged statistics into
:class:`Check` verdicts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "Check",
    "PointStats",
    "duplicate_keys",
    "count_duplicates",
    "header_checks",
    "point_checks",
    "worst",
    "PASS",
    "WARN",
    "FAIL",
    "CHECK_ORDER",
]

PASS, WARN, FAIL = "pass", "warn", "fail"
_RANK = {PASS: 0, WARN: 1, FAIL: 2}

#: The per-tile checks, in report order.
CHECK_ORDER = (
    "readable", "las_version", "point_format", "crs", "gps_time", "return_numbers", "classes",
    "header", "duplicates", "source_ids", "flags", "scan_angle", "density",
    "spatial_distribution", "voids", "classification",
)


@dataclass(frozen=True)
class Check:
    """One check of one tile: status (pass/warn/fail), measured value, limit, message."""

    status: str
    value: Any = None
    limit: Any = None
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the conformance facts."""
        return {"status": self.status, "value": self.value, "limit": self.limit,
                "message": self.message}


def worst(statuses: Any) -> str:
    """The worst of some statuses (fail > warn > pass); pass when there are none."""
    out = PASS
    for s in statuses:
        if _RANK.get(s, 0) > _RANK[out]:
            out = s
    return out


@dataclass(frozen=True)
class PointStats:
    """Mergeable statistics of a tile's points (``a + b`` is the statistics of both)."""

    n: int = 0
    mins: tuple[float, ...] = (np.inf, np.inf, np.inf)
    maxs: tuple[float, ...] = (-np.inf, -np.inf, -np.inf)
    by_return: tuple[int, ...] = (0,) * 15
    invalid_returns: int = 0
    has_returns: bool = True
    classes: tuple[int, ...] = (0,) * 256
    withheld: int = 0
    overlap: int = 0
    synthetic: int = 0
    key_point: int = 0
    source_ids: dict[int, int] = field(default_factory=dict)
    scan_angle_min: float = np.inf
    scan_angle_max: float = -np.inf

    def __add__(self, o: PointStats) -> PointStats:
        sids = dict(self.source_ids)
        for k, v in o.source_ids.items():
            sids[k] = sids.get(k, 0) + v
        return PointStats(
            n=self.n + o.n,
            mins=tuple(min(a, b) for a, b in zip(self.mins, o.mins, strict=True)),
            maxs=tuple(max(a, b) for a, b in zip(self.maxs, o.maxs, strict=True)),
            by_return=tuple(a + b for a, b in zip(self.by_return, o.by_return, strict=True)),
            invalid_returns=self.invalid_returns + o.invalid_returns,
            has_returns=self.has_returns and o.has_returns,
            classes=tuple(a + b for a, b in zip(self.classes, o.classes, strict=True)),
            withheld=self.withheld + o.withheld,
            overlap=self.overlap + o.overlap,
            synthetic=self.synthetic + o.synthetic,
            key_point=self.key_point + o.key_point,
            source_ids=sids,
            scan_angle_min=min(self.scan_angle_min, o.scan_angle_min),
            scan_angle_max=max(self.scan_angle_max, o.scan_angle_max),
        )

    def class_counts(self) -> dict[str, int]:
        """``{"2": 1200, ...}``: points per class code present."""
        return {str(c): int(n) for c, n in enumerate(self.classes) if n}


def scan_angle_deg(fields: dict[str, np.ndarray]) -> np.ndarray | None:
    """Scan angles in degrees: PDRF 6-10 store 0.006° units, PDRF 0-5 whole degrees."""
    if "scan_angle" in fields:
        return np.asarray(fields["scan_angle"], dtype=np.float64) * 0.006
    if "scan_angle_rank" in fields:
        return np.asarray(fields["scan_angle_rank"], dtype=np.float64)
    return None


_P1, _P2, _P3, _P4 = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F),
                      np.uint64(0x165667B19E3779F9), np.uint64(0x27D4EB2F165667C5))


def duplicate_keys(points: np.ndarray, gps_time: np.ndarray | None, *,
                   scales: Any, offsets: Any, ints: Any = None) -> np.ndarray:
    """A 64-bit key per point from its stored X, Y, Z integers and GPS time.

    Two records with the same key are duplicates (the chance that two different records
    share a key is about N² / 2^65: 2e-5 for 30 million points). `ints`, the stored
    (X, Y, Z) integer arrays when the reader has them, saves recomputing them from
    `points` with `scales` and `offsets`.
    """
    if ints is None:
        s = np.asarray(scales, dtype=np.float64)
        o = np.asarray(offsets, dtype=np.float64)
        q = np.rint((points - o) / s).astype(np.int64)
        cols = [q[:, 0], q[:, 1], q[:, 2]]
    else:
        cols = [np.asarray(c) for c in ints]
    u = [c.astype(np.int64).view(np.uint64) for c in cols]
    with np.errstate(over="ignore"):
        k = u[0] * _P1 ^ u[1] * _P2 ^ u[2] * _P3
        if gps_time is not None:
            k = k ^ (np.asarray(gps_time, dtype=np.float64).view(np.uint64) * _P4)
    return k


def count_duplicates(keys: np.ndarray) -> int:
    """Records that repeat an earlier record (same key): ``len(keys) - distinct keys``."""
    if len(keys) < 2:
        return 0
    k = np.sort(keys)  # equality only: the unstable sort is 4x faster
    return int(np.count_nonzero(k[1:] == k[:-1]))


def header_checks(facts: dict[str, Any], spec: Any, *, crs: Any = None) -> dict[str, Check]:
    """Version, point format, CRS and GPS time type of a header against `spec`."""
    out: dict[str, Check] = {}
    v = facts["version"]
    out["las_version"] = Check(
        PASS if v in spec.las_versions else FAIL, v, list(spec.las_versions),
        f"LAS {v}" + ("" if v in spec.las_versions else
                      f", the spec requires LAS {' or '.join(spec.las_versions)}"))
    f = facts["point_format"]
    ok = f in spec.point_formats
    out["point_format"] = Check(
        PASS if ok else FAIL, f, list(spec.point_formats),
        f"point data record format {f}" + ("" if ok else ", not one the spec allows"))
    problems = []
    if crs is None:
        problems.append("no CRS in the header")
    if spec.require_wkt and not (facts.get("wkt") and facts.get("has_wkt_vlr")):
        problems.append("CRS not stored as OGC WKT (global encoding WKT bit and WKT VLR)")
    if spec.require_vertical_crs and crs is not None and not _has_vertical(crs):
        problems.append("no vertical CRS")
    name = getattr(crs, "name", None)
    out["crs"] = Check(FAIL if problems else PASS, name,
                       "horizontal + vertical CRS as WKT" if spec.require_wkt else "CRS",
                       "; ".join(problems) if problems else f"CRS {name}")
    if spec.gps_time_type:
        t = facts["gps_time_type"]
        ok = t == spec.gps_time_type
        msg = f"GPS time type: {t}" + ("" if ok else f", the spec requires {spec.gps_time_type}")
        out["gps_time"] = Check(PASS if ok else FAIL, t, spec.gps_time_type, msg)
    return out


def _has_vertical(crs: Any) -> bool:
    try:
        if crs.is_compound:
            return any(c.is_vertical for c in crs.sub_crs_list)
        return bool(crs.is_vertical) or len(crs.axis_info) >= 3
    except Exception:
        return False


def point_checks(stats: PointStats, facts: dict[str, Any], spec: Any, *,
                 duplicates: int) -> dict[str, Check]:
    """Return numbers, classes, header-against-data, duplicates, source ids, flags, scan angle."""
    out: dict[str, Check] = {}
    n = stats.n
    if not stats.has_returns:
        out["return_numbers"] = Check(FAIL, None, "1 <= return <= number of returns <= 15",
                                      "the points carry no return numbers")
    else:
        bad = stats.invalid_returns
        out["return_numbers"] = Check(
            FAIL if bad else PASS, bad, 0,
            f"{bad:,} point(s) with an invalid return number (return < 1, return > number of "
            "returns, or more returns than the format allows)" if bad else
            "every return number valid")
    present = {c for c, k in enumerate(stats.classes) if k}
    allowed = set(spec.allowed_classes)
    wrong = sorted(present - allowed)
    n_wrong = sum(stats.classes[c] for c in wrong)
    out["classes"] = Check(
        FAIL if wrong else PASS, sorted(present), "allowed by the spec",
        f"class code(s) the spec does not allow: {', '.join(map(str, wrong))} "
        f"({n_wrong:,} points)" if wrong else f"{len(present)} class code(s), all allowed")
    problems = []
    if facts["point_count"] != n:
        problems.append(f"header declares {facts['point_count']:,} points, the file holds {n:,}")
    if n:
        tol = [0.5 * s + 1e-7 for s in facts["scales"]]
        hmin, hmax = facts["mins"], facts["maxs"]
        off = max(max(abs(hmin[i] - stats.mins[i]) - tol[i], abs(hmax[i] - stats.maxs[i]) - tol[i])
                  for i in range(3))
        if off > 0:
            problems.append(
                "header bounds differ from the data by up to "
                f"{off + max(tol):.3f} m (header x {hmin[0]:.2f}..{hmax[0]:.2f}, y "
                f"{hmin[1]:.2f}..{hmax[1]:.2f}, z {hmin[2]:.2f}..{hmax[2]:.2f}; data x "
                f"{stats.mins[0]:.2f}..{stats.maxs[0]:.2f}, y {stats.mins[1]:.2f}.."
                f"{stats.maxs[1]:.2f}, z {stats.mins[2]:.2f}..{stats.maxs[2]:.2f})")
    else:
        off = 0.0
    if stats.has_returns:
        hb = list(facts["points_by_return"]) + [0] * 15
        if any(hb[i] != stats.by_return[i] for i in range(15)) and any(hb[:15]):
            problems.append("header points by return "
                            f"{[int(v) for v in hb[:5]]} differ from the data "
                            f"{list(stats.by_return[:5])}")
    out["header"] = Check(FAIL if problems else PASS, round(max(off, 0.0), 6), 0.0,
                          "; ".join(problems) if problems else
                          "point count, bounds and points by return match the data")
    key = ("X, Y, Z and GPS time" if facts["point_format"] not in (0, 2)
           else "X, Y and Z; the format stores no GPS time")
    out["duplicates"] = Check(
        FAIL if duplicates > spec.max_duplicates else PASS, duplicates, spec.max_duplicates,
        f"{duplicates:,} duplicate record(s) (same {key})" if duplicates else
        "no duplicate record")
    zero = stats.source_ids.get(0, 0)
    ids = sorted(stats.source_ids)
    out["source_ids"] = Check(
        WARN if zero and n else PASS, len([i for i in ids if i]), "point source id = swath id",
        (f"{zero:,} point(s) with point source id 0 (the swath is unknown)" if zero else
         f"point source ids {', '.join(map(str, ids[:8]))}{' ...' if len(ids) > 8 else ''}")
        + f"; file source id {facts.get('file_source_id', 0)}")
    out["flags"] = Check(
        PASS, stats.withheld, None,
        f"withheld {stats.withheld:,}, overlap {stats.overlap:,}, synthetic {stats.synthetic:,}, "
        f"key-point {stats.key_point:,}")
    if np.isfinite(stats.scan_angle_min):
        lo, hi = stats.scan_angle_min, stats.scan_angle_max
        amax = max(abs(lo), abs(hi))
        legal = 180.0 if facts["point_format"] >= 6 else 90.0
        if amax > legal:
            st, msg = FAIL, f"scan angle {amax:.2f}° outside the LAS range ±{legal:g}°"
        elif spec.max_scan_angle_deg is not None and amax > spec.max_scan_angle_deg:
            st, msg = FAIL, f"scan angle up to {amax:.2f}°, over {spec.max_scan_angle_deg:g}°"
        else:
            st, msg = PASS, f"scan angle {lo:.2f}° .. {hi:.2f}°"
        out["scan_angle"] = Check(st, round(amax, 4),
                                  spec.max_scan_angle_deg if spec.max_scan_angle_deg is not None
                                  else legal, msg)
    return out
