"""Private TIN machinery shared by point-based and segment-based PTD.

Everything here trusts its inputs (validated in ``ptd.py`` / ``segment_ptd.py``).
Coordinates are expected to be already shifted near the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import get_num_threads, njit, prange
from scipy.spatial import Delaunay, QhullError

from .._arrays import colmax, colmin
from .._gridkernels import sort_runs_lex

EPS = 1e-9
#: vertex numbers below this fit the 21-bit fields of a facet key (judge_points(keys=True))
KEY_VERTICES = 1 << 21

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
    """The acceptance thresholds of :ref:`alg-ptd`, in radians and metres."""

    iter_angle: float  # rad
    iter_distance: float  # m
    max_terrain_angle: float  # rad
    min_edge_length: float  # m
    mirror: bool = True
    edge_mode: str = "freeze"
    mirror_max_distance: float = np.inf  # m, horizontal P–V* limit of mirroring


def tree_workers() -> int:
    """Threads for cKDTree queries: numba's thread count (``NUMBA_NUM_THREADS``).

    Every query is answered on its own, so the result does not depend on it.
    """
    return int(get_num_threads())


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
    ij -= colmin(ij)
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
        self.vxyz = np.ascontiguousarray(vxyz, dtype=np.float64)
        self.vsrc = vsrc
        self.real_pos = np.flatnonzero(vsrc >= 0)
        self.real_idx = vsrc[self.real_pos]
        self.n_real = self.real_idx.size
        simp = np.ascontiguousarray(simp, dtype=np.int64)
        have_nb = nb is not None
        nb = (
            np.ascontiguousarray(nb, dtype=np.int64)
            if have_nb
            else np.empty(simp.shape, dtype=np.int64)
        )
        # every triangle made counter-clockwise; adjacency, longest XY edge, upward
        # unit normal and slope of each facet, in one pass
        self.edge_max, self.normal, self.slope, self.n_virtual = _setup_kernel(
            self.vxyz, np.ascontiguousarray(vsrc, dtype=np.int64), simp, nb, have_nb
        )
        self.simplices = simp
        self.neighbors = nb

    def locate(self, xy: np.ndarray, *, presorted: bool = False) -> np.ndarray:
        """Triangle index of each XY point, -1 outside the TIN.

        The points are walked to in spatial (Morton) order, each walk starting
        from the previous hit; ``presorted=True`` says `xy` is in that order already.
        """
        if xy.shape[0] == 0:
            return np.zeros(0, dtype=np.int64)
        order = None if presorted else spatial_order(xy)
        q = np.ascontiguousarray(xy if order is None else xy[order], dtype=np.float64)
        out = _locate_kernel(
            q,
            np.ascontiguousarray(self.vxyz[:, :2]),
            self.simplices,
            self.neighbors,
            self.n_virtual,
        )
        if order is None:
            return out
        res = np.empty_like(out)
        res[order] = out
        return res

    def is_real(self, v: np.ndarray) -> np.ndarray:
        return self.vsrc[v] >= 0

    def real_triangles(self) -> np.ndarray:
        """Triangles with three real vertices, as positions into :attr:`real_idx`."""
        keep = (self.vsrc[self.simplices] >= 0).all(axis=1)
        pos = np.full(self.vxyz.shape[0], -1, dtype=np.int64)
        pos[self.real_pos] = np.arange(self.n_real)
        return pos[self.simplices[keep]]


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
        self.pts: list[np.ndarray] = []  # inserted coordinates, in startinpy's vertex order
        self.n = 0
        self._insert(
            np.asarray(virtual, dtype=np.float64), np.full(len(virtual), -1, dtype=np.int64)
        )
        self.add(real_idx)

    def _insert(self, pts: np.ndarray, src: np.ndarray) -> None:
        if pts.shape[0] == 0:
            return
        pts = np.ascontiguousarray(pts, dtype=np.float64)
        self.dt.insert(pts)
        self.n += pts.shape[0]
        self.src.append(src)
        self.pts.append(pts)
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
        # vertex i of startinpy is the i-th inserted point (0 is its infinite vertex);
        # no vertex was merged (checked on insertion), so the coordinates are ours
        simp = np.asarray(self.dt.triangles, dtype=np.int64) - 1
        return TIN.from_triangles(np.concatenate(self.pts), np.concatenate(self.src), simp)


class _MergedVertices(Exception):
    """startinpy merged two vertices closer than its snap tolerance."""


def build_tin(xyz: np.ndarray, real_idx: np.ndarray, virtual: np.ndarray) -> TIN:
    """A TIN of `real_idx` and the `virtual` vertices, by insertion (startinpy).

    Four times faster than Qhull on tens of thousands of vertices; falls back to
    :class:`TIN` (Qhull) when startinpy would merge vertices closer than 1e-7 m.
    Co-circular vertices may get the other diagonal than Qhull's, in a canonical
    (spatial, then coordinate) insertion order that does not depend on the input order.
    """
    try:
        return IncrementalTIN(xyz, real_idx, virtual).snapshot()
    except _MergedVertices:
        return TIN(xyz, real_idx, virtual)


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
    # (M,) int64, with ``keys=True``: the point's facet as its sorted vertex triple
    # packed in 21 bits each (:data:`KEY_VERTICES`), -1 when the point lies on an edge
    # or outside (its facet then depends on the triangle numbering); and the facet of
    # its mirrored point the same way, -2 when no mirrored point was located
    tri_key: np.ndarray | None = None
    mirror_key: np.ndarray | None = None


def judge_points(
    tin: TIN,
    p: np.ndarray,
    crit: Criteria,
    *,
    check_frozen: bool = True,
    presorted: bool = False,
    keys: bool = False,
) -> PointTest:
    """Run the densification tests of :ref:`alg-ptd` for candidate points `p` (M, 3) against `tin`.

    One compiled pass per point: locate its facet (walk), XY-duplicate test,
    frozen-triangle test, distance and iteration angle, sub-facet slopes, and
    mirroring through the nearest real vertex (the mirrored point is walked to
    from the point's own facet). ``presorted=True``: `p` is in
    :func:`spatial_order` already (saves a sort per call in the densification).
    ``keys=True`` also returns the facet keys of :class:`PointTest` (the TIN must have
    fewer than :data:`KEY_VERTICES` vertices): a point whose keys name facets that
    are still in a later TIN gets the same result there.
    """
    m = p.shape[0]
    order = None if presorted or m < 2 else spatial_order(p[:, :2])
    q = np.ascontiguousarray(p if order is None else p[order], dtype=np.float64)
    out = _judge_kernel(
        q,
        tin.vxyz,
        np.ascontiguousarray(tin.vsrc, dtype=np.int64),
        tin.simplices,
        tin.neighbors,
        tin.n_virtual,
        tin.edge_max,
        tin.normal,
        float(crit.iter_angle),
        float(crit.iter_distance),
        float(crit.max_terrain_angle),
        float(crit.min_edge_length),
        crit.edge_mode == "freeze",
        bool(check_frozen),
        bool(crit.mirror),
        float(crit.mirror_max_distance),
        max(1, min(4 * get_num_threads(), m // 2048)),
        bool(keys),
    )
    if not keys:
        out = out[:-2]
    if order is not None:
        inv = np.empty_like(order)
        inv[order] = np.arange(m)
        out = tuple(a[inv] for a in out)
    return PointTest(*out)


def best_per_triangle(
    tri: np.ndarray, score: np.ndarray, beta: np.ndarray, p: np.ndarray, idx: np.ndarray
) -> np.ndarray:
    """Position of the best point of each triangle, in ascending triangle order.

    Best = smallest `score`, then `beta`, then x, y, z of `p`, then `idx`: a strict
    total order, so the winners do not depend on the order of the input.
    """
    if tri.size == 0:
        return np.zeros(0, dtype=np.int64)
    return _best_per_group(
        np.ascontiguousarray(tri, dtype=np.int64),
        int(tri.max()) + 1,
        np.ascontiguousarray(score, dtype=np.float64),
        np.ascontiguousarray(beta, dtype=np.float64),
        np.ascontiguousarray(p, dtype=np.float64),
        np.ascontiguousarray(idx, dtype=np.int64),
    )


@njit(cache=True, nogil=True)
def _best_per_group(grp, n_grp, score, beta, p, idx):  # pragma: no cover - numba
    best = np.full(n_grp, -1, np.int64)
    for j in range(grp.size):
        g = grp[j]
        b = best[g]
        if b < 0:
            best[g] = j
            continue
        # lexicographic (score, beta, x, y, z, idx)
        better = False
        if score[j] != score[b]:
            better = score[j] < score[b]
        elif beta[j] != beta[b]:
            better = beta[j] < beta[b]
        elif p[j, 0] != p[b, 0]:
            better = p[j, 0] < p[b, 0]
        elif p[j, 1] != p[b, 1]:
            better = p[j, 1] < p[b, 1]
        elif p[j, 2] != p[b, 2]:
            better = p[j, 2] < p[b, 2]
        else:
            better = idx[j] < idx[b]
        if better:
            best[g] = j
    out = np.empty(grp.size, np.int64)
    n = 0
    for g in range(n_grp):
        if best[g] >= 0:
            out[n] = best[g]
            n += 1
    return out[:n]


def spatial_order(xy: np.ndarray) -> np.ndarray:
    """A Morton (Z-order) permutation of XY points, ties by index."""
    n = xy.shape[0]
    if n < 2:
        return np.arange(n)
    lo = colmin(xy)
    span = max(float((colmax(xy) - lo).max()), 1e-12)
    q = np.minimum(((xy - lo) / span * 65535.0).astype(np.int64), 65535)
    code = _interleave(q[:, 0]) | (_interleave(q[:, 1]) << 1)
    # = np.lexsort((xy[:, 1], xy[:, 0], code)), a third of its time on a million points
    return _morton_sort(code, np.ascontiguousarray(xy[:, :2], dtype=np.float64))


def _interleave(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.int64) & 0xFFFF
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    v = (v | (v << 1)) & 0x55555555
    return v


# ---------------------------------------------------------------- compiled kernels


@njit(cache=True, nogil=True)
def _morton_sort(code, xy):  # pragma: no cover - numba
    """The permutation sorting by (`code`, `x`, `y`), ties by index: a stable sort.

    `code` < 2**32: a stable radix sort of two 16-bit passes, then each run of equal
    codes (one or two points, almost always) sorted by (x, y) in place (stable).
    `xy`: (n, 2) float64.
    """
    n = code.shape[0]
    perm = np.arange(n)
    key = code.copy()
    perm2 = np.empty(n, dtype=np.int64)
    key2 = np.empty(n, dtype=np.int64)
    for shift in (0, 16):
        cnt = np.zeros(65537, dtype=np.int64)
        for i in range(n):
            cnt[((key[i] >> shift) & 0xFFFF) + 1] += 1
        for b in range(65536):
            cnt[b + 1] += cnt[b]
        for i in range(n):
            b = (key[i] >> shift) & 0xFFFF
            perm2[cnt[b]] = perm[i]
            key2[cnt[b]] = key[i]
            cnt[b] += 1
        perm, perm2 = perm2, perm
        key, key2 = key2, key
    return sort_runs_lex(perm, key, xy)


@njit(cache=True, nogil=True, parallel=True)
def _setup_kernel(vxyz, vsrc, simp, nb, have_nb):  # pragma: no cover - numba
    """Orient triangles CCW (in place), fill adjacency ``nb`` unless given, facet geometry.

    ``nb[k, i]`` is the triangle across the side opposite vertex i (-1 on the hull),
    found through the triangles incident to each vertex (no global sort). Every
    triangle finds its own neighbours (no shared writes), so the loops run in
    parallel and the result does not depend on the thread count.
    Returns (longest XY edge, upward unit normal, slope in rad, number of virtual
    vertices, i.e. with ``vsrc < 0``) per triangle.
    """
    k = simp.shape[0]
    nv = vxyz.shape[0]
    for t in prange(k):
        a, b, c = simp[t, 0], simp[t, 1], simp[t, 2]
        o = (vxyz[b, 0] - vxyz[a, 0]) * (vxyz[c, 1] - vxyz[a, 1]) - (vxyz[b, 1] - vxyz[a, 1]) * (
            vxyz[c, 0] - vxyz[a, 0]
        )
        if o < 0.0:
            simp[t, 1], simp[t, 2] = c, b
            if have_nb:
                nb[t, 1], nb[t, 2] = nb[t, 2], nb[t, 1]
    if not have_nb:
        # incidence lists: for each vertex, its triangles and the vertex that follows
        # it in each (CCW), stored side by side so the search below reads no `simp` row
        start = np.zeros(nv + 1, np.int64)
        for t in range(k):
            start[simp[t, 0] + 1] += 1
            start[simp[t, 1] + 1] += 1
            start[simp[t, 2] + 1] += 1
        for v in range(nv):
            start[v + 1] += start[v]
        fill = start[:-1].copy()
        inc_t = np.empty(3 * k, np.int64)
        inc_next = np.empty(3 * k, np.int64)
        for t in range(k):
            for i in range(3):
                v = simp[t, i]
                inc_t[fill[v]] = t
                inc_next[fill[v]] = simp[t, (i + 1) % 3]
                fill[v] += 1
        for t in prange(k):
            for i in range(3):
                a = simp[t, (i + 1) % 3]
                b = simp[t, (i + 2) % 3]
                r = -1
                # the neighbour holds the same side in the opposite direction: b, then a
                for q in range(start[b], start[b + 1]):
                    if inc_next[q] == a and inc_t[q] != t:
                        r = inc_t[q]
                        break
                nb[t, i] = r
    edge_max = np.empty(k)
    normal = np.empty((k, 3))
    slope = np.empty(k)
    n_virtual = np.empty(k, np.int64)
    for t in prange(k):
        i0, i1, i2 = simp[t, 0], simp[t, 1], simp[t, 2]
        n_virtual[t] = (vsrc[i0] < 0) + (vsrc[i1] < 0) + (vsrc[i2] < 0)
        x0, y0, z0 = vxyz[i0, 0], vxyz[i0, 1], vxyz[i0, 2]
        ux, uy, uz = vxyz[i1, 0] - x0, vxyz[i1, 1] - y0, vxyz[i1, 2] - z0
        wx, wy, wz = vxyz[i2, 0] - x0, vxyz[i2, 1] - y0, vxyz[i2, 2] - z0
        e0 = ux * ux + uy * uy
        e1 = (wx - ux) ** 2 + (wy - uy) ** 2
        e2 = wx * wx + wy * wy
        edge_max[t] = math.sqrt(max(e0, e1, e2))
        nx = uy * wz - uz * wy
        ny = uz * wx - ux * wz
        nz = ux * wy - uy * wx
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if norm == 0.0:
            norm = 1.0
        if nz < 0.0:
            norm = -norm
        normal[t, 0] = nx / norm
        normal[t, 1] = ny / norm
        normal[t, 2] = nz / norm
        slope[t] = math.acos(min(abs(normal[t, 2]), 1.0))
    return edge_max, normal, slope, n_virtual


@njit(cache=True, nogil=True)
def _orient(vxy, a, b, px, py):  # pragma: no cover - numba
    return (vxy[b, 0] - vxy[a, 0]) * (py - vxy[a, 1]) - (vxy[b, 1] - vxy[a, 1]) * (px - vxy[a, 0])


@njit(cache=True, nogil=True)
def _locate_one(px, py, start, vxy, simp, nb, n_virtual):  # pragma: no cover - numba
    """Visibility walk from triangle `start`; -1 outside the TIN.

    A point on an edge gets the one of its two triangles with fewer virtual
    vertices, then the lower-numbered one, so the answer does not depend on
    `start`. A walk that does not converge (degenerate geometry) falls back to testing
    every triangle.
    """
    t = start
    r = 0
    for _ in range(4 * simp.shape[0] + 16):
        moved = False
        for jj in range(3):
            i = (jj + r) % 3
            if _orient(vxy, simp[t, (i + 1) % 3], simp[t, (i + 2) % 3], px, py) < 0.0:
                nt = nb[t, i]
                if nt < 0:
                    return -1
                t = nt
                moved = True
                break
        if not moved:
            # on an edge (common with cm-quantised coordinates) the point is in both
            # triangles: take the one with fewer virtual vertices (real facets are the
            # better evidence), then the lower-numbered one, whatever the walk came from
            best = t
            for i in range(3):
                nt = nb[t, i]
                if nt < 0:
                    continue
                if _orient(vxy, simp[t, (i + 1) % 3], simp[t, (i + 2) % 3], px, py) != 0.0:
                    continue
                if n_virtual[nt] < n_virtual[best] or (
                    n_virtual[nt] == n_virtual[best] and nt < best
                ):
                    best = nt
            return best
        r += 1
    for u in range(simp.shape[0]):  # pragma: no cover - lost walk
        if (
            _orient(vxy, simp[u, 0], simp[u, 1], px, py) >= 0.0
            and _orient(vxy, simp[u, 1], simp[u, 2], px, py) >= 0.0
            and _orient(vxy, simp[u, 2], simp[u, 0], px, py) >= 0.0
        ):
            return u
    return -1


@njit(cache=True, nogil=True)
def _locate_kernel(pts, vxy, simp, nb, n_virtual):  # pragma: no cover - numba
    """Triangle of each point, walking from the previous hit (pass points spatially sorted)."""
    out = np.empty(pts.shape[0], np.int64)
    start = 0
    for m in range(pts.shape[0]):
        t = _locate_one(pts[m, 0], pts[m, 1], start, vxy, simp, nb, n_virtual)
        out[m] = t
        if t >= 0:
            start = t
    return out


@njit(cache=True, nogil=True)
def _facet_dist(px, py, pz, vxyz, simp, normal, t):  # pragma: no cover - numba
    """Distance of P to the plane of facet t."""
    i0 = simp[t, 0]
    return abs(
        (px - vxyz[i0, 0]) * normal[t, 0]
        + (py - vxyz[i0, 1]) * normal[t, 1]
        + (pz - vxyz[i0, 2]) * normal[t, 2]
    )


@njit(cache=True, nogil=True)
def _facet_beta(px, py, pz, dist, vxyz, simp, t):  # pragma: no cover - numba
    """The largest vertex angle beta (rad) of P at distance `dist` from facet t.

    asin is increasing, so the largest angle is the asin of the largest sine: one
    asin instead of three.
    """
    smax = 0.0
    for j in range(3):
        v = simp[t, j]
        pv = math.sqrt((px - vxyz[v, 0]) ** 2 + (py - vxyz[v, 1]) ** 2 + (pz - vxyz[v, 2]) ** 2)
        s = dist / pv if pv > EPS else 1.0
        smax = max(smax, s)
    return math.asin(min(max(smax, 0.0), 1.0))


@njit(cache=True, nogil=True, parallel=True)
def _judge_kernel(
    p,
    vxyz,
    vsrc,
    simp,
    nb,
    n_virtual,
    edge_max,
    normal,
    iter_angle,
    iter_dist,
    max_angle,
    min_edge,
    freeze,
    check_frozen,
    mirror,
    mirror_max,
    n_chunks,
    keys,
):  # pragma: no cover - numba
    """The densification tests (:ref:`alg-ptd`) of each point against the TIN."""
    m = p.shape[0]
    tri = np.full(m, -1, np.int64)
    passed = np.zeros(m, np.bool_)
    score = np.full(m, np.inf)
    beta_out = np.full(m, np.inf)
    dup_ok = np.zeros(m, np.bool_)
    dup = np.zeros(m, np.bool_)
    frozen = np.zeros(m, np.bool_)
    frozen_ok = np.zeros(m, np.bool_)
    mirrored = np.zeros(m, np.bool_)
    dist_out = np.full(m, np.inf)
    tkey = np.full(m if keys else 0, -1, np.int64)
    mkey = np.full(m if keys else 0, -2, np.int64)
    vxy = vxyz[:, :2]
    d_tol = iter_dist + 1e-12
    cos_max = math.cos(max_angle) - 1e-12
    # contiguous chunks of the (spatially sorted) points, one walk per chunk; a point's
    # triangle does not depend on where its walk starts, so neither do the results
    for c in prange(n_chunks):
        start = 0
        for i in range(c * m // n_chunks, (c + 1) * m // n_chunks):
            px, py, pz = p[i, 0], p[i, 1], p[i, 2]
            t = _locate_one(px, py, start, vxy, simp, nb, n_virtual)
            tri[i] = t
            if t < 0:
                continue
            start = t
            if keys:
                tkey[i] = _facet_key(px, py, t, vxy, simp)
            theta = iter_angle
            is_frozen = False
            if check_frozen and min_edge > 0.0 and edge_max[t] < min_edge:
                if freeze:
                    is_frozen = True
                else:  # "reduce"
                    theta = iter_angle * (edge_max[t] / min_edge) ** 2
            frozen[i] = is_frozen
            # XY duplicate of a vertex (the nearest one in XY, first on ties)
            jmin = 0
            dmin = np.inf
            for j in range(3):
                v = simp[t, j]
                dxy = math.sqrt((px - vxyz[v, 0]) ** 2 + (py - vxyz[v, 1]) ** 2)
                if dxy < dmin:
                    dmin = dxy
                    jmin = j
            is_dup = dmin < EPS
            dup[i] = is_dup
            dup_ok[i] = is_dup and abs(pz - vxyz[simp[t, jmin], 2]) <= d_tol
            dist = _facet_dist(px, py, pz, vxyz, simp, normal, t)
            dist_out[i] = dist
            frozen_ok[i] = is_frozen and not is_dup and dist <= d_tol
            if is_dup or is_frozen:
                continue
            ok = False
            beta = np.inf
            if dist <= d_tol:  # the angle only matters within the distance
                beta = _facet_beta(px, py, pz, dist, vxyz, simp, t)
                ok = beta <= theta + 1e-12
            if ok:
                # sub-facets (P,A,B), (P,B,C), (P,C,A) no steeper than max_angle;
                # those with XY area < EPS (P on an edge) are ignored
                for j in range(3):
                    a = simp[t, j]
                    b = simp[t, (j + 1) % 3]
                    ax, ay, az = vxyz[a, 0] - px, vxyz[a, 1] - py, vxyz[a, 2] - pz
                    bx, by, bz = vxyz[b, 0] - px, vxyz[b, 1] - py, vxyz[b, 2] - pz
                    nx = ay * bz - az * by
                    ny = az * bx - ax * bz
                    nz = abs(ax * by - ay * bx)
                    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
                    cosv = nz / nn if nn > 0.0 else 1.0
                    if not (0.5 * nz < EPS or cosv >= cos_max):
                        ok = False
                        break
            if ok:
                passed[i] = True
                score[i] = dist
                beta_out[i] = beta
                continue
            if not mirror:
                continue
            # mirror through the nearest real vertex (3D; ties: lower vertex number)
            best = -1
            dbest = np.inf
            for j in range(3):
                v = simp[t, j]
                if vsrc[v] < 0:
                    continue
                d3 = math.sqrt(
                    (px - vxyz[v, 0]) ** 2 + (py - vxyz[v, 1]) ** 2 + (pz - vxyz[v, 2]) ** 2
                )
                if d3 < dbest or (d3 == dbest and v < best):
                    dbest = d3
                    best = v
            if best < 0:
                continue
            if math.sqrt((vxyz[best, 0] - px) ** 2 + (vxyz[best, 1] - py) ** 2) > mirror_max:
                continue
            mx = 2.0 * vxyz[best, 0] - px
            my = 2.0 * vxyz[best, 1] - py
            mz = 2.0 * vxyz[best, 2] - pz
            t2 = _locate_one(mx, my, t, vxy, simp, nb, n_virtual)
            if t2 < 0:
                continue
            if keys:
                mkey[i] = _facet_key(mx, my, t2, vxy, simp)
            d2 = _facet_dist(mx, my, mz, vxyz, simp, normal, t2)
            if d2 > d_tol:
                continue
            b2 = _facet_beta(mx, my, mz, d2, vxyz, simp, t2)
            if b2 <= theta + 1e-12:
                passed[i] = True
                mirrored[i] = True
                score[i] = d2
                beta_out[i] = b2
    return (
        tri, passed, score, beta_out, dup_ok, dup, frozen, frozen_ok, mirrored, dist_out, tkey, mkey
    )


@njit(cache=True, nogil=True)
def _facet_key(px, py, t, vxy, simp):  # pragma: no cover - numba
    """Sorted vertex triple of facet `t` in 21 bits each; -1 when (px, py) is on an edge.

    On an edge the point's facet is chosen by triangle number (:func:`_locate_one`),
    which another TIN may number differently: such a point is always judged again.
    """
    a, b, c = simp[t, 0], simp[t, 1], simp[t, 2]
    for j in range(3):
        if _orient(vxy, simp[t, (j + 1) % 3], simp[t, (j + 2) % 3], px, py) == 0.0:
            return -1
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return (a << 42) | (b << 21) | c


def facets_present(tin: TIN, keys: np.ndarray) -> np.ndarray:
    """Which `keys` (as in :class:`PointTest`) name a facet of `tin`; negative keys never do."""
    return _facets_present(tin.simplices, np.ascontiguousarray(keys, dtype=np.int64))


@njit(cache=True, nogil=True)
def _facets_present(simp, keys):  # pragma: no cover - numba
    # open-addressing hash set of the facets' keys, then one probe per query
    size = 1
    while size < 2 * simp.shape[0] + 2:
        size *= 2
    mask = size - 1
    table = np.full(size, -1, np.int64)
    for t in range(simp.shape[0]):
        a, b, c = simp[t, 0], simp[t, 1], simp[t, 2]
        if a > b:
            a, b = b, a
        if b > c:
            b, c = c, b
        if a > b:
            a, b = b, a
        k = (a << 42) | (b << 21) | c
        h = (k * -7046029254386353131) >> 17 & mask
        while table[h] >= 0 and table[h] != k:
            h = (h + 1) & mask
        table[h] = k
    out = np.zeros(keys.size, np.bool_)
    for i in range(keys.size):
        k = keys[i]
        if k < 0:
            continue
        h = (k * -7046029254386353131) >> 17 & mask
        while table[h] >= 0:
            if table[h] == k:
                out[i] = True
                break
            h = (h + 1) & mask
    return out


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
    ij -= colmin(ij)
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
    q -= colmin(q) - 1
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
    counts = (
        np.asarray(
            tree.query_ball_point(
                p[look] * scale, r=radius, return_length=True, workers=tree_workers()
            )
        )
        - 1
    )
    good = counts >= min_support
    if min_ratio > 0:
        tree2 = cKDTree(ps[:, :2])
        total = (
            np.asarray(
                tree2.query_ball_point(
                    p[look, :2], r=radius, return_length=True, workers=tree_workers()
                )
            )
            - 1
        )
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
