"""Array kernels of the 3D road reconstruction: smooth segments, local planes, shift scores.

No I/O and no shapely here.

All lengths in metres. Every function is a pure function of its arrays.
"""

from __future__ import annotations

import numpy as np

# 8-neighbourhood offsets of a cell; each undirected pair is visited once
_OFFSETS = ((1, 0), (0, 1), (1, 1), (1, -1))


def grid_nodes(points: np.ndarray, *, cell_size: float, max_step: float) -> tuple[np.ndarray, ...]:
    """Split the points into nodes: one per grid cell and height layer.

    Within a cell the points are sorted by height and a new layer starts where
    consecutive heights differ by more than `max_step`, so a bridge deck and the
    road under it fall into different nodes of the same cell.

    Returns
    -------
    node : (N,) int64
        Node of each point.
    node_ij : (K, 2) int64
        Cell indices of each node.
    node_xyz : (K, 3)
        Mean x, y, z of each node's points.
    node_count : (K,) int64
    """
    n = len(points)
    if n == 0:
        return (
            np.empty(0, np.int64),
            np.empty((0, 2), np.int64),
            np.empty((0, 3)),
            np.empty(0, np.int64),
        )
    origin = points[:, :2].min(axis=0)
    ij = np.floor((points[:, :2] - origin) / cell_size).astype(np.int64)
    # sort by cell, then z (two stable sorts: 3-4x faster than a lexsort over five keys).
    # Points with equal cell and z always fall into the same node, so the order among
    # them does not matter and the nodes do not depend on the input order.
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    order = np.argsort(points[:, 2], kind="stable")
    order = order[np.argsort(key[order], kind="stable")]
    sij, sz = ij[order], points[order, 2]
    new_cell = np.ones(n, dtype=bool)
    new_cell[1:] = (sij[1:] != sij[:-1]).any(axis=1)
    new_layer = new_cell.copy()
    new_layer[1:] |= np.diff(sz) > max_step
    node_sorted = np.cumsum(new_layer) - 1
    node = np.empty(n, dtype=np.int64)
    node[order] = node_sorted
    k = int(node_sorted[-1]) + 1
    count = np.bincount(node_sorted, minlength=k)
    xyz = (
        np.column_stack(
            [np.bincount(node_sorted, weights=points[order, d], minlength=k) for d in range(3)]
        )
        / count[:, None]
    )
    node_ij = sij[new_layer]
    return node, node_ij, xyz, count.astype(np.int64)


def node_edges(node_ij: np.ndarray, node_xyz: np.ndarray, *, max_step: float) -> np.ndarray:
    """Pairs of nodes in neighbouring cells whose mean heights differ by at most `max_step`.

    Nodes must be sorted by cell (as :func:`grid_nodes` returns them).
    """
    k = len(node_ij)
    if k == 0:
        return np.empty((0, 2), dtype=np.int64)
    span = int(node_ij[:, 1].max()) + 3
    key = node_ij[:, 0] * span + node_ij[:, 1] + 1
    new = np.ones(k, dtype=bool)
    new[1:] = key[1:] != key[:-1]
    ukey = key[new]
    start = np.flatnonzero(new)
    end = np.append(start[1:], k)
    layers = int((end - start).max())
    out = []
    for di, dj in _OFFSETS:
        nkey = key + di * span + dj
        pos = np.searchsorted(ukey, nkey)
        pos_c = np.minimum(pos, len(ukey) - 1)
        hit = ukey[pos_c] == nkey
        src = np.flatnonzero(hit)
        s0, s1 = start[pos_c[hit]], end[pos_c[hit]]
        for layer in range(layers):
            j = s0 + layer
            ok = j < s1
            a, b = src[ok], j[ok]
            close = np.abs(node_xyz[a, 2] - node_xyz[b, 2]) <= max_step
            out.append(np.column_stack([a[close], b[close]]))
    return np.concatenate(out) if out else np.empty((0, 2), dtype=np.int64)


def components(n_nodes: int, edges: np.ndarray, subset: np.ndarray | None = None) -> np.ndarray:
    """Connected components of the node graph (optionally restricted to `subset` nodes).

    Labels are numbered by the smallest node index of each component, so they
    do not depend on the input order. Nodes outside `subset` get -1.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if subset is None:
        e = edges
        keep = np.ones(n_nodes, dtype=bool)
    else:
        keep = np.zeros(n_nodes, dtype=bool)
        keep[subset] = True
        e = edges[keep[edges[:, 0]] & keep[edges[:, 1]]]
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_nodes, n_nodes))
    _, lab = connected_components(g, directed=False)
    lab = lab.astype(np.int64)
    # renumber by first node
    first = np.full(lab.max() + 1 if len(lab) else 0, n_nodes, dtype=np.int64)
    np.minimum.at(first, lab, np.arange(n_nodes))
    rank = np.argsort(np.argsort(first))
    out = rank[lab]
    out[~keep] = -1
    return out


def local_plane_predict(
    xyz: np.ndarray, weight: np.ndarray, query_xy: np.ndarray, *, k: int = 12
) -> tuple[np.ndarray, np.ndarray]:
    """Height of a weighted least-squares plane through the `k` nearest nodes at each query.

    Returns the predicted height and the distance to the nearest node. Too few
    or collinear nodes fall back to the weighted mean height.
    """
    from scipy.spatial import cKDTree

    q = np.asarray(query_xy, dtype=np.float64).reshape(-1, 2)
    if len(xyz) == 0 or len(q) == 0:
        return np.full(len(q), np.nan), np.full(len(q), np.inf)
    kk = min(k, len(xyz))
    tree = cKDTree(xyz[:, :2])
    d, idx = tree.query(q, k=kk)
    if kk == 1:
        d, idx = d[:, None], idx[:, None]
    w = weight[idx].astype(np.float64)
    px = xyz[idx, 0] - q[:, 0:1]
    py = xyz[idx, 1] - q[:, 1:2]
    pz = xyz[idx, 2]
    a = np.stack([np.ones_like(px), px, py], axis=-1)  # height at the query is the intercept
    ata = np.einsum("mk,mki,mkj->mij", w, a, a)
    atz = np.einsum("mk,mki,mk->mi", w, a, pz)
    mean = (w * pz).sum(axis=1) / w.sum(axis=1)
    det = np.linalg.det(ata)
    scale = (ata[:, 1, 1] * ata[:, 2, 2]) + 1e-12
    ok = (kk >= 3) & (np.abs(det) > 1e-6 * scale * ata[:, 0, 0])
    h = mean.copy()
    if ok.any():
        sol = np.linalg.solve(ata[ok], atz[ok][..., None])[..., 0]
        h[ok] = sol[:, 0]
    return h, d[:, 0]


def shift_scores(
    sd: np.ndarray, normal: np.ndarray, sign: np.ndarray, shifts: np.ndarray, *, tau: float
) -> np.ndarray:
    """Agreement of shifted map polygons with the laser levels, for each candidate shift.

    A point at signed distance `sd` (negative inside) from a boundary with
    outward unit `normal` lies inside the polygon moved by s when
    sd − normal·s < 0. The score sums `sign` (+1: the point lies on the
    polygon's level, −1: it does not) times a soft inside indicator (logistic
    of width `tau`), so the best shift puts level points inside and the others
    outside.
    """
    out = np.empty(len(shifts))
    for i, s in enumerate(shifts):  # a loop over candidate shifts, vectorised over points
        arg = (normal @ s - sd) / tau
        out[i] = float(np.sum(sign / (1.0 + np.exp(-np.clip(arg, -50, 50)))))
    return out
