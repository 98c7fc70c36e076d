"""Corners as intersections of three planes ([S-FH] eq. 4; :ref:`alg-corners`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import as_points, check_positive, check_range
from ..errors import DegenerateGeometryError, OptionError
from ..io.vector import PointSet
from .planes import PlaneFit
from .segmentation import PlaneSegmentation, segment_planes

__all__ = ["Corner", "corner_from_planes", "extract_corners", "corners_from_segmentation"]


@dataclass(frozen=True, eq=False)
class Corner:
    """A three-plane corner.

    Attributes
    ----------
    xyz : ndarray of shape (3,)
        The corner (m).
    det : float
        ``|det N|`` of the unit normals (volume of their parallelepiped, <= 1).
    min_angle_deg : float
        Smallest angle (degrees, in [0, 90]) between two of the planes.
    covariance : ndarray of shape (3, 3)
        Covariance (m²) of `xyz`; NaN when no plane uncertainty was given.
    """

    xyz: np.ndarray
    det: float
    min_angle_deg: float
    covariance: np.ndarray = field(repr=False)

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviations (m) of x, y, z."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {"xyz": self.xyz.tolist(), "det": self.det, "min_angle_deg": self.min_angle_deg,
                "sigma": self.sigma.tolist()}


def _as_plane(pl: Any, k: int) -> tuple[np.ndarray, float, PlaneFit | None]:
    if isinstance(pl, PlaneFit):
        return np.asarray(pl.normal, float), float(pl.rho), pl
    try:
        n, rho = pl
        n = np.asarray(n, dtype=np.float64).reshape(3)
        rho = float(rho)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"plane {k}: expected a PlaneFit or a (normal, rho) pair") from exc
    return n, rho, None


def _angles_deg(nn: np.ndarray) -> float:
    out = 90.0
    for i, j in ((0, 1), (0, 2), (1, 2)):
        s = float(np.linalg.norm(np.cross(nn[i], nn[j])))
        out = min(out, math.degrees(math.asin(min(1.0, s))))
    return out


def _solve(nn: np.ndarray, rho: np.ndarray, min_det: float,
           min_angle: float) -> tuple[np.ndarray, float, float]:
    """Conditioning checks and the solution of N x = rho (unit normals)."""
    ang = _angles_deg(nn)
    if ang < min_angle:
        raise DegenerateGeometryError(
            f"near-parallel planes: two normals are {ang:.3g}° apart (< min_angle={min_angle}°)")
    det = abs(float(np.linalg.det(nn)))
    if det < min_det:
        raise DegenerateGeometryError(
            f"near-coplanar normals: |det N| = {det:.3g} < min_det={min_det}")
    return np.linalg.solve(nn, rho), det, ang


def corner_from_planes(
    planes: Any,
    *,
    sigma_rho: Any = None,
    min_det: float = 0.1,
    min_angle: float = 10.0,
    normal_uncertainty: bool = True,
) -> Corner:
    """Intersect three planes: solve ``N x = rho`` with conditioning checks (:ref:`alg-corners`).

    Parameters
    ----------
    planes : sequence of 3 PlaneFit or (normal, rho) pairs
        Planes ``normal · p = rho``. Normals need not be unit: each plane is
        normalised first (so explicit-z planes ``a x + b y + z = c`` can be given
        as ``((a, b, 1), c)``).
    sigma_rho : array_like of shape (3,), optional
        Standard deviations (m) of the offsets; overrides the PlaneFit
        uncertainties.
    min_det : float, default 0.1
        Smallest ``|det N|`` of the unit normals accepted.
    min_angle : float, default 10.0
        Smallest angle (degrees) accepted between any two planes.
    normal_uncertainty : bool, default True
        With PlaneFit input, propagate the normal covariance as well: plane k's
        position error at the corner has variance ``σ_ρk² + (x - c_k)ᵀ Σ_nk (x - c_k)``
        (c_k its centroid). False ignores normal errors (σ_ρ at the centroid only).

    Returns
    -------
    Corner
        The corner, ``|det N|``, the smallest pair angle and ``Σ_x = N⁻¹ D N⁻ᵀ`` with D
        the diagonal of plane position variances (NaN without any uncertainty).

    Raises
    ------
    DegenerateGeometryError
        "near-parallel" (two planes closer than `min_angle`) or "near-coplanar
        normals" (``|det N|`` < `min_det`, e.g. three planes sharing a direction).

    Examples
    --------
    >>> c = corner_from_planes([((1, 0, 0), 1), ((0, 1, 0), 2), ((0, .6, .8), 3)])
    >>> c.xyz.round(9).tolist(), round(c.det, 9)
    ([1.0, 2.0, 2.25], 0.8)
    """
    planes = list(planes)
    if len(planes) != 3:
        raise OptionError(f"planes must hold 3 planes, got {len(planes)}")
    min_det = check_range(min_det, "min_det", 0.0, 1.0)
    min_angle = check_range(min_angle, "min_angle", 0.0, 90.0)
    nn = np.empty((3, 3))
    rho = np.empty(3)
    fits = []
    for k, pl in enumerate(planes):
        n, r, fit = _as_plane(pl, k)
        ln = float(np.linalg.norm(n))
        if not np.isfinite(ln) or ln < 1e-12 or not np.isfinite(r):
            raise DegenerateGeometryError(f"plane {k}: zero or non-finite normal/offset")
        nn[k] = n / ln
        rho[k] = r / ln
        fits.append(fit)
    x, det, ang = _solve(nn, rho, min_det, min_angle)
    var = np.full(3, np.nan)
    if sigma_rho is not None:
        s = np.asarray(sigma_rho, dtype=np.float64).reshape(3)
        var = s**2
    elif all(f is not None for f in fits):
        for k, f in enumerate(f for f in fits if f is not None):
            var[k] = f.covariance[3, 3]
            if normal_uncertainty:
                d = x - f.centroid
                var[k] += d @ f.covariance[:3, :3] @ d
    ninv = np.linalg.inv(nn)
    cov = ninv @ np.diag(var) @ ninv.T
    return Corner(xyz=x, det=det, min_angle_deg=ang, covariance=cov)


def corners_from_segmentation(
    seg: PlaneSegmentation,
    points: np.ndarray,
    *,
    min_det: float = 0.1,
    min_angle: float = 10.0,
    max_dist: float = 1.0,
    normal_uncertainty: bool = True,
    crs: Any = None,
) -> tuple[PointSet, list[dict]]:
    """Corners of every triple of mutually adjacent segments, and the refused triples.

    A triple is kept when it passes the conditioning checks and the corner lies
    within `max_dist` (m) of contact points of each of its three segments (so two
    roofs and a wall of different buildings that happen to touch do not make a
    corner far away).
    """
    pts = np.asarray(points, dtype=np.float64)
    adj = {tuple(map(int, p)): m for m, p in enumerate(seg.adjacency)}
    neigh: dict[int, set[int]] = {}
    for a, b in adj:
        neigh.setdefault(a, set()).add(b)
        neigh.setdefault(b, set()).add(a)
    rows = []
    refused = []
    for a, b in sorted(adj):
        for c in sorted(neigh[a] & neigh[b]):
            if c <= b:
                continue
            trip = (a, b, c)
            nn = seg.normal[list(trip)]
            try:
                x, det, ang = _solve(nn, seg.rho[list(trip)], min_det, min_angle)
            except DegenerateGeometryError as exc:
                refused.append({"planes": trip, "reason": str(exc).split(":")[0]})
                continue
            # the corner must be near each segment's contact points
            ok = True
            for k in trip:
                idx = []
                for pair in ((a, b), (a, c), (b, c)):
                    if k not in pair:
                        continue
                    m = adj[pair]
                    sl = slice(seg.contact_ptr[m], seg.contact_ptr[m + 1])
                    idx.append(seg.contact_i[sl])
                    idx.append(seg.contact_j[sl])
                ii = np.concatenate(idx)
                ii = ii[seg.labels[ii] == k]
                if len(ii) == 0 or np.min(np.linalg.norm(pts[ii] - x, axis=1)) > max_dist:
                    ok = False
                    break
            if not ok:
                refused.append({"planes": trip, "reason": "corner far from the segments"})
                continue
            var = seg.covariance[list(trip), 3, 3].copy()
            if normal_uncertainty:
                for j, k in enumerate(trip):
                    d = x - seg.centroid[k]
                    var[j] += d @ seg.covariance[k, :3, :3] @ d
            ninv = np.linalg.inv(nn)
            cov = ninv @ np.diag(var) @ ninv.T
            if not np.isfinite(x).all():
                refused.append({"planes": trip, "reason": "not finite"})
                continue
            rows.append((x, trip, det, ang, np.sqrt(np.maximum(np.diag(cov), 0.0))))
    n = len(rows)
    ps = PointSet(
        ids=np.arange(n, dtype=np.int64),
        xyz=np.array([r[0] for r in rows]).reshape(n, 3),
        attributes={
            "plane_a": np.array([r[1][0] for r in rows], dtype=np.int64),
            "plane_b": np.array([r[1][1] for r in rows], dtype=np.int64),
            "plane_c": np.array([r[1][2] for r in rows], dtype=np.int64),
            "det": np.array([r[2] for r in rows], dtype=np.float64),
            "min_angle_deg": np.array([r[3] for r in rows], dtype=np.float64),
            "sigma_x": np.array([r[4][0] for r in rows], dtype=np.float64),
            "sigma_y": np.array([r[4][1] for r in rows], dtype=np.float64),
            "sigma_z": np.array([r[4][2] for r in rows], dtype=np.float64),
        },
        crs=crs,
    )
    return ps, refused


def extract_corners(
    points: Any,
    *,
    segmentation: PlaneSegmentation | None = None,
    min_det: float = 0.1,
    min_angle: float = 10.0,
    max_dist: float = 1.0,
    normal_uncertainty: bool = True,
    crs: Any = None,
    left_out: list[dict[str, Any]] | None = None,
    **segment_options: Any,
) -> PointSet:
    """Corners of a cloud: intersections of three mutually adjacent planes.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres.
    segmentation : PlaneSegmentation, optional
        Computed with :func:`segment_planes` (`segment_options`) when omitted.
    min_det : float, default 0.1
        Smallest ``|det N|`` of the three unit normals.
    min_angle : float, default 10.0
        Smallest angle (degrees) between any two of the planes.
    max_dist : float, default 1.0
        The corner must lie within this distance (m) of points of each of the
        three segments where they touch.
    normal_uncertainty : bool, default True
        Propagate the normal covariances too (see :func:`corner_from_planes`).
    crs : pyproj.CRS, optional
        Stored on the result.
    left_out : list, optional
        Extended with the refused triples, as ``{"planes", "reason"}`` (see
        :func:`corners_from_segmentation`).

    Returns
    -------
    PointSet
        ids 0..n-1, xyz, and attributes ``plane_a, plane_b, plane_c`` (segment
        ids), ``det``, ``min_angle_deg``, ``sigma_x, sigma_y, sigma_z`` (m).
    """
    pts = as_points(points)
    min_det = check_range(min_det, "min_det", 0.0, 1.0)
    min_angle = check_range(min_angle, "min_angle", 0.0, 90.0)
    max_dist = check_positive(max_dist, "max_dist")
    if segmentation is None:
        segmentation = segment_planes(pts, **segment_options)
    elif len(segmentation.labels) != len(pts):
        raise OptionError("segmentation was computed for a different number of points")
    corners, refused = corners_from_segmentation(segmentation, pts, min_det=min_det,
                                                 min_angle=min_angle, max_dist=max_dist,
                                                 normal_uncertainty=normal_uncertainty, crs=crs)
    if left_out is not None:
        left_out.extend(refused)
    return corners
