"""ISPRS filter-test error measures (Sithole & Vosselman 2004), :ref:`alg-isprs`.

Type I (ground rejected), type II (object accepted as ground), total error and
Cohen's kappa, from two boolean label arrays or from the four counts of the
2×2 cross table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidPointsError

__all__ = ["FilterErrors", "filter_errors", "filter_errors_from_counts", "filter_errors_from_file"]


@dataclass(frozen=True)
class FilterErrors:
    """The 2×2 cross table of a ground filter against a reference, and its error measures.

    Attributes
    ----------
    a, b, c, d : int
        Counts: reference ground predicted ground (a) / object (b); reference
        object predicted ground (c) / object (d).
    type_i : float
        b / (a + b), fraction of reference ground rejected (nan without reference ground).
    type_ii : float
        c / (c + d), fraction of reference objects accepted as ground (nan without objects).
    total : float
        (b + c) / n.
    kappa : float
        Cohen's kappa (nan when the chance agreement is 1).
    p_o, p_e : float
        Observed and chance agreement.
    """

    a: int
    b: int
    c: int
    d: int
    type_i: float
    type_ii: float
    total: float
    kappa: float
    p_o: float
    p_e: float

    @property
    def n(self) -> int:
        """Number of evaluated points."""
        return self.a + self.b + self.c + self.d

    @property
    def confusion(self) -> np.ndarray:
        """The 2×2 table ``[[a, b], [c, d]]`` (rows: reference ground, object)."""
        return np.array([[self.a, self.b], [self.c, self.d]], dtype=np.int64)

    @property
    def type_i_pct(self) -> float:
        """Type I error (ground rejected) in percent."""
        return 100.0 * self.type_i

    @property
    def type_ii_pct(self) -> float:
        """Type II error (non-ground accepted) in percent."""
        return 100.0 * self.type_ii

    @property
    def total_pct(self) -> float:
        """Total error in percent."""
        return 100.0 * self.total

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dictionary: fractions, percentages, ``n_evaluated`` and ``confusion``."""
        return {
            "type_i": self.type_i,
            "type_ii": self.type_ii,
            "total": self.total,
            "kappa": self.kappa,
            "type_i_pct": self.type_i_pct,
            "type_ii_pct": self.type_ii_pct,
            "total_pct": self.total_pct,
            "p_o": self.p_o,
            "p_e": self.p_e,
            "n_evaluated": self.n,
            "confusion": {
                "ref_ground_pred_ground": self.a,
                "ref_ground_pred_object": self.b,
                "ref_object_pred_ground": self.c,
                "ref_object_pred_object": self.d,
            },
        }


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


def filter_errors_from_counts(a: int, b: int, c: int, d: int) -> FilterErrors:
    """Error measures from the four cross-table counts.

    Parameters
    ----------
    a, b, c, d : int
        Reference ground → predicted ground (a) / object (b); reference object →
        predicted ground (c) / object (d). Non-negative.

    Returns
    -------
    FilterErrors

    Raises
    ------
    InvalidPointsError
        If a count is negative or all counts are zero.

    Examples
    --------
    >>> e = filter_errors_from_counts(40, 10, 5, 45)
    >>> round(e.type_i, 2), round(e.type_ii, 2), round(e.total, 2), round(e.kappa, 2)
    (0.2, 0.1, 0.15, 0.7)
    """
    counts = [int(v) for v in (a, b, c, d)]
    if min(counts) < 0:
        raise InvalidPointsError(f"counts must be >= 0, got {counts}")
    a, b, c, d = counts
    n = a + b + c + d
    if n == 0:
        raise InvalidPointsError("cannot compute filter errors of zero points")
    e, f, g, h = a + b, c + d, a + c, b + d
    p_o = (a + d) / n
    p_e = (e * g + f * h) / (n * n)
    kappa = (p_o - p_e) / (1.0 - p_e) if p_e < 1.0 else math.nan
    return FilterErrors(
        a=a,
        b=b,
        c=c,
        d=d,
        type_i=_ratio(b, e),
        type_ii=_ratio(c, f),
        total=(b + c) / n,
        kappa=kappa,
        p_o=p_o,
        p_e=p_e,
    )


def filter_errors(ref_ground: Any, pred_ground: Any, *, mask: Any = None) -> FilterErrors:
    """ISPRS type I / type II / total error and Cohen's kappa of a ground filter.

    Parameters
    ----------
    ref_ground : array_like of bool, shape (N,)
        Reference labels, True = ground.
    pred_ground : array_like of bool, shape (N,)
        Filter output, True = ground.
    mask : array_like of bool, shape (N,), optional
        Only points where `mask` is True are evaluated (e.g. to ignore some classes).

    Returns
    -------
    FilterErrors

    Raises
    ------
    InvalidPointsError
        If the arrays differ in length or no point is evaluated.

    Examples
    --------
    >>> e = filter_errors([True, True, False, False], [True, False, False, False])
    >>> e.type_i, e.type_ii, e.total
    (0.5, 0.0, 0.25)
    """
    ref = np.asarray(ref_ground)
    pred = np.asarray(pred_ground)
    if ref.ndim != 1 or pred.ndim != 1 or ref.shape != pred.shape:
        raise InvalidPointsError(
            "ref_ground and pred_ground must be 1-D of the same length, "
            f"got {ref.shape} and {pred.shape}"
        )
    ref = ref.astype(bool)
    pred = pred.astype(bool)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != ref.shape:
            raise InvalidPointsError(f"mask must have shape {ref.shape}, got {m.shape}")
        m = m.astype(bool)
        ref, pred = ref[m], pred[m]
    a = int(np.count_nonzero(ref & pred))
    b = int(np.count_nonzero(ref & ~pred))
    c = int(np.count_nonzero(~ref & pred))
    d = int(np.count_nonzero(~ref & ~pred))
    return filter_errors_from_counts(a, b, c, d)


def filter_errors_from_file(
    reference: Any,
    pred_ground: Any,
    *,
    ground_class: int = 2,
    ignore_classes: Any = None,
) -> FilterErrors:
    """Filter errors against the classification of a reference cloud or file.

    Parameters
    ----------
    reference : str, path or PointCloud
        Reference point cloud, same points in the same order as `pred_ground`.
    pred_ground : array_like of bool, shape (N,)
        Filter output, True = ground.
    ground_class : int, default 2
        Reference class that means ground; every other class is an object.
    ignore_classes : sequence of int, optional
        Reference classes left out of the evaluation.

    Returns
    -------
    FilterErrors
    """
    from ..io import PointCloud, read

    cloud = reference if isinstance(reference, PointCloud) else read(reference)
    cls = cloud.classification
    if cls is None:
        raise InvalidPointsError("the reference cloud has no classification field")
    cls = np.asarray(cls)
    mask = None
    if ignore_classes:
        mask = ~np.isin(cls, np.asarray(list(ignore_classes)))
    return filter_errors(cls == ground_class, pred_ground, mask=mask)
