"""Human labels and units for the keys the report shows: one table, used everywhere.

The report's Parameters section and its figure tables show each value under a
label with its unit (and the config or JSON key beside it, so a reviewer can
find it in ``report.json``). Keys are looked up by their dotted path with the
most specific match first: ``check.n`` before ``n``. Fractions (``scale`` 100)
are shown in percent.

A key missing here is shown under its raw name; the tests walk a demo report and
every registered analysis's keys and parameters and fail on any such key. An
analysis module may bring its own labels: ``register(..., labels={...})`` adds
them here (:func:`add`), so a new analysis stays one file.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Label", "LABELS", "add", "lookup", "label_text", "display_value", "labelled_rows"]


@dataclass(frozen=True)
class Label:
    """A key's label, its unit as shown and the display factor of its values."""

    text: str
    unit: str = ""
    scale: float = 1.0  # 100 for fractions shown in percent


def _l(text: str, unit: str = "", scale: float = 1.0) -> Label:
    return Label(text, unit, scale)


M, DEG, PCT, N = "m", "°", "%", ""

#: key (last component, or a dotted suffix for context) -> Label
LABELS: dict[str, Label] = {
    # framework keys of every analysis
    "title": _l("section title"),
    "enabled": _l("enabled"),
    "name": _l("analysis name"),
    "cloud": _l("point cloud input"),
    "classes": _l("point classes used"),
    "source_id": _l("flight strips (point_source_id)"),
    "source_ids": _l("flight strips (point_source_id)"),
    "format": _l("vector output format"),
    "method": _l("filter method"),
    "evaluate": _l("score against the input's classes"),
    "ignore_classes": _l("classes left out of the score"),
    "write_cloud": _l("write the classified cloud"),
    "cloud_format": _l("classified cloud format"),
    "test": _l("test segments"),
    "model": _l("model segments"),
    "edges": _l("edge-extraction options"),
    "ground_truth": _l("true pairs file"),
    "measured": _l("measured points input"),
    "check": _l("check points input"),
    "vertical": _l("vertical check against a TIN of the cloud"),
    "map": _l("map points input"),
    "reference": _l("reference heights input"),
    "map_spacing": _l("map points along polygon boundaries every", M),
    # nested tables
    "check.from_cloud": _l("check points sampled from"),
    "check.classes": _l("classes of the sampled check points"),
    "check.source_id": _l("flight strips of the sampled check points"),
    "check.n": _l("number of check points sampled"),
    "check.seed": _l("random seed of the sample"),
    "check.min_spacing": _l("minimum spacing between check points", M),
    "map.grid": _l("map-point grid spacing", M),
    "map.min_points": _l("laser points needed within grid/2 to keep a map point"),
    "reference.from_cloud": _l("reference heights held apart from the cloud"),
    "reference.fraction": _l("share of the points held apart as reference", PCT, 100.0),
    "reference.seed": _l("random seed of the split"),
    "reference.max_points": _l("at most this many reference points"),
    # ground filter parameters
    "last_returns_only": _l("only last/single returns can be ground"),
    "exclude_classes": _l("classes never taken as ground (noise)"),
    "preset": _l("parameter preset"),
    "cell_size": _l("seed cell size (largest building)", M),
    "max_terrain_angle": _l("maximum terrain slope", DEG),
    "iter_angle": _l("iteration angle", DEG),
    "iter_distance": _l("iteration distance", M),
    "min_edge_length": _l("minimum triangle edge length", M),
    "mirror": _l("test points mirrored through the nearest vertex"),
    "mirror_max_distance": _l("largest distance for the mirror test", M),
    "max_iter": _l("maximum number of iterations"),
    "edge_mode": _l("short-triangle handling"),
    "accept_ratio": _l("share of passing points that makes a segment ground", PCT, 100.0),
    "reject_ratio": _l("share of passing points below which a segment is rejected", PCT, 100.0),
    "seed_segments": _l("segments holding a seed are ground"),
    "min_tested": _l("tested points needed to decide a segment"),
    "unsegmented": _l("handling of unsegmented points"),
    "orientation_thr": _l("façade if segment tilt exceeds", DEG),
    "scatter_thr": _l("vegetation if segment scatter exceeds"),
    "k_feat": _l("neighbours of the scatter feature"),
    "min_facade_points": _l("points a façade segment needs"),
    "grow_radius": _l("surface-growing radius", M),
    "grow_radius_factor": _l("surface-growing radius / point spacing"),
    "terrain_grow_radius": _l("surface-growing radius of the terrain pass", M),
    "point_spacing": _l("point spacing (step edges' scale)", M),
    "max_segment_density": _l("cloud thinned for segmentation above", "pts/m²"),
    "grow_dist": _l("surface-growing distance to the plane", M),
    "seed_dist": _l("seed-surface distance to the plane", M),
    "k_seed": _l("neighbours of a seed surface"),
    "min_segment_size": _l("points a segment needs"),
    "final_distance": _l("final pass: distance to the ground TIN", M),
    "min_gain_frac": _l("stop when an iteration adds less than", PCT, 100.0),
    "seed_support": _l("seed check: supporting points needed"),
    "seed_radius": _l("seed check: radius", M),
    "seed_dz": _l("seed check: height tolerance", M),
    "sensor": _l("kind of acquisition (auto preset; measured when empty)"),
    "outlines": _l("also roof-plane outline sides as edges"),
    "steps": _l("also step edges (roof boundaries over a lower or missing surface)"),
    "threshold_range": _l("band the automatic threshold is kept in (none when empty)", M),
    "threshold_floor_m": _l("automatic threshold: floor of the sampling band", M),
    "threshold_ceiling_m": _l("automatic threshold: ceiling of the sampling band", M),
    "low_outlier_distance": _l("low-outlier pre-filter: depth below the neighbours (0 = off)", M),
    "low_outlier_radius": _l("low-outlier pre-filter: neighbourhood radius", M),
    "seed_support_ratio": _l("seed check: share of supporting points", PCT, 100.0),
    "raised_step": _l("raised-segment test: step height (0 = off)", M),
    "raised_angle": _l("raised-segment test: angle", DEG),
    "raised_ratio": _l("raised-segment test: share of the boundary", PCT, 100.0),
    "raised_radius": _l("raised-segment test: radius", M),
    "connect_min_size": _l("connection pass: segment size (0 = off)"),
    "connect_distance": _l("connection pass: distance", M),
    "connect_angle": _l("connection pass: angle", DEG),
    "connect_ratio": _l("connection pass: share of connected points", PCT, 100.0),
    "below_pass": _l("final pass for points below the ground"),
    "below_distance": _l("final pass: distance below the ground", M),
    "perched_step": _l("perched-surface test: drop on opposite sides (0 = off)", M),
    "perched_angle": _l("perched-surface test: steepest grade of terrain", DEG),
    "perched_radius": _l("perched-surface test: search radius", M),
    "gap_step": _l("gap test: clearance under a deck, drop with no return in between (0 = off)", M),
    "filter_density": _l("dense cloud filtered on its lowest points, at (0 = all)", "pts/m²"),
    "join_distance": _l("other points of a ground cell join within", M),
    "join_below": _l("a cell whose lowest point lies below the ground joins its neighbours' plane"),
    "surface_support": _l(
        "a cell is filtered on its lowest return with this many others 5 cm above (0 = lowest)"
    ),
    "terrain_density": _l("terrain first: filtered on its lowest points, at (0 = off)", "pts/m²"),
    "terrain_distance": _l("ground kept up to this height above the terrain", M),
    "terrain_band": _l("terrain first: lowest points filtered up to this height above it", M),
    "facade_distance": _l("façade points join the final ground within (0 = never)", M),
    "roof_ratio": _l("final roof check: raised share of a gable pair (0 = off)", PCT, 100.0),
    # plane segmentation and edges
    "near_dist": _l("edge support: distance to the line", M),
    "min_angle": _l("minimum angle between planes", DEG),
    "q_lo": _l("edge extent: lower quantile of the support", PCT, 100.0),
    "q_hi": _l("edge extent: upper quantile of the support", PCT, 100.0),
    "min_support": _l("edge support: points needed per plane"),
    "min_length": _l("shortest edge kept", M),
    "min_seed_points": _l("points a seed surface needs"),
    "hough_angle_step": _l("Hough angle step", DEG),
    "refit_growth": _l("refit the plane after growing by", PCT, 100.0),
    "seed_method": _l("seed-surface method"),
    "seed": _l("random seed"),
    "max_rmse": _l("largest plane RMS residual", M),
    "trim": _l("trim residuals beyond (× RMS)"),
    "adjacency_dist": _l("planes adjacent within", M),
    "min_contacts": _l("contact points for adjacent planes"),
    # line matching
    "weight": _l("weight W of the angle distance"),
    "sensitivity": _l("peak sensitivity of the automatic threshold", M),
    "threshold": _l("correspondence threshold (auto when empty)", M),
    "rotate": _l("segment rotated to parallel"),
    "denominator": _l("OLHD weights summed over"),
    "cutoff": _l("pairs farther than this are not computed", M),
    # check points
    "transform": _l("transformation fitted on control points"),
    "control_ids": _l("control point ids"),
    "match": _l("pairing of measured and check points"),
    "max_distance": _l("largest pairing distance", M),
    "include_control": _l("control points also counted as check points"),
    "checkpoint_rmse_h": _l("horizontal RMSE of the check-point survey", M),
    "checkpoint_rmse_v": _l("vertical RMSE of the check-point survey", M),
    "ddof": _l("RMSE divisor n − ddof"),
    "max_edge": _l("longest TIN edge at a check point (auto when empty)", M),
    "search_radius": _l("ground point needed within (auto when empty)", M),
    "parameters.classes": _l("classes of the ground TIN"),
    # heights
    "radius": _l("plane-fit radius", M),
    "max_radius": _l("largest plane-fit radius", M),
    "min_points": _l("laser points a plane needs"),
    "growth": _l("radius growth factor when too few points"),
    "sigma_point": _l("laser point noise σ (E1)", M),
    "sigma_gps": _l("GPS block error σ (E2)", M),
    "sigma_ins": _l("INS block error σ (E3)", M),
    "sigma_strip": _l("strip adjustment error σ (E4)", M),
    "sigma_ref": _l("reference height σ", M),
    "curvature": _l("largest surface curvature", "1/m"),
    "s_mode": _l("extrapolation distance measured to"),
    "correlation": _l("correlation of TIN vertex heights"),
    "alpha": _l("w-test significance level α₀"),
    "estimate_offset": _l("estimate a common height offset"),
    "eq8_diagonal": _l("paper's eq. 8 (no slope covariance)"),
    "posterior": _l("σ from the plane residuals"),
    "largest_segment": _l("fit only the largest planar segment"),
    # figures: the ground filter's terrain model against the reference's (ground section)
    "terrain.rmse_m": _l("terrain model RMSE (filter − reference TIN)", M),
    "terrain.bias_m": _l("terrain model mean difference (filter − reference)", M),
    "terrain.cells_off": _l("grid cells off by more than the limit", PCT, 100.0),
    "terrain.objects_taken": _l(
        "filter ground above the reference terrain (objects taken)", PCT, 100.0
    ),
    "terrain.ground_lost": _l(
        "reference ground off the filter's terrain (ground lost)", PCT, 100.0
    ),
    "terrain.reference_on_surface_ratio": _l(
        "reference non-ground points on its ground surface per ground point"
    ),
    "terrain.reference_thinned": _l("the reference ground looks thinned"),
    "terrain.n_cells": _l("grid cells scored (inside both TINs)"),
    "terrain.n_pred_scored": _l("filter ground points scored"),
    "terrain.n_ref_scored": _l("reference ground points scored"),
    "terrain.n_pred_ground": _l("filter ground points"),
    "terrain.n_ref_ground": _l("reference ground points"),
    "terrain.cell_m": _l("grid cell", M),
    "terrain.off_limit_m": _l("a cell is off beyond", M),
    "terrain.above_limit_m": _l("a point is taken / lost beyond", M),
    "terrain.near_limit_m": _l("on the reference surface within", M),
    "terrain.thinned_ratio_limit": _l("the reference looks thinned above this ratio"),
    "terrain.reason": _l("why the terrain model was not scored"),
    "terrain.note": _l("note on the reference"),
    # figures: NSSDA and ASPRS
    "nssda.accuracy_r": _l("NSSDA horizontal accuracy (95 %)", M),
    "nssda.accuracy_z": _l("NSSDA vertical accuracy (95 %)", M),
    "nssda.formula": _l("NSSDA horizontal formula"),
    "nssda.formula_z": _l("NSSDA vertical formula"),
    "nssda.ratio": _l("RMSE_min / RMSE_max (NSSDA)"),
    "nssda.accuracy_r_exact": _l("NSSDA horizontal accuracy, exact (95 %)", M),
    "nssda.n_check": _l("check points (NSSDA)"),
    "asprs2023.rmse_h": _l("ASPRS horizontal RMSE", M),
    "asprs2023.rmse_v": _l("ASPRS vertical RMSE", M),
    "asprs2023.rmse_3d": _l("ASPRS 3D RMSE", M),
    "asprs2023.rmse_h1": _l("ASPRS horizontal RMSE of the product alone", M),
    "asprs2023.rmse_v1": _l("ASPRS vertical RMSE of the product alone", M),
    "asprs2023.checkpoint_rmse_h": _l("ASPRS check-point survey horizontal RMSE", M),
    "asprs2023.checkpoint_rmse_v": _l("ASPRS check-point survey vertical RMSE", M),
    "asprs2023.n_check": _l("check points (ASPRS)"),
    "asprs2023.standard": _l("standard"),
    "rmse_h": _l("horizontal RMSE", M),
    "rmse_3d": _l("3D RMSE", M),
    # figures: heights
    "comparison.n": _l("reference heights compared"),
    "comparison.mean": _l("mean Δh", M),
    "comparison.std": _l("standard deviation of Δh", M),
    "comparison.rms": _l("RMS Δh", M),
    "comparison.max_abs": _l("max |Δh|", M),
    "comparison.sigma_model_empirical": _l("empirical model precision", M),
    "w.critical": _l("critical value of |w|"),
    "w.std": _l("standard deviation of w"),
    "w.std_without_outliers": _l("standard deviation of w without outliers"),
    "w.frac_lt1": _l("share of |w| < 1 (68 % expected)", PCT, 100.0),
    "w.frac_lt2": _l("share of |w| < 2 (95 % expected)", PCT, 100.0),
    "w.n_outliers": _l("outliers (|w| above the critical value)"),
}


def add(labels: dict[str, Label]) -> None:
    """Add labels (an analysis module's own keys); a key may not change its meaning.

    Raises
    ------
    ValueError
        If a key already has a different label.
    """
    for key, lab in labels.items():
        if not isinstance(lab, Label):
            raise TypeError(f"label of {key!r} must be a Label, got {type(lab).__name__}")
        old = LABELS.get(key)
        if old is not None and old != lab:
            raise ValueError(f"{key!r} is already labelled {old.text!r}; use a dotted key")
        LABELS[key] = lab


def lookup(path: str) -> Label | None:
    """The label of a dotted key path (most specific suffix first), or None."""
    parts = path.split(".")
    for i in range(len(parts)):
        hit = LABELS.get(".".join(parts[i:]))
        if hit is not None:
            return hit
    return None


def label_text(path: str) -> str:
    """``label (unit)`` of a key path, or the path itself when it has no label."""
    lab = lookup(path)
    if lab is None:
        return path
    return f"{lab.text} ({lab.unit})" if lab.unit else lab.text


def display_value(path: str, value: Any, *, none: str = "–") -> Any:
    """A value as the report shows it: fractions in percent, None as `none`."""
    if value is None:
        return none
    lab = lookup(path)
    if lab is not None and lab.scale != 1.0 and isinstance(value, int | float):
        if not isinstance(value, bool):
            return value * lab.scale
    return value


def labelled_rows(values: dict[str, Any], *, prefix: str = "", none: str = "–") -> list[list[Any]]:
    """Rows ``[label (unit), value, key]`` of a (nested) dict, for a report table."""
    rows: list[list[Any]] = []

    def walk(p: str, v: Any) -> None:
        if isinstance(v, dict):
            for k, x in v.items():  # an empty table gives no row
                walk(f"{p}.{k}" if p else str(k), x)
        else:
            full = f"{prefix}.{p}" if prefix else p
            rows.append([label_text(full), display_value(full, v, none=none), full])

    walk("", values)
    return rows
