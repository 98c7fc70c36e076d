"""Private TIN machinery shared by point-based and segment-based PTD.

Everything here trusts its inputs (validated in ``ptd.py`` / ``segment_ptd.py``).
Coordinates are expected to be already shifted near the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import Delaunay, QhullError

EPS = 1e-9

__all__ = [
    "EPS",
    "Criteria",
    "TIN",
    "lowest_per_cell",
    "virtual_hull",
    "screen_seeds",
    "judge_points",
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
    mirror_max_distance: float = np.inf  # m, horizontal P–V* limit of mirroring


def lowest_per_cell(
    xyz: np.ndarray, idx: np.ndarray, cell_size: float, origin: np.ndarray
) -> np.ndarray:
    """Index (into the full array) of the lowest point of each non-empty grid cell.

    Ties go to the smaller index, so the result does not depend on input order.
    """
    if idx.size == 0:
        return idx
    p = xyz[idx]
    ij = np.floor((p[:, :2] - origin[:2]) / cell_size).astype(np.int64)
    ij -= ij.min(axis=0)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    order = np.lexsort((idx, p[:, 1], p[:, 0], p[:, 2], key))
    k = key[order]
    first = np.ones(k.size, dtype=bool)
    first[1:] = k[1:] != k[:-1]
    return np.sort(idx[order[first]])


def virtual_hull(
    xyz: np.ndarray, seed_idx: np.ndarray, margin: float, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """Four virtual corner vertices outside the bounding box, z of the XY-nearest seed."""
    corners = np.array(
        [
            [lo[0] - margin, lo[1] - margin],
            [hi[0] + margin, lo[1] - margin],
            [hi[0] + margin, hi[1] + margin],
            [lo[0] - margin, hi[1] + margin],
        ],
        dtype=np.float64,
    )
    s = xyz[seed_idx]
    d2 = ((corners[:, None, :] - s[None, :, :2]) ** 2).sum(axis=2)
    # ties: smaller seed index (seed_idx is sorted, argmin takes the first)
    z = s[np.argmin(d2, axis=1), 2]
    return np.column_stack([corners, z])


class TIN:
    """A 2.5-D Delaunay TIN of real vertices (indices into the cloud) plus virtual ones.

    Built with scipy (Qhull) from scratch; :class:`IncrementalTIN` produces the same
    kind of object from a startinpy triangulation that grows by insertion.
    """

    def __init__(self, xyz: np.ndarray, real_idx: np.ndarray, virtual: np.ndarray) -> None:
        real_idx = np.asarray(real_idx, dtype=np.int64)
        # canonical vertex order (by coordinates) so the triangulation of
        # co-circular points does not depend on the input order
        r = xyz[real_idx]
        real_idx = real_idx[np.lexsort((real_idx, r[:, 2], r[:, 1], r[:, 0]))]
        vxyz = np.vstack([xyz[real_idx], virtual])
        try:
            dt = Delaunay(vxyz[:, :2])
        except QhullError:  # pragma: no cover - virtual hull makes this nearly impossible
            dt = Delaunay(vxyz[:, :2], qhull_options="QJ")
        vsrc = np.concatenate([real_idx, np.full(len(virtual), -1, dtype=np.int64)])
        self._setup(vxyz, vsrc, dt.simplices.astype(np.int64), dt.neighbors.astype(np.int64))
        self.dt = dt

    @classmethod
    def from_triangles(cls, vxyz: np.ndarray, vsrc: np.ndarray, simplices: np.ndarray) -> TIN:
        """A TIN from vertex coordinates, their sources (-1 = virtual) and triangles."""
        self = cls.__new__(cls)
        self._setup(vxyz, vsrc, simplices.astype(np.int64), None)
        self.dt = None
        return self

    def _setup(
        self, vxyz: np.ndarray, vsrc: np.ndarray, simp: np.ndarray, nb: np.ndarray | None
    ) -> None:
        self.vxyz = vxyz
        self.vsrc = vsrc
        self.real_pos = np.flatnonzero(vsrc >= 0)
        self.real_idx = vsrc[self.real_pos]
        self.n_real = self.real_idx.size
        xy = vxyz[:, :2]
        a, b, c = xy[simp[:, 0]], xy[simp[:, 1]], xy[simp[:, 2]]
        cw = (
            (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        ) < 0
        if cw.any():  # make every triangle counter-clockwise (swap vertices 1 and 2)
            simp[cw] = simp[cw][:, [0, 2, 1]]
            if nb is not None:
                nb[cw] = nb[cw][:, [0, 2, 1]]
        if nb is None:
            nb = _neighbors(simp, vxyz.shape[0])
        self.simplices = np.ascontiguousarray(simp)
        self.neighbors = np.ascontiguousarray(nb)
        t = vxyz[self.simplices]  # (K, 3, 3)
        e = np.stack(
            [t[:, 1, :2] - t[:, 0, :2], t[:, 2, :2] - t[:, 1, :2], t[:, 0, :2] - t[:, 2, :2]], 1
        )
        self.edge_max = np.sqrt((e**2).sum(axis=2)).max(axis=1)
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
        order = spatial_order(xy)
        vxy = np.ascontiguousarray(self.vxyz[:, :2])
        out = np.empty(xy.shape[0], dtype=np.int64)
        lost = _walk_all(np.ascontiguousarray(xy[order]), vxy, self.simplices, self.neighbors, out)
        res = np.empty_like(out)
        res[order] = out
        if lost:  # walk did not converge (degenerate geometry): exact fallback
            bad = np.flatnonzero(res == -2)
            res[bad] = _brute_locate(xy[bad], vxy, self.simplices)
        return res

    def is_real(self, v: np.ndarray) -> np.ndarray:
        return self.vsrc[v] >= 0

    def real_triangles(self) -> np.ndarray:
        """Triangles with three real vertices, as positions into :attr:`real_idx`."""
        keep = (self.vsrc[self.simplices] >= 0).all(axis=1)
        pos = np.full(self.vxyz.shape[0], -1, dtype=np.int64)
        pos[self.real_pos] = np.arange(self.n_real)
        return pos[self.simplices[keep]]


def _neighbors(simp: np.ndarray, nv: int) -> np.ndarray:
    """Triangle adjacency: ``nb[k, i]`` is the triangle across the side opposite vertex i."""
    k = simp.shape[0]
    a = simp[:, [1, 2, 0]].astype(np.int64)
    b = simp[:, [2, 0, 1]].astype(np.int64)
    key = (a * nv + b).ravel()
    rkey = (b * nv + a).ravel()
    order = np.argsort(key, kind="stable")
    sk = key[order]
    pos = np.minimum(np.searchsorted(sk, rkey), sk.size - 1)
    found = sk[pos] == rkey
    return np.where(found, order[pos] // 3, -1).reshape(k, 3)


def _brute_locate(pts: np.ndarray, vxy: np.ndarray, simp: np.ndarray) -> np.ndarray:
    out = np.full(pts.shape[0], -1, dtype=np.int64)
    a, b, c = vxy[simp[:, 0]], vxy[simp[:, 1]], vxy[simp[:, 2]]
    for m, (px, py) in enumerate(pts):
        o1 = (b[:, 0] - a[:, 0]) * (py - a[:, 1]) - (b[:, 1] - a[:, 1]) * (px - a[:, 0])
        o2 = (c[:, 0] - b[:, 0]) * (py - b[:, 1]) - (c[:, 1] - b[:, 1]) * (px - b[:, 0])
        o3 = (a[:, 0] - c[:, 0]) * (py - c[:, 1]) - (a[:, 1] - c[:, 1]) * (px - c[:, 0])
        hit = np.flatnonzero((o1 >= 0) & (o2 >= 0) & (o3 >= 0))
        if hit.size:
            out[m] = hit[0]
    return out


class IncrementalTIN:
    """A TIN that grows by insertion (startinpy), in a canonical spatial order.

    Virtual vertices are inserted first, then every batch of real points in
    Morton order (ties by coordinates), so the triangulation depends only on the
    point set of each batch, not on the input order.
    """

    def __init__(self, xyz: np.ndarray, real_idx: np.ndarray, virtual: np.ndarray) -> None:
        import startinpy

        self.xyz = xyz
        self.dt = startinpy.DT()
        self.dt.snap_tolerance = 1e-7
        self.src: list[np.ndarray] = []
        self.n = 0
        self._insert(
            np.asarray(virtual, dtype=np.float64), np.full(len(virtual), -1, dtype=np.int64)
        )
        self.add(real_idx)

    def _insert(self, pts: np.ndarray, src: np.ndarray) -> None:
        if pts.shape[0] == 0:
            return
        self.dt.insert(np.ascontiguousarray(pts))
        self.n += pts.shape[0]
        self.src.append(src)
        if self.dt.number_of_vertices() != self.n:
            raise _MergedVertices

    def add(self, idx: np.ndarray) -> None:
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size == 0:
            return
        p = self.xyz[idx]
        order = spatial_order(p[:, :2])
        self._insert(p[order], idx[order])

    def snapshot(self) -> TIN:
        vxyz = np.asarray(self.dt.points)[1:]
        simp = np.asarray(self.dt.triangles, dtype=np.int64) - 1
        return TIN.from_triangles(vxyz, np.concatenate(self.src), simp)


class _MergedVertices(Exception):
    """startinpy merged two vertices closer than its snap tolerance."""


def screen_seeds(
    xyz: np.ndarray,
    seeds: np.ndarray,
    virtual: np.ndarray,
    max_angle: float,
    max_rounds: int = 100_000,
) -> np.ndarray:
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
        orig = tin.real_idx[v]
        order = np.lexsort((-orig, -z))
        seeds = seeds[seeds != orig[order[0]]]
    return seeds


def mirror_point(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Point reflection of `p` through `v`: ``2 v - p``."""
    return 2.0 * np.asarray(v, dtype=np.float64) - np.asarray(p, dtype=np.float64)


def _facet_measures(
    p: np.ndarray, t: np.ndarray, normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
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
    frozen_ok: np.ndarray  # (M,) bool, in a frozen triangle and within d of its facet
    mirrored: np.ndarray  # (M,) bool, passed only by mirroring
    dist: np.ndarray  # (M,) distance to the facet plane (inf outside)


def judge_points(
    tin: TIN, p: np.ndarray, crit: Criteria, *, check_frozen: bool = True
) -> PointTest:
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
    frozen_ok = np.zeros(m, dtype=bool)
    dist_out = np.full(m, np.inf)
    if not inside.any():
        return PointTest(
            tri, passed, score, beta_out, dup_ok, dup, frozen, frozen_ok, mirrored, dist_out
        )
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
    dist_out[ii] = dist
    frozen_ok[ii] = frozen[ii] & ~is_dup & (dist <= crit.iter_distance + 1e-12)
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
            hd = np.sqrt(((vstar[:, :2] - pp[todo, :2]) ** 2).sum(axis=1))
            has_real &= hd <= crit.mirror_max_distance
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
    return PointTest(
        tri, passed, score, beta_out, dup_ok, dup, frozen, frozen_ok, mirrored, dist_out
    )


def spatial_order(xy: np.ndarray) -> np.ndarray:
    """A Morton (Z-order) permutation of XY points, ties by index."""
    n = xy.shape[0]
    if n < 2:
        return np.arange(n)
    lo = xy.min(axis=0)
    span = max(float((xy.max(axis=0) - lo).max()), 1e-12)
    q = np.minimum(((xy - lo) / span * 65535.0).astype(np.int64), 65535)
    code = _interleave(q[:, 0]) | (_interleave(q[:, 1]) << 1)
    return np.lexsort((xy[:, 1], xy[:, 0], code))


def _interleave(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.int64) & 0xFFFF
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    v = (v | (v << 1)) & 0x55555555
    return v


@njit(cache=True)
def _walk_all(pts, vxy, simp, nb, out):  # pragma: no cover - numba
    """Visibility walk for each point (in the given order), starting from the last hit."""
    k = simp.shape[0]
    start = 0
    lost = 0
    max_steps = 4 * k + 16
    for m in range(pts.shape[0]):
        px = pts[m, 0]
        py = pts[m, 1]
        t = start
        found = -2
        r = 0
        for _ in range(max_steps):
            moved = False
            for jj in range(3):
                i = (jj + r) % 3
                a = simp[t, (i + 1) % 3]
                b = simp[t, (i + 2) % 3]
                o = (vxy[b, 0] - vxy[a, 0]) * (py - vxy[a, 1]) - (vxy[b, 1] - vxy[a, 1]) * (
                    px - vxy[a, 0]
                )
                if o < 0.0:
                    nt = nb[t, i]
                    if nt < 0:
                        found = -1
                    else:
                        t = nt
                        moved = True
                    break
            if found == -1:
                break
            if not moved:
                found = t
                break
            r += 1
        if found == -2:
            lost += 1
        out[m] = found
        if found >= 0:
            start = found
    return lost


def supported_lowest_per_cell(
    xyz: np.ndarray,
    idx: np.ndarray,
    cell_size: float,
    origin: np.ndarray,
    *,
    radius: float,
    dz: float,
    min_support: int,
    min_ratio: float = 0.0,
    n_lowest: int = 32,
) -> np.ndarray:
    """Lowest point of each cell that is not an isolated low outlier.

    A point is *supported* when at least `min_support` other candidates lie within
    `radius` (m, horizontal) and `dz` (m, vertical) of it (ellipsoidal
    neighbourhood). Only the `n_lowest` lowest points of each cell are examined;
    a cell without a supported point gives no seed. With ``min_support=0`` this
    is :func:`lowest_per_cell`.
    """
    if min_support <= 0 or idx.size == 0:
        return lowest_per_cell(xyz, idx, cell_size, origin)
    from scipy.spatial import cKDTree

    p = xyz[idx]
    ij = np.floor((p[:, :2] - origin[:2]) / cell_size).astype(np.int64)
    ij -= ij.min(axis=0)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    # rank by (cell, z in mm) with one integer sort; every point tying with the
    # n_lowest-th z of its cell is examined too, so the set does not depend on order
    zq = np.round((p[:, 2] - p[:, 2].min()) * 1000.0).astype(np.int64)
    order = np.argsort((key << 40) | zq, kind="stable")
    k = key[order]
    start = np.ones(k.size, dtype=bool)
    start[1:] = k[1:] != k[:-1]
    gs = np.flatnonzero(start)
    gid = np.cumsum(start) - 1
    sizes = np.diff(np.append(gs, k.size))
    thr = zq[order][gs + np.minimum(sizes, n_lowest) - 1]
    cell_of = np.empty(k.size, dtype=np.int64)
    cell_of[order] = gid
    look = np.flatnonzero(zq <= thr[cell_of])  # positions into idx
    # only points in the grid cells (size `radius`) around the examined ones matter
    q = np.floor(p[:, :2] / radius).astype(np.int64)
    q -= q.min(axis=0) - 1
    w = int(q[:, 1].max()) + 2
    ckey = q[:, 0] * w + q[:, 1]
    lk = ckey[look]
    near_keys = np.unique(
        (
            lk[:, None]
            + (np.array([-1, 0, 1])[:, None] * w + np.array([-1, 0, 1])[None, :]).ravel()[None, :]
        ).ravel()
    )
    sub = np.flatnonzero(np.isin(ckey, near_keys))
    ps = p[sub]
    scale = np.array([1.0, 1.0, radius / max(dz, 1e-9)])
    tree = cKDTree(ps * scale)
    counts = np.asarray(tree.query_ball_point(p[look] * scale, r=radius, return_length=True)) - 1
    good = counts >= min_support
    if min_ratio > 0:
        tree2 = cKDTree(ps[:, :2])
        total = np.asarray(tree2.query_ball_point(p[look, :2], r=radius, return_length=True)) - 1
        good &= counts >= min_ratio * total
    sup = look[good]
    ps2 = p[sup]
    o2 = np.lexsort((idx[sup], ps2[:, 1], ps2[:, 0], ps2[:, 2], key[sup]))
    sel = sup[o2]  # supported, in (cell, z, x, y, idx) order
    ks = key[sel]
    first = np.ones(sel.size, dtype=bool)
    first[1:] = ks[1:] != ks[:-1]
    return np.sort(idx[sel[first]])


def distance_to_tin(tin: TIN, p: np.ndarray) -> np.ndarray:
    """Orthogonal distance (m) of points to the plane of their facet; inf outside."""
    tri = tin.locate(p[:, :2])
    out = np.full(p.shape[0], np.inf)
    ok = tri >= 0
    if ok.any():
        t = tin.vxyz[tin.simplices[tri[ok]]]
        out[ok] = np.abs(((p[ok] - t[:, 0]) * tin.normal[tri[ok]]).sum(axis=1))
    return out
