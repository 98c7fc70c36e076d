"""The per-tile work of ``qc``: one streaming pass over a tile's points (runs on a worker)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..io.crs import metre_factors
from .conformance import (
    FAIL,
    PASS,
    WARN,
    Check,
    PointStats,
    count_duplicates,
    duplicate_keys,
    header_checks,
    point_checks,
    worst,
)
from .density import DensityGrids, DensityResult, density_result
from .voids import VOID_CELLS, VoidResult, find_voids

__all__ = ["TileQC", "TileTask", "READ_STEP"]

#: Points read from a tile at a time (memory per worker: one piece plus the grids).
READ_STEP = 1_000_000

#: The dimensions qc reads (a layered LAZ tile decompresses only these; no copy of the
#: others is made). "X", "Y", "Z" are the stored integers, for the duplicate keys.
QC_FIELDS = ("X", "Y", "Z", "return_number", "number_of_returns", "classification",
             "withheld", "overlap", "synthetic", "key_point", "scan_angle", "scan_angle_rank",
             "point_source_id", "gps_time")


@dataclass(frozen=True)
class TileQC:
    """Everything ``qc`` measured on one tile (picklable, small: grids are per cell)."""

    path: str
    checks: dict[str, Check]
    n_points: int = 0
    facts: dict[str, Any] = field(default_factory=dict)
    stats: PointStats | None = None
    density: DensityResult | None = None
    voids: VoidResult | None = None
    data_bounds: tuple[float, float, float, float] | None = None
    crs_name: str | None = None

    @property
    def status(self) -> str:
        return worst(c.status for c in self.checks.values())


@dataclass(frozen=True)
class TileTask:
    """``TileTask(spec)(tile_info) -> TileQC``: conformance, density and voids of one tile.

    Attributes
    ----------
    spec : QCSpec
    exclude_wkb : bytes, optional
        Polygons (WKB) subtracted from the voids (water bodies).
    read_step : int
        Points per streamed piece.
    """

    spec: Any
    exclude_wkb: bytes | None = None
    read_step: int = READ_STEP

    def __call__(self, tile: Any) -> TileQC:
        from ..io.las import LasReader, las_header_facts

        spec = self.spec
        with LasReader(tile.path, dimensions=QC_FIELDS) as r:
            facts = las_header_facts(r)
            crs = r.crs
            pf = facts["point_format"]
            hb = (facts["mins"][0], facts["mins"][1], facts["maxs"][0], facts["maxs"][1])
            # the grids are laid in the tile's own units (x, y in feet, say): the spec's
            # lengths in those units, the densities and areas back in metres below
            unit = metre_factors(crs)[0]
            cell = spec.distribution_cell_m / unit
            grids = DensityGrids(hb, cell=cell, void_cell=spec.void_side_m / unit / VOID_CELLS,
                                 coarse_factor=max(int(round(spec.density_cell
                                                             / spec.distribution_cell_m)), 1))
            keys = []
            for piece in r.chunks(self.read_step, fields=QC_FIELDS):
                xyz, f = piece.xyz, piece.fields
                grids.scan(xyz, f, point_format=pf)
                ints = (f.pop("X"), f.pop("Y"), f.pop("Z")) if "X" in f else None
                keys.append(duplicate_keys(xyz, f.get("gps_time"), scales=facts["scales"],
                                           offsets=facts["offsets"], ints=ints))
        stats = grids.stats()
        has_returns = grids.has_returns
        dup = count_duplicates(np.concatenate(keys)) if keys else 0
        del keys
        checks = header_checks(facts, spec, crs=crs)
        checks.update(point_checks(stats, facts, spec, duplicates=dup))
        if stats.n == 0:
            checks["density"] = Check(FAIL, 0.0, spec.min_anpd, "the tile holds no point")
            return TileQC(tile.path, checks, 0, facts, stats, crs_name=_name(crs))
        data_bounds = (stats.mins[0], stats.mins[1], stats.maxs[0], stats.maxs[1])
        dens = density_result(grids, data_bounds, unit)
        vg = grids.void
        inside = vg.inner_mask(data_bounds)
        exclude = None
        if self.exclude_wkb is not None:
            import shapely

            exclude = shapely.from_wkb(self.exclude_wkb)
        voids = find_voids(grids.occupied.reshape(vg.ny, vg.nx), x0=vg.x0, y0=vg.y0,
                           cell=vg.cell, min_side=spec.void_side_m / unit, inside=inside,
                           water=grids.water_void.reshape(vg.ny, vg.nx), exclude=exclude)
        if unit != 1.0:  # polygons stay in the tile's units, their areas in m²
            voids = replace(voids, areas=tuple(a * unit * unit for a in voids.areas))
        checks.update(_density_checks(dens, voids, spec, has_returns, grids.outside))
        return TileQC(tile.path, checks, stats.n, facts, stats, dens, voids, data_bounds,
                      _name(crs))


def _name(crs: Any) -> str | None:
    return None if crs is None else str(crs.name)


def _density_checks(dens: DensityResult, voids: VoidResult, spec: Any, has_returns: bool,
                    outside: int) -> dict[str, Check]:
    out: dict[str, Check] = {}
    note = "" if has_returns else " (no return numbers: every point counted as a first return)"
    a = dens.anpd
    if not math.isfinite(a):
        st, msg = FAIL, "no first return to measure the density on"
    elif a < spec.min_anpd:
        st, msg = FAIL, f"ANPD {a:.2f} first returns/m² below the minimum {spec.min_anpd:g}"
    else:
        st, msg = PASS, f"ANPD {a:.2f} first returns/m² (single swath, overlap excluded)"
    if st == PASS and not has_returns:
        st = WARN
    if dens.n_multi_swath_cells:
        msg += f"; {dens.n_multi_swath_cells:,} cells with unflagged overlap (dominant swath kept)"
    if outside:
        msg += f"; {outside:,} points outside the header bounds not gridded"
    out["density"] = Check(st, _r(a), spec.min_anpd, msg + note)
    d = dens.distribution
    if not math.isfinite(d):
        st, msg = FAIL, "no 2 x ANPS cell inside the data extent"
    else:
        st = PASS if d >= spec.min_spatial_distribution else FAIL
        msg = (f"{100 * d:.1f} % of {dens.n_distribution_cells:,} cells of "
               f"{spec.distribution_cell_m:.2f} m hold a first return")
    if st == PASS and not has_returns:
        st = WARN
    out["spatial_distribution"] = Check(st, _r(d), spec.min_spatial_distribution, msg + note)
    area = voids.total_area
    st = FAIL if area > spec.max_void_area_m2 else PASS
    if voids.areas:
        msg = (f"{len(voids.areas)} void(s) of at least ({spec.void_side_m:.2f} m)², "
               f"{area:.1f} m² in all, largest {max(voids.areas):.1f} m²")
    else:
        msg = f"no void of ({spec.void_side_m:.2f} m)² or more"
    if voids.n_water:
        msg += f"; {voids.n_water} empty area(s) left out as water"
    out["voids"] = Check(st, round(area, 3), spec.max_void_area_m2, msg)
    return out


def _r(v: float) -> float | None:
    return round(float(v), 6) if math.isfinite(v) else None
