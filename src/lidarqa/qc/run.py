"""``run_qc``: the whole acceptance run over a delivery, and its outputs.

Inputs are opened with :func:`lidarqa.tiling.open_catalog` (a file is a catalog of one
tile; folders, globs, ``.vpc``) and every tile is checked by one task on the engine
(:func:`lidarqa.tiling.run_tiles`, serial by default). A tile that cannot be read, or
whose CRS differs from the block's, is a failed tile in the result, not the end of the
run. Vertical accuracy at check points is ``checkpoints --vertical`` over the catalog
(:func:`lidarqa.tiling.jobs_api.catalog_vertical_check`), so NVA/VVA are its figures.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from ..errors import OptionError, ReadError
from .conformance import CHECK_ORDER, FAIL, PASS, WARN, Check, worst
from .profiles import QCSpec, get_spec

__all__ = ["TileReport", "QCResult", "run_qc", "CHECK_ORDER", "VEGETATED"]

#: Land-cover values (lower case) that make a check point *vegetated* (VVA); any other
#: value is non-vegetated (NVA).
VEGETATED = frozenset({"vegetated", "vva", "veg", "forest", "forested", "shrub", "shrubs",
                       "scrub", "brush", "tall grass", "tall weeds", "crops", "woods"})


@dataclass(frozen=True)
class TileReport:
    """The verdict on one tile: its checks and footprint."""

    path: str
    checks: dict[str, Check]
    footprint: tuple[float, ...] | None = None
    n_points: int = 0
    classes: dict[str, int] = field(default_factory=dict)

    @property
    def status(self) -> str:
        """Worst status of the checks: ``fail``, ``warn`` or ``pass``."""
        return worst(c.status for c in self.checks.values())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary ``{path, status, checks}``."""
        names = [k for k in CHECK_ORDER if k in self.checks] + sorted(
            k for k in self.checks if k not in CHECK_ORDER)
        return {"path": self.path, "status": self.status, "n_points": self.n_points,
                "classes": dict(self.classes),
                "checks": {k: self.checks[k].to_dict() for k in names}}


@dataclass(frozen=True, eq=False)
class QCResult:
    """Everything ``run_qc`` found.

    Attributes
    ----------
    spec : QCSpec
    tiles : tuple of TileReport
        Sorted by path.
    voids : tuple of (path, polygon, area m²)
    density : dict or None
        The block density raster: ``array`` (row 0 north), ``x0``, ``y1``, ``cell``.
    crs : pyproj.CRS or None
    block : dict
        Block-level checks (``nva``, ``vva``, ``confusion``, ...), each ``{status, value,
        limit, message, ...}``.
    outputs : dict
        Output name -> path (when written).
    ground : dict or None
        With ``ground_consistency``: ``raster`` (share of disagreeing points per cell,
        as `density`) and ``polygons`` (list of (geometry, kind)).
    """

    spec: QCSpec
    tiles: tuple[TileReport, ...]
    voids: tuple[tuple[str, Any, float], ...] = ()
    density: dict[str, Any] | None = None
    crs: Any = None
    block: dict[str, dict[str, Any]] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)
    ground: dict[str, Any] | None = None

    @property
    def status(self) -> str:
        """Worst status over the tiles and the block checks."""
        return worst([t.status for t in self.tiles]
                     + [b.get("status", PASS) for b in self.block.values()])

    @property
    def failed_tiles(self) -> list[str]:
        """Paths of the tiles that failed a check."""
        return [t.path for t in self.tiles if t.status == FAIL]

    def summary(self) -> dict[str, Any]:
        """Counts of tiles by status and the failing checks."""
        n = {s: sum(1 for t in self.tiles if t.status == s) for s in (PASS, WARN, FAIL)}
        by_check: dict[str, int] = {}
        for t in self.tiles:
            for k, c in t.checks.items():
                if c.status == FAIL:
                    by_check[k] = by_check.get(k, 0) + 1
        anpd = [t.checks["density"].value for t in self.tiles
                if "density" in t.checks and t.checks["density"].value is not None]
        return {
            "status": self.status,
            "n_tiles": len(self.tiles),
            "n_pass": n[PASS], "n_warn": n[WARN], "n_fail": n[FAIL],
            "failed_by_check": dict(sorted(by_check.items())),
            "n_voids": len(self.voids),
            "void_area_m2": float(sum(a for _, _, a in self.voids)),
            "median_anpd_per_m2": float(np.median(anpd)) if anpd else None,
            "n_points": int(sum(t.n_points for t in self.tiles)),
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary ``{spec, tiles, block, summary}``."""
        return {"spec": self.spec.to_dict(), "summary": self.summary(),
                "tiles": [t.to_dict() for t in self.tiles], "block": self.block,
                "outputs": dict(self.outputs)}


def _read_exclude(path: Any, crs: Any) -> bytes | None:
    if path is None:
        return None
    from ..io.vector import read_features

    p = Path(path)
    if not p.is_file():
        raise ReadError(f"exclude file {p} does not exist")
    _, _, geoms, _ = read_features(p)
    import shapely

    polys = [g for g in geoms if g is not None and g.geom_type in ("Polygon", "MultiPolygon")]
    if not polys:
        raise ReadError(f"exclude file {p} holds no polygon")
    return shapely.to_wkb(shapely.union_all(polys))


def _checkpoints(path: Any, land_cover: str | None) -> tuple[Any, Any]:
    """(non-vegetated, vegetated or None) check points."""
    from ..io.vector import PointSet, read_points

    cp = path if isinstance(path, PointSet) else read_points(path)
    if land_cover is None:
        return cp, None
    col = land_cover.lower()
    if col not in cp.attributes:
        raise ReadError(f"check points {path}: no land-cover column {land_cover!r} for the VVA "
                        f"(columns: {', '.join(sorted(cp.attributes)) or 'none'})")
    lc = np.array([str(v).strip().lower() for v in cp.attributes[col]])
    veg = np.isin(lc, list(VEGETATED))
    return cp.subset(~veg), cp.subset(veg)


def _accuracy(catalog: Any, cps: Any, spec: QCSpec, *, checkpoint_rmse_v: float,
              engine: Any) -> dict[str, dict[str, Any]]:
    from ..tiling.jobs_api import catalog_vertical_check

    nva, vva = cps
    out: dict[str, dict[str, Any]] = {}
    for name, ps in (("nva", nva), ("vva", vva)):
        if ps is None:
            continue
        if len(ps) == 0:
            out[name] = {"status": WARN if name == "nva" else PASS, "value": None,
                         "limit": spec.max_nva_rmse_m if name == "nva" else None,
                         "message": "no check point in this land cover", "n_check": 0}
            continue
        run = catalog_vertical_check(catalog, ps, checkpoint_rmse_v=checkpoint_rmse_v,
                                     engine=engine)
        d = run.value.to_dict()
        rmse = d.get("rmse_z")
        n = int(d.get("n_check", 0))
        ok = rmse is not None and math.isfinite(rmse)
        if name == "vva":  # ASPRS Ed. 2: VVA is reported, not judged
            st, lim = PASS, None
            msg = (f"VVA RMSEz {rmse:.3f} m at {n} check points (reported, not judged)"
                   if ok else "no VVA")
        else:
            lim = spec.max_nva_rmse_m
            if not ok:
                st, msg = FAIL, "no check point on the ground TIN"
            elif n < spec.min_checkpoints:
                st = WARN
                msg = (f"NVA RMSEz {rmse:.3f} m at {n} check points: fewer than "
                       f"{spec.min_checkpoints}, not judged")
            else:
                st = PASS if rmse <= lim else FAIL
                msg = f"NVA RMSEz {rmse:.3f} m at {n} check points (limit {lim:.3f} m)"
        out[name] = {"status": st, "value": rmse if ok else None, "limit": lim, "message": msg,
                     "n_check": n, "accuracy_z": d.get("accuracy_z"),
                     "mean_z": d.get("mean_z"), "std_z": d.get("std_z")}
    return out


def run_qc(
    source: Any,
    spec: str | os.PathLike | QCSpec = "usgs-ql2",
    *,
    out: str | os.PathLike | None = None,
    overwrite: bool = False,
    checkpoints: Any = None,
    land_cover: str | None = None,
    checkpoint_rmse_v: float = 0.0,
    reference: Any = None,
    reference_tolerance: float = 0.0,
    exclude: Any = None,
    engine: Any = None,
    progress: bool = False,
    html: bool = True,
    crs: Any = None,
    relative_accuracy: bool = False,
    ground_consistency: bool = False,
) -> QCResult:
    """Check a delivery against an acceptance profile, tile by tile.

    Parameters
    ----------
    source : path, folder, glob, .vpc, list of those, or Catalog
    spec : str, path or QCSpec, default "usgs-ql2"
        ``usgs-ql0`` .. ``usgs-ql3`` or a TOML file of limits (:mod:`lidarqa.qc.profiles`).
    out : path, optional
        Output folder: ``qc.json``, ``qc.gpkg`` (``tiles`` and ``voids`` layers),
        ``density.tif`` and ``qc.html``.
    overwrite : bool, default False
    checkpoints : path or PointSet, optional
        Surveyed check points (``id,x,y,z``): NVA (and VVA with `land_cover`).
    land_cover : str, optional
        Column of the check points holding the land cover; values in :data:`VEGETATED`
        are vegetated (VVA), the others non-vegetated (NVA).
    checkpoint_rmse_v : float, default 0
        Vertical RMSE of the check-point survey (m), folded in (ASPRS Ed. 2).
    reference : path, optional
        A reference classification (a point cloud, catalog) for the confusion matrix.
    reference_tolerance : float, default 0
        Largest distance (m) from a delivery point to its reference point (0: the same
        points, matched by position to 1 mm).
    exclude : path, optional
        Polygons (GeoPackage, GeoJSON) left out of the voids (water bodies).
    engine : Engine, optional
        Default: serial.
    progress : bool, default False
    html : bool, default True
        Write ``qc.html`` too (needs matplotlib for the map).
    crs : optional
        CRS assumed for tiles that declare none (they still fail the ``crs`` check: the
        spec wants it in the header).
    relative_accuracy : bool, default False
        Also run the swath analysis (strips by point source id; another pass over the
        points) and judge it with the profile's relative-accuracy limits: the block
        check ``relative_accuracy`` (:func:`lidarqa.qc.block.relative_accuracy`).
    ground_consistency : bool, default False
        Also filter the ground with lidarqa's filter and map where it disagrees with
        the delivery's class 2 (information, not pass/fail; the costliest option):
        block entry ``ground_consistency``, ``ground_consistency.tif`` and the
        ``ground_disagreement`` layer (:func:`lidarqa.qc.block.ground_consistency`).

    Returns
    -------
    QCResult
    """
    from ..tiling import Catalog, open_catalog, run_tiles
    from ._task import TileQC, TileTask

    spec = get_spec(spec)
    if out is not None:
        from .outputs import check_outputs

        check_outputs(out, overwrite=overwrite)
    if reference_tolerance < 0 or not math.isfinite(reference_tolerance):
        raise OptionError(f"reference_tolerance must be >= 0 m, got {reference_tolerance}")
    cps = _checkpoints(checkpoints, land_cover) if checkpoints is not None else None
    if land_cover is not None and checkpoints is None:
        raise OptionError("land_cover (VVA) needs check points")
    catalog = (source if isinstance(source, Catalog)
               else open_catalog(source, skip_bad=True, crs=crs))
    exclude_wkb = _read_exclude(exclude, catalog.crs)
    # tiles in another CRS than the block's are checked too, and fail their crs check
    other: list[Any] = []
    unreadable: list[tuple[str, str]] = []
    for p, why in catalog.bad:
        if why.startswith("CRS differs"):
            try:
                other.extend(open_catalog(p).tiles)
                continue
            except Exception as exc:  # noqa: BLE001 - reported as the tile's failure
                why = str(exc)
        unreadable.append((p, why))
    mismatch = {t.path: f"CRS differs from the block's ({getattr(catalog.crs, 'name', None)})"
                for t in other}
    work = Catalog(tiles=tuple(sorted(list(catalog.tiles) + other, key=lambda t: t.path)),
                   crs=catalog.crs)
    outcomes = run_tiles(work, TileTask(spec, exclude_wkb), engine=engine, progress=progress,
                         description="Checking tiles")
    reports: list[TileReport] = []
    voids: list[tuple[str, Any, float]] = []
    dens_parts = []
    for oc in outcomes:
        tile = work.tiles[oc.chunk.index]
        hb = tuple(float(v) for v in tile.bounds2d)
        if not oc.ok:
            reports.append(TileReport(tile.path, {"readable": Check(FAIL, None, None,
                                                                    oc.error or "failed")}, hb,
                                      tile.n_points))
            continue
        r = cast(TileQC, oc.result)  # ok: the task's result
        checks = dict(r.checks)
        if tile.path in mismatch:
            old = checks.get("crs")
            checks["crs"] = Check(FAIL, old.value if old else None,
                                  getattr(catalog.crs, "name", None),
                                  mismatch[tile.path] + (f"; {old.message}" if old and
                                                         old.status == FAIL else ""))
        reports.append(TileReport(tile.path, checks, r.data_bounds or hb, r.n_points,
                                  r.stats.class_counts() if r.stats else {}))
        if r.voids is not None:
            voids.extend((tile.path, g, a) for g, a in zip(r.voids.polygons, r.voids.areas,
                                                           strict=True))
        if r.density is not None and tile.path not in mismatch:
            dens_parts.append(r.density)
    for p, why in unreadable:
        reports.append(TileReport(str(p), {"readable": Check(FAIL, None, None, why)}))
    reports.sort(key=lambda t: t.path)
    block: dict[str, dict[str, Any]] = {}
    if cps is not None:
        block.update(_accuracy(catalog, cps, spec, checkpoint_rmse_v=checkpoint_rmse_v,
                               engine=engine))
    if reference is not None:
        from .classification import reference_confusion

        conf, per_tile = reference_confusion(catalog, reference, tolerance=reference_tolerance,
                                             allowed=spec.allowed_classes, engine=engine,
                                             progress=progress)
        block["confusion"] = conf
        reports = [_with_check(t, "classification", per_tile.get(t.path)) for t in reports]
    if relative_accuracy:
        from .block import relative_accuracy as _relative

        block["relative_accuracy"] = _relative(catalog, spec, engine=engine, progress=progress)
    ground = None
    if ground_consistency:
        from .block import ground_consistency as _ground

        check, raster, polys = _ground(catalog, engine=engine, progress=progress)
        block["ground_consistency"] = check
        ground = {"raster": raster, "polygons": polys}
    result = QCResult(spec, tuple(reports), tuple(voids), _block_raster(dens_parts),
                      catalog.crs, block, ground=ground)
    if out is not None:
        from .outputs import write_outputs

        outputs = write_outputs(result, out, overwrite=overwrite, html=html)
        result = QCResult(result.spec, result.tiles, result.voids, result.density, result.crs,
                          result.block, outputs, ground)
    return result


def _with_check(t: TileReport, name: str, check: Check | None) -> TileReport:
    if check is None:
        return t
    return TileReport(t.path, {**t.checks, name: check}, t.footprint, t.n_points, t.classes)


def _block_raster(parts: list[Any]) -> dict[str, Any] | None:
    """The tiles' density rasters added into one block raster (same aligned grid)."""
    if not parts:
        return None
    cell = parts[0].cell
    parts = [p for p in parts if abs(p.cell - cell) < 1e-9]
    x0 = min(p.x0 for p in parts)
    y0 = min(p.y0 for p in parts)
    x1 = max(p.x0 + p.raster.shape[1] * cell for p in parts)
    y1 = max(p.y0 + p.raster.shape[0] * cell for p in parts)
    nx = int(round((x1 - x0) / cell))
    ny = int(round((y1 - y0) / cell))
    if nx * ny > 200_000_000:
        return None
    acc = np.zeros((ny, nx))
    seen = np.zeros((ny, nx), dtype=bool)
    for p in parts:
        i0 = int(round((p.x0 - x0) / cell))
        j0 = int(round((p.y0 - y0) / cell))
        h, w = p.raster.shape
        ok = np.isfinite(p.raster)
        acc[j0:j0 + h, i0:i0 + w] += np.where(ok, p.raster, 0.0)
        seen[j0:j0 + h, i0:i0 + w] |= ok
    arr = np.where(seen, acc, np.nan)[::-1]  # row 0 north
    return {"array": arr, "x0": x0, "y1": y1, "cell": cell}
