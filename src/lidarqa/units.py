"""The unit policy of lidarqa: one place for every unit of every number it writes.

Policy
------
- **Lengths and coordinates are metres**, angles are **degrees**, in text, JSON,
  CSV and the report. ``checkpoints`` converts coordinates whose CRS axes are
  in feet to metres before computing (and says so in a warning); ``heights``
  and the geometry commands convert heights (z) in feet and refuse a cloud
  whose x, y are in feet or degrees (reproject it to metres first).
- **Ratios** (error rates, shares of points) are stored in JSON as **fractions
  between 0 and 1**; text and report show them as percentages. Keys ending in
  ``_pct`` are percentages (0–100).
- **Targets** ``target_<metric>`` (config keys and verdicts) have the unit of
  their metric: ``target_total = 0.05`` is a fraction (5 %), ``target_lhd = 0.5``
  metres.
- **Key names carry their unit** where the name alone would be ambiguous:
  ``_m`` metres, ``_deg`` degrees, ``_m2`` square metres, ``_per_m2`` per square
  metre, ``_s`` seconds, ``_pct`` percent, ``_ppm`` parts per million. Every other
  numeric key of a JSON document has its unit in :data:`KEY_UNITS` below (a test
  walks every command's JSON document and fails on a number whose unit is not
  defined here).
- **Coordinates written to files** keep the precision of their source: a LAS
  file's scale (usually 1 cm or 1 mm); computed coordinates (corners, edges)
  and coordinate differences (check-point residuals ``dx``, ``dy``, ``dz``,
  ``dh``) are written to 0.1 mm, other decimal numbers to at most 10
  significant digits, never ``770500.05000000005``.
- **CRS**: every file lidarqa writes carries the CRS of its source. CSV files
  get a sidecar ``<name>.prj`` with the CRS as WKT (ESRI ``.prj`` convention,
  which GDAL/OGR and QGIS read for a CSV) ; lidarqa reads it back when
  ``--crs`` is not given.

The table
---------
:data:`SUFFIX_UNITS` maps key suffixes to units, :data:`KEY_UNITS` maps exact
key names to units ("1" means dimensionless, "count" a number of things,
"fraction" a ratio between 0 and 1, "id" an identifier).
"""

from __future__ import annotations

import re

__all__ = [
    "SUFFIX_UNITS",
    "KEY_UNITS",
    "STAT_KEYS",
    "GROUP_KEYS",
    "GROUP_UNITS",
    "key_unit",
    "param_unit",
    "COORDINATE_DECIMALS",
    "format_coordinate",
    "format_decimal",
    "undefined_units",
]

#: Unit of a key from its suffix (checked in this order).
SUFFIX_UNITS: dict[str, str] = {
    "_per_m2": "1/m²",
    "_m2": "m²",
    "_m": "m",
    "_deg": "degree",
    "_pct": "percent",
    "_ppm": "ppm",
    "_s": "second",
}

_M = "m"
_D = "degree"
_N = "count"
_F = "fraction"
_1 = "1"
_ID = "id"


def _keys(unit: str, names: str) -> dict[str, str]:
    return dict.fromkeys(names.split(), unit)


#: Unit of every numeric JSON key without a unit suffix. "1" is dimensionless,
#: "count" a number of things, "fraction" a ratio between 0 and 1 (shown as % in
#: text and report), "id" a code or identifier (class, strip, EPSG, format).
KEY_UNITS: dict[str, str] = {
    # coordinates, bounds, translations, lengths, distances, precisions: metres
    **_keys(
        _M,
        """x y z x1 y1 z1 x2 y2 z2 dx dy dz tin_z min_x min_y min_z max_x max_y max_z
        station offsets scales tx ty tz c d e translation_at_coordinate_origin
        mean_x mean_y mean_z std_x std_y std_z rmse_x rmse_y rmse_z rmse_h rmse_v rmse_3d
        rmse_r rmse_h1 rmse_v1 max_abs_x max_abs_y max_abs_z
        accuracy_r accuracy_r_exact accuracy_z accuracy_h accuracy_v accuracy_3d
        sigma0 sigma0_h sigma0_v sigma_x sigma_y sigma_z sigma_line sigma_point sigma_gps
        sigma_ins sigma_strip sigma_ref sigma_map sigma_reference sigma_mean sigma_p95
        sigma_model_empirical sigma_h sigma comparison
        checkpoint_rmse_h checkpoint_rmse_v max_distance max_edge radius max_radius
        search_radius threshold threshold_tm threshold_mt olhd_tm olhd_mt lhd sensitivity
        cell_size spacing point_spacing mean_spacing ground_spacing min_spacing
        iter_distance final_distance below_distance connect_distance min_edge_length
        grow_dist grow_radius terrain_grow_radius seed_dist seed_dz seed_radius raised_radius
        raised_step perched_step perched_radius join_distance terrain_distance terrain_band
        facade_distance gap_step
        adjacency_dist near_dist max_dist min_length max_rmse instrument_height
        distance length rho rms rmse buffer tolerance cutoff gao_leung_tm gao_leung_mt
        hausdorff_tm hausdorff_mt grid map_spacing median_length median_sigma_line
        total_length""",
    ),
    # angles: degrees
    **_keys(
        _D,
        """omega phi kappa iter_angle max_terrain_angle connect_angle raised_angle perched_angle
        orientation_thr orientation min_angle hough_angle_step angle""",
    ),
    # numbers of things
    **_keys(
        _N,
        """n p q dof flags confusion ok no_ground_nearby sparse_tin
        outside_tin support_a support_b support_c min_points min_segment_size
        min_seed_points min_contacts min_tested min_facade_points connect_min_size k_feat
        surface_support k_seed seed_support max_iter points_per_segment_median chunk_size workers
        accepted_per_iter added_per_iter max_points min_support sigma_classes
        kernels_compiled kernels_loaded failed retried skipped attempts""",
    ),
    # ratios between 0 and 1
    **_keys(
        _F,
        """type_i type_ii total precision recall frac_lt1 frac_lt2 ground_fraction
        cells_off objects_taken ground_lost
        segmented_fraction accept_ratio connect_ratio raised_ratio reject_ratio roof_ratio
        seed_support_ratio min_gain_frac refit_growth correlation alpha fraction q_lo q_hi""",
    ),
    # dimensionless numbers
    **_keys(
        _1,
        """a b scale ratio weight w critical std_without_outliers rotation_matrix det
        min_det scatter_thr trim growth grow_radius_factor kappa_coefficient seed
        reference_on_surface_ratio thinned_ratio_limit""",
    ),
    # codes and identifiers
    **_keys(
        _ID,
        """crs_epsg point_format classes point_source_ids source_id source_ids test_source_id
        model_source_id exclude_classes ignore_classes id""",
    ),
    # flight strips (lidarqa swaths) and 3D roads (lidarqa roads)
    **_keys(
        _M,
        """e4 rmsdz p95_abs max_range median_range p95_range range_cell sigma_dx sigma_dy
        sigma_dz sigma_robust max_roughness max_step max_shift shift margin repeatability
        pairs thresholds max_rmsdz max_repeatability max_abs_dz""",
    ),
    **_keys(_D, "max_slope offset_max_slope max_normal_angle"),
    **_keys("m²", "area overlap_area min_area"),
    **_keys(
        _N,
        "min_overlap_cells points_other_level polygons_grown polygons_without_points",
    ),
    **_keys(_ID, "strip strip_a strip_b strips reference_strip"),
    # per volume/area densities and curvature
    "max_segment_density": "1/m²",
    "filter_density": "1/m²",
    "terrain_density": "1/m²",
    # the cloud figures of the automatic ground-filter preset (parameters.measured)
    "density": "1/m²",
    "occupied_area": "m²",
    "largest_object_area": "m²",
    "largest_object_diameter": "m",
    "scan_angle_max": "degree",
    "slope_median": "degree",
    "slope_p90": "degree",
    "multi_return_share": "fraction",
    "concentration": "fraction",
    "curvature": "1/m",
    "size": "byte",
    # a verdict's value and target have the unit of the metric named beside them
    "value": "unit of the metric",
    "target": "unit of the metric",
    # lidarqa qc: a check's limit has the unit of its value; the profile's limits
    "limit": "unit of the metric",
    "min_anpd": "1/m²",
    "min_spatial_distribution": _F,
    "distribution": _F,
    "void_factor": _1,
    "max_duplicates": _N,
    "min_checkpoints": _N,
    "n_check": _N,
    "point_formats": _ID,
    "codes": _ID,
    "matrix": _N,
    "reference_tolerance": _M,
    "overall_accuracy": _F,
}

#: Statistics whose unit is that of the quantity they summarise (the parent key):
#: ``{"angle_deg": {"min": ..., "median": ..., "max": ...}}`` is in degrees.
STAT_KEYS = frozenset("min max median mean std p95 rms max_abs".split())

#: Objects whose members all have one unit: ``{"classes": {"2": 21786}}`` counts points per
#: class code (while a list ``"classes": [2, 6]`` holds codes), ``timings_s`` seconds per step.
GROUP_UNITS: dict[str, str] = {
    **dict.fromkeys(
        "classes point_source_ids flags confusion sigma_classes failed_by_check per_chunk skipped "
        "refused".split(),
        _N,
    ),
    **dict.fromkeys("producers_accuracy users_accuracy".split(), _F),
    "timings_s": "second",
}
GROUP_KEYS = frozenset(GROUP_UNITS)


def key_unit(key: str, parent: str | None = None) -> str | None:
    """The unit of a JSON key by the policy (None when it is not defined).

    `parent` is the key of the enclosing object: a statistic (``min``, ``max``,
    ``mean``, ...) has the unit of the quantity it summarises, and an object
    keyed by codes (``{"classes": {"2": 1200}}``) has the unit of its own key.

    Examples
    --------
    >>> key_unit("rmse_z"), key_unit("angle_deg"), key_unit("density_per_m2")
    ('m', 'degree', '1/m²')
    >>> key_unit("max", parent="angle_deg"), key_unit("2", parent="classes"), key_unit("classes")
    ('degree', 'count', 'id')
    """
    k = key.lower()
    if parent is not None and parent.lower() in GROUP_UNITS:
        return GROUP_UNITS[parent.lower()]
    if parent is not None and (k in STAT_KEYS or k.lstrip("-").isdigit()):
        unit = key_unit(parent)
        if unit is not None:
            return unit
    if k in KEY_UNITS:
        return KEY_UNITS[k]
    if k.startswith("target_"):  # target_<metric> has the unit of the metric
        return key_unit(k[len("target_") :])
    for suffix, unit in SUFFIX_UNITS.items():
        if k.endswith(suffix):
            return unit
    if re.fullmatch(r"n_\w+", k):
        return _N
    return None


_SHORT = {"m": "m", "degree": "°", "1": "", "count": "", "fraction": "", "ppm": "ppm"}


def param_unit(key: str) -> str:
    """Short unit label of a parameter for text output (``m``, ``°``, or empty)."""
    u = key_unit(key)
    return _SHORT.get(u or "", u or "")


#: Decimals of computed coordinates written to files (0.1 mm).
COORDINATE_DECIMALS = 4


def format_coordinate(value: float, decimals: int = COORDINATE_DECIMALS) -> str:
    """A coordinate for a text file: fixed decimals, no trailing float noise.

    Examples
    --------
    >>> format_coordinate(770500.05000000005), format_coordinate(1.0, 2)
    ('770500.0500', '1.00')
    """
    return f"{float(value):.{decimals}f}"


def format_decimal(value: float) -> str:
    """A non-coordinate decimal for a text file: at most 10 significant digits.

    Examples
    --------
    >>> format_decimal(0.1 + 0.2), format_decimal(1e-12)
    ('0.3', '1e-12')
    """
    return f"{float(value):.10g}"


def _numbers(obj: object, key: str | None, parent: str | None, path: str):
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numbers(v, str(k), key, f"{path}/{k}")
    elif isinstance(obj, list | tuple):
        for v in obj:
            yield from _numbers(v, key, parent, f"{path}[]")
    elif isinstance(obj, int | float) and not isinstance(obj, bool):
        yield path, key, parent


def undefined_units(document: object) -> list[str]:
    """Paths of the numbers in a JSON document whose unit this policy does not define.

    Examples
    --------
    >>> undefined_units({"results": {"rmse_z": 0.1, "wobble": 2.0, "classes": {"2": 7}}})
    ['/results/wobble']
    """
    found = _numbers(document, None, None, "")
    return sorted({p for p, k, parent in found if key_unit(k or "", parent) is None})
