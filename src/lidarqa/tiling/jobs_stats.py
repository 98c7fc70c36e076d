"""Statistics of a whole catalog merged exactly from per-chunk sufficient statistics.

A job on a catalog runs chunk by chunk, possibly on several machines, and the
chunks finish in any order. Its figures must not depend on how the area was cut
or on which chunk finished first, and they must be the figures of one
in-memory run over the whole area. Averaging per-chunk averages does neither,
and even plain floating-point sums depend on the order of addition. So every
statistic here is built from *sufficient statistics* that merge exactly:

* counts (ISPRS cross-table counts, histogram bins, outlier counts) are Python
  integers;
* sums and sums of squares are kept as exact rationals
  (:class:`fractions.Fraction`). A chunk computes the exact sum of its values
  with :func:`math.fsum` (correctly rounded, fast) plus the exact remainders
  (``fsum`` of the values minus what was already taken, repeated until the
  remainder is zero), and squares are split into two floats whose sum is the
  exact square (Veltkamp/Dekker). Adding Fractions is exact, associative and
  commutative;
* extremes (max |residual|) merge with ``max``, which is exact.

Final figures (mean, RMSE, standard deviation) are computed once from the
merged exact sums and rounded once, so a catalog run gives bit-for-bit the same
numbers whatever the chunk size, the number of workers or the completion order,
and the same numbers as one chunk holding every value. They agree with the
in-memory kernels (``residual_statistics``, ``compare_heights``,
``WTestResult.to_dict``) to floating-point round-off (those sum in array order).

Each point or reference point must be counted by exactly one chunk: the chunk
whose core contains it (see :mod:`lidarqa.tiling.jobs_vector` for the rule).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from ..errors import InvalidPointsError

__all__ = [
    "ConfusionCounts",
    "Histogram",
    "Moments",
    "ResidualMoments",
    "WStatistics",
    "exact_sum",
    "exact_sum_of_squares",
    "merge",
]

_ZERO = Fraction(0)
_SPLIT = 134217729.0  # 2**27 + 1, Veltkamp splitter for float64
# Outside [_TINY, _HUGE] Dekker's product could overflow or underflow: exact Fraction path.
_HUGE = 1e150
_TINY = 1e-140


def _finite_1d(values: Any, name: str) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if not np.isfinite(v).all():
        raise InvalidPointsError(f"{name} contain NaN or infinite values")
    return v


def _exact_fsum(parts: Sequence[np.ndarray]) -> Fraction:
    """Exact sum of the float64 values in ``parts`` as a Fraction."""
    values = np.concatenate(parts).tolist()
    if not values:
        return _ZERO
    taken: list[float] = []
    # Each fsum is the correctly rounded remainder, so the remainder loses at
    # least 53 bits per pass and becomes exactly zero after a few passes.
    while True:
        r = math.fsum(values + [-t for t in taken])
        if r == 0.0:
            break
        taken.append(r)
    return sum((Fraction(t) for t in taken), _ZERO)


def exact_sum(values: Any) -> Fraction:
    """Exact sum of float values, as a :class:`fractions.Fraction`.

    Parameters
    ----------
    values : array_like of float
        Finite values.

    Examples
    --------
    >>> float(exact_sum([1e20, 1.0, -1e20]))
    1.0
    """
    return _exact_fsum([_finite_1d(values, "values")])


def exact_sum_of_squares(values: Any) -> Fraction:
    """Exact sum of squares of float values, as a :class:`fractions.Fraction`.

    Each x² is split into ``p + e`` with ``p = fl(x*x)`` and ``e`` the exact
    rounding error (Dekker's product), so no bit is lost before summing.

    Examples
    --------
    >>> exact_sum_of_squares([0.1, 0.2]) == Fraction(0.1) ** 2 + Fraction(0.2) ** 2
    True
    """
    x = _finite_1d(values, "values")
    ax = np.abs(x)
    big = (ax > _HUGE) | ((ax < _TINY) & (ax > 0))
    out = _ZERO
    if big.any():
        out = sum((Fraction(v) ** 2 for v in x[big].tolist()), _ZERO)
        x = x[~big]
    c = _SPLIT * x
    hi = c - (c - x)
    lo = x - hi
    p = x * x
    e = ((hi * hi - p) + 2.0 * hi * lo) + lo * lo
    return out + _exact_fsum([p, e])


def _to_float(q: Fraction) -> float:
    return float(q)  # correctly rounded


# ------------------------------------------------------------------ moments


@dataclass(frozen=True)
class Moments:
    """Mergeable n, Σx, Σx², min, max and max|x| of one variable.

    Build with :meth:`of`, combine with ``+`` (or :func:`merge`); the result
    does not depend on how the values were split or in which order the parts
    are added.
    """

    n: int = 0
    total: Fraction = _ZERO
    total_sq: Fraction = _ZERO
    min: float = math.inf
    max: float = -math.inf

    @classmethod
    def of(cls, values: Any) -> Moments:
        """Sufficient statistics of finite ``values`` (any shape, flattened)."""
        v = _finite_1d(values, "values")
        if v.size == 0:
            return cls()
        return cls(
            n=int(v.size),
            total=exact_sum(v),
            total_sq=exact_sum_of_squares(v),
            min=float(v.min()),
            max=float(v.max()),
        )

    def __add__(self, other: Moments) -> Moments:
        if not isinstance(other, Moments):
            return NotImplemented
        return Moments(
            n=self.n + other.n,
            total=self.total + other.total,
            total_sq=self.total_sq + other.total_sq,
            min=min(self.min, other.min),
            max=max(self.max, other.max),
        )

    @property
    def mean(self) -> float:
        return _to_float(self.total / self.n) if self.n else math.nan

    def rms(self, *, ddof: int = 0) -> float:
        """sqrt(Σx² / (n - ddof)); NaN when n <= ddof."""
        return math.sqrt(_to_float(self.total_sq / (self.n - ddof))) if self.n > ddof else math.nan

    def variance(self, *, ddof: int = 1) -> float:
        """(Σx² - (Σx)²/n) / (n - ddof), computed exactly then rounded once."""
        if self.n <= ddof:
            return math.nan
        ss = self.total_sq - self.total * self.total / self.n
        return _to_float(ss / (self.n - ddof))

    def std(self, *, ddof: int = 1) -> float:
        var = self.variance(ddof=ddof)
        return math.sqrt(var) if var == var else math.nan

    @property
    def max_abs(self) -> float:
        return max(abs(self.min), abs(self.max)) if self.n else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "mean": self.mean,
            "std": self.std(),
            "rms": self.rms(),
            "min": self.min if self.n else math.nan,
            "max": self.max if self.n else math.nan,
            "max_abs": self.max_abs,
        }


@dataclass(frozen=True)
class ResidualMoments:
    """Mergeable per-axis residual statistics of a check-point or line job.

    ``axes`` holds one :class:`Moments` per axis x, y, z; an axis without data
    (e.g. x and y of a vertical-only check) is empty. The figures match
    :func:`lidarqa.accuracy.checkpoints.residual_statistics` (RMSE with divisor
    n - ddof, sample std with n - 1).
    """

    axes: tuple[Moments, Moments, Moments] = (Moments(), Moments(), Moments())

    @classmethod
    def of(cls, residuals: Any) -> ResidualMoments:
        """From an (n, 3) array of residuals dx, dy, dz (m); an all-NaN column is skipped."""
        r = np.asarray(residuals, dtype=np.float64)
        if r.ndim != 2 or r.shape[1] != 3:
            raise InvalidPointsError(f"residuals must have shape (n, 3), got {r.shape}")
        axes = []
        for k in range(3):
            col = r[:, k]
            if col.size and np.isnan(col).all():
                axes.append(Moments())
            else:
                axes.append(Moments.of(col))
        return cls(axes=tuple(axes))  # type: ignore[arg-type]

    def __add__(self, other: ResidualMoments) -> ResidualMoments:
        if not isinstance(other, ResidualMoments):
            return NotImplemented
        axes = tuple(a + b for a, b in zip(self.axes, other.axes, strict=True))
        return ResidualMoments(axes=axes)  # type: ignore[arg-type]

    @property
    def n(self) -> int:
        return max(a.n for a in self.axes)

    def rmse(self, *, ddof: int = 0) -> np.ndarray:
        return np.array([a.rms(ddof=ddof) for a in self.axes])

    def to_dict(self, *, ddof: int = 0) -> dict[str, Any]:
        """Same keys as ``ResidualStats.to_dict()``."""
        rmse = self.rmse(ddof=ddof)
        out: dict[str, Any] = {"n": self.n}
        for i, ax in enumerate("xyz"):
            out[f"rmse_{ax}"] = float(rmse[i])
        out["rmse_h"] = float(math.hypot(rmse[0], rmse[1]))
        out["rmse_3d"] = float(math.sqrt(rmse[0] ** 2 + rmse[1] ** 2 + rmse[2] ** 2))
        for name, fn in (
            ("mean", lambda m: m.mean),
            ("std", lambda m: m.std(ddof=1)),
            ("max_abs", lambda m: m.max_abs),
        ):
            for i, ax in enumerate("xyz"):
                out[f"{name}_{ax}"] = float(fn(self.axes[i]))
        return out


# ------------------------------------------------------------------ ISPRS counts


@dataclass(frozen=True)
class ConfusionCounts:
    """The ISPRS 2×2 cross table as integer counts (a, b, c, d), merged by addition.

    a: reference ground predicted ground, b: reference ground predicted object,
    c: reference object predicted ground, d: reference object predicted object.
    """

    a: int = 0
    b: int = 0
    c: int = 0
    d: int = 0

    @classmethod
    def of(cls, ref_ground: Any, pred_ground: Any, *, mask: Any = None) -> ConfusionCounts:
        """Counts from two boolean arrays (optionally restricted to ``mask``, e.g. core points)."""
        r = np.asarray(ref_ground, dtype=bool).reshape(-1)
        p = np.asarray(pred_ground, dtype=bool).reshape(-1)
        if r.shape != p.shape:
            raise InvalidPointsError(
                f"ref_ground and pred_ground must have the same length, got {r.size} and {p.size}"
            )
        if mask is not None:
            m = np.asarray(mask, dtype=bool).reshape(-1)
            if m.shape != r.shape:
                raise InvalidPointsError(f"mask must have length {r.size}, got {m.size}")
            r, p = r[m], p[m]
        return cls(
            a=int(np.count_nonzero(r & p)),
            b=int(np.count_nonzero(r & ~p)),
            c=int(np.count_nonzero(~r & p)),
            d=int(np.count_nonzero(~r & ~p)),
        )

    def __add__(self, other: ConfusionCounts) -> ConfusionCounts:
        if not isinstance(other, ConfusionCounts):
            return NotImplemented
        return ConfusionCounts(
            self.a + other.a, self.b + other.b, self.c + other.c, self.d + other.d
        )

    @property
    def n(self) -> int:
        return self.a + self.b + self.c + self.d

    def errors(self) -> Any:
        """:class:`lidarqa.ground.metrics.FilterErrors` of the merged counts."""
        from ..ground.metrics import filter_errors_from_counts

        return filter_errors_from_counts(self.a, self.b, self.c, self.d)

    def to_dict(self) -> dict[str, Any]:
        return self.errors().to_dict()


# ------------------------------------------------------------------ histograms


@dataclass(frozen=True, eq=False)
class Histogram:
    """Counts in fixed bins; parts merge only when their edges are identical.

    Values below the first edge or at/above the last one are counted in
    ``under`` and ``over`` so nothing is silently lost.
    """

    edges: tuple[float, ...]
    counts: tuple[int, ...]
    under: int = 0
    over: int = 0

    @classmethod
    def of(cls, values: Any, edges: Sequence[float]) -> Histogram:
        e = np.asarray(edges, dtype=np.float64).reshape(-1)
        if e.size < 2 or not np.all(np.diff(e) > 0) or not np.isfinite(e).all():
            raise InvalidPointsError(
                "histogram edges must be >= 2 finite, strictly increasing values"
            )
        v = _finite_1d(values, "values")
        idx = np.searchsorted(e, v, side="right") - 1  # bin i holds [e[i], e[i+1])
        inside = (idx >= 0) & (idx < e.size - 1)
        counts = np.bincount(idx[inside], minlength=e.size - 1)
        return cls(
            edges=tuple(e.tolist()),
            counts=tuple(int(c) for c in counts),
            under=int(np.count_nonzero(idx < 0)),
            over=int(np.count_nonzero(idx >= e.size - 1)),
        )

    def __add__(self, other: Histogram) -> Histogram:
        if not isinstance(other, Histogram):
            return NotImplemented
        if self.edges != other.edges:
            raise InvalidPointsError("cannot merge histograms with different bin edges")
        return Histogram(
            edges=self.edges,
            counts=tuple(a + b for a, b in zip(self.counts, other.counts, strict=True)),
            under=self.under + other.under,
            over=self.over + other.over,
        )

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Histogram) and (
            self.edges, self.counts, self.under, self.over
        ) == (other.edges, other.counts, other.under, other.over)

    def __hash__(self) -> int:
        return hash((self.edges, self.counts, self.under, self.over))

    def to_dict(self) -> dict[str, Any]:
        return {"edges": list(self.edges), "counts": list(self.counts), "under": self.under,
                "over": self.over}


# ------------------------------------------------------------------ w-tests


@dataclass(frozen=True)
class WStatistics:
    """Mergeable summary of w-test values (``WTestResult.to_dict()`` figures).

    Exact only when each w is fixed by its own reference point, i.e. the
    w-test without a common offset (``estimate_offset=False``, the default):
    then data snooping is the threshold |w| > k and each chunk can flag its own
    points. With an estimated offset the w values depend on every point and a
    catalog job must gather Δh and σ and test them once.
    """

    critical: float = math.nan
    all: Moments = field(default_factory=Moments)
    kept: Moments = field(default_factory=Moments)
    n_lt1: int = 0
    n_lt2: int = 0

    @classmethod
    def of(cls, w: Any, outlier: Any, *, critical: float) -> WStatistics:
        wv = np.asarray(w, dtype=np.float64).reshape(-1)
        out = np.asarray(outlier, dtype=bool).reshape(-1)
        if out.shape != wv.shape:
            raise InvalidPointsError(f"outlier must have length {wv.size}, got {out.size}")
        ok = np.isfinite(wv)
        a = np.abs(wv[ok])
        return cls(
            critical=float(critical),
            all=Moments.of(wv[ok]),
            kept=Moments.of(wv[ok & ~out]),
            n_lt1=int(np.count_nonzero(a < 1)),
            n_lt2=int(np.count_nonzero(a < 2)),
        )

    def __add__(self, other: WStatistics) -> WStatistics:
        if not isinstance(other, WStatistics):
            return NotImplemented
        crit = self.critical if math.isfinite(self.critical) else other.critical
        if math.isfinite(other.critical) and other.critical != crit:
            raise InvalidPointsError("cannot merge w-statistics tested at different levels")
        return WStatistics(
            critical=crit,
            all=self.all + other.all,
            kept=self.kept + other.kept,
            n_lt1=self.n_lt1 + other.n_lt1,
            n_lt2=self.n_lt2 + other.n_lt2,
        )

    @property
    def n_outliers(self) -> int:
        return self.all.n - self.kept.n

    def to_dict(self) -> dict[str, Any]:
        n = self.all.n
        return {
            "critical": self.critical,
            "std": self.all.std(ddof=1),
            "std_without_outliers": self.kept.std(ddof=1),
            "frac_lt1": self.n_lt1 / n if n else math.nan,
            "frac_lt2": self.n_lt2 / n if n else math.nan,
            "n_outliers": self.n_outliers,
        }


def merge(parts: Iterable[Any]) -> Any:
    """Merge per-chunk statistics (all of one type) into the whole-area statistic.

    ``None`` parts (failed or empty chunks) are skipped. The result is the same
    for any order of ``parts``.

    Raises
    ------
    InvalidPointsError
        If there is nothing to merge.
    """
    items = [p for p in parts if p is not None]
    if not items:
        raise InvalidPointsError("no statistics to merge (every chunk failed or was empty)")
    out = items[0]
    for p in items[1:]:
        out = out + p
    return out
