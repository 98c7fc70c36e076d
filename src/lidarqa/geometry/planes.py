"""Plane fitting: total least squares, explicit z, iterative rejection, RANSAC (:ref:`alg-planes`).

Every fit works in coordinates centred on the bounding-box middle of its points
(so UTM-sized coordinates lose no precision) and reports the plane as a unit
normal ``n`` (canonical sign: n_z >= 0, then n_x >= 0, then n_y >= 0) and offset
``rho`` with ``n · p = rho`` in the input frame.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._arrays import colmax, colmin
from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import DataQualityWarning, DegenerateGeometryError, EstimationError, OptionError

__all__ = [
    "PlaneFit",
    "IterativePlaneFit",
    "RansacPlane",
    "fit_plane",
    "fit_plane_iterative",
    "ransac",
    "canonical_normal",
    "plane_covariance",
]

_EPS = 1e-9


def canonical_normal(n: np.ndarray) -> np.ndarray:
    """Unit normal(s) flipped so that n_z >= 0 (if 0: n_x >= 0, then n_y >= 0); shape (..., 3)."""
    n = np.asarray(n, dtype=np.float64)
    zero_x = (n[..., 0] == 0) & (n[..., 1] < 0)
    flip = (n[..., 2] < 0) | ((n[..., 2] == 0) & ((n[..., 0] < 0) | zero_x))
    return np.where(flip[..., None], -n, n)


@dataclass(frozen=True, eq=False)
class PlaneFit:
    """A fitted plane ``normal · p = rho``.

    Attributes
    ----------
    normal : ndarray of shape (3,)
        Unit normal, canonical sign.
    rho : float
        Offset (m): ``normal · p = rho`` for points p on the plane.
    centroid : ndarray of shape (3,)
        Mean of the fitted points (m).
    n : int
        Number of fitted points.
    rmse : float
        RMS residual (m): orthogonal for ``"svd"``/``"eig"``, vertical for ``"explicit_z"``.
    sigma0 : float
        Residual standard deviation sqrt(Σr²/(n-3)) (m); NaN when n = 3.
    residuals : ndarray of shape (n,)
        Signed residuals (m) in the input order: ``normal · p - rho`` (orthogonal),
        or ``z - (a x + b y + c)`` (explicit z).
    covariance : ndarray of shape (4, 4)
        Covariance of (n_x, n_y, n_z, rho_c), where rho_c is the offset of the
        plane at its centroid (independent of the normal to first order); see
        :func:`plane_covariance` to propagate to a point.
    eigenvalues : ndarray of shape (3,)
        Eigenvalues (ascending, m²) of the point covariance about the centroid.
    method : str
        ``"svd"``, ``"eig"`` or ``"explicit_z"``.
    coefficients : ndarray of shape (3,) or None
        For ``"explicit_z"``: (a, b, c) of ``z = a x + b y + c``.
    coefficient_covariance : ndarray of shape (3, 3) or None
        For ``"explicit_z"``: covariance of (a, b, c).
    """

    normal: np.ndarray
    rho: float
    centroid: np.ndarray
    n: int
    rmse: float
    sigma0: float
    residuals: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    eigenvalues: np.ndarray = field(repr=False)
    method: str = "svd"
    coefficients: np.ndarray | None = None
    coefficient_covariance: np.ndarray | None = field(default=None, repr=False)

    @property
    def sigma_normal_deg(self) -> float:
        """Approximate standard deviation (degrees) of the normal direction."""
        v = float(np.trace(self.covariance[:3, :3]))
        return float(np.degrees(np.sqrt(max(v, 0.0))))

    @property
    def sigma_rho(self) -> float:
        """Standard deviation (m) of the plane position at its centroid."""
        return float(np.sqrt(max(self.covariance[3, 3], 0.0)))

    def distance(self, points: Any) -> np.ndarray:
        """Signed orthogonal distances (m) of `points` (N, 3) to the plane."""
        p = np.asarray(points, dtype=np.float64)
        return (p - self.centroid) @ self.normal + (self.normal @ self.centroid - self.rho)

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        d = {
            "normal": self.normal.tolist(),
            "rho": self.rho,
            "centroid": self.centroid.tolist(),
            "n": self.n,
            "rmse": self.rmse,
            "sigma0": self.sigma0,
            "sigma_rho": self.sigma_rho,
            "sigma_normal_deg": self.sigma_normal_deg,
            "method": self.method,
        }
        if self.coefficients is not None:
            d["coefficients"] = self.coefficients.tolist()
        return d


def plane_covariance(fit: PlaneFit, at: Any) -> np.ndarray:
    """Variance (m²) of the plane's position along its normal at point(s) `at` (..., 3).

    ``var = sigma_rho_c² + (x - c)ᵀ Σ_n (x - c)``: the centroid offset and the
    normal direction errors, which grow with the distance from the centroid.
    """
    d = np.asarray(at, dtype=np.float64) - fit.centroid
    sn = fit.covariance[:3, :3]
    return fit.covariance[3, 3] + np.einsum("...i,ij,...j->...", d, sn, d)


def _tls(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centroid, ascending eigenvalues (of the mean covariance), eigenvectors, centred points."""
    c = p.mean(axis=0)
    d = p - c
    cov = d.T @ d / len(p)
    w, v = np.linalg.eigh(cov)
    return c, w, v, d


def _check_rank(w: np.ndarray, d: np.ndarray) -> None:
    scale = float(np.max(np.abs(d))) if len(d) else 0.0
    if scale == 0.0 or w[2] <= (_EPS * scale) ** 2:
        raise DegenerateGeometryError("cannot fit a plane: all points are equal")
    if w[1] <= 1e-12 * w[2] or w[1] <= (_EPS * scale) ** 2:
        raise DegenerateGeometryError("cannot fit a plane: the points are collinear")


def _fit_orthogonal(p: np.ndarray, origin: np.ndarray, method: str) -> PlaneFit:
    c, w, v, d = _tls(p)
    _check_rank(w, d)
    if method == "svd":
        _, s, vt = np.linalg.svd(d, full_matrices=False)
        normal = vt[2]
        w = np.sort(s**2 / len(p))
        # the other two directions for the covariance
        v = vt[::-1].T
    else:
        normal = v[:, 0]
    normal = canonical_normal(normal / np.linalg.norm(normal))
    r = d @ normal
    n = len(p)
    rmse = float(np.sqrt(np.mean(r**2)))
    dof = n - 3
    s2 = float(r @ r / dof) if dof > 0 else np.nan
    cov = np.zeros((4, 4))
    if dof > 0:
        # Σ_n = σ² Σ_k v_k v_kᵀ / (S_k - S_3), S = scatter eigenvalues (n · covariance eigenvalues)
        big = n * w
        for k in (1, 2):
            vk = v[:, k]
            gap = big[k] - big[0]
            if gap > 0:
                cov[:3, :3] += s2 * np.outer(vk, vk) / gap
        cov[3, 3] = s2 / n
    centroid = c + origin
    return PlaneFit(normal=normal, rho=float(normal @ centroid), centroid=centroid, n=n, rmse=rmse,
                    sigma0=float(np.sqrt(s2)) if dof > 0 else float("nan"), residuals=r,
                    covariance=cov, eigenvalues=w, method=method)


def _fit_explicit_z(p: np.ndarray, origin: np.ndarray) -> PlaneFit:
    c = p.mean(axis=0)
    d = p - c
    a_mat = np.column_stack([d[:, 0], d[:, 1], np.ones(len(p))])
    sv = np.linalg.svd(a_mat[:, :2], compute_uv=False)
    scale = float(np.max(np.abs(d[:, :2]))) if len(d) else 0.0
    if scale == 0.0 or sv[-1] <= 1e-9 * max(sv[0], 1e-300) or sv[-1] <= _EPS * scale:
        raise DegenerateGeometryError(
            "explicit-z plane fit is rank-deficient: "
            "the points lie on a vertical line or plane in XY")
    coef, *_ = np.linalg.lstsq(a_mat, d[:, 2], rcond=None)
    r = d[:, 2] - a_mat @ coef
    n = len(p)
    dof = n - 3
    s2 = float(r @ r / dof) if dof > 0 else np.nan
    ata_inv = np.linalg.inv(a_mat.T @ a_mat)
    ccov = s2 * ata_inv if dof > 0 else np.zeros((3, 3))
    a, b, c0 = coef
    centroid = c + origin
    # back to the input frame: z = a x + b y + c with c = c0 + cz - a cx - b cy
    c_glob = c0 + centroid[2] - a * centroid[0] - b * centroid[1]
    j_c = np.array([-centroid[0], -centroid[1], 1.0])
    cov_glob = ccov.copy()
    cov_glob[2, :] = j_c @ ccov
    cov_glob[:, 2] = cov_glob[2, :]
    cov_glob[2, 2] = j_c @ ccov @ j_c
    v = np.array([-a, -b, 1.0])
    s = float(np.linalg.norm(v))
    normal = v / s
    dv = np.array([[-1.0, 0.0], [0.0, -1.0], [0.0, 0.0]])  # d(-a, -b, 1)/d(a, b)
    jac = (np.eye(3) - np.outer(normal, normal)) / s @ dv
    cov = np.zeros((4, 4))
    cov[:3, :3] = jac @ ccov[:2, :2] @ jac.T
    cov[3, 3] = normal[2] ** 2 * ccov[2, 2]
    plane_pt = centroid + np.array([0.0, 0.0, c0])
    _, w, _, _ = _tls(p)
    return PlaneFit(normal=normal, rho=float(normal @ plane_pt), centroid=centroid, n=n,
                    rmse=float(np.sqrt(np.mean(r**2))),
                    sigma0=float(np.sqrt(s2)) if dof > 0 else float("nan"), residuals=r,
                    covariance=cov, eigenvalues=w, method="explicit_z",
                    coefficients=np.array([a, b, c_glob]), coefficient_covariance=cov_glob)


def _origin(p: np.ndarray) -> np.ndarray:
    return (colmin(p) + colmax(p)) / 2.0


def fit_plane(points: Any, *, method: str = "svd") -> PlaneFit:
    """Fit a plane to 3-D points by total least squares or explicit z.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres; N >= 3, finite.
    method : {"svd", "eig", "explicit_z"}, default "svd"
        ``"svd"`` and ``"eig"``: orthogonal (total least squares) fit, through
        an SVD of the centred points or the eigen-decomposition of their
        covariance. ``"explicit_z"``: least squares ``z = a x + b y + c`` with
        vertical residuals ([S-FH] eq. 2-3); it cannot represent vertical planes.

    Returns
    -------
    PlaneFit
        Unit normal (n_z >= 0), offset ``rho`` (m), residuals, RMSE (m) and the
        covariance of the normal and of the offset at the centroid.

    Raises
    ------
    InvalidPointsError
        If `points` is not (N, 3) with N >= 3, or has NaN.
    DegenerateGeometryError
        If all points are equal or collinear, or (explicit z) vertical in XY.

    Examples
    --------
    >>> fit_plane(np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1.]])).normal
    array([0., 0., 1.])
    """
    p = as_points(points, min_points=3)
    check_choice(method, ("svd", "eig", "explicit_z"), "method")
    o = _origin(p)
    if method == "explicit_z":
        return _fit_explicit_z(p - o, o)
    return _fit_orthogonal(p - o, o, method)


@dataclass(frozen=True, eq=False)
class IterativePlaneFit:
    """Result of :func:`fit_plane_iterative`.

    Attributes
    ----------
    plane : PlaneFit
        The final fit on the inliers.
    inliers : ndarray of shape (N,), bool
        Points kept (input order).
    n_iter : int
        Number of rejections made.
    converged : bool
        True if the RMSE reached `rmse_max` within the limits.
    reason : str
        Empty when converged, else why the iteration stopped.
    """

    plane: PlaneFit
    inliers: np.ndarray = field(repr=False)
    n_iter: int
    converged: bool
    reason: str = ""

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the segment's plane."""
        return self.plane.normal

    @property
    def rho(self) -> float:
        """Offset of the segment's plane (``normal · p = rho``), in metres."""
        return self.plane.rho

    @property
    def rmse(self) -> float:
        """RMS distance of the segment's points to its plane, in metres."""
        return self.plane.rmse

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {**self.plane.to_dict(), "n_iter": self.n_iter, "converged": self.converged,
                "reason": self.reason, "n_inliers": int(self.inliers.sum())}


def fit_plane_iterative(
    points: Any,
    *,
    rmse_max: float = 0.01,
    min_points: int = 3,
    model: str = "orthogonal",
    max_reject_frac: float = 0.5,
) -> IterativePlaneFit:
    """Fit a plane, dropping the worst point until the RMSE is small enough ([S-FH] §2.1).

    While RMSE > `rmse_max`, the point with the largest absolute residual is
    dropped (ties: the smaller canonical index first) and the plane refitted.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres, N >= 3.
    rmse_max : float, default 0.01
        Target RMS residual (m).
    min_points : int, default 3
        The iteration stops (not converged) rather than leave fewer points.
    model : {"orthogonal", "explicit_z"}, default "orthogonal"
        Total least squares, or z = a x + b y + c with vertical residuals.
    max_reject_frac : float, default 0.5
        The iteration stops (not converged) rather than drop more than this
        fraction of the points.

    Returns
    -------
    IterativePlaneFit
        Final plane, inlier mask, number of rejections, convergence flag and reason.

    Warns
    -----
    DataQualityWarning
        With fewer than 20 points ([S-FH] used at least 20 per plane).

    Examples
    --------
    >>> pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [.5, .5, 0], [.5, .2, 1.]])
    >>> import warnings; warnings.simplefilter("ignore")
    >>> r = fit_plane_iterative(pts)
    >>> r.n_iter, r.plane.normal.tolist(), r.plane.rmse
    (1, [0.0, 0.0, 1.0], 0.0)
    """
    p = as_points(points, min_points=3)
    rmse_max = check_positive(rmse_max, "rmse_max", allow_zero=True)
    check_choice(model, ("orthogonal", "explicit_z"), "model")
    max_reject_frac = check_range(max_reject_frac, "max_reject_frac", 0.0, 1.0)
    if int(min_points) != min_points or min_points < 3:
        raise OptionError(f"min_points must be an integer >= 3, got {min_points!r}")
    n = len(p)
    if n < 20:
        warnings.warn(f"fitting a plane to {n} points; at least 20 are recommended",
                      DataQualityWarning, stacklevel=2)
    method = "svd" if model == "orthogonal" else "explicit_z"
    # canonical order so ties do not depend on the input order
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))
    keep = np.ones(n, dtype=bool)
    o = _origin(p)
    q = p - o
    n_iter = 0
    reason = ""
    tol = rmse_max + 1e-12 * max(1.0, rmse_max)
    while True:
        idx = order[keep[order]]
        fit = (_fit_explicit_z(q[idx], o) if method == "explicit_z"
               else _fit_orthogonal(q[idx], o, method))
        if fit.rmse <= tol:
            converged = True
            break
        if len(idx) - 1 < min_points:
            converged, reason = False, f"fewer than min_points={min_points} points would remain"
            break
        if (n_iter + 1) > max_reject_frac * n:
            converged = False
            reason = f"more than max_reject_frac={max_reject_frac} of the points rejected"
            break
        worst = int(np.argmax(np.abs(fit.residuals)))  # first max = smaller canonical index
        keep[idx[worst]] = False
        n_iter += 1
    inl = np.zeros(n, dtype=bool)
    inl[idx] = True
    # residuals back in input order of the kept points
    fit_final = _reorder(fit, idx)
    return IterativePlaneFit(plane=fit_final, inliers=inl, n_iter=n_iter, converged=converged,
                             reason=reason)


def _reorder(fit: PlaneFit, idx: np.ndarray) -> PlaneFit:
    """The same fit with residuals listed in ascending input index."""
    srt = np.argsort(idx, kind="stable")
    from dataclasses import replace

    return replace(fit, residuals=fit.residuals[srt])


@dataclass(frozen=True, eq=False)
class RansacPlane:
    """Result of :func:`ransac`: the refined plane and its inliers (input order)."""

    plane: PlaneFit
    inliers: np.ndarray = field(repr=False)
    n_trials: int

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {**self.plane.to_dict(), "n_inliers": int(self.inliers.sum()),
                "n_trials": self.n_trials}


def ransac(
    points: Any,
    *,
    residual_threshold: float = 0.05,
    max_trials: int = 1000,
    min_inliers: int = 3,
    confidence: float = 0.999,
    refine: int = 3,
    seed: int = 0,
) -> RansacPlane:
    """Fit one plane robustly: three-point RANSAC, then total-least-squares refinement.

    Hypotheses are drawn in batches (vectorised) from a canonical ordering of the
    points with ``numpy.random.default_rng(seed)``, so the result does not depend
    on the input order. The best hypothesis (most inliers within
    `residual_threshold`) is refitted by total least squares on its inliers, and
    the inliers recomputed, `refine` times.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres, N >= 3.
    residual_threshold : float, default 0.05
        Inlier distance (m) to the plane.
    max_trials : int, default 1000
        Upper bound on hypotheses; fewer are drawn once `confidence` is reached.
    min_inliers : int, default 3
        Fail with :class:`EstimationError` if the best plane has fewer inliers.
    confidence : float, default 0.999
        Probability of having drawn one all-inlier sample, for early stopping.
    refine : int, default 3
        Refit / re-select rounds after the RANSAC stage.
    seed : int, default 0
        Random seed.

    Returns
    -------
    RansacPlane
        Refined plane, inlier mask and number of hypotheses tried.

    Raises
    ------
    DegenerateGeometryError
        If the points are all equal or collinear.
    EstimationError
        If no plane has `min_inliers` inliers.
    """
    p = as_points(points, min_points=3)
    thr = check_positive(residual_threshold, "residual_threshold")
    confidence = check_range(confidence, "confidence", 0.0, 1.0, hi_open=True)
    n = len(p)
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))
    o = _origin(p)
    q = (p - o)[order]
    _, w, _, d = _tls(q)
    _check_rank(w, d)
    rng = np.random.default_rng(seed)
    best_count = -1
    best = None
    tried = 0
    needed = int(max_trials)
    batch = 64
    tol = thr + 1e-12 * max(1.0, thr)
    while tried < min(needed, max_trials):
        m = min(batch, max_trials - tried)
        tri = rng.integers(0, n, size=(m, 3))
        a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
        nrm = np.cross(b - a, c - a)
        ln = np.linalg.norm(nrm, axis=1)
        good = ln > 1e-12
        tried += m
        if not good.any():
            continue
        nrm = nrm[good] / ln[good, None]
        rho = np.einsum("ij,ij->i", nrm, a[good])
        counts = (np.abs(q @ nrm.T - rho) <= tol).sum(axis=0)
        j = int(np.argmax(counts))
        if counts[j] > best_count:
            best_count = int(counts[j])
            best = (nrm[j], rho[j])
            frac = best_count / n
            if frac >= 1.0:
                needed = tried
            elif frac > 0:
                needed = int(np.ceil(np.log(1 - confidence) / np.log(1 - frac**3)))
    if best is None or best_count < max(min_inliers, 3):
        raise EstimationError(f"RANSAC found no plane with {min_inliers} inliers within {thr} m")
    inl = np.abs(q @ best[0] - best[1]) <= tol
    fit = None
    for _ in range(max(1, int(refine))):
        if inl.sum() < 3:
            break
        try:
            fit = _fit_orthogonal(q[inl], np.zeros(3), "svd")
        except DegenerateGeometryError:
            break
        new = np.abs(fit.distance(q)) <= tol
        if np.array_equal(new, inl):
            break
        inl = new
    if fit is None or inl.sum() < max(min_inliers, 3):
        raise EstimationError(f"RANSAC found no plane with {min_inliers} inliers within {thr} m")
    mask = np.zeros(n, dtype=bool)
    mask[order[inl]] = True
    final = fit_plane(p[mask])
    return RansacPlane(plane=final, inliers=mask, n_trials=tried)
