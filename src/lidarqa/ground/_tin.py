"""Private TIN machinery shared by point-based and segment-based PTD.

Everything here trusts its inputs (validated in ``ptd.py`` / ``segment_ptd.py``).
Coordinates are expected to be already shifted near the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError

EPS = 1e-9

__all__ = [
    "EPS",
    "Criteria",
    "TIN",
    "lowest_per_cell",
    "virtual_hull",
    "screen_seeds",
    "test_points",
    "mirror_point",
]


@dataclass(frozen=True)
class Criteria:
    """The §1.1 acceptance thresholds, in radians and metres."""

    iter_angle: float  # rad
    iter_distance: float  # m
    max_terrain_angle: float  # rad
    min_edge_length: float  # m
    mirror: bool = True
    edge_mode: str = "freeze"


def lowest_per_cell(xyz: np.ndarray, idx: np.ndarray, cell_size: float, origin: np.ndarray) -> np.ndarray:
    """Index (into the full array) of the lowest point of each non-empty grid cell.

    Ties go to the smaller index, so the result does not depend on input order.
    """
    if idx.size == 0:
        return idx
    p = xyz[idx]
    ij = np.floor((p[:, :2] - origin[:2]) / cell_size).astype(np.int64)
    ij -= ij.min(axis=0)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    order = np.lexsort((idx, p[:, 2], key))
    k = key[order]
    first = np.ones(k.size, dtype=bool)
    first[1:] = k[1:] != k[:-1]
    return np.sort(idx[order[first]])


def virtual_hull(xyz: np.ndarray, seed_idx: np.ndarray, margin: float, lo: np.ndarray,
                 hi: np.ndarray) -> np.ndarray:
    """Four virtual corner vertices outside the bounding box, z of the XY-nearest seed."""
    corners = np.array(
        [[lo[0] - margin, lo[1] - margin], [hi[0] + margin, lo[1] - margin],
         [hi[0] + margin, hi[1] + margin], [lo[0] - margin, hi[1] + margin]],
        dtype=np.float64,
    )
    s = xyz[seed_idx]
    d2 = ((corners[:, None, :] - s[None, :, :2]) ** 2).sum(axis=2)
    # ties: smaller seed index (seed_idx is sorted, argmin takes the first)
    z = s[np.argmin(d2, axis=1), 2]
    return np.column_stack([corners, z])


class TIN:
    """A 2.5-D Delaunay TIN of real vertices (indices into the cloud) plus virtual ones."""

    def __init__(self, xyz: np.ndarray, real_idx: np.ndarray, virtual: np.ndarray) -> None:
        self.real_idx = np.asarray(real_idx, dtype=np.int64)
        self.n_real = self.real_idx.size
        self.vxyz = np.vstack([xyz[self.real_idx], virtual])
        try:
            self.dt = Delaunay(self.vxyz[:, :2])
        except QhullError:  # pragma: no cover - virtual hull makes this nearly impossible
            self.dt = Delaunay(self.vxyz[:, :2], qhull_options="QJ")
        self.simplices = self.dt.simplices.astype(np.int64)
        t = self.vxyz[self.simplices]  # (K, 3, 3)
        e = np.stack([t[:, 1, :2] - t[:, 0, :2], t[:, 2, :2] - t[:, 1, :2], t[:, 0, :2] - t[:, 2, :2]], 1)
        self.edge_max = np.sqrt((e ** 2).sum(axis=2)).max(axis=1)
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        norm = np.linalg.norm(n, axis=1)
        norm[norm == 0] = 1.0
        n = n / norm[:, None]
        n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]
        self.normal = n
        self.slope = np.arccos(np.clip(np.abs(n[:, 2]), 0.0, 1.0))

    def locate(self, xy: np.ndarray) -> np.ndarray:
        """Triangle index of each XY point, -1 outside the TIN."""
        if xy.shape[0] == 0:
            return np.zeros(0, dtype=np.int64)
        return self.dt.find_simplex(xy).astype(np.int64)

    def is_real(self, v: np.ndarray) -> np.ndarray:
        return v < self.n_real


def screen_seeds(xyz: np.ndarray, seeds: np.ndarray, virtual: np.ndarray, max_angle: float,
                 max_rounds: int = 100_000) -> np.ndarray:
    """Remove the highest real vertex of facets steeper than `max_angle` (rad) until none is."""
    seeds = np.asarray(seeds)
    for _ in range(max_rounds):
        if seeds.size <= 3:
            break
        tin = TIN(xyz, seeds, virtual)
        bad = tin.slope > max_angle + 1e-12
        if not bad.any():
            break
        v = np.unique(tin.simplices[bad])
        v = v[tin.is_real(v)]
        if v.size == 0:
            break
        z = tin.vxyz[v, 2]
        # highest; ties: larger original index goes first (deterministic)
        order = np.lexsort((-seeds[v], -z))
        seeds = np.delete(seeds, v[order[0]])
    return seeds


def mirror_point(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Point reflection of `p` through `v`: ``2 v - p``."""
    return 2.0 * np.asarray(v, dtype=np.float64) - np.asarray(p, dtype=np.float64)


def _facet_measures(p: np.ndarray, t: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the facet plane and largest vertex angle beta (rad), vectorised.

    `p` (M, 3), `t` (M, 3, 3) triangle vertices, `normal` (M, 3) unit normals.
    """
    dist = np.abs(((p - t[:, 0]) * normal).sum(axis=1))
    pv = np.sqrt(((p[:, None, :] - t) ** 2).sum(axis=2))  # (M, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(pv > EPS, dist[:, None] / pv, 1.0)
    beta = np.arcsin(np.clip(s, 0.0, 1.0)).max(axis=1)
    return dist, beta


def _subfacet_slope_ok(p: np.ndarray, t: np.ndarray, max_angle: float) -> np.ndarray:
    """All three sub-facets (P,A,B), (P,B,C), (P,C,A) no steeper than `max_angle`.

    Sub-facets with XY area < EPS (P on an edge) are ignored.
    """
    ok = np.ones(p.shape[0], dtype=bool)
    cos_max = np.cos(max_angle)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        n = np.cross(t[:, i] - p, t[:, j] - p)
        nz = np.abs(n[:, 2])
        nn = np.linalg.norm(n, axis=1)
        area_xy = 0.5 * nz
        with np.errstate(divide="ignore", invalid="ignore"):
            cosv = np.where(nn > 0, nz / nn, 1.0)
        ok &= (area_xy < EPS) | (cosv >= cos_max - 1e-12)
    return ok


@dataclass
class PointTest:
    """Per-candidate outcome of one test sweep against a TIN."""

    tri: np.ndarray  # (M,) triangle, -1 outside
    passed: np.ndarray  # (M,) bool, passed direct or mirrored test (insertable)
    score: np.ndarray  # (M,) distance used to rank passing points
    beta: np.ndarray  # (M,) vertex angle used to rank
    duplicate_ok: np.ndarray  # (M,) bool, coincides in XY with a vertex and within d in z
    duplicate: np.ndarray  # (M,) bool, coincides in XY with a vertex
    frozen: np.ndarray  # (M,) bool, skipped because its triangle is frozen
    mirrored: np.ndarray  # (M,) bool, passed only by mirroring


def test_points(tin: TIN, p: np.ndarray, crit: Criteria, *, check_frozen: bool = True) -> PointTest:
    """Run the §1.1 step 5b–f tests for candidate points `p` (M, 3) against `tin`."""
    m = p.shape[0]
    tri = tin.locate(p[:, :2])
    inside = tri >= 0
    passed = np.zeros(m, dtype=bool)
    mirrored = np.zeros(m, dtype=bool)
    score = np.full(m, np.inf)
    beta_out = np.full(m, np.inf)
    dup = np.zeros(m, dtype=bool)
    dup_ok = np.zeros(m, dtype=bool)
    frozen = np.zeros(m, dtype=bool)
    if not inside.any():
        return PointTest(tri, passed, score, beta_out, dup_ok, dup, frozen, mirrored)
    ii = np.flatnonzero(inside)
    tt = tri[ii]
    pp = p[ii]
    verts = tin.simplices[tt]  # (M', 3)
    t = tin.vxyz[verts]  # (M', 3, 3)
    theta = np.full(ii.size, crit.iter_angle)
    if check_frozen and crit.min_edge_length > 0:
        emax = tin.edge_max[tt]
        small = emax < crit.min_edge_length
        if crit.edge_mode == "freeze":
            frozen[ii] = small
        else:  # "reduce"
            theta = np.where(small, crit.iter_angle * (emax / crit.min_edge_length) ** 2, theta)
    # XY duplicates of a vertex
    dxy = np.sqrt(((pp[:, None, :2] - t[:, :, :2]) ** 2).sum(axis=2))  # (M', 3)
    jmin = np.argmin(dxy, axis=1)
    is_dup = dxy[np.arange(ii.size), jmin] < EPS
    dz = np.abs(pp[:, 2] - t[np.arange(ii.size), jmin, 2])
    dup[ii] = is_dup
    dup_ok[ii] = is_dup & (dz <= crit.iter_distance + 1e-12)
    live = ~is_dup & ~frozen[ii]
    normal = tin.normal[tt]
    dist, beta = _facet_measures(pp, t, normal)
    ok = live & (dist <= crit.iter_distance + 1e-12) & (beta <= theta + 1e-12)
    if ok.any():
        ok[ok] = _subfacet_slope_ok(pp[ok], t[ok], crit.max_terrain_angle)
    sc = np.where(ok, dist, np.inf)
    bt = np.where(ok, beta, np.inf)
    mir = np.zeros(ii.size, dtype=bool)
    if crit.mirror:
        todo = np.flatnonzero(live & ~ok)
        if todo.size:
            tv = t[todo]
            d3 = np.sqrt(((pp[todo, None, :] - tv) ** 2).sum(axis=2))
            real = tin.is_real(verts[todo])
            d3 = np.where(real, d3, np.inf)
            # ties: lower vertex index
            key = np.where(real, verts[todo], np.iinfo(np.int64).max)
            dmin = d3.min(axis=1)
            tie = d3 == dmin[:, None]
            keyt = np.where(tie, key, np.iinfo(np.int64).max)
            best = np.argmin(keyt, axis=1)
            has_real = np.isfinite(dmin)
            vstar = tv[np.arange(todo.size), best]
            pm = 2.0 * vstar - pp[todo]
            tri2 = tin.locate(pm[:, :2])
            good = has_real & (tri2 >= 0)
            if good.any():
                g = np.flatnonzero(good)
                t2 = tin.vxyz[tin.simplices[tri2[g]]]
                d2, b2 = _facet_measures(pm[g], t2, tin.normal[tri2[g]])
                okm = (d2 <= crit.iter_distance + 1e-12) & (b2 <= theta[todo[g]] + 1e-12)
                sel = todo[g[okm]]
                mir[sel] = True
                sc[sel] = d2[okm]
                bt[sel] = b2[okm]
    passed[ii] = ok | mir
    mirrored[ii] = mir & ~ok
    score[ii] = sc
    beta_out[ii] = bt
    return PointTest(tri, passed, score, beta_out, dup_ok, dup, frozen, mirrored)
