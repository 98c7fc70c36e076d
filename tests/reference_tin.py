"""Plain-NumPy reference of the compiled TIN tests in ``lidarqa.ground._tin``.

The first, vectorised implementation of the §1.1 point tests (and the
sort-based triangle adjacency), kept as an independent oracle: the numba
kernels must agree with it point for point.
"""

from __future__ import annotations

import numpy as np

from lidarqa.ground._tin import EPS, TIN, Criteria, PointTest


def neighbors_reference(simp: np.ndarray, nv: int) -> np.ndarray:
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


def facet_measures(
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


def subfacet_slope_ok(p: np.ndarray, t: np.ndarray, max_angle: float) -> np.ndarray:
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


def judge_points_reference(
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
    dist, beta = facet_measures(pp, t, normal)
    dist_out[ii] = dist
    frozen_ok[ii] = frozen[ii] & ~is_dup & (dist <= crit.iter_distance + 1e-12)
    ok = live & (dist <= crit.iter_distance + 1e-12) & (beta <= theta + 1e-12)
    if ok.any():
        ok[ok] = subfacet_slope_ok(pp[ok], t[ok], crit.max_terrain_angle)
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
                d2, b2 = facet_measures(pm[g], t2, tin.normal[tri2[g]])
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
