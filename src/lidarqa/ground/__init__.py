"""Ground filtering: point-based and segment-based progressive TIN densification.

- :class:`PTD` — Axelsson's progressive TIN densification (:ref:`alg-ptd`);
- :class:`SegmentPTD` — Lin & Zhang's segment-based PTD (:ref:`alg-segment-ptd`);
- :func:`filter_errors` — ISPRS type I / type II / total error and Cohen's kappa (:ref:`alg-isprs`);
- :func:`classify_ground` — the library function behind ``lidarqa ground``: return
  handling, noise exclusion, filtering and (optionally) evaluation on a
  :class:`~lidarqa.io.PointCloud`.

Examples
--------
>>> import numpy as np
>>> from lidarqa.ground import PTD
>>> g = np.mgrid[0:30, 0:30].reshape(2, -1).T.astype(float)
>>> pts = np.column_stack([g, 0.01 * g[:, 0]])
>>> bool(PTD(cell_size=20).ground_mask(pts).all())
True
"""

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import check_choice
from ..errors import DataQualityWarning, OptionError
from .auto import (
    ALS_PARAMS,
    ALS_SEGMENT_PARAMS,
    DENSE_ALS,
    FILTER_DENSITY,
    PRESET_CHOICES,
    PRESETS,
    SENSORS,
    CloudMeasures,
    auto_parameters,
    measure_cloud,
    parameter_notes,
    regime_reason,
    with_given,
)
from .features import SegmentFeatures, detect_object_segments, point_scatterness, segment_features
from .metrics import (
    FilterErrors,
    TerrainScores,
    filter_errors,
    filter_errors_from_counts,
    filter_errors_from_file,
    terrain_scores,
)
from .ptd import PTD, PTDResult, mirror_point, ptd_filter
from .segment_ptd import SegmentPTD, SegmentPTDResult, default_grow_radius, segment_ptd

__all__ = [
    "PTD",
    "PTDResult",
    "ptd_filter",
    "mirror_point",
    "SegmentPTD",
    "SegmentPTDResult",
    "segment_ptd",
    "default_grow_radius",
    "SegmentFeatures",
    "segment_features",
    "point_scatterness",
    "detect_object_segments",
    "FilterErrors",
    "filter_errors",
    "filter_errors_from_counts",
    "filter_errors_from_file",
    "TerrainScores",
    "terrain_scores",
    "GroundResult",
    "classify_ground",
    "ground_candidates",
    "kernels_cached",
    "relabel_classification",
    "METHODS",
    "NOISE_CLASSES",
    "ALS_PARAMS",
    "ALS_SEGMENT_PARAMS",
    "PRESETS",
    "PRESET_CHOICES",
    "CloudMeasures",
    "measure_cloud",
    "auto_parameters",
    "SENSORS",
    "DENSE_ALS",
    "FILTER_DENSITY",
]

METHODS = ("segment-ptd", "ptd")
NOISE_CLASSES = (7, 18)

@dataclass(frozen=True)
class GroundResult:
    """Result of :func:`classify_ground`.

    Attributes
    ----------
    ground_mask : ndarray of bool, shape (N,)
        True for points the filter labelled ground, in input order.
    candidates : ndarray of bool, shape (N,)
        Points the filter was allowed to label ground (returns, noise).
    method : str
    parameters : dict
        Every filter parameter that ran (round-trips through ``PTD(**p)`` / ``SegmentPTD(**p)``).
    details : PTDResult or SegmentPTDResult
    return_handling : str
        ``"last_only"``, ``"last_only_partial"`` (some return numbers were 0),
        ``"absent"`` or ``"all"``.
    n_excluded_noise : int
    evaluation : FilterErrors or None
    parameter_sources : dict
        Per parameter: ``"preset"`` (a constant of the preset or of the regime the
        measured figures chose), ``"given"`` (an explicit option) or ``"default"``
        (the filter class's default).
    parameter_notes : dict
        Per ``"preset"`` parameter: which preset, and (with ``preset="auto"``) the
        measured figures and thresholds that chose its regime.
    regime_reason : str or None
        With ``preset="auto"``: the measured figures and thresholds that chose `regime`.
    terrain : TerrainScores or None
        With `evaluate`: the terrain model of the result against the reference's
        (:func:`~lidarqa.ground.metrics.terrain_scores`), and whether the reference
        ground looks thinned.
    """

    ground_mask: np.ndarray
    candidates: np.ndarray
    method: str
    parameters: dict
    details: Any
    return_handling: str
    n_excluded_noise: int = 0
    evaluation: FilterErrors | None = None
    warnings: tuple[str, ...] = field(default=())
    preset: str | None = None
    parameter_sources: dict = field(default_factory=dict)
    measures: CloudMeasures | None = None
    regime: str | None = None
    terrain: TerrainScores | None = None
    parameter_notes: dict = field(default_factory=dict)
    regime_reason: str | None = None

    @property
    def n_ground(self) -> int:
        """Number of points classified as ground."""
        return int(self.ground_mask.sum())

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        d = {
            "method": self.method,
            "n_points": int(self.ground_mask.size),
            "n_candidates": int(self.candidates.sum()),
            "n_ground": self.n_ground,
            "ground_fraction": (self.n_ground / self.ground_mask.size)
            if self.ground_mask.size
            else None,
            "return_handling": self.return_handling,
            "n_excluded_noise": self.n_excluded_noise,
            "filter": self.details.to_dict() if self.details is not None else None,
            "warnings": list(self.warnings),
            "preset": self.preset,
            "regime": self.regime,
            "regime_reason": self.regime_reason,
            "measured": self.measures.to_dict() if self.measures is not None else None,
            "parameter_sources": dict(self.parameter_sources),
            "parameter_notes": dict(self.parameter_notes),
        }
        if self.evaluation is not None:
            d.update(_evaluation_dict(self.evaluation))
        if self.terrain is not None:
            d["terrain"] = self.terrain.to_dict()
        return d


def _evaluation_dict(e: FilterErrors) -> dict[str, Any]:
    full = e.to_dict()
    return {k: full[k] for k in ("type_i", "type_ii", "total", "kappa", "n_evaluated", "confusion")}


def kernels_cached() -> bool:
    """True when numba's on-disk cache holds the ground filter's compiled kernels.

    The kernels are compiled with ``cache=True``: the first run after installing
    (or upgrading) spends 20-30 s compiling, later runs load them. The CLI uses
    this to say so before a first run. It asks numba where the TIN kernels'
    cache index lives and whether it is valid for the installed source.
    """
    from .._jitcache import kernels_cached as _cached
    from . import _tin

    return _cached(_tin._judge_kernel, _tin._setup_kernel)


def ground_candidates(
    cloud: Any,
    *,
    last_returns_only: bool = True,
    exclude_classes: Any = NOISE_CLASSES,
) -> tuple[np.ndarray, str, int, list[str]]:
    """Points that may be ground: last/single returns, not in `exclude_classes`.

    Returns ``(mask, return_handling, n_excluded_noise, warning_messages)``. When
    return numbers are present but partly zero (real IGN tiles), points with a
    zero return number are kept as candidates and a
    :class:`~lidarqa.errors.DataQualityWarning` is issued. All-zero return
    numbers mean "not recorded" and are ignored.
    """
    n = len(cloud)
    mask = np.ones(n, dtype=bool)
    msgs: list[str] = []
    handling = "all"
    rn = cloud.fields.get("return_number")
    nr = cloud.fields.get("number_of_returns")
    if last_returns_only:
        if rn is None or nr is None or n == 0:
            handling = "absent"
        else:
            rn = np.asarray(rn)  # compared in their own (unsigned) type: no copies
            nr = np.asarray(nr)
            zero = (rn == 0) | (nr == 0)
            if zero.all():
                handling = "absent"
            else:
                handling = "last_only"
                if zero.any():
                    handling = "last_only_partial"
                    msg = (
                        f"{int(zero.sum()):,} of {n:,} points have return number or number of "
                        "returns 0; they are treated as possible last returns"
                    )
                    warnings.warn(msg, DataQualityWarning, stacklevel=3)
                    msgs.append(msg)
                mask &= zero | (rn >= nr)
    n_noise = 0
    if (
        exclude_classes is not None
        and len(list(exclude_classes))
        and cloud.classification is not None
    ):
        noise = np.isin(np.asarray(cloud.classification), np.asarray(list(exclude_classes)))
        n_noise = int(noise.sum())
        mask &= ~noise
    return mask, handling, n_noise, msgs


def relabel_classification(
    classification: Any, ground_mask: Any, *, ground_class: int = 2, demoted_class: int = 1
) -> np.ndarray:
    """New classification: ground → `ground_class`, former `ground_class` → `demoted_class`.

    All other classes are kept. The input is not modified; the dtype is preserved.
    """
    cls = np.asarray(classification)
    g = np.asarray(ground_mask, dtype=bool)
    out = cls.copy()
    out[(cls == ground_class) & ~g] = demoted_class
    out[g] = ground_class
    return out


def classify_ground(
    cloud: Any,
    *,
    method: str = "segment-ptd",
    last_returns_only: bool = True,
    exclude_classes: Any = NOISE_CLASSES,
    evaluate: bool = False,
    ignore_classes: Any = None,
    preset: str | None = "auto",
    sensor: str = "auto",
    progress: Any = None,
    **params: Any,
) -> GroundResult:
    """Detect ground points in a point cloud from geometry and return numbers alone.

    Existing ground labels are never used as input; only `exclude_classes` (noise
    by default) are kept out of the candidates.

    Parameters
    ----------
    cloud : PointCloud or ndarray of shape (N, 3)
        Point cloud (coordinates in metres) or a bare point array.
    method : {"segment-ptd", "ptd"}, default "segment-ptd"
    last_returns_only : bool, default True
        When return numbers are present, only last and single returns can be ground.
    exclude_classes : sequence of int, default (7, 18)
        Classes never considered (noise).
    evaluate : bool, default False
        Compare with the cloud's own classification (class 2 = ground, everything
        else object; `ignore_classes` left out) and attach :class:`FilterErrors`
        and the terrain-model scores (:class:`TerrainScores`).
    ignore_classes : sequence of int, optional
        Reference classes excluded from the evaluation.
    preset : {"auto", "als", "mls"} or None, default "auto"
        ``"auto"``: measure the candidates (density, returns, sensor, slopes,
        object footprints, see :func:`measure_cloud`) and choose the parameters
        from those figures (:func:`auto_parameters`). ``"als"``/``"mls"``: start
        from :data:`PRESETS` ``[preset]``; None: the class defaults (= ``"mls"``).
        Explicit `params` always override.
    sensor : {"auto", "als", "mls"}, default "auto"
        With ``preset="auto"``: the kind of acquisition if known (overrides the
        measured one).
    progress : callable, optional
        Called with the estimated fraction of the work done (0..1), e.g. to show
        a progress bar; the filter itself never prints.
    **params
        Filter parameters of :class:`SegmentPTD` or :class:`PTD` (m, degrees).

    Returns
    -------
    GroundResult
    """
    from ..io import PointCloud

    check_choice(method, METHODS, "method")
    check_choice(sensor, SENSORS, "sensor")
    if preset is not None:
        check_choice(preset, PRESET_CHOICES, "preset")
    if not isinstance(cloud, PointCloud):
        from .._validate import as_points

        cloud = PointCloud(as_points(cloud, "cloud"))
    cand, handling, n_noise, msgs = ground_candidates(
        cloud, last_returns_only=last_returns_only, exclude_classes=exclude_classes
    )
    # the filter's distances, slopes and densities are metric: a cloud in feet is
    # filtered in metres (the labels are the same per point, the input is not modified)
    from ..io.crs import crs_name, metre_factors

    xyz = cloud.xyz
    fh, fv = metre_factors(cloud.crs)
    if fh != 1.0 or fv != 1.0:
        xyz = xyz * np.array([fh, fh, fv])
        msgs = [*msgs, f"filtered in metres: x, y scaled by {fh:.10g} and z by {fv:.10g} "
                       f"(the units of {crs_name(cloud.crs)})"]
    given = dict(params)
    measures = None
    regime = None
    chosen: dict[str, Any] = {}
    sources: dict[str, str] = {}
    if preset == "auto":
        fields = {
            k: np.asarray(v)[cand]
            for k, v in cloud.fields.items()
            if k in ("return_number", "number_of_returns", "scan_angle", "scan_angle_rank")
        }
        measures = measure_cloud(xyz[cand], fields=fields)
        chosen, sources, regime = auto_parameters(measures, method, sensor=sensor)
    elif preset is not None:
        chosen = dict(PRESETS[preset][method])
        sources = dict.fromkeys(chosen, "preset")
    params = with_given(chosen, given)
    sources = {k: v for k, v in sources.items() if k in params}
    cls_type = SegmentPTD if method == "segment-ptd" else PTD
    try:
        filt = cls_type(**params)
    except TypeError as exc:
        raise OptionError(f"invalid parameter for method {method!r}: {exc}") from None
    sources = {
        k: ("given" if k in given else sources.get(k, "default")) for k in filt.to_dict()
    }
    reason = None
    if measures is not None and regime is not None:
        notes = parameter_notes(measures, sources, regime, sensor=sensor)
        reason = regime_reason(measures, regime, sensor=sensor)
    else:
        notes = {k: f"constant of the {preset} preset" for k, v in sources.items() if v == "preset"}
    details = filt.run(xyz, candidates=cand, progress=progress)
    ground = details.ground_mask
    evaluation = terrain = None
    if evaluate:
        if cloud.classification is None:
            raise OptionError(
                "evaluate needs a classification field in the input to use as reference"
            )
        ref = np.asarray(cloud.classification)
        mask = None
        if ignore_classes:
            mask = ~np.isin(ref, np.asarray(list(ignore_classes)))
        evaluation = filter_errors(ref == 2, ground, mask=mask)
        terrain = terrain_scores(xyz, ground, ref == 2, mask=mask)
    return GroundResult(
        ground_mask=ground,
        candidates=cand,
        method=method,
        parameters=filt.to_dict(),
        details=details,
        return_handling=handling,
        n_excluded_noise=n_noise,
        evaluation=evaluation,
        warnings=tuple(msgs),
        preset=preset,
        parameter_sources=sources,
        measures=measures,
        regime=regime,
        terrain=terrain,
        parameter_notes=notes,
        regime_reason=reason,
    )
