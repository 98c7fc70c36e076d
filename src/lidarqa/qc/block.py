"""Block-level checks of ``qc`` that need the points of several tiles at once.

- :func:`relative_accuracy`: the swath analysis of ``lidarqa swaths`` over the catalog
  (:func:`lidarqa.tiling.jobs_swaths.catalog_swaths`, strips by point source id) judged
  with the profile's limits: smooth-surface repeatability (intraswath, the worst strip's
  median max - min residual), swath-overlap RMSDz and largest absolute dz (the worst pair).
- :func:`ground_consistency`: the delivery's class 2 against lidarqa's own ground filter
  (:func:`lidarqa.ground.classify_ground`) on buffered chunks, as a raster of the share of
  points on which the two disagree, and polygons of the cells where most points disagree.
  Information, never pass/fail.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .conformance import FAIL, PASS, WARN

__all__ = ["relative_accuracy", "ground_consistency", "GroundConsistencyTask",
           "GROUND_CELL_M"]

#: Cell (m) of the ground-consistency raster.
GROUND_CELL_M = 5.0


def relative_accuracy(catalog: Any, spec: Any, *, engine: Any = None,
                      progress: bool = False) -> dict[str, Any]:
    """The ``relative_accuracy`` block check: swath analysis against the profile's limits.

    Parameters
    ----------
    catalog : Catalog
    spec : QCSpec
        ``max_intraswath_m``, ``max_swath_rmsdz_m``, ``max_swath_abs_dz_m``.
    engine : Engine, optional
    progress : bool, default False

    Returns
    -------
    dict
        ``{status, value, limit, message, ...}``: `value` the worst pair RMSDz (m); a
        block without two overlapping strips (point source ids) warns, not assessed.
    """
    from ..errors import LidarQAError
    from ..tiling.jobs_swaths import catalog_swaths

    limit = {"intraswath_m": spec.max_intraswath_m, "rmsdz_m": spec.max_swath_rmsdz_m,
             "max_abs_dz_m": spec.max_swath_abs_dz_m}
    try:
        run = catalog_swaths(catalog, by_source_id=True, estimate_offsets=False,
                             return_grids=False, engine=engine, progress=progress)
    except LidarQAError as exc:
        return {"status": WARN, "value": None, "limit": spec.max_swath_rmsdz_m,
                "message": f"not assessed: {exc}", "limits": limit}
    rep = run.value
    pairs = [p for p in rep.pairs if p.n_cells > 0 and math.isfinite(p.rmsdz)]
    strips = [r for r in rep.repeatability if r.assessed and math.isfinite(r.median_range)]
    worst_rms = max((p.rmsdz for p in pairs), default=math.nan)
    worst_max = max((p.max_abs for p in pairs), default=math.nan)
    worst_rep = max((r.median_range for r in strips), default=math.nan)
    problems = []
    if pairs and worst_rms > spec.max_swath_rmsdz_m:
        problems.append(f"swath-overlap RMSDz {worst_rms:.3f} m over {spec.max_swath_rmsdz_m:g} m")
    if pairs and worst_max > spec.max_swath_abs_dz_m:
        problems.append(f"largest |dz| {worst_max:.3f} m over {spec.max_swath_abs_dz_m:g} m")
    if strips and worst_rep > spec.max_intraswath_m:
        problems.append(f"smooth-surface repeatability {worst_rep:.3f} m over "
                        f"{spec.max_intraswath_m:g} m")
    if not pairs and not strips:
        st, msg = WARN, "not assessed: no smooth overlap between strips"
    else:
        st = FAIL if problems else PASS
        msg = "; ".join(problems) if problems else (
            f"{len(pairs)} strip pair(s): worst RMSDz {worst_rms:.3f} m, largest |dz| "
            f"{worst_max:.3f} m; {len(strips)} strip(s): worst repeatability {worst_rep:.3f} m")
        if not pairs:
            st, msg = WARN, msg + " (no overlapping pair: swath overlap not assessed)"

    def fin(v: float) -> float | None:
        return round(float(v), 6) if math.isfinite(v) else None

    return {"status": st, "value": fin(worst_rms), "limit": spec.max_swath_rmsdz_m,
            "message": msg, "limits": limit, "max_abs_dz_m": fin(worst_max),
            "intraswath_m": fin(worst_rep), "n_pairs": len(pairs), "n_strips": len(strips),
            "cell_size_m": float(rep.cell_size)}


@dataclass(frozen=True)
class GroundCells:
    """One chunk's ground-consistency counts on the block grid (sparse)."""

    keys: np.ndarray  # flat cell index
    n: np.ndarray  # points compared
    only_delivery: np.ndarray  # class 2 in the delivery, not ground for the filter
    only_filter: np.ndarray  # ground for the filter, not class 2 in the delivery


@dataclass(frozen=True)
class GroundConsistencyTask:
    """Per buffered chunk: filter the ground, count disagreements per cell on core points."""

    x0: float
    y0: float
    nx: int
    cell: float

    def __call__(self, data: Any) -> GroundCells | None:
        """The ground cells of one chunk (None when it holds no points)."""
        from ..ground import classify_ground

        core = data.core
        cloud = data.cloud
        cls = cloud.fields.get("classification")
        if not core.any() or cls is None:
            return None
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = classify_ground(cloud)
        cls = np.asarray(cls)
        # compared: last returns (the filter's candidates), neither noise nor withheld
        m = core & ~np.isin(cls, (7, 18))
        rn, nr = cloud.fields.get("return_number"), cloud.fields.get("number_of_returns")
        if rn is not None and nr is not None and np.any(rn):
            m &= np.asarray(rn) == np.asarray(nr)
        w = cloud.fields.get("withheld")
        if w is not None:
            m &= np.asarray(w) == 0
        if not m.any():
            return None
        g = np.asarray(res.ground_mask, dtype=bool)[m]
        d = cls[m] == 2
        xy = cloud.xyz[m]
        i = np.floor((xy[:, 0] - self.x0) / self.cell).astype(np.int64)
        j = np.floor((xy[:, 1] - self.y0) / self.cell).astype(np.int64)
        k = j * self.nx + i
        keys, inv = np.unique(k, return_inverse=True)
        return GroundCells(keys, np.bincount(inv), np.bincount(inv, weights=d & ~g).astype(int),
                           np.bincount(inv, weights=g & ~d).astype(int))


def ground_consistency(catalog: Any, *, engine: Any = None, progress: bool = False,
                       cell: float = GROUND_CELL_M) -> tuple[dict[str, Any], dict[str, Any],
                                                             list[tuple[Any, str]]]:
    """The delivery's class 2 against lidarqa's ground filter, over the block.

    Parameters
    ----------
    catalog : Catalog
    engine : Engine, optional
    progress : bool, default False
    cell : float, default :data:`GROUND_CELL_M`
        Raster cell (m).

    Returns
    -------
    check : dict
        The ``ground_consistency`` block entry (status always ``pass``: information).
    raster : dict
        ``array`` (share 0-1 of compared points on which they disagree, row 0 north,
        NaN: no point), ``x0``, ``y1``, ``cell``.
    polygons : list of (geometry, kind)
        Cells where more than half the compared points disagree, merged;
        `kind` is ``"delivery ground only"`` or ``"filter ground only"`` (the larger).
    """
    from ..tiling import make_chunks, run_chunks

    b = catalog.bounds
    x0 = math.floor(b[0] / cell) * cell
    y0 = math.floor(b[1] / cell) * cell
    nx = int(math.floor((b[2] - x0) / cell)) + 1
    ny = int(math.floor((b[3] - y0) / cell)) + 1
    chunks = make_chunks(catalog)
    outcomes = run_chunks(catalog, list(chunks), GroundConsistencyTask(x0, y0, nx, cell),
                          engine=engine, progress=progress, skip_failed=True,
                          description="Ground consistency")
    size = nx * ny
    n = np.zeros(size, np.int64)
    od = np.zeros(size, np.int64)
    of = np.zeros(size, np.int64)
    failed = 0
    for o in outcomes:
        if not o.ok:
            failed += 1
            continue
        r = o.result
        if r is None:
            continue
        ok = (r.keys >= 0) & (r.keys < size)
        np.add.at(n, r.keys[ok], r.n[ok])
        np.add.at(od, r.keys[ok], r.only_delivery[ok])
        np.add.at(of, r.keys[ok], r.only_filter[ok])
    tot = int(n.sum())
    share = np.where(n > 0, (od + of) / np.maximum(n, 1), np.nan).reshape(ny, nx)
    polys: list[tuple[Any, str]] = []
    bad = (np.nan_to_num(share) > 0.5)
    if bad.any():
        import shapely
        from rasterio import features
        from rasterio.transform import Affine

        kind = np.where(od.reshape(ny, nx) >= of.reshape(ny, nx), 1, 2).astype(np.int32)
        lab = np.where(bad, kind, 0).astype(np.int32)
        tr = Affine(cell, 0.0, x0, 0.0, cell, y0)
        for geom, v in features.shapes(lab, mask=lab > 0, connectivity=8, transform=tr):
            polys.append((shapely.geometry.shape(geom),
                          "delivery ground only" if int(v) == 1 else "filter ground only"))
    agree = 1.0 - (int(od.sum()) + int(of.sum())) / tot if tot else math.nan
    msg = (f"the delivery's ground (class 2) and lidarqa's ground filter agree on "
           f"{100 * agree:.1f} % of {tot:,} last returns; {int(od.sum()):,} class-2 point(s) "
           f"the filter does not take for ground, {int(of.sum()):,} ground point(s) of the "
           f"filter not in class 2; {len(polys)} area(s) where most points disagree "
           "(information, not judged)" if tot else "no point to compare")
    if failed:
        msg += f"; {failed} chunk(s) failed"
    check = {"status": PASS, "value": round(agree, 6) if tot else None, "limit": None,
             "message": msg, "n_compared": tot, "n_delivery_only": int(od.sum()),
             "n_filter_only": int(of.sum()), "n_areas": len(polys), "cell_size_m": cell}
    raster = {"array": share[::-1].copy(), "x0": x0, "y1": y0 + ny * cell, "cell": cell}
    return check, raster, polys
