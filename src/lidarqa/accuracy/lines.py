"""Line-segment accuracy: match 3D edge segments with the modified line-segment Hausdorff distance.

Poreba & Goulette (2013) compare a Test set of 3D line segments with a Model
(reference) set: a similarity matrix of segment distances (angle, parallel and
perpendicular components; Gao & Leung 2002, Chen et al. 2003), an automatic
threshold at the knee of the sorted nearest distances, a one-to-many
correspondence matrix, and the length-weighted oriented / symmetric modified
LHD. The method, and the choices made where the paper is open: :ref:`alg-lines`.

Lengths are in the data's units (metres for the usual projected CRSs).

Large sets are matched without the p × q matrix: candidate pairs come from
KD-trees over the segment midpoints, with a pruning rule that provably never
drops a pair whose distance is ≤ the cutoff (see :mod:`._lines_kernels`); the
nearest distance of every segment is always exact (an expanding search finds
it for segments with nothing within the cutoff), and the final cutoff is
raised to the chosen thresholds, so the matching is identical to the dense
computation.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._progress import report
from .._validate import check_choice, check_positive
from ..errors import DegenerateGeometryError, InvalidPointsError, OptionError
from ..io.crs import ensure_same_crs
from ..io.vector import Segments
from . import _lines_kernels as _k

__all__ = [
    "segment_distance",
    "segment_distances",
    "auto_threshold",
    "Threshold",
    "LineMatch",
    "match_segments",
    "olhd",
    "primary_lhd",
    "hausdorff",
    "detection_rate",
    "DEFAULT_CUTOFF",
    "sampling_threshold_range",
    "match_strips",
    "SAMPLING_FACTOR",
    "SAMPLING_BAND",
]

#: Initial pruning cutoff (data units, metres): only a speed knob, never changes results.
DEFAULT_CUTOFF = 1.0
_EPS = 1e-12


# ------------------------------------------------------------------ inputs


def _as_segments(value: Any, name: str) -> Segments:
    """Segments, an (n, 2, 3) array, or a (start, end) pair → Segments (validated)."""
    if isinstance(value, Segments):
        seg = value
    else:
        if isinstance(value, tuple) and len(value) == 2:
            start, end = (np.asarray(v, dtype=np.float64) for v in value)
        else:
            try:
                arr = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise InvalidPointsError(f"{name} must be Segments or an (n, 2, 3) array") from exc
            if arr.ndim == 2 and arr.shape[1] == 6:
                arr = arr.reshape(-1, 2, 3)
            if arr.ndim != 3 or arr.shape[1:] != (2, 3):
                raise InvalidPointsError(f"{name} must have shape (n, 2, 3), got {arr.shape}")
            start, end = arr[:, 0], arr[:, 1]
        seg = Segments(ids=np.arange(len(start)), start=start, end=end)
    if len(seg) == 0:
        raise InvalidPointsError(f"{name} segment set is empty")
    if not (np.isfinite(seg.start).all() and np.isfinite(seg.end).all()):
        raise InvalidPointsError(f"{name} segments have NaN or infinite coordinates")
    return seg


def _check_lengths(length: np.ndarray, seg: Segments, name: str, scale: float) -> None:
    bad = length <= _EPS * max(scale, 1.0)
    if bad.any():
        ids = ", ".join(str(x) for x in seg.ids[bad][:5])
        more = "" if bad.sum() <= 5 else f" (and {int(bad.sum()) - 5} more)"
        raise DegenerateGeometryError(
            f"{name} has {int(bad.sum())} zero-length segment(s): id {ids}{more}"
        )


def _check_weight(weight: float) -> float:
    return check_positive(weight, "weight", allow_zero=True)


# ---------------------------------------------------------------- distances


def segment_distance(t: Any, m: Any, *, weight: float = 10.0, rotate: str = "shorter") -> tuple:
    """Distance between 3D line segments: angle, parallel, perpendicular components and total.

    :ref:`alg-lines` ([S-PG] eqs. 3–5): ``dθ = min(L_t, L_m)·sinθ``; the shorter
    segment (or the test one with ``rotate="test"``) is rotated about its midpoint
    parallel to the other; ``d∥`` aligns the nearer pair of end points (0 when one
    interval contains the other) and ``d⊥`` is the distance between the parallel
    supporting lines; ``d = sqrt(W·dθ² + d∥² + d⊥²)``.

    Parameters
    ----------
    t, m : array_like of shape (..., 2, 3)
        End points of the test and model segments (broadcast against each other).
    weight : float, default 10
        Dimensionless weight W of the squared angle distance.
    rotate : {"shorter", "test"}, default "shorter"
        Which segment is rotated; "shorter" makes d symmetric (equal lengths: test).

    Returns
    -------
    d_theta, d_par, d_perp, d : float or ndarray
        Distances in the coordinates' units (metres).

    Raises
    ------
    DegenerateGeometryError
        If a segment has zero length.

    Examples
    --------
    >>> segment_distance([[3, 0, 1], [3, 4, 1]], [[0, 0, 0], [10, 0, 0]])[3]
    12.84523257866513
    """
    weight = _check_weight(weight)
    check_choice(rotate, ("shorter", "test"), "rotate")
    t = np.asarray(t, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    if t.shape[-2:] != (2, 3) or m.shape[-2:] != (2, 3):
        raise InvalidPointsError(
            f"segments must have shape (..., 2, 3), got {t.shape} and {m.shape}"
        )
    vt = t[..., 1, :] - t[..., 0, :]
    vm = m[..., 1, :] - m[..., 0, :]
    lt = np.linalg.norm(vt, axis=-1)
    lm = np.linalg.norm(vm, axis=-1)
    if (lt <= _EPS).any() or (lm <= _EPS).any():
        raise DegenerateGeometryError("zero-length segment: the two end points coincide")
    origin = t[..., 0, :]  # local origin per pair, for precision at projected coordinates
    ct = 0.5 * vt
    cm = 0.5 * (m[..., 0, :] - origin) + 0.5 * (m[..., 1, :] - origin)
    out = _k.broadcast_distances(
        ct,
        vt / lt[..., None],
        lt,
        cm,
        vm / lm[..., None],
        lm,
        weight=weight,
        rotate_test=rotate == "test",
    )
    if np.ndim(out[3]) == 0:
        return tuple(float(x) for x in out)
    return out


def segment_distances(
    test: Any, model: Any, *, weight: float = 10.0, rotate: str = "shorter"
) -> tuple:
    """Dense p × q similarity matrices ``(d_theta, d_par, d_perp, d)`` of two segment sets.

    `test` and `model` are :class:`~lidarqa.io.vector.Segments` or (n, 2, 3) arrays.
    Memory grows with p·q; :func:`match_segments` prunes instead. Units: metres.
    """
    t = _as_segments(test, "test")
    m = _as_segments(model, "model")
    origin = np.floor(
        np.minimum(np.minimum(t.start, t.end).min(axis=0), np.minimum(m.start, m.end).min(axis=0))
    )
    ta = np.stack([t.start, t.end], axis=1) - origin
    ma = np.stack([m.start, m.end], axis=1) - origin
    return segment_distance(ta[:, None], ma[None, :], weight=weight, rotate=rotate)


# ---------------------------------------------------------------- threshold


@dataclass(frozen=True, eq=False)
class Threshold:
    """The automatic threshold of one direction (:ref:`alg-lines-threshold`).

    Attributes
    ----------
    threshold : float
        δ (metres): s[k+1] at the first accepted peak, or the largest nearest distance.
    found : bool
        False when p < 3 or no peak ≥ sensitivity was confirmed (fallback) or when fixed.
    sorted_nearest : ndarray (p,)
        Nearest distances sorted ascending, s.
    second_diff : ndarray (max(p-2, 0),)
        Second differences Δ²_k (centred on s[k+1]).
    peak_index : int
        k of the accepted peak (δ = s[k+1]); -1 if none.
    reason : str
        "peak", "fixed", "too few segments" or "no peak".
    """

    threshold: float
    found: bool
    sorted_nearest: np.ndarray = field(repr=False)
    second_diff: np.ndarray = field(repr=False)
    peak_index: int
    reason: str

    def to_dict(self) -> dict:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            "threshold": self.threshold,
            "found": self.found,
            "peak_index": self.peak_index,
            "reason": self.reason,
        }


def _peaks(v: np.ndarray, sens: float) -> list[tuple[int, float]]:
    """Classic peak detection (running max confirmed after a drop of more than `sens`)."""
    peaks = []
    mx, mn = -np.inf, np.inf
    mxpos = 0
    look_for_max = True
    for i, x in enumerate(v.tolist()):
        if x > mx:
            mx, mxpos = x, i
        if x < mn:
            mn = x
        if look_for_max:
            if x < mx - sens:
                peaks.append((mxpos, mx))
                mn = x
                look_for_max = False
        elif x > mn + sens:
            mx, mxpos = x, i
            look_for_max = True
    return peaks


def auto_threshold(nearest: Any, *, sensitivity: float = 0.1) -> Threshold:
    """Automatic correspondence threshold from nearest distances (:ref:`alg-lines-threshold`).

    Sorts the nearest distances, takes second differences, runs a peak detector
    with the a-priori `sensitivity` on ``[0] + Δ² + [min(Δ²) − sens − 1]`` and
    returns δ = s[k+1] at the first confirmed peak k with Δ²_k ≥ sens.

    Parameters
    ----------
    nearest : array_like of shape (p,)
        Nearest distance of each segment (metres), finite.
    sensitivity : float, default 0.1
        A-priori sensitivity of the peak search (metres).

    Returns
    -------
    Threshold
        δ, whether a peak was found, and the arrays behind it.

    Examples
    --------
    >>> auto_threshold([0.1, 0.11, 0.12, 0.13, 5.0]).threshold
    0.13
    """
    sens = check_positive(sensitivity, "sensitivity", allow_zero=True)
    s = np.sort(np.asarray(nearest, dtype=np.float64).ravel())
    if len(s) == 0:
        raise InvalidPointsError("nearest distances are empty")
    if not np.isfinite(s).all():
        raise InvalidPointsError("nearest distances must be finite")
    if len(s) < 3:
        return Threshold(float(s[-1]), False, s, np.empty(0), -1, "too few segments")
    d2 = np.diff(s, n=2)
    v = np.concatenate([[0.0], d2, [d2.min() - sens - 1.0]])
    for pos, val in _peaks(v, sens):
        if 1 <= pos <= len(d2) and val >= sens:
            k = pos - 1
            return Threshold(float(s[k + 1]), True, s, d2, k, "peak")
    return Threshold(float(s[-1]), False, s, d2, -1, "no peak")


#: Centre of the sampling band: this many times the sparser strip's point spacing (m/m).
SAMPLING_FACTOR = 1.5
#: Half-width of the sampling band, as a factor on each side of its centre.
SAMPLING_BAND = 1.34


def sampling_threshold_range(test: Any, model: Any) -> tuple[float, float] | None:
    """Band (m) an automatic threshold between two flight strips must fall into.

    Edges of two strips of one survey are found from points of a known
    sampling: the ``point_spacing`` attribute of each set (the median distance
    of a point to its 10th neighbour in the strip, metres, written by the edge
    extraction of ``lidarqa repeatability``). The same edge seen by two strips
    is displaced by a fraction of that spacing (outline and step edges run
    through the outermost points) and its ends by up to about one spacing, so
    the distance between matched edges scales with the sparser strip's spacing
    ``s``. The band is centred on ``SAMPLING_FACTOR · s`` (1.5 s) and reaches
    ``SAMPLING_BAND`` (1.34) times below and above it, about [1.1 s, 2.0 s]:
    a knee of the sorted nearest distances below it is a fluctuation among a
    handful of matches, one above it (or no knee at all) means the strips'
    edges disagree by more than their sampling explains. Neighbouring tiles
    of one survey have nearly the same spacing (±10 %), so their thresholds
    stay within a factor 2 of each other (1.34² · 1.1 = 1.98).

    Returns None when either set has no ``point_spacing`` attribute (e.g.
    segments read from a file): the plain knee is then used.
    """
    spacings = []
    for seg in (test, model):
        attrs = getattr(seg, "attributes", None) or {}
        v = attrs.get("point_spacing")
        if v is None:
            return None
        v = np.asarray(v, dtype=np.float64)
        v = v[np.isfinite(v) & (v > 0)]
        if len(v) == 0:
            return None
        spacings.append(float(np.median(v)))
    centre = SAMPLING_FACTOR * max(spacings)
    return centre / SAMPLING_BAND, centre * SAMPLING_BAND


def _clip_threshold(auto: Threshold, lo: float, hi: float) -> Threshold:
    """`auto` moved into [lo, hi]; the reason says which bound applied."""
    if not auto.found:  # no knee: the ceiling, not the farthest edge
        return replace(auto, threshold=float(hi), reason=f"{auto.reason}, band ceiling")
    if auto.threshold < lo:
        return replace(auto, threshold=float(lo), reason=f"{auto.reason}, raised to the band")
    if auto.threshold > hi:
        return replace(auto, threshold=float(hi), reason=f"{auto.reason}, lowered to the band")
    return auto


# ---------------------------------------------------------------- measures


def olhd(distances: Any, weights: Any, *, total_weight: float | None = None) -> float:
    """Oriented modified LHD ([S-PG] eq. 7): length-weighted mean of matched pair distances.

    `weights` are the lengths of the second-argument set's segment of each pair.
    `total_weight` replaces the denominator (the literal "Σ over all of M" reading).
    Returns nan when there are no pairs.
    """
    d = np.asarray(distances, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    den = float(w.sum()) if total_weight is None else float(total_weight)
    if len(d) == 0 or den <= 0:
        return float("nan")
    return float(np.dot(w, d) / den)


def primary_lhd(nearest: Any, lengths: Any) -> float:
    """Gao–Leung primary LHD h(A, B) = Σ_a L_a·min_b d(a, b) / Σ_a L_a (no threshold)."""
    n = np.asarray(nearest, dtype=np.float64)
    w = np.asarray(lengths, dtype=np.float64)
    return float(np.dot(w, n) / w.sum())


def hausdorff(a: Any, b: Any, *, metric: Any = "euclidean") -> tuple[float, float, float]:
    """Classic Hausdorff distance ([S-PG] eqs. 1–2): ``(OHD(A,B), OHD(B,A), HD)``.

    `a`, `b` are (n, k) point arrays with ``metric="euclidean"`` (KD-tree), or any
    sequences with a callable ``metric(x, y) -> float`` (dense, O(n·m)).
    """
    if callable(metric):
        dm = np.array([[metric(x, y) for y in b] for x in a], dtype=np.float64)
        if dm.size == 0:
            raise InvalidPointsError("hausdorff needs two non-empty sets")
        ab, ba = float(dm.min(axis=1).max()), float(dm.min(axis=0).max())
    else:
        check_choice(metric, ("euclidean",), "metric")
        from scipy.spatial import cKDTree

        pa = np.asarray(a, dtype=np.float64)
        pb = np.asarray(b, dtype=np.float64)
        if len(pa) == 0 or len(pb) == 0:
            raise InvalidPointsError("hausdorff needs two non-empty sets")
        ab = float(cKDTree(pb).query(pa)[0].max())
        ba = float(cKDTree(pa).query(pb)[0].max())
    return ab, ba, max(ab, ba)


def detection_rate(p: int, q: int, fn: int, fp: int) -> float:
    """Detection rate (TP + TN)/(p·q) = (p·q − FN − FP)/(p·q), as a fraction."""
    total = int(p) * int(q)
    if total <= 0:
        raise OptionError(f"detection rate needs p, q > 0, got {p}, {q}")
    return (total - int(fn) - int(fp)) / total


# ---------------------------------------------------------------- matching


@dataclass(frozen=True, eq=False)
class LineMatch:
    """Result of :func:`match_segments` (both directions).

    ``to_dict()`` gives the JSON keys of issue 5. Arrays for reports:

    Attributes
    ----------
    p, q : int
        Numbers of test and model segments.
    threshold_tm, threshold_mt : float
        δ of each direction (metres).
    threshold_found_tm, threshold_found_mt : bool
        False when the threshold fell back to the largest nearest distance (or was fixed).
    olhd_tm, olhd_mt, lhd : float
        Oriented modified LHDs and their maximum (metres; nan without pairs).
    n_pairs_tm, n_pairs_mt : int
        Sizes of the correspondence matrices.
    test_ids, model_ids : ndarray
        Segment ids.
    test_lengths, model_lengths : ndarray
    nearest_tm : ndarray (p,)
        Exact nearest distance of each test segment to the model set.
    nearest_model : ndarray (p,)
        Index of that nearest model segment.
    nearest_mt, nearest_test : ndarray (q,)
        The same from the model set to the test set.
    auto_tm, auto_mt : Threshold
        Sorted nearest distances, second differences and peak of each direction.
    pair_test, pair_model : ndarray (n,)
        Evaluated pairs (indices), every pair whose pruning bound is ≤ `cutoff`
        (all pairs with d ≤ cutoff are among them; cutoff ≥ both thresholds).
    pair_components : ndarray (n, 4)
        dθ, d∥, d⊥, d of each evaluated pair, test→model.
    pair_d_mt : ndarray (n,)
        d of each pair model→test (equal to d test→model with rotate="shorter").
    match_tm, match_mt : ndarray (n,) bool
        Correspondence of each direction (Cor and Cor′).
    cutoff : float
        Final pruning cutoff (metres).
    gao_leung_tm, gao_leung_mt : float
        Gao–Leung primary LHD of each direction (no threshold).
    hausdorff_tm, hausdorff_mt : float
        Classic OHD with the segment distance d (max of nearest distances).
    tp_tm ... detection_rate_mt : int / float or None
        Ground-truth evaluation (None without ground truth).
    """

    p: int
    q: int
    threshold_tm: float
    threshold_mt: float
    threshold_found_tm: bool
    threshold_found_mt: bool
    olhd_tm: float
    olhd_mt: float
    lhd: float
    n_pairs_tm: int
    n_pairs_mt: int
    weight: float
    sensitivity: float
    rotate: str
    denominator: str
    cutoff: float
    test_ids: np.ndarray = field(repr=False)
    model_ids: np.ndarray = field(repr=False)
    test_lengths: np.ndarray = field(repr=False)
    model_lengths: np.ndarray = field(repr=False)
    nearest_tm: np.ndarray = field(repr=False)
    nearest_model: np.ndarray = field(repr=False)
    nearest_mt: np.ndarray = field(repr=False)
    nearest_test: np.ndarray = field(repr=False)
    auto_tm: Threshold = field(repr=False)
    auto_mt: Threshold = field(repr=False)
    pair_test: np.ndarray = field(repr=False)
    pair_model: np.ndarray = field(repr=False)
    pair_components: np.ndarray = field(repr=False)
    pair_d_mt: np.ndarray = field(repr=False)
    match_tm: np.ndarray = field(repr=False)
    match_mt: np.ndarray = field(repr=False)
    gao_leung_tm: float
    gao_leung_mt: float
    hausdorff_tm: float
    hausdorff_mt: float
    ground_truth: dict | None = field(default=None)

    @property
    def pair_d_tm(self) -> np.ndarray:
        """Distance d of each evaluated pair, test→model (metres)."""
        return self.pair_components[:, 3]

    def pairs_tm(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(test index, model index, d) of the test→model correspondence."""
        k = self.match_tm
        return self.pair_test[k], self.pair_model[k], self.pair_components[k, 3]

    def pairs_mt(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(test index, model index, d model→test) of the model→test correspondence."""
        k = self.match_mt
        return self.pair_test[k], self.pair_model[k], self.pair_d_mt[k]

    def to_dict(self) -> dict:
        """The JSON ``results`` of ``lidarqa lines`` (issue 5 keys; ground truth keys if given)."""
        out = {
            "p": self.p,
            "q": self.q,
            "threshold_tm": self.threshold_tm,
            "threshold_mt": self.threshold_mt,
            "threshold_found_tm": self.threshold_found_tm,
            "threshold_found_mt": self.threshold_found_mt,
            "olhd_tm": self.olhd_tm,
            "olhd_mt": self.olhd_mt,
            "lhd": self.lhd,
            "n_pairs_tm": self.n_pairs_tm,
            "n_pairs_mt": self.n_pairs_mt,
        }
        if self.ground_truth is not None:
            out.update(self.ground_truth)
        return out


def _nearest_exact(
    tree_b, ca, ua, la, cb, ub, lb, rows, start_cutoff, span, *, weight, rotate_test, swap
):
    """Exact nearest distance for `rows` of set a by an expanding pruned search.

    A row is settled in a round with cutoff c when its best candidate has d ≤ c:
    every pair with d ≤ c is a candidate, so nothing outside can be nearer. When
    c exceeds the span of all midpoints every pair is a candidate (exact too).
    `swap` evaluates d with b as the first (test) argument: for the model rows with
    rotate="shorter", so that ties rotate the test segment as in D_MT = D_TMᵀ.
    """
    best = np.full(len(ca), np.inf)
    arg = np.full(len(ca), -1, dtype=np.int64)
    cutoff = start_cutoff
    todo = np.asarray(rows, dtype=np.int64)
    while len(todo):
        cutoff *= 4.0
        sub = _k.BinnedTree(ca, la, todo)
        ii, jj = _k.candidate_pairs(sub, tree_b, cutoff)
        if swap:
            d = _k.pair_distances(
                cb, ub, lb, ca, ua, la, jj, ii, weight=weight, rotate_test=rotate_test
            )[:, 3]
        else:
            d = _k.pair_distances(
                ca, ua, la, cb, ub, lb, ii, jj, weight=weight, rotate_test=rotate_test
            )[:, 3]
        bmin, barg = _k.group_min(ii, d, len(ca))
        done_all = cutoff >= span
        settled = todo[(bmin[todo] <= cutoff) | done_all]
        best[settled] = bmin[settled]
        arg[settled] = jj[barg[settled]]
        todo = np.setdiff1d(todo, settled, assume_unique=True)
    return best, arg


def _ground_truth_matrix(gt: Any, test: Segments, model: Segments) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth as sorted unique (test index, model index) arrays."""
    p, q = len(test), len(model)
    arr = gt if isinstance(gt, np.ndarray) else None
    if arr is not None and arr.dtype == bool:
        if arr.shape != (p, q):
            raise OptionError(f"ground_truth matrix must have shape ({p}, {q}), got {arr.shape}")
        i, j = np.nonzero(arr)
        return i.astype(np.int64), j.astype(np.int64)
    pairs = list(gt)
    tix = {_id_str(v): k for k, v in enumerate(test.ids.tolist())}
    mix = {_id_str(v): k for k, v in enumerate(model.ids.tolist())}
    ii, jj = [], []
    for row in pairs:
        if len(row) != 2:
            raise OptionError(f"ground_truth pairs must be (test_id, model_id), got {row!r}")
        a, b = _id_str(row[0]), _id_str(row[1])
        if a not in tix:
            raise OptionError(
                f"ground truth names test id {row[0]!r}, which is not in the test set"
            )
        if b not in mix:
            raise OptionError(
                f"ground truth names model id {row[1]!r}, which is not in the model set"
            )
        ii.append(tix[a])
        jj.append(mix[b])
    if not ii:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    key = np.unique(np.asarray(ii, np.int64) * q + np.asarray(jj, np.int64))
    return key // q, key % q


def _id_str(v: Any) -> str:
    if isinstance(v, float | np.floating) and float(v).is_integer():
        return str(int(v))
    if isinstance(v, np.generic):
        v = v.item()
    return str(v)


def _confusion(cor_key: np.ndarray, gt_key: np.ndarray, p: int, q: int, suffix: str) -> dict:
    tp = int(np.isin(cor_key, gt_key, assume_unique=True).sum())
    fp = int(len(cor_key) - tp)
    fn = int(len(gt_key) - tp)
    tn = int(p * q - tp - fp - fn)
    return {
        f"tp_{suffix}": tp,
        f"fp_{suffix}": fp,
        f"fn_{suffix}": fn,
        f"tn_{suffix}": tn,
        f"detection_rate_{suffix}": detection_rate(p, q, fn, fp),
    }


def match_segments(
    test: Any,
    model: Any,
    *,
    weight: float = 10.0,
    sensitivity: float = 0.1,
    threshold: float | None = None,
    rotate: str = "shorter",
    denominator: str = "matched",
    ground_truth: Any = None,
    cutoff: float | None = None,
    threshold_range: tuple[float, float] | None = None,
    progress: Any = None,
) -> LineMatch:
    """Match a test set of 3D segments to a model set, both ways ([S-PG]; :ref:`alg-lines`).

    Parameters
    ----------
    test, model : Segments or array_like of shape (n, 2, 3)
        The Test and Model (reference) segments; each set non-empty, no zero-length
        segment, same CRS (when both declare one).
    weight : float, default 10
        Weight W of the squared angle distance (dimensionless).
    sensitivity : float, default 0.1
        A-priori sensitivity of the automatic threshold (metres).
    threshold : float, optional
        Fixed threshold δ (metres) for both directions instead of the automatic one
        (then ``threshold_found_* = False``).
    rotate : {"shorter", "test"}, default "shorter"
        Rotated segment of each pair; "shorter" is symmetric (D_MT = D_TMᵀ).
    denominator : {"matched", "all"}, default "matched"
        OLHD denominator: lengths over the matched pairs (a weighted mean) or over all
        segments of the second set (the literal eq. 7).
    ground_truth : (p, q) bool array or iterable of (test_id, model_id), optional
        True pairs, for TP/FP/FN/TN and the detection rate of each direction.
    cutoff : float, optional
        Initial pruning cutoff (metres, default 1.0, or the fixed threshold). Only a
        speed knob: results equal the dense computation for any cutoff.
    threshold_range : (float, float), optional
        Band (metres) the automatic thresholds are moved into (a knee below it is
        raised to its floor; one above it, or no knee, lowered to its ceiling), e.g.
        :func:`sampling_threshold_range` for two flight strips. Ignored with a fixed
        `threshold`. ``Threshold.reason`` says when a bound applied.

        .. versionadded:: 0.2
    progress : callable, optional
        Called with the fraction of the work done (0..1).

    Returns
    -------
    LineMatch

    Raises
    ------
    InvalidPointsError
        Empty set or non-finite coordinates.
    DegenerateGeometryError
        Zero-length segment.
    CRSMismatchError
        The two sets declare different CRSs.
    """
    weight = _check_weight(weight)
    sensitivity = check_positive(sensitivity, "sensitivity", allow_zero=True)
    check_choice(rotate, ("shorter", "test"), "rotate")
    check_choice(denominator, ("matched", "all"), "denominator")
    if threshold is not None:
        threshold = check_positive(threshold, "threshold", allow_zero=True)
    t = _as_segments(test, "test")
    m = _as_segments(model, "model")
    ensure_same_crs(t.crs, m.crs, what=("test", "model"))
    p, q = len(t), len(m)

    allpts = np.concatenate([t.start, t.end, m.start, m.end])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    origin = np.floor(lo)
    span = float(np.linalg.norm(hi - lo)) + 1.0
    ct, ut, lt = _k.prepare(t.start, t.end, origin)
    cm, um, lm = _k.prepare(m.start, m.end, origin)
    _check_lengths(lt, t, "test", span)
    _check_lengths(lm, m, "model", span)
    rotate_test = rotate == "test"

    if cutoff is None:
        c0 = threshold if threshold is not None and threshold > 0 else DEFAULT_CUTOFF
    else:
        c0 = check_positive(cutoff, "cutoff")
    tree_t = _k.BinnedTree(ct, lt)
    tree_m = _k.BinnedTree(cm, lm)

    def evaluate(c: float):
        ii, jj = _k.candidate_pairs(tree_t, tree_m, c)
        comp = _k.pair_distances(
            ct, ut, lt, cm, um, lm, ii, jj, weight=weight, rotate_test=rotate_test
        )
        if rotate_test:
            dmt = _k.pair_distances(
                cm, um, lm, ct, ut, lt, jj, ii, weight=weight, rotate_test=True
            )[:, 3]
        else:
            dmt = comp[:, 3]
        return ii, jj, comp, dmt

    ii, jj, comp, dmt = evaluate(c0)
    report(progress, 0.4)

    # exact nearest distances, both directions
    # (no pair within the cutoff leaves ii/jj empty: every index is then -1)
    near_tm, karg = _k.group_min(ii, comp[:, 3], p)
    arg_tm = np.where(karg >= 0, jj[np.maximum(karg, 0)] if len(jj) else -1, -1)
    near_mt, karg = _k.group_min(jj, dmt, q)
    arg_mt = np.where(karg >= 0, ii[np.maximum(karg, 0)] if len(ii) else -1, -1)
    todo_t = np.flatnonzero(~(near_tm <= c0))
    if len(todo_t):
        b, a = _nearest_exact(
            tree_m,
            ct,
            ut,
            lt,
            cm,
            um,
            lm,
            todo_t,
            c0,
            span,
            weight=weight,
            rotate_test=rotate_test,
            swap=False,
        )
        near_tm[todo_t], arg_tm[todo_t] = b[todo_t], a[todo_t]
    todo_m = np.flatnonzero(~(near_mt <= c0))
    if len(todo_m):
        b, a = _nearest_exact(
            tree_t,
            cm,
            um,
            lm,
            ct,
            ut,
            lt,
            todo_m,
            c0,
            span,
            weight=weight,
            rotate_test=rotate_test,
            swap=not rotate_test,
        )
        near_mt[todo_m], arg_mt[todo_m] = b[todo_m], a[todo_m]

    report(progress, 0.7)
    # thresholds
    if threshold is None:
        auto_tm = auto_threshold(near_tm, sensitivity=sensitivity)
        auto_mt = auto_threshold(near_mt, sensitivity=sensitivity)
        if threshold_range is not None:
            try:
                lo, hi = (float(v) for v in threshold_range)
            except (TypeError, ValueError):
                lo = hi = float("nan")
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi):
                raise OptionError(f"threshold_range must be 0 <= lo <= hi, got {threshold_range}")
            auto_tm = _clip_threshold(auto_tm, lo, hi)
            auto_mt = _clip_threshold(auto_mt, lo, hi)
    else:
        fixed = float(threshold)
        auto_tm = Threshold(
            fixed, False, np.sort(near_tm), np.diff(np.sort(near_tm), n=2), -1, "fixed"
        )
        auto_mt = Threshold(
            fixed, False, np.sort(near_mt), np.diff(np.sort(near_mt), n=2), -1, "fixed"
        )
    d_tm, d_mt = auto_tm.threshold, auto_mt.threshold
    c_final = c0
    if max(d_tm, d_mt) > c0:
        c_final = max(d_tm, d_mt)
        ii, jj, comp, dmt = evaluate(c_final)

    match_tm = comp[:, 3] <= d_tm
    match_mt = dmt <= d_mt
    tot_tm: float | None
    tot_mt: float | None
    if denominator == "all":
        tot_tm, tot_mt = float(lm.sum()), float(lt.sum())
    else:
        tot_tm = tot_mt = None
    o_tm = olhd(comp[match_tm, 3], lm[jj[match_tm]], total_weight=tot_tm)
    o_mt = olhd(dmt[match_mt], lt[ii[match_mt]], total_weight=tot_mt)
    lhd = (
        float(np.nanmax([o_tm, o_mt])) if not (np.isnan(o_tm) and np.isnan(o_mt)) else float("nan")
    )

    gt = None
    if ground_truth is not None:
        gi, gj = _ground_truth_matrix(ground_truth, t, m)
        gkey = gi * q + gj
        key = ii * q + jj
        gt = {
            **_confusion(key[match_tm], gkey, p, q, "tm"),
            **_confusion(key[match_mt], gkey, p, q, "mt"),
        }

    report(progress, 1.0)
    return LineMatch(
        p=p,
        q=q,
        threshold_tm=float(d_tm),
        threshold_mt=float(d_mt),
        threshold_found_tm=bool(auto_tm.found),
        threshold_found_mt=bool(auto_mt.found),
        olhd_tm=o_tm,
        olhd_mt=o_mt,
        lhd=lhd,
        n_pairs_tm=int(match_tm.sum()),
        n_pairs_mt=int(match_mt.sum()),
        weight=weight,
        sensitivity=sensitivity,
        rotate=rotate,
        denominator=denominator,
        cutoff=float(c_final),
        test_ids=t.ids,
        model_ids=m.ids,
        test_lengths=lt,
        model_lengths=lm,
        nearest_tm=near_tm,
        nearest_model=arg_tm,
        nearest_mt=near_mt,
        nearest_test=arg_mt,
        auto_tm=auto_tm,
        auto_mt=auto_mt,
        pair_test=ii,
        pair_model=jj,
        pair_components=comp,
        pair_d_mt=dmt,
        match_tm=match_tm,
        match_mt=match_mt,
        gao_leung_tm=primary_lhd(near_tm, lt),
        gao_leung_mt=primary_lhd(near_mt, lm),
        hausdorff_tm=float(near_tm.max()),
        hausdorff_mt=float(near_mt.max()),
        ground_truth=gt,
    )


def match_strips(test: Any, model: Any, *, auto: str = "sampling", threshold: float | None = None,
                 **options: Any) -> dict:
    """Match the edges of two flight strips: the ``LineMatch.to_dict()`` row of the pair.

    With ``auto="sampling"`` (and no fixed `threshold`) the automatic threshold
    of each direction is kept in the band of :func:`sampling_threshold_range`;
    the row then also has ``threshold_floor_m``, ``threshold_ceiling_m`` and
    ``threshold_rule_tm``/``threshold_rule_mt`` (how each threshold was found,
    e.g. ``"peak"`` or ``"no peak, lowered to the band"``). ``auto="knee"``
    (or sets without a ``point_spacing`` attribute) is the plain knee.
    `options` go to :func:`match_segments`.
    """
    check_choice(auto, ("sampling", "knee"), "auto")
    band = sampling_threshold_range(test, model) if auto == "sampling" and threshold is None \
        else None
    r = match_segments(test, model, threshold=threshold, threshold_range=band, **options)
    row = r.to_dict()
    if band is not None:
        row.update(threshold_floor_m=band[0], threshold_ceiling_m=band[1],
                   threshold_rule_tm=r.auto_tm.reason, threshold_rule_mt=r.auto_mt.reason)
    return row
