"""Height quality by error propagation, TIN precision and w-tests (Oude Elberink & Vosselman).

:ref:`alg-heights`. Map points (x, y) get a height from a least-squares plane
``z = −x·p1 − y·p2 + p3`` fitted, in coordinates centred on the laser points,
to the laser points within a search radius that grows until enough points are
found. Their predicted precision is

    σ²_map = σ²_plane + σ²_laser_block + σ²_model

with σ²_plane = aᵀQa, Q = σ_z²(AᵀA)⁻¹ (the full form; the paper's eq. 8 drops
the p1–p2 covariance and is available as an option), σ²_laser_block = E2² + E3²
+ E4² (GPS, INS, strip adjustment; common to all points of a neighbourhood, so
they do not enter Q) and σ_model = κ·s²/2/3 (curvature κ, extrapolation
distance s). Heights and precisions are interpolated in a TIN over the map
points to reference points with a correlation ρ between the TIN vertices, the
differences Δh = h_model − h_ref are tested with w = Δh/σ_Δh, and outliers are
found by iterative data snooping with the critical value k = Φ⁻¹(1 − α₀/2).

All lengths are in metres (horizontal units of a metric projected CRS), heights
in metres, curvature in 1/m.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._arrays import spatial_order
from .._validate import as_points, check_choice, check_positive, check_range, require
from ..errors import DegenerateGeometryError, InvalidPointsError, OptionError, ReadError
from . import _heights_kernels as _k

__all__ = [
    "SIGMA_POINT",
    "SIGMA_GPS",
    "SIGMA_INS",
    "SIGMA_STRIP",
    "SIGMA_REF",
    "CURVATURE",
    "RADIUS",
    "MAX_RADIUS",
    "MIN_POINTS",
    "PlaneHeight",
    "MapPointHeights",
    "TinInterpolation",
    "HeightComparison",
    "WTestResult",
    "HeightReport",
    "laser_block_sigma",
    "model_sigma",
    "empirical_model_sigma",
    "critical_value",
    "tin_sigma",
    "fit_plane_height",
    "map_point_heights",
    "interpolate_tin",
    "compare_heights",
    "w_test",
    "assess_heights",
    "summarise_heights",
    "densify_polygons",
    "read_map_points",
]

#: a-priori laser point noise E1 (m), [S-OV] §5.1
SIGMA_POINT = 0.08
#: GPS noise E2 (m)
SIGMA_GPS = 0.03
#: INS noise E3 (m)
SIGMA_INS = 0.04
#: strip-adjustment noise E4 (m)
SIGMA_STRIP = 0.03
#: reference height noise (m): paint strips, [S-OV] §4.1
SIGMA_REF = 0.09
#: maximum vertical curvature of the surface (1/m): a 10 km vertical radius
CURVATURE = 1e-4
#: first search radius (m)
RADIUS = 2.0
#: largest search radius (m), [S-OV] §5.2 ("increases up to 50 or even 100 meter")
MAX_RADIUS = 50.0
#: laser points needed for a plane fit
MIN_POINTS = 10


def _freeze(obj: Any) -> None:
    """Store read-only views of the array fields (the caller's arrays stay writable)."""
    for name, value in vars(obj).items():
        if isinstance(value, np.ndarray):
            view = value.view()
            view.setflags(write=False)
            object.__setattr__(obj, name, view)


def _nanstat(values: np.ndarray, func: Any) -> float:
    v = values[np.isfinite(values)]
    return float(func(v)) if v.size else float("nan")


# ------------------------------------------------------------------ scalar helpers


def laser_block_sigma(
    *, sigma_gps: float = SIGMA_GPS, sigma_ins: float = SIGMA_INS, sigma_strip: float = SIGMA_STRIP
) -> float:
    """σ_laser_block = √(E2² + E3² + E4²) (eq. 9), in metres.

    Examples
    --------
    >>> round(laser_block_sigma() * 100, 6)
    5.830952
    """
    e = [
        check_positive(v, n, allow_zero=True)
        for v, n in (
            (sigma_gps, "sigma_gps"),
            (sigma_ins, "sigma_ins"),
            (sigma_strip, "sigma_strip"),
        )
    ]
    return float(np.sqrt(sum(x * x for x in e)))


def model_sigma(distance: Any, *, curvature: float = CURVATURE) -> np.ndarray | float:
    """Model (idealisation) σ = e_max/3 with e_max = κ·s²/2 (:ref:`alg-heights`).

    Parameters
    ----------
    distance : float or ndarray
        Extrapolation distance s (m).
    curvature : float, default 1e-4
        Maximum curvature κ of the surface (1/m).

    Examples
    --------
    >>> round(float(model_sigma(100.0, curvature=1e-4)), 6)
    0.166667
    """
    kappa = check_positive(curvature, "curvature", allow_zero=True)
    s = np.asarray(distance, dtype=np.float64)
    out = kappa * s * s / 6.0
    return float(out) if out.ndim == 0 else out


def empirical_model_sigma(std: float, sigma_ref: float = SIGMA_REF) -> float:
    """The model's empirical σ = √(std² − σ_ref²); NaN when std <= σ_ref or std is NaN.

    Examples
    --------
    >>> round(empirical_model_sigma(15.4, 9.0), 4)
    12.4964
    """
    std = float(std)
    sigma_ref = float(sigma_ref)
    if not np.isfinite(std) or std <= sigma_ref:
        return float("nan")
    return float(np.sqrt(std * std - sigma_ref * sigma_ref))


def critical_value(alpha: float = 0.001) -> float:
    """Two-sided critical value k = Φ⁻¹(1 − α₀/2) of the w-test.

    Examples
    --------
    >>> round(critical_value(0.001), 6)
    3.290527
    """
    from scipy.special import ndtri

    a = check_range(alpha, "alpha", 0.0, 1.0, lo_open=True, hi_open=True)
    return float(-ndtri(a / 2.0))


def tin_sigma(
    weights: Any, sigmas: Any, *, correlation: float = 0.0, covariance: Any = None
) -> np.ndarray | float:
    """σ of a TIN-interpolated height from the vertex σ's and barycentric weights.

    Method: :ref:`alg-heights`.

    σ_h² = Σ w_k²σ_k² + 2ρ Σ_{k<l} w_k w_l σ_k σ_l, or wᵀCw with a full 3x3
    covariance C.

    Parameters
    ----------
    weights : ndarray of shape (..., 3)
        Barycentric weights (sum 1).
    sigmas : ndarray of shape (..., 3)
        σ of the three vertex heights (m); ignored when `covariance` is given.
    correlation : float in [0, 1], default 0
        Uniform correlation ρ between the vertex heights.
    covariance : ndarray of shape (..., 3, 3), optional
        Full covariance of the three vertex heights (m²).

    Examples
    --------
    >>> round(float(tin_sigma([0.5, 0.3, 0.2], [0.05, 0.10, 0.20], correlation=0.5)), 6)
    0.077942
    """
    w = np.asarray(weights, dtype=np.float64)
    if covariance is not None:
        c = np.asarray(covariance, dtype=np.float64)
        var = np.einsum("...i,...ij,...j->...", w, c, w)
    else:
        rho = check_range(correlation, "correlation", 0.0, 1.0)
        var = _k.tin_variance(w, np.asarray(sigmas, dtype=np.float64), rho)
    out = np.sqrt(var)
    return float(out) if np.ndim(out) == 0 else out


# ------------------------------------------------------------------ plane heights


@dataclass(frozen=True, eq=False)
class PlaneHeight:
    """One plane fit and the height/precision it gives at a map point.

    Attributes
    ----------
    height : float
        Plane height at the map point (m).
    sigma_plane : float
        σ of that height from the plane parameters only (m).
    params : ndarray of shape (3,)
        p1, p2 (slopes) and p3 (height at the centroid, m) of z = −x·p1 − y·p2 + p3
        in coordinates centred on `centroid`.
    covariance : ndarray of shape (3, 3)
        Q = σ_z²(AᵀA)⁻¹ of the parameters.
    centroid : ndarray of shape (2,)
        Mean x, y of the laser points (m).
    n : int
        Number of laser points.
    sigma0 : float
        σ_z used (a priori, or a posteriori √(rᵀr/(n−3))) (m).
    """

    height: float
    sigma_plane: float
    params: np.ndarray
    covariance: np.ndarray
    centroid: np.ndarray
    n: int
    sigma0: float

    def __post_init__(self) -> None:
        _freeze(self)

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "height": self.height,
            "sigma_plane": self.sigma_plane,
            "n": self.n,
            "sigma0": self.sigma0,
        }


def fit_plane_height(
    points: Any,
    map_xy: Any,
    *,
    sigma_point: float = SIGMA_POINT,
    eq8_diagonal: bool = False,
    posterior: bool = False,
) -> PlaneHeight:
    """Fit z = −x·p1 − y·p2 + p3 to laser points and predict the height at a map point.

    Method: :ref:`alg-heights`.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Laser points x, y, z (m); N >= 3 (N > 3 with `posterior`).
    map_xy : array_like of shape (2,)
        Map point x, y (m).
    sigma_point : float, default 0.08
        A-priori σ_z of a laser point height (E1, m).
    eq8_diagonal : bool, default False
        Use the paper's eq. 8 (Δx²σ²_p1 + Δy²σ²_p2 + σ²_p3), which omits the
        p1–p2 covariance, instead of the full form aᵀQa.
    posterior : bool, default False
        Use σ̂² = rᵀr/(n−3) instead of `sigma_point` squared.

    Returns
    -------
    PlaneHeight

    Raises
    ------
    InvalidPointsError
        Fewer than 3 points (4 with `posterior`), NaN, wrong shape.
    DegenerateGeometryError
        XY of the points collinear (condition number of AᵀA > 1e12).

    Examples
    --------
    >>> pts = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [3, 2, 0], [1, 3, 0.]])
    >>> round(fit_plane_height(pts, (5, 5)).sigma_plane, 6)
    0.150904
    """
    pts = as_points(points, min_points=4 if posterior else 3)
    mxy = np.asarray(map_xy, dtype=np.float64).reshape(-1)[:2].reshape(1, 2)
    if not np.isfinite(mxy).all():
        raise InvalidPointsError(f"map_xy must be finite, got {map_xy!r}")
    s = check_positive(sigma_point, "sigma_point")
    res = _k.fit_planes(
        pts,
        np.zeros(len(pts), dtype=np.int64),
        mxy,
        sigma_z=s,
        posterior=posterior,
        eq8_diagonal=eq8_diagonal,
        min_points=3,
    )
    if res["reason"][0] == _k.COLLINEAR:
        raise DegenerateGeometryError(
            "the x, y of the laser points are collinear "
            "(condition number of AᵀA > 1e12); no plane can be fitted"
        )
    q11, q12, q22, q33 = res["q"][0]
    cov = np.array([[q11, q12, 0.0], [q12, q22, 0.0], [0.0, 0.0, q33]])
    return PlaneHeight(
        height=float(res["height"][0]),
        sigma_plane=float(res["sigma_plane"][0]),
        params=res["p"][0].copy(),
        covariance=cov,
        centroid=mxy[0] + res["centroid_offset"][0],
        n=int(res["n_used"][0]),
        sigma0=float(res["sigma0"][0]),
    )


@dataclass(frozen=True, eq=False)
class MapPointHeights:
    """Heights and predicted precision of map points (one row per map point).

    Attributes
    ----------
    xy : ndarray of shape (M, 2)
        Map point x, y (m).
    height : ndarray of shape (M,)
        Fitted height (m); NaN where `failed`.
    sigma : ndarray of shape (M,)
        σ_map = √(σ_plane² + σ_block² + σ_model²) (m).
    sigma_plane, sigma_block, sigma_model : ndarray of shape (M,)
        The three terms of the error budget (m).
    n_points : ndarray of shape (M,)
        Laser points used (for failed points: found within the maximum radius).
    radius : ndarray of shape (M,)
        Search radius used (m); NaN when the minimum count was never reached.
    distance : ndarray of shape (M,)
        Extrapolation distance s used for σ_model (m).
    failed : ndarray of shape (M,) bool
        Not fitted.
    reason : ndarray of shape (M,) object
        "" or why not: "too_few_points", "too_few_segment_points", "collinear".
    """

    xy: np.ndarray
    height: np.ndarray
    sigma: np.ndarray
    sigma_plane: np.ndarray
    sigma_block: np.ndarray
    sigma_model: np.ndarray
    n_points: np.ndarray
    radius: np.ndarray
    distance: np.ndarray
    failed: np.ndarray
    reason: np.ndarray

    def __post_init__(self) -> None:
        _freeze(self)

    def __len__(self) -> int:
        return len(self.height)

    def to_dict(self) -> dict[str, Any]:
        """``{"n", "sigma_mean", "sigma_p95", "n_failed"}`` (σ over the fitted map points)."""
        s = self.sigma[~self.failed]
        return {
            "n": int(len(self.height)),
            "sigma_mean": _nanstat(s, np.mean),
            "sigma_p95": _nanstat(s, lambda v: np.percentile(v, 95)),
            "n_failed": int(self.failed.sum()),
        }


def _check_common(
    radius: float, max_radius: float, min_points: int, growth: float | None, posterior: bool
) -> tuple[float, float, int, float | None]:
    r = check_positive(radius, "radius")
    rmax = check_positive(max_radius, "max_radius")
    if rmax < r:
        raise OptionError(f"max_radius must be >= radius ({r}), got {max_radius!r}")
    try:
        k = int(min_points)
    except (TypeError, ValueError):
        raise OptionError(f"min_points must be an integer, got {min_points!r}") from None
    if k != min_points or k < 3 or (posterior and k < 4):
        raise OptionError(
            f"min_points must be an integer >= {4 if posterior else 3}"
            f"{' with posterior=True' if posterior else ''}, got {min_points!r}"
        )
    if growth is not None:
        growth = check_positive(growth, "growth")
        if growth <= 1.0:
            raise OptionError(
                f"growth must be > 1 (or None for a continuous radius), got {growth!r}"
            )
    return r, rmax, k, growth


def _segment_labels(pts: np.ndarray, labels: Any, largest_segment: bool) -> np.ndarray | None:
    if labels is not None:
        lab = np.asarray(labels)
        if lab.shape != (len(pts),):
            raise InvalidPointsError(f"labels must have shape ({len(pts)},), got {lab.shape}")
        return lab.astype(np.int64, copy=False)
    if not largest_segment:
        return None
    try:
        from ..geometry.segmentation import surface_growing
    except ImportError as exc:  # pragma: no cover - depends on the geometry package
        raise OptionError(
            "largest_segment=True needs lidarqa.geometry.segmentation.surface_growing, "
            "which is not available; pass labels= instead"
        ) from exc
    return np.asarray(surface_growing(pts), dtype=np.int64)


def map_point_heights(
    points: Any,
    map_xy: Any,
    *,
    radius: float = RADIUS,
    max_radius: float = MAX_RADIUS,
    min_points: int = MIN_POINTS,
    growth: float | None = 2.0,
    sigma_point: float = SIGMA_POINT,
    sigma_gps: float = SIGMA_GPS,
    sigma_ins: float = SIGMA_INS,
    sigma_strip: float = SIGMA_STRIP,
    curvature: float = CURVATURE,
    s_mode: str = "centroid",
    eq8_diagonal: bool = False,
    posterior: bool = False,
    largest_segment: bool = False,
    labels: Any = None,
) -> MapPointHeights:
    """Height and error budget of every map point from the laser points around it.

    Method: :ref:`alg-heights`.
    The laser points within `radius` (horizontal distance) are used; where there
    are fewer than `min_points`, the radius grows as radius·growth**j up to
    `max_radius` (``growth=None``: exactly to the distance of the
    `min_points`-th nearest point). Map points that never reach `min_points`
    are flagged ``too_few_points`` and not fitted; neighbourhoods with
    collinear x, y are flagged ``collinear``. Vectorised: one k-NN and one ball
    query on a cKDTree, stacked normal equations.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Laser points x, y, z (m).
    map_xy : ndarray of shape (M, 2) or (M, 3)
        Map points (z ignored).
    radius, max_radius : float, default 2.0, 50.0
        First and largest search radius (m).
    min_points : int, default 10
        Laser points needed (>= 3; >= 4 with `posterior`).
    growth : float > 1 or None, default 2.0
        Radius growth factor.
    sigma_point : float, default 0.08
        E1, a-priori laser point height σ (m).
    sigma_gps, sigma_ins, sigma_strip : float, default 0.03, 0.04, 0.03
        E2, E3, E4 (m): the laser block term, common to a neighbourhood.
    curvature : float, default 1e-4
        Maximum surface curvature κ (1/m) for σ_model = κ·s²/6; 0 switches it off.
    s_mode : {"centroid", "nearest"}, default "centroid"
        Extrapolation distance s: to the centroid of the used laser points, or
        to the nearest used laser point.
    eq8_diagonal : bool, default False
        σ_plane by the paper's eq. 8 instead of the full form.
    posterior : bool, default False
        σ_z from the residuals of each fit instead of `sigma_point`.
    largest_segment : bool, default False
        Use only the points of the segment with most points among the
        neighbours (segments from `labels`, else from
        :func:`lidarqa.geometry.segmentation.surface_growing` on all points).
    labels : ndarray of shape (N,), optional
        Segment label per laser point (-1 = none); implies `largest_segment`.

    Returns
    -------
    MapPointHeights
    """
    pts = as_points(points)
    mxy = _as_xy(map_xy, "map_xy")
    r, rmax, k, growth = _check_common(radius, max_radius, min_points, growth, posterior)
    s_z = check_positive(sigma_point, "sigma_point")
    block = laser_block_sigma(sigma_gps=sigma_gps, sigma_ins=sigma_ins, sigma_strip=sigma_strip)
    kappa = check_positive(curvature, "curvature", allow_zero=True)
    check_choice(s_mode, ("centroid", "nearest"), "s_mode")
    lab = _segment_labels(pts, labels, largest_segment)
    m = len(mxy)
    tree = None
    order = np.empty(0, dtype=np.int64)
    cell = 4.0 * r
    if len(pts):
        from scipy.spatial import cKDTree

        origin = pts[:, :2].min(axis=0)
        order = spatial_order(pts[:, :2], origin, cell)
        tree = cKDTree(pts[order, :2] - origin, balanced_tree=False)
    else:
        origin = np.zeros(2)
    q_order = spatial_order(mxy, origin, cell) if m else np.empty(0, dtype=np.int64)
    q_group, q_index, q_r, q_n = _k.neighbourhoods(
        tree, mxy[q_order] - origin, radius=r, max_radius=rmax, min_points=k, growth=growth
    )
    group, index = q_order[q_group], order[q_index]
    if len(index):
        # entries by map point, then by the laser point's (x, y, z): the sums of each fit run in
        # the same order whatever subset of the cloud (a chunk of a catalog) was searched
        p = pts[index]
        canon = np.lexsort((p[:, 2], p[:, 1], p[:, 0], group))
        group, index = group[canon], index[canon]
    r_used, n_found = np.empty(m), np.empty(m, dtype=np.int64)
    r_used[q_order], n_found[q_order] = q_r, q_n
    enough_before = np.bincount(group, minlength=m) >= k
    if lab is not None and len(group):
        keep = _k.largest_segment_filter(group, lab[index], m)
        group, index = group[keep], index[keep]
    sel = pts[index]
    res = _k.fit_planes(
        sel, group, mxy, sigma_z=s_z, posterior=posterior, eq8_diagonal=eq8_diagonal, min_points=k
    )
    reason = res["reason"]
    if lab is not None:
        reason = np.where(enough_before & (reason == _k.TOO_FEW), _k.TOO_FEW_SEGMENT, reason)
    good = res["good"]
    n_pts = np.where(np.isnan(r_used), n_found, res["n_used"])
    if s_mode == "centroid":
        dist = res["distance"]
    else:
        dist = _k.nearest_used_distance(sel, group, mxy)
    sig_model = np.where(good, kappa * dist * dist / 6.0, np.nan)
    sig_plane = res["sigma_plane"]
    sig_block = np.where(good, block, np.nan)
    sigma = np.sqrt(sig_plane**2 + sig_block**2 + sig_model**2)
    return MapPointHeights(
        xy=mxy,
        height=res["height"],
        sigma=sigma,
        sigma_plane=sig_plane,
        sigma_block=sig_block,
        sigma_model=sig_model,
        n_points=n_pts.astype(np.int64),
        radius=r_used,
        distance=np.where(good, dist, np.nan),
        failed=~good,
        reason=np.asarray(reason, dtype=object),
    )


def _as_xy(xy: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(xy, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidPointsError(f"{name} must be numeric, got {type(xy).__name__}") from exc
    if arr.ndim == 2 and arr.shape[0] == 0:
        return np.empty((0, 2))
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise InvalidPointsError(f"{name} must have shape (M, 2) or (M, 3), got {arr.shape}")
    arr = np.ascontiguousarray(arr[:, :2])
    if not np.isfinite(arr).all():
        raise InvalidPointsError(f"{name} has rows with NaN or infinite x, y")
    return arr


# ------------------------------------------------------------------ TIN


@dataclass(frozen=True, eq=False)
class TinInterpolation:
    """Heights and σ interpolated in the TIN of the map points (one row per query point).

    Attributes
    ----------
    height, sigma : ndarray of shape (R,)
        Interpolated height and its σ (m); NaN outside the TIN.
    inside : ndarray of shape (R,) bool
        Inside a (non-degenerate) TIN triangle.
    vertices : ndarray of shape (R, 3) int64
        Indices of the three map points (-1 outside).
    weights : ndarray of shape (R, 3)
        Barycentric weights (NaN outside).
    has_tin : bool
        Whether a TIN could be built (>= 3 non-collinear vertices).
    """

    height: np.ndarray
    sigma: np.ndarray
    inside: np.ndarray
    vertices: np.ndarray
    weights: np.ndarray
    has_tin: bool = True

    def __post_init__(self) -> None:
        _freeze(self)


def interpolate_tin(
    vertices: Any, sigma: Any, query_xy: Any, *, correlation: float = 0.0, covariance: Any = None
) -> TinInterpolation:
    """Interpolate heights and precisions in a Delaunay TIN (:ref:`alg-heights`).

    Parameters
    ----------
    vertices : ndarray of shape (M, 3)
        TIN nodes x, y, height (m); all finite.
    sigma : ndarray of shape (M,)
        σ of each node height (m).
    query_xy : ndarray of shape (R, 2) or (R, 3)
        Points to interpolate at (z ignored).
    correlation : float in [0, 1], default 0
        Uniform correlation ρ between the three node heights (0: independent
        groups of laser points; 1: the same group).
    covariance : ndarray or scipy.sparse matrix of shape (M, M), optional
        Full covariance of the node heights (m²); replaces `sigma`/`correlation`.

    Returns
    -------
    TinInterpolation
        NaN and ``inside=False`` outside the TIN, in triangles of area < 1e-9 m²,
        and everywhere when no TIN can be built.
    """
    v = as_points(vertices, "vertices")
    s = np.asarray(sigma, dtype=np.float64).reshape(-1)
    if s.shape != (len(v),):
        raise InvalidPointsError(f"sigma must have shape ({len(v)},), got {s.shape}")
    q = _as_xy(query_xy, "query_xy")
    rho = check_range(correlation, "correlation", 0.0, 1.0)
    verts, w, has_tin = _k.triangulate_locate(v[:, :2], q)
    inside = verts[:, 0] >= 0
    height = np.full(len(q), np.nan)
    sig = np.full(len(q), np.nan)
    if inside.any():
        vi, wi = verts[inside], w[inside]
        height[inside] = np.sum(wi * v[vi, 2], axis=1)
        if covariance is not None:
            c = covariance
            if getattr(c, "shape", None) != (len(v), len(v)):
                raise InvalidPointsError(
                    f"covariance must have shape ({len(v)}, {len(v)}), "
                    f"got {getattr(c, 'shape', None)}"
                )
            rows = np.repeat(vi, 3, axis=1).ravel()
            cols = np.tile(vi, (1, 3)).ravel()
            sub = np.asarray(c[rows, cols], dtype=np.float64).reshape(-1, 3, 3)
            var = np.einsum("ri,rij,rj->r", wi, sub, wi)
        else:
            var = _k.tin_variance(wi, s[vi], rho)
        sig[inside] = np.sqrt(np.maximum(var, 0.0))
    return TinInterpolation(
        height=height, sigma=sig, inside=inside, vertices=verts, weights=w, has_tin=has_tin
    )


# ------------------------------------------------------------------ comparison


@dataclass(frozen=True, eq=False)
class WTestResult:
    """w-tests and iterative data snooping (:ref:`alg-heights`).

    Attributes
    ----------
    w : ndarray of shape (R,)
        w per reference point (NaN where no difference exists).
    outlier : ndarray of shape (R,) bool
        Flagged by data snooping.
    critical : float
        k = Φ⁻¹(1 − α₀/2).
    n_passes : int
        Passes of the data-snooping loop (0 when nothing was tested).
    offset : float
        Estimated common bias (m); 0 unless ``estimate_offset=True``.
    """

    w: np.ndarray
    outlier: np.ndarray
    critical: float
    n_passes: int
    offset: float

    def __post_init__(self) -> None:
        _freeze(self)

    @property
    def n_outliers(self) -> int:
        """Number of points flagged as outliers by the w-test."""
        return int(self.outlier.sum())

    def to_dict(self) -> dict[str, Any]:
        """``{"critical", "std", "std_without_outliers", "frac_lt1", "frac_lt2", "n_outliers"}``."""
        w = self.w[np.isfinite(self.w)]
        wo = self.w[np.isfinite(self.w) & ~self.outlier]
        n = w.size
        return {
            "critical": self.critical,
            "std": float(np.std(w, ddof=1)) if n > 1 else float("nan"),
            "std_without_outliers": float(np.std(wo, ddof=1)) if wo.size > 1 else float("nan"),
            "frac_lt1": float(np.mean(np.abs(w) < 1)) if n else float("nan"),
            "frac_lt2": float(np.mean(np.abs(w) < 2)) if n else float("nan"),
            "n_outliers": self.n_outliers,
        }


def w_test(
    dh: Any, sigma_dh: Any, *, alpha: float = 0.001, estimate_offset: bool = False
) -> WTestResult:
    """w_i = Δh_i/σ_Δh,i with iterative data snooping at level α₀ (:ref:`alg-heights`).

    Entries with a NaN Δh or σ are not tested (w NaN, never an outlier).

    Parameters
    ----------
    dh : ndarray of shape (R,)
        Height differences (m).
    sigma_dh : ndarray of shape (R,)
        Their predicted σ (m), > 0.
    alpha : float, default 0.001
        Significance level α₀ of each test.
    estimate_offset : bool, default False
        Re-estimate a common weighted-mean bias on each pass and use the
        redundancy-corrected residual σ (the paper does not).

    Examples
    --------
    >>> r = w_test([0.10, -0.05, 0.60, 0.02], [0.15] * 4)
    >>> r.outlier.tolist(), r.n_passes
    ([False, False, True, False], 2)
    """
    d = np.asarray(dh, dtype=np.float64).reshape(-1)
    s = np.asarray(sigma_dh, dtype=np.float64).reshape(-1)
    if s.size == 1 and d.size != 1:
        s = np.full(d.shape, float(s[0]))
    if s.shape != d.shape:
        raise InvalidPointsError(f"sigma_dh must have shape {d.shape}, got {s.shape}")
    ok = np.isfinite(d) & np.isfinite(s)
    if (s[ok] <= 0).any():
        raise InvalidPointsError("sigma_dh must be > 0")
    k = critical_value(alpha)
    w = np.full(d.shape, np.nan)
    outlier = np.zeros(d.shape, dtype=bool)
    wk, ok_out, passes, offset = _k.data_snooping(
        d[ok], s[ok], critical=k, estimate_offset=bool(estimate_offset)
    )
    w[ok] = wk
    outlier[ok] = ok_out
    return WTestResult(
        w=w,
        outlier=outlier,
        critical=k,
        n_passes=passes,
        offset=offset if ok.any() else float("nan"),
    )


@dataclass(frozen=True, eq=False)
class HeightComparison:
    """Model heights against reference heights (one row per reference point).

    Attributes
    ----------
    dh : ndarray of shape (R,)
        Δh = h_model − h_ref (m); NaN where no model height exists.
    sigma_dh : ndarray of shape (R,)
        √(σ_model² + σ_ref²) (m).
    n : int
        Differences compared.
    mean, std, rms, max_abs : float
        Of Δh (m); std with ddof = 1.
    sigma_model_empirical : float
        √(std² − σ_ref²) (m); NaN when std <= σ_ref.
    sigma_ref : float
        σ of the reference heights used (m).
    flags : tuple of str
        ``"sigma_model_empirical_undefined"`` when std <= σ_ref or n < 2.
    """

    dh: np.ndarray
    sigma_dh: np.ndarray
    n: int
    mean: float
    std: float
    rms: float
    max_abs: float
    sigma_model_empirical: float
    sigma_ref: float
    flags: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        _freeze(self)

    def to_dict(self) -> dict[str, Any]:
        """``{"n", "mean", "std", "rms", "max_abs", "sigma_model_empirical"}``."""
        return {
            "n": self.n,
            "mean": self.mean,
            "std": self.std,
            "rms": self.rms,
            "max_abs": self.max_abs,
            "sigma_model_empirical": self.sigma_model_empirical,
        }


def compare_heights(
    model_height: Any, model_sigma: Any, reference_z: Any, *, sigma_ref: float = SIGMA_REF
) -> HeightComparison:
    """Δh statistics of model against reference heights (:ref:`alg-heights`).

    Parameters
    ----------
    model_height, model_sigma : ndarray of shape (R,)
        Model height and its σ at the reference points (m); NaN = no model.
    reference_z : ndarray of shape (R,)
        Reference heights (m).
    sigma_ref : float, default 0.09
        σ of the reference heights (m).
    """
    h = np.asarray(model_height, dtype=np.float64).reshape(-1)
    sm = np.asarray(model_sigma, dtype=np.float64).reshape(-1)
    z = np.asarray(reference_z, dtype=np.float64).reshape(-1)
    if not (h.shape == sm.shape == z.shape):
        raise InvalidPointsError(
            f"model_height, model_sigma and reference_z must have the same "
            f"length, got {h.shape}, {sm.shape}, {z.shape}"
        )
    s_ref = check_positive(sigma_ref, "sigma_ref", allow_zero=True)
    dh = h - z
    sig = np.sqrt(sm * sm + s_ref * s_ref)
    ok = np.isfinite(dh) & np.isfinite(sig)
    d = dh[ok]
    n = int(d.size)
    std = float(np.std(d, ddof=1)) if n > 1 else float("nan")
    emp = empirical_model_sigma(std, s_ref)
    flags = () if np.isfinite(emp) else ("sigma_model_empirical_undefined",)
    return HeightComparison(
        dh=np.where(ok, dh, np.nan),
        sigma_dh=np.where(ok, sig, np.nan),
        n=n,
        mean=float(d.mean()) if n else float("nan"),
        std=std,
        rms=float(np.sqrt(np.mean(d * d))) if n else float("nan"),
        max_abs=float(np.abs(d).max()) if n else float("nan"),
        sigma_model_empirical=emp,
        sigma_ref=s_ref,
        flags=flags,
    )


# ------------------------------------------------------------------ the whole chain


@dataclass(frozen=True, eq=False)
class HeightReport:
    """Result of :func:`assess_heights`.

    Attributes
    ----------
    map_points : MapPointHeights
        Per map point: height, σ terms, failed flag and reason.
    reference_xyz : ndarray of shape (R, 3)
        Reference points (m).
    tin : TinInterpolation
        Model height and σ at the reference points, inside flag.
    comparison : HeightComparison
        Δh, σ_Δh per reference point and their statistics.
    w : WTestResult
        w and outlier flag per reference point.
    parameters : dict
        The options used.
    flags : tuple of str
        Conditions that left results undefined: ``"no_tin"`` (fewer than 3
        non-collinear fitted map points), ``"no_reference_points"``,
        ``"reference_outside_tin"``, ``"sigma_model_empirical_undefined"``,
        ``"map_points_failed"``.
    """

    map_points: MapPointHeights
    reference_xyz: np.ndarray
    tin: TinInterpolation
    comparison: HeightComparison
    w: WTestResult
    parameters: dict = field(default_factory=dict)
    flags: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _freeze(self)

    # per-reference-point conveniences
    @property
    def dh(self) -> np.ndarray:
        """Height differences, model (map) minus reference, in metres."""
        return self.comparison.dh

    @property
    def sigma_dh(self) -> np.ndarray:
        """Predicted standard deviation of each height difference, in metres."""
        return self.comparison.sigma_dh

    @property
    def w_values(self) -> np.ndarray:
        """The w-test statistic of each height difference (dimensionless)."""
        return self.w.w

    @property
    def outlier(self) -> np.ndarray:
        """True where the w-test rejects the height difference."""
        return self.w.outlier

    @property
    def inside(self) -> np.ndarray:
        """True where the reference point lies inside the TIN."""
        return self.tin.inside

    @property
    def n_outside(self) -> int:
        """Number of reference points outside the TIN."""
        return int((~self.tin.inside).sum())

    def to_dict(self) -> dict[str, Any]:
        """The ``results`` of ``lidarqa heights --json``: map_points, comparison, w."""
        return {
            "map_points": self.map_points.to_dict(),
            "comparison": self.comparison.to_dict(),
            "w": self.w.to_dict(),
        }


def assess_heights(
    points: Any,
    map_xy: Any,
    reference_xyz: Any,
    *,
    radius: float = RADIUS,
    max_radius: float = MAX_RADIUS,
    min_points: int = MIN_POINTS,
    growth: float | None = 2.0,
    sigma_point: float = SIGMA_POINT,
    sigma_gps: float = SIGMA_GPS,
    sigma_ins: float = SIGMA_INS,
    sigma_strip: float = SIGMA_STRIP,
    sigma_ref: float = SIGMA_REF,
    curvature: float = CURVATURE,
    s_mode: str = "centroid",
    correlation: float = 0.0,
    covariance: Any = None,
    alpha: float = 0.001,
    estimate_offset: bool = False,
    eq8_diagonal: bool = False,
    posterior: bool = False,
    largest_segment: bool = False,
    labels: Any = None,
) -> HeightReport:
    """Predict map point heights and precisions, and test them against reference points.

    Method: :ref:`alg-heights`.
    Map point heights come from :func:`map_point_heights`; the fitted map
    points form a Delaunay TIN in which heights and σ are interpolated to the
    reference points (:func:`interpolate_tin`); the differences are summarised
    (:func:`compare_heights`) and w-tested with data snooping (:func:`w_test`).
    Reference points outside the TIN get NaN and ``inside=False``; an empty
    reference set gives NaN statistics.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Laser points x, y, z (m).
    map_xy : ndarray of shape (M, 2) or (M, 3)
        Map points (z ignored).
    reference_xyz : ndarray of shape (R, 3)
        Reference points x, y, height (m); R may be 0.
    sigma_ref : float, default 0.09
        σ of the reference heights (m).
    correlation : float in [0, 1], default 0
        Correlation between TIN vertex heights. 0 fits map points whose
        neighbourhoods do not overlap (independent laser block errors), 1
        vertices fitted from the same laser points.
    covariance : ndarray or sparse matrix of shape (M, M), optional
        Full covariance of the map point heights (m²), replacing the σ's and
        `correlation` in the TIN.
    alpha : float, default 0.001
        Significance level of the w-tests (k = 3.29).
    estimate_offset : bool, default False
        See :func:`w_test`.
    **other
        As in :func:`map_point_heights`.

    Returns
    -------
    HeightReport
    """
    ref = as_points(reference_xyz, "reference_xyz")
    rho = check_range(correlation, "correlation", 0.0, 1.0)
    mp = map_point_heights(
        points,
        map_xy,
        radius=radius,
        max_radius=max_radius,
        min_points=min_points,
        growth=growth,
        sigma_point=sigma_point,
        sigma_gps=sigma_gps,
        sigma_ins=sigma_ins,
        sigma_strip=sigma_strip,
        curvature=curvature,
        s_mode=s_mode,
        eq8_diagonal=eq8_diagonal,
        posterior=posterior,
        largest_segment=largest_segment,
        labels=labels,
    )
    fitted = np.flatnonzero(~mp.failed)
    cov = None
    if covariance is not None:
        m = len(mp)
        if getattr(covariance, "shape", None) != (m, m):
            raise InvalidPointsError(
                f"covariance must have shape ({m}, {m}), got {getattr(covariance, 'shape', None)}"
            )
        cov = covariance[fitted][:, fitted]
    vertices = np.column_stack([mp.xy[fitted], mp.height[fitted]])
    tin = interpolate_tin(vertices, mp.sigma[fitted], ref[:, :2], correlation=rho, covariance=cov)
    # vertex indices back to map point numbering
    verts = np.full_like(tin.vertices, -1)
    found = tin.vertices >= 0
    verts[found] = fitted[tin.vertices[found]]
    tin = TinInterpolation(
        height=tin.height,
        sigma=tin.sigma,
        inside=tin.inside,
        vertices=verts,
        weights=tin.weights,
        has_tin=tin.has_tin,
    )
    return summarise_heights(
        mp, ref, tin, radius=radius, max_radius=max_radius, min_points=min_points,
        growth=growth, sigma_point=sigma_point, sigma_gps=sigma_gps, sigma_ins=sigma_ins,
        sigma_strip=sigma_strip, sigma_ref=sigma_ref, curvature=curvature, s_mode=s_mode,
        correlation=rho, covariance=covariance, alpha=alpha, estimate_offset=estimate_offset,
        eq8_diagonal=eq8_diagonal, posterior=posterior, largest_segment=largest_segment,
        labels=labels)


def summarise_heights(
    map_points: MapPointHeights, reference_xyz: Any, tin: TinInterpolation, **options: Any
) -> HeightReport:
    """The summary half of :func:`assess_heights`: Δh statistics, w-tests, flags, parameters.

    One in-memory run and a catalog run (whose regions give the map points and
    the TIN values at their reference points) both end here, so their figures
    come from the same code.

    Parameters
    ----------
    map_points : MapPointHeights
        Every map point's fit.
    reference_xyz : ndarray of shape (R, 3)
        Reference points (m).
    tin : TinInterpolation
        The map point TIN at the reference points.
    **options
        The options of :func:`assess_heights` (defaults where not given).

    Returns
    -------
    HeightReport
    """
    import inspect

    p = {k: v.default for k, v in inspect.signature(assess_heights).parameters.items()
         if v.default is not inspect.Parameter.empty}
    unknown = sorted(set(options) - set(p))
    if unknown:
        raise OptionError(f"unknown option(s): {', '.join(unknown)}")
    p.update(options)
    ref = as_points(reference_xyz, "reference_xyz")
    comp = compare_heights(tin.height, tin.sigma, ref[:, 2], sigma_ref=p["sigma_ref"])
    wt = w_test(comp.dh, comp.sigma_dh, alpha=p["alpha"], estimate_offset=p["estimate_offset"])
    flags: list[str] = []
    if not tin.has_tin:
        flags.append("no_tin")
    if len(ref) == 0:
        flags.append("no_reference_points")
    elif not tin.inside.all():
        flags.append("reference_outside_tin")
    flags.extend(comp.flags)
    if map_points.failed.any():
        flags.append("map_points_failed")
    params = {k: p[k] for k in ("radius", "max_radius", "min_points", "growth", "sigma_point",
                                "sigma_gps", "sigma_ins", "sigma_strip", "sigma_ref",
                                "curvature", "s_mode")}
    params.update(
        correlation=float(p["correlation"]), covariance=p["covariance"] is not None,
        alpha=p["alpha"], critical=critical_value(p["alpha"]),
        estimate_offset=bool(p["estimate_offset"]), eq8_diagonal=bool(p["eq8_diagonal"]),
        posterior=bool(p["posterior"]),
        largest_segment=bool(p["largest_segment"] or p["labels"] is not None))
    return HeightReport(map_points=map_points, reference_xyz=ref, tin=tin, comparison=comp,
                        w=wt, parameters=params, flags=tuple(flags))


# ------------------------------------------------------------------ map points from files


def densify_polygons(polygons: Any, *, spacing: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Map points on polygon boundaries: the vertices plus points so that no gap exceeds `spacing`.

    Every ring (exterior and holes) is segmentized (shapely) so that each edge
    is split into equal parts of at most `spacing`; the closing vertex of each
    ring and points shared by adjacent polygons (same x, y to 1 µm) appear once.

    Parameters
    ----------
    polygons : sequence of shapely Polygon/MultiPolygon
    spacing : float, default 10.0
        Largest distance between consecutive map points along a boundary (m).

    Returns
    -------
    xy : ndarray of shape (M, 2)
    polygon : ndarray of shape (M,) int64
        Index of the (first) polygon each map point comes from.
    """
    shapely = require("shapely", "vector")
    step = check_positive(spacing, "spacing")
    geoms = np.asarray(polygons, dtype=object).reshape(-1)
    if geoms.size == 0:
        return np.empty((0, 2)), np.empty(0, dtype=np.int64)
    bad = [g for g in geoms if g is not None and g.geom_type not in ("Polygon", "MultiPolygon")]
    if bad:
        raise InvalidPointsError(
            f"expected Polygon/MultiPolygon geometries, got {bad[0].geom_type}"
        )
    valid = np.array([g is not None and not g.is_empty for g in geoms])
    src = np.flatnonzero(valid)
    if src.size == 0:
        return np.empty((0, 2)), np.empty(0, dtype=np.int64)
    boundary = shapely.boundary(geoms[valid])
    rings, ring_src = shapely.get_parts(boundary, return_index=True)
    rings = shapely.segmentize(rings, step)
    coords, ring_of = shapely.get_coordinates(rings, return_index=True)
    last = np.ones(len(coords), dtype=bool)
    last[:-1] = ring_of[1:] != ring_of[:-1]
    closed = shapely.is_closed(rings)
    drop = last & closed[ring_of]
    xy = coords[~drop]
    poly = src[ring_src[ring_of[~drop]]]
    key = np.round(xy, 6)
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    return np.ascontiguousarray(xy[first]), poly[first].astype(np.int64)


def read_map_points(path: str | os.PathLike, *, spacing: float = 10.0, crs: Any = None) -> Any:
    """Read map points from a point list or derive them from polygons.

    CSV (``id,x,y[,z]``) and Point GeoPackage/GeoJSON files are read with
    :func:`lidarqa.io.vector.read_points`; Polygon/MultiPolygon layers are turned
    into boundary points every `spacing` metres by :func:`densify_polygons`
    (attribute ``polygon``: the source feature's id).

    `crs` (a pyproj CRS) is the CRS of a file that declares none.

    Returns
    -------
    lidarqa.io.vector.PointSet
        z is NaN (map heights come from the laser points).
    """
    from ..io.crs import resolve_crs
    from ..io.vector import PointSet, read_features, read_points

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".gpkg", ".geojson", ".json") and p.is_file() and p.stat().st_size > 0:
        pyogrio = require("pyogrio", "vector")
        try:
            info = pyogrio.read_info(str(p))
        except Exception as exc:
            raise ReadError(f"cannot read {p}: {exc}") from exc
        gtype = str(info.get("geometry_type") or "")
        if "polygon" in gtype.lower():
            map_crs, names, geoms, field_data = read_features(p)
            ids = (
                np.asarray(field_data[names.index("id")])
                if "id" in names
                else np.arange(len(geoms))
            )
            xy, poly = densify_polygons(geoms, spacing=spacing)
            xyz = np.column_stack([xy, np.full(len(xy), np.nan)])
            return PointSet(
                ids=np.arange(len(xy)),
                xyz=xyz,
                attributes={"polygon": ids[poly]},
                crs=resolve_crs(map_crs, crs, p),
            )
    return read_points(p, require_z=False, crs=crs)
