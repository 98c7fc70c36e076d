"""Segment features and object-segment detection, :ref:`alg-features`.

Orientation (tilt of a segment's best-fit plane) and scatterness (mean
per-point dimensionality sqrt(λ3/λ1) of the k nearest neighbours), after
Zhang, Lin & Ning (2013) as reconstructed in the spec; a segment is an object
(façade or vegetation) when its orientation exceeds `orientation_thr` or its
scatterness exceeds `scatter_thr`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from .._gridkernels import centred_moments
from .._validate import as_points, check_positive, check_range
from ..errors import InvalidPointsError
from ._tin import tree_workers

__all__ = [
    "SegmentFeatures",
    "segment_features",
    "point_scatterness",
    "detect_object_segments",
    "vegetation_segments",
]


@dataclass(frozen=True)
class SegmentFeatures:
    """Per-segment features, indexed by label 0 .. n_segments-1.

    Attributes
    ----------
    orientation : ndarray (S,)
        ``arccos(|n_z|)`` of the segment plane, degrees in [0, 90] (nan for < 3 points).
    scatterness : ndarray (S,)
        Mean sqrt(λ3/λ1) of the point neighbourhoods, in [0, 1].
    size : ndarray (S,) int
        Points per segment.
    non_single_ratio : ndarray (S,) or None
        Fraction of points that are not single returns (when returns were given).
    """

    orientation: np.ndarray
    scatterness: np.ndarray
    size: np.ndarray
    non_single_ratio: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "n_segments": int(self.size.size),
            "orientation": self.orientation.tolist(),
            "scatterness": self.scatterness.tolist(),
            "size": self.size.tolist(),
        }


def _eig_sym3(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ascending eigenvalues and eigenvectors of a stack of 3×3 symmetric matrices."""
    w, v = np.linalg.eigh(cov)
    return np.clip(w, 0.0, None), v


def point_scatterness(points: Any, *, k: int = 10, subset: Any = None) -> np.ndarray:
    """Per-point scatterness sqrt(λ3/λ1) of the `k` nearest neighbours (3-D).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres.
    k : int, default 10
        Neighbourhood size, the point itself included (N is used if N < k).
    subset : ndarray of int, optional
        Only compute for these point indices (neighbours still come from all points).

    Returns
    -------
    ndarray of shape (N,) or (len(subset),)
        0 on a plane, about 0.5 for isotropic scatter; nan where λ1 = 0.

    Examples
    --------
    >>> g = np.mgrid[0:10, 0:10].reshape(2, -1).T.astype(float)
    >>> float(point_scatterness(np.column_stack([g, np.zeros(100)])).max()) < 1e-6
    True
    """
    pts = as_points(points)
    n = pts.shape[0]
    idx = np.arange(n) if subset is None else np.asarray(subset, dtype=np.int64)
    if n == 0 or idx.size == 0:
        return np.zeros(idx.size)
    kk = int(min(max(k, 1), n))
    c = pts - pts.mean(axis=0)
    tree = cKDTree(c)
    out = np.empty(idx.size)

    def chunk(s: int) -> None:
        q = idx[s : s + _SCATTER_CHUNK]
        _, nb = tree.query(c[q], k=kk)
        nb = np.asarray(nb, dtype=np.int64).reshape(q.size, kk)
        out[s : s + _SCATTER_CHUNK] = _scatter_kernel(c, nb)

    # chunks are independent (each writes its own slice) and NumPy / cKDTree release
    # the GIL, so threads give the same result as one loop, whatever their number
    starts = range(0, idx.size, _SCATTER_CHUNK)
    workers = min(tree_workers(), len(starts))
    if workers > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(chunk, starts))
    else:
        for s in starts:
            chunk(s)
    return out


_SCATTER_CHUNK = 100_000  # points per chunk of point_scatterness (bounds the (n, k) arrays)


@njit(cache=True, nogil=True)
def _scatter_kernel(c, nb):  # pragma: no cover - numba
    """sqrt(λ3/λ1) of the covariance of each row's neighbours `nb` in `c`; nan where λ1 = 0.

    The eigenvalues of the symmetric 3×3 covariance in closed form (trigonometric
    solution of the characteristic cubic), clipped at 0 like the LAPACK ones.
    """
    m, k = nb.shape
    out = np.empty(m)
    for i in range(m):
        _, _, _, a00, a01, a02, a11, a12, a22 = centred_moments(c, nb[i], k)
        a00 /= k
        a01 /= k
        a02 /= k
        a11 /= k
        a12 /= k
        a22 /= k
        p1 = a01 * a01 + a02 * a02 + a12 * a12
        q = (a00 + a11 + a22) / 3.0
        b00, b11, b22 = a00 - q, a11 - q, a22 - q
        p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
        if p2 <= 0.0:  # a multiple of the identity (or all neighbours equal)
            lo = hi = q
        else:
            pp = math.sqrt(p2 / 6.0)
            det = (
                b00 * (b11 * b22 - a12 * a12)
                - a01 * (a01 * b22 - a12 * a02)
                + a02 * (a01 * a12 - b11 * a02)
            )
            r = det / (2.0 * pp * pp * pp)
            r = min(max(r, -1.0), 1.0)
            phi = math.acos(r) / 3.0
            hi = q + 2.0 * pp * math.cos(phi)
            lo = q + 2.0 * pp * math.cos(phi + 2.0 * math.pi / 3.0)
        lo = max(lo, 0.0)
        hi = max(hi, 0.0)
        out[i] = math.sqrt(lo / hi) if hi > 0.0 else np.nan
    return out


def segment_features(
    points: Any,
    labels: Any,
    *,
    k_feat: int = 10,
    max_sample: int = 256,
    return_number: Any = None,
    number_of_returns: Any = None,
) -> SegmentFeatures:
    """Orientation and scatterness of every segment (:ref:`alg-features`).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres.
    labels : ndarray of int, shape (N,)
        Segment label per point, -1 = unsegmented.
    k_feat : int, default 10
        Neighbourhood size of the per-point scatterness (taken in the full cloud).
    max_sample : int, default 256
        The mean scatterness of a larger segment is estimated from about this many
        of its points, picked by a hash of their coordinates (deterministic and
        independent of the input order); 0 = all.
    return_number, number_of_returns : ndarray (N,), optional
        When both are given, the fraction of non-single returns per segment is
        also computed.

    Returns
    -------
    SegmentFeatures
    """
    pts = as_points(points)
    lab = np.asarray(labels)
    if lab.shape != (pts.shape[0],):
        raise InvalidPointsError(f"labels must have shape ({pts.shape[0]},), got {lab.shape}")
    lab = lab.astype(np.int64)
    n_seg = int(lab.max()) + 1 if lab.size and lab.max() >= 0 else 0
    if n_seg == 0:
        e = np.zeros(0)
        return SegmentFeatures(e, e, np.zeros(0, dtype=np.int64), None)
    m = lab >= 0
    sl = lab[m]
    _, normal, size = _segment_planes(pts[m], sl, n_seg)
    cnt = np.maximum(size, 1).astype(float)
    orientation = np.degrees(np.arccos(np.clip(np.abs(normal[:, 2]), 0.0, 1.0)))
    orientation[size < 3] = np.nan
    seg_idx = np.flatnonzero(m)
    if max_sample and max_sample > 0:
        # deterministic, order-free subsample: a hash of the millimetre coordinates
        step = np.maximum(1, -(-size // max_sample))  # ceil(size / max_sample)
        qc = np.round(pts[seg_idx] * 1000.0).astype(np.int64)
        h = (qc[:, 0] * 73856093) ^ (qc[:, 1] * 19349663) ^ (qc[:, 2] * 83492791)
        h = (h ^ (h >> 17)) & 0x7FFFFFFF
        seg_idx = seg_idx[h % step[sl] == 0]
    sc_pt = point_scatterness(pts, k=k_feat, subset=seg_idx)
    sc_pt = np.nan_to_num(sc_pt, nan=0.0)
    ls = lab[seg_idx]
    n_used = np.maximum(np.bincount(ls, minlength=n_seg), 1).astype(float)
    scatter = np.bincount(ls, weights=sc_pt, minlength=n_seg) / n_used
    ratio = None
    if return_number is not None and number_of_returns is not None:
        nr = np.asarray(number_of_returns)[m]
        ratio = np.bincount(sl, weights=(nr > 1).astype(float), minlength=n_seg) / cnt
    return SegmentFeatures(orientation, scatter, size, ratio)


def _segment_planes(
    points: np.ndarray, labels: np.ndarray, n_seg: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares plane of every segment: centroid (S, 3), unit normal (S, 3), size (S,).

    `labels` are 0 .. n_seg-1 (no -1). Normals point up (n_z >= 0); segments with
    fewer than 3 points get an arbitrary normal. One batched eigen-decomposition of
    the per-segment covariances, accumulated about the global mean.
    """
    size = np.bincount(labels, minlength=n_seg).astype(np.int64)
    cnt = np.maximum(size, 1).astype(float)
    origin = points.mean(axis=0) if points.shape[0] else np.zeros(3)
    sp = points - origin
    s1 = np.zeros((n_seg, 3))
    for j in range(3):
        s1[:, j] = np.bincount(labels, weights=sp[:, j], minlength=n_seg)
    s2 = np.zeros((n_seg, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            v = np.bincount(labels, weights=sp[:, i] * sp[:, j], minlength=n_seg)
            s2[:, i, j] = v
            s2[:, j, i] = v
    mean = s1 / cnt[:, None]
    cov = s2 / cnt[:, None, None] - mean[:, :, None] * mean[:, None, :]
    _, v = _eig_sym3(cov)
    normal = v[:, :, 0] * np.where(v[:, 2, 0] < 0, -1.0, 1.0)[:, None]
    return mean + origin, normal, size


def vegetation_segments(features: SegmentFeatures, *, scatter_thr: float = 0.2) -> np.ndarray:
    """Vegetation flag per segment: mean scatterness above `scatter_thr` (:ref:`alg-features`)."""
    return np.asarray(features.scatterness > scatter_thr, dtype=bool)


def detect_object_segments(
    features: SegmentFeatures,
    *,
    orientation_thr: float = 45.0,
    scatter_thr: float = 0.2,
    min_facade_points: int = 0,
    echo_ratio_thr: float | None = None,
) -> np.ndarray:
    """Object flag per segment: façade (orientation > o) or vegetation (scatterness > s).

    Method: :ref:`alg-features`.

    Parameters
    ----------
    features : SegmentFeatures
    orientation_thr : float, default 45.0
        Degrees; a segment steeper than this is a façade.
    scatter_thr : float, default 0.2
        A segment with mean scatterness above this is vegetation.
    min_facade_points : int, default 0
        Façades must have at least this many points.
    echo_ratio_thr : float, optional
        Also flag segments whose fraction of non-single returns exceeds this
        (needs `features.non_single_ratio`).

    Returns
    -------
    ndarray of bool, shape (S,)
    """
    check_range(orientation_thr, "orientation_thr", 0.0, 90.0)
    check_positive(scatter_thr, "scatter_thr")
    facade = (features.orientation > orientation_thr) & (features.size >= min_facade_points)
    obj = facade | vegetation_segments(features, scatter_thr=scatter_thr)
    if echo_ratio_thr is not None and features.non_single_ratio is not None:
        obj |= features.non_single_ratio > echo_ratio_thr
    return np.asarray(obj, dtype=bool)
