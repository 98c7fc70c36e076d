"""Least-squares coordinate transformations between two sets of common points.

Four models map *source* coordinates (e.g. corners measured in a point cloud)
onto *target* coordinates (e.g. total-station check points):

``"none"``
    No transformation; residuals are the raw coordinate differences.
``"similarity2d"``
    2D similarity plus a height shift (Fang & Huang eq. 6, :ref:`alg-transforms`)::

        x2 = a*x1 - b*y1 + c,   y2 = b*x1 + a*y1 + d,   z2 = z1 + e

    Needs >= 2 points not coincident in XY. Scale = sqrt(a²+b²), rotation = atan2(b, a).
``"helmert"``
    3D similarity (7-parameter Helmert) ``X2 = t + s·R·X1`` (:ref:`alg-transforms`).
    Needs >= 3 non-collinear points.
``"helmert-fixed-scale"``
    The same with s = 1 (6-parameter rigid-body transformation).

Parameters surveyors can read
-----------------------------
Rotations and scale about the coordinate origin make the translation of a
national grid (x ≈ 10⁵–10⁶ m) absorb ``(s·R - I)·X̄``: a rotation of a few
thousandths of a degree moves it by metres and its σ is metres too. So the
reported translations ``tx, ty, tz`` are taken **about the centroid of the
source control points** ``X0`` (the Molodensky–Badekas form)::

    X2 = X0 + T + s·R·(X1 - X0)

``T`` is then the shift of the control-point centroid, close to the mean
coordinate difference, and its σ is about σ0/√n (centimetres for a cm-level
survey). ``X0`` is reported as ``origin_x, origin_y, origin_z``. Rotation
angles and scale are the same in both forms. The 2D similarity likewise
reports ``tx, ty`` about the centroid (``tz = e``) next to the paper's
``a, b, c, d, e``, whose ``c, d`` are taken at the coordinate origin.
``TransformFit.translation`` and :meth:`TransformFit.apply` use the
translation at the coordinate origin.

Estimation is by ordinary least squares in the Gauss-Markov model: the target
coordinates are the observations, all with the same (unknown) variance σ0², the
source coordinates are taken as error-free. The Helmert estimate starts from the
closed-form Horn/Umeyama solution and is refined by Gauss-Newton, whose final
design matrix gives the parameter covariance ``σ0²·(AᵀA)⁻¹`` (linearised at the
solution). Every computation is done in centred coordinates (:ref:`alg-conventions`),
so UTM-sized coordinates lose no precision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import as_points, check_choice
from ..errors import DegenerateGeometryError, EstimationError, InvalidPointsError

__all__ = [
    "TRANSFORMS",
    "EPS",
    "TransformFit",
    "estimate_transform",
    "fit_similarity2d",
    "fit_helmert",
    "rotation_matrix",
    "euler_angles",
]

#: The transformation models accepted by :func:`estimate_transform`.
TRANSFORMS = ("none", "similarity2d", "helmert", "helmert-fixed-scale")

#: Tolerance of the conventions (docs: Algorithms, Conventions) (m, or dimensionless for ratios).
EPS = 1e-9


@dataclass(frozen=True)
class TransformFit:
    """A transformation estimated from common points, with its precision.

    Attributes
    ----------
    name : str
        One of :data:`TRANSFORMS`.
    params : dict of str to float
        Estimated parameters. ``similarity2d``: ``a, b, c, d, e`` (c, d, e in m;
        c, d at the coordinate origin), the derived ``scale`` and
        ``rotation_deg``, and ``tx, ty, tz`` (m), the shift about the centroid
        `origin`. ``helmert``: ``tx, ty, tz`` (m, about the centroid `origin`),
        ``omega_deg, phi_deg, kappa_deg`` (R = R_z(κ)·R_y(φ)·R_x(ω)) and
        ``scale``. ``none``: empty.
    sigmas : dict of str to float
        Standard deviation of each parameter (same keys and units), from the
        full covariance matrix scaled by the a-posteriori σ0². NaN without
        redundancy; 0 for a fixed parameter (the scale of ``helmert-fixed-scale``).
    sigma0 : float
        A-posteriori standard deviation of unit weight, sqrt(vᵀv / dof) (m):
        the estimated standard deviation of one target coordinate. NaN if dof = 0.
    dof : int
        Redundancy: number of observations minus number of parameters.
    n_points : int
        Number of common points used.
    param_names : tuple of str
        Order of the estimated (not derived) parameters in `covariance`.
    covariance : ndarray of shape (u, u)
        Covariance of the estimated parameters (angles in degrees).
    residuals : ndarray of shape (n_points, 3)
        Transformed source minus target (m), per point, in input order.
    rotation : ndarray of shape (3, 3)
        Rotation part of the model (identity for ``none``).
    translation : ndarray of shape (3,)
        Translation part (m).
    scale : float
        Scale factor (1 for ``none`` and ``helmert-fixed-scale``).
    linear : ndarray of shape (3, 3)
        Linear part: target = linear @ source + translation (for
        ``similarity2d`` z is shifted, not scaled).
    origin : ndarray of shape (3,)
        Centroid of the source control points (m): the point about which
        ``tx, ty, tz`` are given (zeros for ``none``).
    sigma0_h, sigma0_v : float
        ``similarity2d`` only: separate σ0 of the horizontal (dof 2n-4) and
        vertical (dof n-1) adjustments, which are independent; the parameter
        sigmas use them. NaN for the other models.
    notes : tuple of str
        Remarks such as "no redundancy: sigmas are undefined".
    """

    name: str
    params: dict[str, float]
    sigmas: dict[str, float]
    sigma0: float
    dof: int
    n_points: int
    param_names: tuple[str, ...]
    covariance: np.ndarray
    residuals: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    linear: np.ndarray
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sigma0_h: float = math.nan
    sigma0_v: float = math.nan
    notes: tuple[str, ...] = field(default_factory=tuple)

    def apply(self, points: Any) -> np.ndarray:
        """Transform ``(N, 3)`` source coordinates into the target frame (m).

        Parameters
        ----------
        points : ndarray of shape (N, 3)

        Returns
        -------
        ndarray of shape (N, 3)
        """
        pts = as_points(points, "points")
        return self.translation + pts @ self.linear.T

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: ``name``, ``params``, ``sigmas``, ``sigma0``, ``dof``, ..."""
        out: dict[str, Any] = {
            "name": self.name,
            "params": dict(self.params),
            "sigmas": dict(self.sigmas),
            "sigma0": self.sigma0,
            "dof": self.dof,
            "n_points": self.n_points,
        }
        if self.name != "none":
            out["origin"] = dict(zip(("x", "y", "z"), map(float, self.origin), strict=True))
            out["translation_at_coordinate_origin"] = [float(v) for v in self.translation]
        if self.name == "similarity2d":
            out["sigma0_h"] = self.sigma0_h
            out["sigma0_v"] = self.sigma0_v
        if self.name.startswith("helmert"):
            out["rotation_matrix"] = self.rotation.tolist()
        if self.notes:
            out["notes"] = list(self.notes)
        return out


# ----------------------------------------------------------------- rotations


def rotation_matrix(omega_deg: float, phi_deg: float, kappa_deg: float) -> np.ndarray:
    """Rotation ``R = R_z(κ)·R_y(φ)·R_x(ω)`` from angles in degrees.

    Parameters
    ----------
    omega_deg, phi_deg, kappa_deg : float
        Rotation angles about x, y and z (degrees).

    Returns
    -------
    ndarray of shape (3, 3)

    Examples
    --------
    >>> np.round(rotation_matrix(10.0, 0.0, 30.0)[0], 6)
    array([ 0.866025, -0.492404,  0.086824])
    """
    o, p, k = np.radians([omega_deg, phi_deg, kappa_deg])
    rx = np.array([[1, 0, 0], [0, math.cos(o), -math.sin(o)], [0, math.sin(o), math.cos(o)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(k), -math.sin(k), 0], [math.sin(k), math.cos(k), 0], [0, 0, 1]])
    return rz @ ry @ rx


def euler_angles(rotation: np.ndarray) -> tuple[float, float, float]:
    """Angles ``(ω, φ, κ)`` in degrees with ``R = R_z(κ)·R_y(φ)·R_x(ω)``; φ in [-90, 90]."""
    r = np.asarray(rotation, dtype=np.float64)
    phi = -math.asin(max(-1.0, min(1.0, float(r[2, 0]))))
    omega = math.atan2(float(r[2, 1]), float(r[2, 2]))
    kappa = math.atan2(float(r[1, 0]), float(r[0, 0]))
    return math.degrees(omega), math.degrees(phi), math.degrees(kappa)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _expm_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation by the rotation vector `w` (radians)."""
    theta = float(np.linalg.norm(w))
    k = _skew(w)
    if theta < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + math.sin(theta) / theta * k + (1 - math.cos(theta)) / theta**2 * (k @ k)


# ------------------------------------------------------------------ helpers


def _validate_pair(source: Any, target: Any) -> tuple[np.ndarray, np.ndarray]:
    src = as_points(source, "source")
    tgt = as_points(target, "target")
    if src.shape != tgt.shape:
        raise InvalidPointsError(
            "source and target must hold the same number of common points, "
            f"got {len(src)} and {len(tgt)}"
        )
    return src, tgt


def _sigma(cov: np.ndarray) -> np.ndarray:
    d = np.diag(cov).copy()
    d[d < 0] = 0.0  # round-off
    return np.sqrt(d)


def _safe_inv(n: np.ndarray, what: str) -> np.ndarray:
    try:
        cond = np.linalg.cond(n)
    except np.linalg.LinAlgError:
        cond = np.inf
    if not np.isfinite(cond) or cond > 1e14:
        raise DegenerateGeometryError(
            f"{what}: the normal equations are singular (condition {cond:.3g})"
        )
    return np.linalg.inv(n)


# -------------------------------------------------------------- similarity2d


def fit_similarity2d(source: Any, target: Any) -> TransformFit:
    """2D similarity + height shift by least squares (Fang & Huang eq. 6).

    Parameters
    ----------
    source, target : ndarray of shape (n, 3)
        Common points in the source and target frames (m), row i of one
        matching row i of the other. n >= 2, not all coincident in XY.

    Returns
    -------
    TransformFit
        Parameters ``a, b, c, d, e`` (+ ``scale``, ``rotation_deg``), their
        standard deviations, σ0 and the residuals.

    Raises
    ------
    DegenerateGeometryError
        Fewer than 2 points, or all source points coincident in XY.
    InvalidPointsError
        Shape mismatch, NaN or infinite coordinates.

    Notes
    -----
    Closed form with centred coordinates (:ref:`alg-transforms`): with
    S = Σ(x1'²+y1'²), a = Σ(x1'x2'+y1'y2')/S, b = Σ(x1'y2'-y1'x2')/S,
    c = x̄2 - a·x̄1 + b·ȳ1, d = ȳ2 - b·x̄1 - a·ȳ1, e = mean(z2-z1). This is the
    least-squares solution of the linear model; its normal matrix in centred
    coordinates is diag(S, S, n, n), which gives the covariance (propagated to
    the original origin for c and d). Horizontal and vertical parts are
    independent adjustments with their own σ0 (``sigma0_h`` with 2n-4 degrees of
    freedom, ``sigma0_v`` with n-1); ``sigma0`` pools both (3n-5).

    Examples
    --------
    >>> fit = fit_similarity2d([[0, 0, 0], [10, 0, 1]], [[5, -3, 1.5], [5, 17, 2.5]])
    >>> [round(fit.params[k], 12) for k in "abcde"]
    [0.0, 2.0, 5.0, -3.0, 1.5]
    """
    src, tgt = _validate_pair(source, target)
    n = len(src)
    if n < 2:
        raise DegenerateGeometryError(f"similarity2d needs at least 2 common points, got {n}")
    m1 = src.mean(axis=0)
    m2 = tgt.mean(axis=0)
    p1 = src - m1
    p2 = tgt - m2
    s_xy = float(np.sum(p1[:, 0] ** 2 + p1[:, 1] ** 2))
    if s_xy <= EPS:
        raise DegenerateGeometryError(
            "similarity2d: the source points coincide in XY (S = Σ(x'²+y'²) <= 1e-9 m²), "
            "so scale and rotation are undefined"
        )
    a = float(np.sum(p1[:, 0] * p2[:, 0] + p1[:, 1] * p2[:, 1]) / s_xy)
    b = float(np.sum(p1[:, 0] * p2[:, 1] - p1[:, 1] * p2[:, 0]) / s_xy)
    c = float(m2[0] - a * m1[0] + b * m1[1])
    d = float(m2[1] - b * m1[0] - a * m1[1])
    e = float(np.mean(tgt[:, 2] - src[:, 2]))

    # residuals (model - target) in centred coordinates (no cancellation)
    fx = a * p1[:, 0] - b * p1[:, 1]
    fy = b * p1[:, 0] + a * p1[:, 1]
    res = np.column_stack([fx - p2[:, 0], fy - p2[:, 1], (src[:, 2] + e) - tgt[:, 2]])
    vv_h = float(np.sum(res[:, :2] ** 2))
    vv_v = float(np.sum(res[:, 2] ** 2))
    dof_h, dof_v = 2 * n - 4, n - 1
    dof = 3 * n - 5
    notes = []
    s0_h = math.sqrt(vv_h / dof_h) if dof_h > 0 else math.nan
    s0_v = math.sqrt(vv_v / dof_v) if dof_v > 0 else math.nan
    s0 = math.sqrt((vv_h + vv_v) / dof) if dof > 0 else math.nan
    if dof_h <= 0:
        notes.append(
            "2 points determine a, b, c, d exactly: no horizontal redundancy, "
            "their sigmas are undefined"
        )

    # covariance: centred parameters (a, b, c', d') have normal matrix diag(S, S, n, n)
    q_c = np.diag([1.0 / s_xy, 1.0 / s_xy, 1.0 / n, 1.0 / n])
    # c = c' - a*x̄1 + b*ȳ1 (c' = x̄2 in the centred model), d = d' - b*x̄1 - a*ȳ1
    j = np.array(
        [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [-m1[0], m1[1], 1.0, 0.0],
            [-m1[1], -m1[0], 0.0, 1.0],
        ]
    )
    cov = np.zeros((5, 5))
    cov[:4, :4] = (s0_h**2 if dof_h > 0 else math.nan) * (j @ q_c @ j.T)
    cov[4, 4] = (s0_v**2 if dof_v > 0 else math.nan) / n
    sig = _sigma(cov) if dof_h > 0 else np.concatenate([np.full(4, np.nan), _sigma(cov[4:, 4:])])
    scale = math.hypot(a, b)
    rot = math.degrees(math.atan2(b, a))
    # derived: scale and rotation (first-order propagation from a, b)
    jd = np.array(
        [[a / scale, b / scale], [-b / scale**2 * 180 / math.pi, a / scale**2 * 180 / math.pi]]
    )
    cov_d = jd @ cov[:2, :2] @ jd.T
    sig_d = _sigma(cov_d) if dof_h > 0 else np.full(2, np.nan)
    names = ("a", "b", "c", "d", "e")
    params = dict(zip(names, (a, b, c, d, e), strict=True)) | {"scale": scale, "rotation_deg": rot}
    sigmas = {k: float(v) for k, v in zip(names, sig, strict=True)}
    sigmas |= {"scale": float(sig_d[0]), "rotation_deg": float(sig_d[1])}
    # about the centroid X0 of the source points: x2 = x0 + tx + a(x1-x0) - b(y1-y0), ...
    # tx = x̄2 - x̄1 (the centred model's shift is zero at the LS solution), σ = σ0_h/√n
    params |= {"tx": float(m2[0] - m1[0]), "ty": float(m2[1] - m1[1]), "tz": e}
    s_t = math.sqrt(s0_h**2 / n) if dof_h > 0 else math.nan
    sigmas |= {"tx": s_t, "ty": s_t, "tz": float(sig[4])}
    rotation = np.array(
        [[a / scale, -b / scale, 0.0], [b / scale, a / scale, 0.0], [0.0, 0.0, 1.0]]
    )
    return TransformFit(
        name="similarity2d",
        params=params,
        sigmas=sigmas,
        sigma0=s0,
        dof=dof,
        n_points=n,
        param_names=names,
        covariance=cov,
        residuals=res,
        rotation=rotation,
        translation=np.array([c, d, e]),
        scale=scale,
        linear=np.array([[a, -b, 0.0], [b, a, 0.0], [0.0, 0.0, 1.0]]),
        origin=m1.copy(),
        sigma0_h=s0_h,
        sigma0_v=s0_v,
        notes=tuple(notes),
    )


# ------------------------------------------------------------------- helmert


def _umeyama(p1: np.ndarray, p2: np.ndarray, fix_scale: bool) -> tuple[np.ndarray, float]:
    h = p1.T @ p2
    u, sv, vt = np.linalg.svd(h)
    v = vt.T
    dd = np.ones(3)
    dd[2] = np.sign(np.linalg.det(v @ u.T)) or 1.0
    r = v @ np.diag(dd) @ u.T
    s = 1.0 if fix_scale else float(np.sum(sv * dd) / np.sum(p1**2))
    return r, s


def fit_helmert(
    source: Any, target: Any, *, fix_scale: bool = False, max_iter: int = 20
) -> TransformFit:
    """3D Helmert transformation ``X2 = t + s·R·X1`` by least squares.

    Parameters
    ----------
    source, target : ndarray of shape (n, 3)
        Common points (m); n >= 3, not collinear.
    fix_scale : bool, default False
        Fix s = 1 (6 parameters: rigid-body motion).
    max_iter : int, default 20
        Gauss-Newton iterations at most (the closed-form start is already the
        least-squares solution, so one or two iterations normally suffice).

    Returns
    -------
    TransformFit
        ``tx, ty, tz`` (m, the shift of the source centroid ``origin``:
        ``X2 = X0 + T + s·R·(X1 - X0)``), ``omega_deg, phi_deg, kappa_deg`` with
        R = R_z(κ)·R_y(φ)·R_x(ω), ``scale``; their sigmas, σ0 and residuals.
        ``translation`` is the equivalent shift at the coordinate origin.

    Raises
    ------
    DegenerateGeometryError
        Fewer than 3 points, or collinear source points (second singular value
        of the centred source <= 1e-9 × the first), or target points collapsing
        to one point (scale <= 1e-9).
    EstimationError
        If Gauss-Newton does not converge.

    Notes
    -----
    Start: Horn/Umeyama (:ref:`alg-transforms`). Refinement: Gauss-Newton on the
    centred model ``X2' = s·R·X1' + t'`` with R updated multiplicatively,
    R ← exp([δ]×)·R, so the design matrix rows are ``[I, -s[R·x1']×, R·x1']``.
    The covariance of (t', δ, s) is σ0²(AᵀA)⁻¹ with σ0² = vᵀv/(3n-u); it is
    propagated to (T, ω, φ, κ, s) with T = X̄2 + t' - X̄1 (the shift about the
    centroid) and a numerical Jacobian of the Euler angles. Near φ = ±90°
    (gimbal lock) ω and κ sigmas are unreliable; a note says so.
    """
    src, tgt = _validate_pair(source, target)
    n = len(src)
    name = "helmert-fixed-scale" if fix_scale else "helmert"
    if n < 3:
        raise DegenerateGeometryError(
            f"{name} needs at least 3 non-collinear common points, got {n}"
        )
    m1 = src.mean(axis=0)
    m2 = tgt.mean(axis=0)
    p1 = src - m1
    p2 = tgt - m2
    sv1 = np.linalg.svd(p1, compute_uv=False)
    if sv1[0] <= EPS or sv1[1] <= EPS * sv1[0]:
        raise DegenerateGeometryError(
            f"{name}: the {n} source points are collinear (or coincide), so the rotation about "
            "their line is undefined; use at least 3 non-collinear points"
        )
    r, s = _umeyama(p1, p2, fix_scale)
    if s <= EPS:
        raise DegenerateGeometryError(f"{name}: the target points coincide, the scale is zero")
    t = np.zeros(3)
    u = 6 if fix_scale else 7
    converged = False
    for _ in range(max_iter):
        rp = p1 @ r.T
        v = p2 - (s * rp + t)  # observed - computed
        a_mat = _helmert_design(rp, s, fix_scale)
        dx, *_ = np.linalg.lstsq(a_mat, v.reshape(-1), rcond=None)
        t = t + dx[:3]
        r = _expm_so3(dx[3:6]) @ r
        if not fix_scale:
            s = s + dx[6]
        step = float(np.max(np.abs(dx[:3]))) / max(1.0, float(np.abs(p2).max()))
        if step < 1e-12 and float(np.max(np.abs(dx[3:]))) < 1e-12:
            converged = True
            break
    if not converged:
        raise EstimationError(f"{name}: Gauss-Newton did not converge in {max_iter} iterations")
    # re-orthonormalise R (drift from the updates)
    uu, _, vvt = np.linalg.svd(r)
    r = uu @ vvt
    rp = p1 @ r.T
    fitted = s * rp + t
    res = fitted - p2  # model - target
    a_mat = _helmert_design(rp, s, fix_scale)
    dof = 3 * n - u
    vv = float(np.sum(res**2))
    s0 = math.sqrt(vv / dof) if dof > 0 else math.nan
    q = _safe_inv(a_mat.T @ a_mat, name)
    cov_int = (s0**2 if dof > 0 else math.nan) * q

    # propagate (t', δ, s) -> (tx, ty, tz, ω, φ, κ, s)
    rm1 = r @ m1
    translation = m2 + t - s * rm1
    angles = np.array(euler_angles(r))
    j_e = np.zeros((3, 3))
    h = 1e-7
    for k in range(3):
        dv = np.zeros(3)
        dv[k] = h
        diff = np.array(euler_angles(_expm_so3(dv) @ r)) - angles
        diff = (diff + 180.0) % 360.0 - 180.0
        j_e[:, k] = diff / h
    # about the centroid X0 = X̄1 (Molodensky-Badekas): X2 = X0 + T + s·R·(X1 - X0),
    # T = X̄2 + t' - X̄1 depends on t' only, so its sigma is that of the centred shift
    shift = m2 + t - m1
    j = np.zeros((7, u))
    j[:3, :3] = np.eye(3)
    j[3:6, 3:6] = j_e
    if not fix_scale:
        j[6, 6] = 1.0
    cov7 = j @ cov_int @ j.T
    names = ("tx", "ty", "tz", "omega_deg", "phi_deg", "kappa_deg", "scale")
    sig7 = _sigma(cov7) if dof > 0 else np.full(7, np.nan)
    if fix_scale:
        sig7[6] = 0.0
    notes = []
    if dof <= 0:
        notes.append("no redundancy: sigma0 and the parameter sigmas are undefined")
    if abs(abs(angles[1]) - 90.0) < 1e-3:
        notes.append("phi is ±90° (gimbal lock): omega and kappa are not separable")
    if fix_scale:
        notes.append("scale fixed at 1")
    params = dict(zip(names, (*shift.tolist(), *angles.tolist(), float(s)), strict=True))
    sigmas = {k: float(v) for k, v in zip(names, sig7, strict=True)}
    pnames = names[:6] if fix_scale else names
    cov_out = cov7[:u, :u] if fix_scale else cov7
    return TransformFit(
        name=name,
        params=params,
        sigmas=sigmas,
        sigma0=s0,
        dof=dof,
        n_points=n,
        param_names=pnames,
        covariance=cov_out,
        residuals=res,
        rotation=r,
        translation=translation,
        scale=float(s),
        linear=s * r,
        origin=m1.copy(),
        notes=tuple(notes),
    )


def _helmert_design(rp: np.ndarray, s: float, fix_scale: bool) -> np.ndarray:
    n = len(rp)
    u = 6 if fix_scale else 7
    a = np.zeros((n, 3, u))
    a[:, :, :3] = np.eye(3)
    # d(s·exp([δ]×)·R·x)/dδ = -s·[R·x]×
    sk = np.zeros((n, 3, 3))
    sk[:, 0, 1] = -rp[:, 2]
    sk[:, 0, 2] = rp[:, 1]
    sk[:, 1, 0] = rp[:, 2]
    sk[:, 1, 2] = -rp[:, 0]
    sk[:, 2, 0] = -rp[:, 1]
    sk[:, 2, 1] = rp[:, 0]
    a[:, :, 3:6] = -s * sk
    if not fix_scale:
        a[:, :, 6] = rp
    return a.reshape(3 * n, u)


# ---------------------------------------------------------------- dispatcher


def estimate_transform(source: Any, target: Any, *, method: str = "similarity2d") -> TransformFit:
    """Estimate a transformation from source to target common points.

    Parameters
    ----------
    source, target : ndarray of shape (n, 3)
        Matching common points (m).
    method : {"none", "similarity2d", "helmert", "helmert-fixed-scale"}, default "similarity2d"

    Returns
    -------
    TransformFit

    Raises
    ------
    OptionError
        Unknown `method`.
    DegenerateGeometryError
        Too few points or a degenerate configuration (the message gives the reason).
    InvalidPointsError
        NaN/inf coordinates or mismatched shapes.

    Examples
    --------
    >>> fit = estimate_transform([[0, 0, 0], [1, 0, 0]], [[0, 0, 1], [1, 0, 1]], method="none")
    >>> fit.residuals[:, 2].tolist()
    [-1.0, -1.0]
    """
    check_choice(method, TRANSFORMS, "method")
    if method == "similarity2d":
        return fit_similarity2d(source, target)
    if method == "helmert":
        return fit_helmert(source, target)
    if method == "helmert-fixed-scale":
        return fit_helmert(source, target, fix_scale=True)
    src, tgt = _validate_pair(source, target)
    n = len(src)
    if n < 1:
        raise DegenerateGeometryError("no common points")
    res = src - tgt
    return TransformFit(
        name="none",
        params={},
        sigmas={},
        sigma0=math.sqrt(float(np.sum(res**2)) / (3 * n)),
        dof=3 * n,
        n_points=n,
        param_names=(),
        covariance=np.zeros((0, 0)),
        residuals=res,
        rotation=np.eye(3),
        translation=np.zeros(3),
        scale=1.0,
        linear=np.eye(3),
    )
