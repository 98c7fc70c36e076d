"""Kernels of the line-segment matching (:ref:`alg-lines`): pair distances and candidate pairs.

Everything here works on prepared arrays: segment midpoints ``c`` (n, 3), unit
directions ``u`` (n, 3) and lengths ``L`` (n,), in a common local origin.

Pruning guarantee
-----------------
For any pair (t, m), with r = ‖c_t − c_m‖ the distance of the midpoints,

    d(t, m) ≥ sqrt(d∥² + d⊥²) ≥ max(0, r − |L_t − L_m| / 2)

in both rotation modes: after the rotation, sqrt(d∥² + d⊥²) is exactly the
distance from the rotated segment's midpoint to the "core" of the other
segment (the segment of half-length |L_t − L_m|/2 centred on its midpoint),
and that core lies inside the ball of radius |L_t − L_m|/2 about the midpoint.
:func:`candidate_pairs` returns every pair whose bound is ≤ `cutoff` (a superset of
the pairs with d ≤ cutoff), so a pair it leaves out provably has d > cutoff.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

__all__ = ["prepare", "pair_distances", "candidate_pairs", "BinnedTree", "broadcast_distances"]

# relative slack added to every pruning radius so that rounding can never drop a pair
_SLACK = 1e-9


def prepare(start: np.ndarray, end: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, ...]:
    """Midpoints (relative to `origin`), unit directions and lengths of segments."""
    a = start - origin
    b = end - origin
    v = b - a
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    with np.errstate(invalid="ignore", divide="ignore"):
        u = v / length[:, None]
    c = 0.5 * (a + b)
    return np.ascontiguousarray(c), np.ascontiguousarray(u), np.ascontiguousarray(length)


# ------------------------------------------------------------------ pair kernel


@njit(cache=True, nogil=True, inline="always")
def _one(ct0, ct1, ct2, ut0, ut1, ut2, lt, cm0, cm1, cm2, um0, um1, um2, lm, rotate_test):
    # angle distance (Chen et al. 2003): shorter length * sin(theta), undirected
    x0 = ut1 * um2 - ut2 * um1
    x1 = ut2 * um0 - ut0 * um2
    x2 = ut0 * um1 - ut1 * um0
    s = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if s > 1.0:
        s = 1.0
    d_theta = (lt if lt < lm else lm) * s
    # which segment is rotated: the test one (rotate="test" or ties), else the shorter
    if rotate_test or lt <= lm:
        w0 = ct0 - cm0
        w1 = ct1 - cm1
        w2 = ct2 - cm2
        a0 = um0
        a1 = um1
        a2 = um2
    else:
        w0 = cm0 - ct0
        w1 = cm1 - ct1
        w2 = cm2 - ct2
        a0 = ut0
        a1 = ut1
        a2 = ut2
    along = w0 * a0 + w1 * a1 + w2 * a2
    p0 = w0 - along * a0
    p1 = w1 - along * a1
    p2 = w2 - along * a2
    d_perp = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    half = 0.5 * abs(lt - lm)
    d_par = abs(along) - half
    if d_par < 0.0:
        d_par = 0.0
    return d_theta, d_par, d_perp


@njit(cache=True, nogil=True)
def _pairs_kernel(ct, ut, lt, cm, um, lm, ii, jj, weight, rotate_test, out):
    n = ii.shape[0]
    for k in range(n):
        i = ii[k]
        j = jj[k]
        dt, dp, dq = _one(
            ct[i, 0],
            ct[i, 1],
            ct[i, 2],
            ut[i, 0],
            ut[i, 1],
            ut[i, 2],
            lt[i],
            cm[j, 0],
            cm[j, 1],
            cm[j, 2],
            um[j, 0],
            um[j, 1],
            um[j, 2],
            lm[j],
            rotate_test,
        )
        out[k, 0] = dt
        out[k, 1] = dp
        out[k, 2] = dq
        out[k, 3] = np.sqrt(weight * dt * dt + dp * dp + dq * dq)


def pair_distances(
    ct, ut, lt, cm, um, lm, ii, jj, *, weight: float, rotate_test: bool
) -> np.ndarray:
    """(n, 4) array of dθ, d∥, d⊥, d for the pairs (ii[k], jj[k])."""
    out = np.empty((len(ii), 4), dtype=np.float64)
    if len(ii):
        _pairs_kernel(
            ct,
            ut,
            lt,
            cm,
            um,
            lm,
            np.ascontiguousarray(ii, dtype=np.int64),
            np.ascontiguousarray(jj, dtype=np.int64),
            float(weight),
            bool(rotate_test),
            out,
        )
    return out


def broadcast_distances(ct, ut, lt, cm, um, lm, *, weight: float, rotate_test: bool):
    """Plain-NumPy reference of the pair distance, broadcasting over leading axes.

    The obvious formulation of :ref:`alg-lines` (rotate, project on the long
    axis, compare sorted intervals); the numba kernel is tested against it.
    """
    cross = np.cross(ut, um)
    sin = np.minimum(1.0, np.linalg.norm(cross, axis=-1))
    d_theta = np.minimum(lt, lm) * sin
    test_rot = np.broadcast_to(np.asarray(rotate_test) | (lt <= lm), d_theta.shape)
    ts = test_rot[..., None]
    c_s = np.where(ts, ct, cm)
    c_l = np.where(ts, cm, ct)
    u_l = np.where(ts, um, ut)
    len_s = np.where(test_rot, lt, lm)
    len_l = np.where(test_rot, lm, lt)
    # intervals on the long axis: rotated short segment [a0, a1], long segment [b0, b1]
    ms = np.sum(c_s * u_l, axis=-1)
    ml = np.sum(c_l * u_l, axis=-1)
    a0, a1 = ms - len_s / 2, ms + len_s / 2
    b0, b1 = ml - len_l / 2, ml + len_l / 2
    inside = ((a0 >= b0) & (a1 <= b1)) | ((b0 >= a0) & (b1 <= a1))
    d_par = np.where(inside, 0.0, np.minimum(np.abs(a0 - b0), np.abs(a1 - b1)))
    w = c_s - c_l
    perp = w - np.sum(w * u_l, axis=-1)[..., None] * u_l
    d_perp = np.linalg.norm(perp, axis=-1)
    d = np.sqrt(weight * d_theta**2 + d_par**2 + d_perp**2)
    return d_theta, d_par, d_perp, d


# ------------------------------------------------------------- candidate pairs


class BinnedTree:
    """KD-trees over segment midpoints, one per length class (factor-2 bins).

    Binning by length keeps the pruning radius cutoff + |L_t − L_m|/2 tight:
    within a pair of bins the radius uses the largest length difference of
    that pair of bins, and an exact per-pair test follows.
    """

    def __init__(self, c: np.ndarray, length: np.ndarray, index: np.ndarray | None = None) -> None:
        self.c = c
        self.length = length
        self.index = np.arange(len(c)) if index is None else index
        lc = length[self.index]
        key = np.floor(np.log2(np.maximum(lc, 1e-300))).astype(np.int64)
        self.bins = []
        for k in np.unique(key):
            sel = self.index[key == k]
            ls = length[sel]
            self.bins.append((sel, float(ls.min()), float(ls.max()), cKDTree(c[sel])))


def candidate_pairs(a: BinnedTree, b: BinnedTree, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """All pairs (i of a, j of b) with ‖c_i − c_j‖ − |L_i − L_j|/2 ≤ cutoff, sorted by (i, j)."""
    out_i, out_j = [], []
    scale = 1.0 + cutoff
    for sa, lo_a, hi_a, ta in a.bins:
        for sb, lo_b, hi_b, tb in b.bins:
            dl = max(hi_a - lo_b, hi_b - lo_a, 0.0)
            radius = cutoff + 0.5 * dl + _SLACK * scale * 4
            sp = ta.sparse_distance_matrix(tb, radius, output_type="ndarray")
            if not len(sp):
                continue
            i = sa[sp["i"]]
            j = sb[sp["j"]]
            keep = sp["v"] - 0.5 * np.abs(a.length[i] - b.length[j]) <= cutoff + _SLACK * scale
            out_i.append(i[keep])
            out_j.append(j[keep])
    if not out_i:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    i = np.concatenate(out_i).astype(np.int64)
    j = np.concatenate(out_j).astype(np.int64)
    nb = np.int64(len(b.c))
    key = np.sort(i * nb + j)
    return key // nb, key % nb


@njit(cache=True, nogil=True)
def group_min(keys, values, n):
    """Minimum of `values` per key in 0..n-1 (inf where absent) and the index of its first hit."""
    best = np.full(n, np.inf)
    arg = np.full(n, -1, dtype=np.int64)
    for k in range(keys.shape[0]):
        g = keys[k]
        v = values[k]
        if v < best[g]:
            best[g] = v
            arg[g] = k
    return best, arg
