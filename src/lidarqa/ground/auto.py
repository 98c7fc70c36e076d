"""Filter parameters from the cloud itself: measure, then choose (``preset="auto"``).

:func:`measure_cloud` measures what the ground filters depend on — point density
and spacing (per occupied area, so flight-strip overlaps and gaps do not bias it),
the return structure, the kind of acquisition (airborne or mobile), terrain slope
statistics and the largest object footprint — and :func:`auto_parameters` turns
those figures into filter parameters with fixed rules. Every chosen value carries
its provenance: ``"preset"`` (a fixed constant of the regime the measured figures
chose; :func:`regime_reason` says which figures and thresholds chose it, and the
result's ``parameter_notes`` repeat it per parameter), ``"default"`` (the filter
class's default) or ``"given"`` (an explicit option, which always wins).
``"measured"`` is kept for a value computed from a figure of this cloud; none of
the current rules sets one (the surface-growing radius, 2.5 × the measured point
spacing, is computed inside the filter and shows as ``"default"``). The constants
of the presets were chosen on the data the project has (the sparse set on the 15
ISPRS samples that also score it), not measured on the cloud being filtered.

The rules, in short:

- **Sensor.** Ground-based scans (mobile or terrestrial) get Lin & Zhang's Table 1
  (the library defaults, regime ``mls``). A recorded scan angle decides first (a range
  beyond ±60° is ground-based). Without one, the geometry decides: a ground-based
  scanner's density falls steeply with the range from its trajectory or station, so
  most of its points crowd a few cells, while airborne strips sample the ground almost
  evenly (an overlap doubles the count). The measured figure is the *concentration*,
  the share of the points in cells of the density grid (about 50 points per cell) that
  hold more than :data:`CONCENTRATION_FACTOR` (4) times the median count of the
  occupied cells; above :data:`MLS_CONCENTRATION` (a third) the scan is ground-based.
  Measured: the eight Oakland mobile-scanning chunks 0.57–0.88 and PDAL's lone-star
  terrestrial scan 0.67; the 15 ISPRS samples 0–0.17, the IGN tiles, BC forest tiles,
  Autzen and lidR plots 0–0.004, the synthetic airborne scenes of
  :mod:`lidarqa.testing` (walls sampled as densely as the ground included) 0–0.15.
  Effect: the Oakland chunks (no scan angle, 6–43 points/m², so far filtered as dense
  airborne) are filtered as ground-based scans: thinned (below) but without the
  terrain-first pass and the perched-surface test, which look for what an airborne
  scanner misses; mean total error 1.09 % to 0.94 %, κ 97.66 to 97.97, chunk ah 4.05 %
  to 2.52 % (CSF at PDAL's defaults 2.53 %). Lin & Zhang's Table 1 on every point
  instead gave 0.99 % (ah 1.31 %, six chunks 0.1–0.5 points worse) at 2.5 times the
  CPU. Every other family keeps its regime and so its labels. Denser clouds than
  :data:`MLS_DENSITY` (100 points/m²) without a scan angle stay ground-based whatever
  their concentration, as they were: a part of a scan far from the scanner can be even
  (a quarter of PDAL's lone-star scan measures 0.15 at 517 points/m²; the octree nodes
  of its EPT copy, thinned to an even density level by level, 0–0.4); a drone flight
  that dense without a scan angle is taken for ground-based too (no such file
  measured). A `sensor` hint overrides the measurement.
- **Density regime** (airborne). Below :data:`DENSE_ALS` points/m² a segment of a
  few points cannot show whether it is vegetation (scatterness needs about ten
  neighbours within a metre), so the sparse set switches scatterness off and
  relies on steeper iteration angles and the raised/connection/below passes
  (:data:`~lidarqa.ground.ALS_SEGMENT_PARAMS`). At :data:`DENSE_ALS` points/m² and
  above the dense set keeps scatterness and the tight angles of Table 1: at
  0.2–0.3 m spacing a 16° iteration angle accepts a point 0.1 m above its
  neighbour regardless of what it is.
- **Dense clouds**, airborne or ground-based (from 1.5 × :data:`FILTER_DENSITY` points/m²), are
  filtered on their lowest point per cell of 1/sqrt(:data:`FILTER_DENSITY`) m; the
  other points join the ground by a plane test (segment-PTD's `filter_density`),
  and the TIN of the filter keeps a 2 m minimum edge (:data:`FILTER_MIN_EDGE`).
  At 20 points/m² this is 4 times less work, and the decision is taken where
  terrain shows: on the lower envelope.
- **Echoes below the ground** (the same dense clouds, ground-based only): segment-PTD's
  `join_below` tests the points of a cell whose lowest point was rejected against
  the plane of its ground neighbours when that lowest point lies below it, so the
  road above a multipath echo joins. A preset value with a physical reason (from
  the street a return below the ground is an echo; from the air the lowest return
  is the ground), measured on the eight Oakland chunks (mean total error 0.94 % to
  0.85 %, κ 97.97 to 98.14; chunk ah 2.52 % to 1.81 %). Airborne families keep
  their labels (IGN, BC forest, ISPRS: 100 % identical); switched on for the BC
  forest tiles it raised the DTM RMSE of bcts_2 from 0.19 to 0.25 m, so it is not.
- **Terrain first** (the same dense clouds, airborne only): the filter runs first at
  :data:`TERRAIN_DENSITY` points/m² (1.4 m cells, large enough to hold a ground
  return under a closed canopy); its ground is the terrain model and the seed points
  of the run at :data:`FILTER_DENSITY`, whose ground is kept only up to 0.3 m above it
  (segment-PTD's `terrain_density`; the terrain model is the TIN of the
  median-height terrain point per cell, so a low outlier cannot pull it down). A
  preset value, checked on three families: the BC forest tiles (DTM RMSE 0.69/2.62
  m to 0.19/0.31 m), the six IGN 50 m tiles (mean total error 1.18 % to 1.09 %) and
  the eight Oakland mobile-scanning chunks when they were filtered as dense
  airborne (0.94 % without it, 1.09 % with it; they are now mobile scans, which
  never run it). Seeding the fine run from the terrain (instead of its own 60 m
  seed cells) takes a third off the filter's time on the BC forest tiles for a
  DTM RMSE 0.003–0.008 m worse (``docs/algorithms.md``).
- **Seed cell.** The largest object footprint (the diameter of the largest disc
  inside a raised region of the lowest-point raster) is measured and reported, but
  the seed cell stays at its default (60 m): on small extracts the footprint
  measure cannot tell a hill from a roof, and seed cells sized from it were worse.
- **Perched surfaces** (airborne, segment-PTD, both density regimes): accepted
  ground that drops by more than :data:`PERCHED_STEP` m (a storey) steeply on
  opposite sides is rejected at the end (roofs reached from a hillside, bridge
  decks); the test works on a 1 m raster, so it does not depend on density.
- **Slopes** are measured and reported; the sparse set's steep iteration angle
  and the raised/below passes already cover 30–45° slopes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numba import njit

from .._gridkernels import grid_keys
from .._validate import check_choice

__all__ = [
    "CloudMeasures",
    "measure_cloud",
    "auto_parameters",
    "SENSORS",
    "DENSE_ALS",
    "MLS_CONCENTRATION",
    "MLS_DENSITY",
    "CONCENTRATION_FACTOR",
    "FILTER_DENSITY",
    "FILTER_MIN_EDGE",
    "TERRAIN_DENSITY",
    "regime_reason",
    "parameter_notes",
    "with_given",
    "ALS_PARAMS",
    "ALS_SEGMENT_PARAMS",
    "PRESETS",
    "PRESET_CHOICES",
]

SENSORS = ("auto", "als", "mls")
#: points/m² from which airborne clouds get the dense parameter set
DENSE_ALS = 4.0
#: storey height (m): the perched-surface test of airborne segment-PTD (both regimes)
PERCHED_STEP = 2.0
#: clearance (m) under a bridge deck: the gap test of sparse airborne segment-PTD
#: (`gap_step`; twice the storey, about the 4.5 m headroom of a road under a bridge)
GAP_STEP = 4.0
#: points/m² dense airborne clouds are filtered at (lowest point per cell, the rest
#: joined by a plane test; segment-PTD's `filter_density`), above 1.5 times it
FILTER_DENSITY = 4.0
#: points/m² of the terrain-first pass of dense airborne clouds (segment-PTD's
#: `terrain_density`): 1.4 m cells, large enough to hold a ground return under a
#: closed canopy (BC forest tiles) and small enough for urban blocks (IGN tiles)
TERRAIN_DENSITY = 0.5
#: minimum TIN edge (m) of the filter on the thinned cloud (TIN vertices on 1.4 m cells
#: over its 0.5 m cells): the same decisions, 30 % less work than Table 1's 1 m
FILTER_MIN_EDGE = 2.0
#: a grid cell of the density grid is crowded when it holds more than this many times
#: the median count of the occupied cells (two or three overlapping airborne strips
#: give 2-3 times; see :attr:`CloudMeasures.concentration`)
CONCENTRATION_FACTOR = 4.0
#: share of the points in crowded cells above which a cloud without a scan angle is
#: taken for a ground-based (mobile or terrestrial) scan: airborne files measure at
#: most 0.17, ground-based ones at least 0.57 (see the module notes)
MLS_CONCENTRATION = 1.0 / 3.0
#: points/m² above which a cloud without a scan angle is taken for a ground-based scan
#: whatever its concentration (a part of a scan far from the scanner can be even)
MLS_DENSITY = 100.0
#: One parameter set for airborne scans (about 1 pt/m², ISPRS filter test), used on
#: every ISPRS sample; the library defaults are Lin & Zhang's Table 1 (MLS). Lengths
#: in m, angles in degrees. ``ALS_PARAMS`` is point-PTD's set, ``ALS_SEGMENT_PARAMS``
#: segment-PTD's (scatterness does not separate ground from vegetation at 1 pt/m², so
#: it is switched off; steep terrain segments need a steeper façade threshold). Both
#: were chosen on the 15 ISPRS reference samples themselves (no held-out data): the
#: ISPRS tests (tests/ground/test_isprs.py) are regression guards, not a validation;
#: ``benchmarks/ground_isprs.py --loso`` gives the leave-one-site-out figure per constant.
ALS_PARAMS: dict[str, Any] = {
    "iter_angle": 16.0,
    "iter_distance": 0.8,
    "mirror_max_distance": 3.0,
    "final_distance": 0.4,
}
ALS_SEGMENT_PARAMS: dict[str, Any] = {
    "iter_angle": 16.0,
    "iter_distance": 0.7,
    "mirror_max_distance": 3.0,
    "final_distance": 0.3,
    "accept_ratio": 0.7,
    "reject_ratio": 0.3,
    "scatter_thr": 1.0,
    "orientation_thr": 70.0,
    "grow_radius_factor": 1.5,
    "raised_step": 2.0,
    "connect_min_size": 20,
    "connect_ratio": 0.6,
    "below_pass": True,
    "perched_step": PERCHED_STEP,
    "gap_step": GAP_STEP,  # bridge decks over an unsampled gap (sparse clouds)
    "facade_distance": 0.7,  # = iter_distance: steep banks grown into façade segments
    "roof_ratio": 0.15,  # final roof check: gable pairs with a raised border
}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "mls": {"ptd": {}, "segment-ptd": {}},
    "als": {"ptd": ALS_PARAMS, "segment-ptd": ALS_SEGMENT_PARAMS},
}
#: every accepted `preset`: "auto" (the default) measures the cloud and chooses
PRESET_CHOICES = ("auto", *PRESETS)
#: height (m) above the opened lowest-point surface from which a cell is "raised"
_RAISED = 2.5
#: opening window (m) for the terrain approximation of the footprint measure
_OPEN_WINDOW = 150.0


@dataclass(frozen=True)
class CloudMeasures:
    """Figures measured on the ground candidates of a cloud (see :func:`measure_cloud`).

    Attributes
    ----------
    n_points : int
        Candidate points measured.
    density : float
        Points per m² of occupied area (median of occupied grid cells).
    spacing : float
        Mean point spacing 1/sqrt(density), m.
    occupied_area : float
        Area of the occupied grid cells, m².
    concentration : float
        Share of the points in crowded cells of the density grid: cells holding more
        than :data:`CONCENTRATION_FACTOR` times the median count of the occupied
        cells. Airborne strips sample the ground almost evenly (overlaps double the
        count), so it is near 0; a ground-based scanner's density falls steeply with
        the range from its trajectory or station, so most of its points lie in a few
        crowded cells.
    has_returns : bool
        Return numbers were recorded.
    multi_return_share : float
        Share of points from pulses with more than one return (nan without returns).
    scan_angle_max : float
        Largest absolute scan angle, degrees (nan when not recorded).
    sensor : str
        ``"als"`` or ``"mls"`` as measured (before any hint).
    slope_median, slope_p90 : float
        Terrain slope statistics (degrees) of the opened lowest-point raster.
    largest_object_diameter : float
        Diameter (m) of the largest disc that fits inside a raised region (0 when none).
    largest_object_area : float
        Area (m²) of the largest raised region.
    """

    n_points: int
    density: float
    spacing: float
    occupied_area: float
    concentration: float
    has_returns: bool
    multi_return_share: float
    scan_angle_max: float
    sensor: str
    slope_median: float
    slope_p90: float
    largest_object_diameter: float
    largest_object_area: float

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in asdict(self).items()
        }


def _grid_density(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """(density per m², occupied area m², concentration) from a grid of about 50 points per cell.

    `x`, `y` are contiguous and start at 0. The concentration is the share of the
    points in cells holding more than :data:`CONCENTRATION_FACTOR` times the median
    count of the occupied cells.
    """
    n = x.size
    span = max(float(x.max()), 1e-9) * max(float(y.max()), 1e-9)
    cell = math.sqrt(50.0 * span / n)
    if not cell > 0:
        return math.nan, 0.0, math.nan
    counts = np.bincount(grid_keys(x, y, cell, 0.0, 0.0, int(float(y.max()) / cell) + 1))
    counts = counts[counts > 0]
    med = float(np.median(counts))
    crowded = float(counts[counts > CONCENTRATION_FACTOR * med].sum()) / float(counts.sum())
    return med / (cell * cell), float(counts.size * cell * cell), crowded


def _min_raster(x: np.ndarray, y: np.ndarray, z: np.ndarray, cell: float) -> np.ndarray:
    """Lowest z per XY cell (nan where empty); `x`, `y` start at 0."""
    shape = (int(float(x.max()) / cell) + 1, int(float(y.max()) / cell) + 1)
    flat = _min_per_cell(grid_keys(x, y, cell, 0.0, 0.0, shape[1]), z, shape[0] * shape[1])
    return flat.reshape(shape)


@njit(cache=True, nogil=True)
def _min_per_cell(flat, z, size):  # pragma: no cover - numba
    """Lowest `z` per cell number (nan where empty)."""
    out = np.full(size, np.inf)
    for k in range(flat.size):
        if z[k] < out[flat[k]]:
            out[flat[k]] = z[k]
    for c in range(size):
        if not np.isfinite(out[c]):
            out[c] = np.nan
    return out


def _open(z: np.ndarray, size: int) -> np.ndarray:
    """Grey opening of a raster with nan gaps (gaps ignored); nan where nothing reaches."""
    from scipy import ndimage

    a = np.where(np.isnan(z), np.inf, z)
    e = ndimage.minimum_filter(a, size=size, mode="nearest")
    e[~np.isfinite(e)] = -np.inf
    o = ndimage.maximum_filter(e, size=size, mode="nearest")
    o[~np.isfinite(o)] = np.nan
    return o


def measure_cloud(points: Any, *, fields: dict | None = None) -> CloudMeasures:
    """Measure the figures the automatic parameters depend on.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        The ground candidates (e.g. last returns, noise excluded), metres.
    fields : dict, optional
        Per-point fields of the same points (``return_number``,
        ``number_of_returns``, ``scan_angle`` / ``scan_angle_rank``).

    Returns
    -------
    CloudMeasures
    """
    from scipy import ndimage

    xyz = np.asarray(points, dtype=np.float64)
    fields = fields or {}
    n = xyz.shape[0]
    nan = math.nan
    if n < 10:
        return CloudMeasures(n, nan, nan, 0.0, nan, False, nan, nan, "als", nan, nan, 0.0, 0.0)
    x = np.ascontiguousarray(xyz[:, 0])
    y = np.ascontiguousarray(xyz[:, 1])
    z = np.ascontiguousarray(xyz[:, 2])
    x = x - x.min()  # new arrays: the input is never modified
    y = y - y.min()
    density, area, concentration = _grid_density(x, y)
    spacing = 1.0 / math.sqrt(density) if density > 0 else nan
    nr = fields.get("number_of_returns")
    rn = fields.get("return_number")
    has_ret = nr is not None and rn is not None and bool(np.any(np.asarray(nr) > 0))
    multi = float(np.mean(np.asarray(nr) > 1)) if has_ret else nan
    ang = fields.get("scan_angle")
    if ang is None:
        ang = fields.get("scan_angle_rank")
    angle_max = nan
    if ang is not None and np.size(ang):
        a = np.abs(np.asarray(ang, dtype=np.float64))
        if "scan_angle" in fields and a.max() > 180:  # LAS 1.4: 0.006° units
            a = a * 0.006
        angle_max = float(a.max())
    if math.isfinite(angle_max) and angle_max > 0:
        sensor = "mls" if angle_max > 60.0 else "als"
    else:
        crowded = concentration > MLS_CONCENTRATION
        sensor = "mls" if crowded or density > MLS_DENSITY else "als"
    # terrain slopes and object footprints from the lowest-point raster
    cell = max(1.0, 2.0 * spacing) if math.isfinite(spacing) else 1.0
    zmin = _min_raster(x, y, z, cell)
    size = max(3, int(round(_OPEN_WINDOW / cell)) | 1)
    opened = _open(zmin, size)
    scell = max(5.0, 3.0 * cell)
    k = max(1, int(round(scell / cell)))
    coarse = opened[::k, ::k]
    slope_med = slope_p90 = nan
    if coarse.shape[0] >= 2 and coarse.shape[1] >= 2:
        gx, gy = np.gradient(coarse, k * cell)
        s = np.degrees(np.arctan(np.hypot(gx, gy)))
        s = s[np.isfinite(s)]
        if s.size:
            slope_med = float(np.median(s))
            slope_p90 = float(np.percentile(s, 90))
    # raised regions: above the opened surface by more than _RAISED plus what the
    # opening loses on a slope across half the window
    tol = _RAISED + (
        0.5 * _OPEN_WINDOW * math.tan(math.radians(slope_med)) if math.isfinite(slope_med) else 0.0
    )
    raised = np.nan_to_num(zmin - opened, nan=-1.0) > tol
    # empty cells (no point) next to a raised cell belong to it: holes would shrink it
    raised |= np.isnan(zmin) & ndimage.binary_dilation(raised, np.ones((3, 3), bool))
    diam = area_obj = 0.0
    if raised.any():
        lab, nlab = ndimage.label(raised)
        sizes = np.bincount(lab.ravel())[1:]
        area_obj = float(sizes.max() * cell * cell)
        dt = ndimage.distance_transform_edt(raised)
        diam = float(2.0 * dt.max() * cell)
    return CloudMeasures(
        n_points=int(n),
        density=float(density),
        spacing=float(spacing),
        occupied_area=area,
        concentration=float(concentration),
        has_returns=bool(has_ret),
        multi_return_share=multi,
        scan_angle_max=angle_max,
        sensor=sensor,
        slope_median=slope_med,
        slope_p90=slope_p90,
        largest_object_diameter=diam,
        largest_object_area=area_obj,
    )


def auto_parameters(
    measures: CloudMeasures, method: str = "segment-ptd", *, sensor: str = "auto"
) -> tuple[dict[str, Any], dict[str, str], str]:
    """Filter parameters chosen from `measures`.

    Parameters
    ----------
    measures : CloudMeasures
    method : {"segment-ptd", "ptd"}
    sensor : {"auto", "als", "mls"}
        Hint that overrides the measured kind of acquisition.

    Returns
    -------
    params : dict
        Keyword arguments for :class:`~lidarqa.ground.SegmentPTD` / :class:`~lidarqa.ground.PTD`.
    sources : dict
        ``"preset"`` per parameter in `params`: each is a fixed constant of the
        regime that the measured figures chose (see :func:`regime_reason`).
    regime : str
        ``"mls"``, ``"als-sparse"`` or ``"als-dense"``.
    """
    check_choice(sensor, SENSORS, "sensor")
    kind = measures.sensor if sensor == "auto" else sensor
    params: dict[str, Any] = {}
    sources: dict[str, str] = {}
    if kind == "mls":
        regime = "mls"
    elif math.isfinite(measures.density) and measures.density >= DENSE_ALS:
        regime = "als-dense"
    else:
        regime = "als-sparse"
    if regime == "als-sparse":
        for k, v in PRESETS["als"][method].items():
            params[k] = v
            sources[k] = "preset"  # a constant of the regime the measured density chose
    elif method == "segment-ptd":
        dense = math.isfinite(measures.density) and measures.density >= 1.5 * FILTER_DENSITY
        if dense:  # airborne or ground-based: the lowest point per cell is filtered
            params["filter_density"] = FILTER_DENSITY
            sources["filter_density"] = "preset"
            params["min_edge_length"] = FILTER_MIN_EDGE
            sources["min_edge_length"] = "preset"
        if dense and regime == "mls":
            # seen from the street, a return below the ground is a multipath echo
            params["join_below"] = True
            sources["join_below"] = "preset"
        if regime == "als-dense":
            # airborne at any density: ground never drops steeply on opposite sides
            params["perched_step"] = PERCHED_STEP
            sources["perched_step"] = "preset"
            if dense:  # terrain first: a ground return under the canopy, seen from above
                params["terrain_density"] = TERRAIN_DENSITY
                sources["terrain_density"] = "preset"
    return params, sources, regime


def _fmt(v: float) -> str:
    return f"{v:.3g}" if math.isfinite(v) else "n/a"


def regime_reason(measures: CloudMeasures, regime: str, *, sensor: str = "auto") -> str:
    """Why `regime` was chosen: the measured figures and the thresholds they were held to.

    Parameters
    ----------
    measures : CloudMeasures
    regime : {"mls", "als-sparse", "als-dense"}
        As returned by :func:`auto_parameters` for these `measures` and `sensor`.
    sensor : {"auto", "als", "mls"}
        The hint given (if any).

    Returns
    -------
    str
    """
    m = measures
    dens = f"measured density {_fmt(m.density)} pts/m²"
    if sensor != "auto":
        kind = f"sensor given as {sensor}"
    elif math.isfinite(m.scan_angle_max) and m.scan_angle_max > 0:
        cmp = ">" if m.sensor == "mls" else "<="
        kind = f"measured scan angle up to {_fmt(m.scan_angle_max)}° ({cmp} 60°)"
    else:
        crowded = m.concentration > MLS_CONCENTRATION
        kind = (
            f"no scan angle, {_fmt(100.0 * m.concentration)} % of the points in crowded "
            f"cells ({'>' if crowded else '<='} {100.0 * MLS_CONCENTRATION:.0f} %, "
            "MLS_CONCENTRATION)"
        )
        if not crowded:
            dense = m.density > MLS_DENSITY
            kind += (
                f"{' but' if dense else ','} density {'>' if dense else '<='} "
                f"{MLS_DENSITY:g} pts/m² (MLS_DENSITY)"
            )
    if regime == "mls":
        return f"mobile scan ({kind}); {dens}"
    cmp = "<" if regime == "als-sparse" else ">="
    return f"airborne ({kind}); {dens} {cmp} {DENSE_ALS:g} (DENSE_ALS)"


def parameter_notes(
    measures: CloudMeasures, sources: dict[str, str], regime: str, *, sensor: str = "auto"
) -> dict[str, str]:
    """A note per ``"preset"`` parameter: the regime's constant, and why the regime was chosen.

    Parameters
    ----------
    measures : CloudMeasures
    sources : dict
        Provenance per parameter (as from :func:`auto_parameters`, or after explicit
        options replaced some).
    regime : str
    sensor : {"auto", "als", "mls"}

    Returns
    -------
    dict
        ``{parameter: note}`` for the parameters whose source is ``"preset"``.
    """
    why = regime_reason(measures, regime, sensor=sensor)
    notes = {}
    for k, src in sources.items():
        if src != "preset":
            continue
        note = f"constant of the {regime} preset; regime: {why}"
        if k in ("filter_density", "min_edge_length", "terrain_density", "join_below"):
            note += (
                f"; thinned filtering from a density of 1.5 × {FILTER_DENSITY:g} "
                f"= {1.5 * FILTER_DENSITY:g} pts/m²"
            )
        notes[k] = note
    return notes


def with_given(chosen: dict[str, Any], given: dict[str, Any]) -> dict[str, Any]:
    """The `chosen` parameters overridden by the explicit options in `given`.

    The 2 m minimum TIN edge (:data:`FILTER_MIN_EDGE`) is chosen for the thinned
    filter only: when `given` switches the thinning off (``filter_density=0``) and
    says nothing of ``min_edge_length``, that goes back to its default.
    """
    out = {**chosen, **given}
    if (
        "filter_density" in chosen
        and given.get("filter_density") == 0
        and "min_edge_length" not in given
    ):
        out.pop("min_edge_length", None)
    return out
