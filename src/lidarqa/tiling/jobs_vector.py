"""Planes, edges and corners of a catalog, each feature reported once.

A chunk is read with a buffer around its core so that a roof cut by a chunk
border is still seen whole. Two neighbouring chunks therefore both find the
features near their common border. The rule that keeps each feature once is
the **anchor-in-core rule**:

* a feature has one *anchor* point: a corner its own position, an edge the
  midpoint of its segment, a plane the centroid of its points (all of them, as
  seen in the buffered chunk);
* a chunk keeps a feature only when its anchor lies in the chunk's *core*,
  ``xmin <= x < xmax`` and ``ymin <= y < ymax`` (half-open, so the cores tile
  the plane without overlap and an anchor belongs to exactly one core; with a
  catalog chunk, its own grid-index rule decides, :func:`owned`).

A feature whose plane reaches the edge of the buffered box may belong to a
roof wider than the buffer, cut by the box; it is kept but flagged in the
column ``at_buffer_edge`` so that a user can widen ``--buffer``.

When the buffer is wider than the features (a building's half-size), both
chunks see the same points around a feature and find the same feature, so
exactly one of them keeps it. Two chunks can still disagree by a few
centimetres (a plane fitted from a slightly different neighbourhood), so an
anchor within round-off of a core border might be kept twice or not at all;
:func:`merge_vector_parts` therefore also removes near-duplicates (features
closer than ``tolerance``, 0.05 m by default), keeping the first in the
canonical order. The merged output is sorted by anchor (x, then y, then z) and
numbered 0..n-1, so it does not depend on the number of workers or on which
chunk finished first. The ``chunk`` column names the chunk that kept each
feature; ``plane_a``/``plane_b``/``plane_c`` are plane numbers *within that
chunk* (a plane's number is its ``plane`` column).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from ..errors import InvalidPointsError, OptionError
from ..io.vector import PointSet, Segments

if TYPE_CHECKING:
    from pyproj import CRS

    from ._types import Tiles
    from .chunks import Chunk
    from .engine import ChunkData

    #: A chunk, or a plain half-open core ``(xmin, ymin, xmax, ymax)``.
    Where = Chunk | Sequence[float]

__all__ = [
    "VectorTask",
    "dedupe_points",
    "dedupe_segments",
    "feature_buffer",
    "fixed_auto_options",
    "in_core",
    "keep_anchored",
    "merge_summaries",
    "merge_vector_parts",
    "owned",
    "vector_features",
]

KINDS = ("planes", "edges", "corners")

#: One chunk's part: (chunk id, features) or, from :class:`VectorTask`, (chunk id, features,
#: what the chunk owns of its segmentation, see :func:`vector_features`).
VectorPart = tuple[str, "Segments | PointSet"] | tuple[str, "Segments | PointSet",
                                                       dict[str, object]]


def in_core(xy: ArrayLike, core: Sequence[float]) -> np.ndarray:
    """Mask of points inside a half-open core ``[xmin, xmax) x [ymin, ymax)``.

    Parameters
    ----------
    xy : ndarray of shape (N, 2) or (N, 3)
        Coordinates (m); only x and y are used.
    core : (xmin, ymin, xmax, ymax)

    Examples
    --------
    >>> in_core([[0, 0], [1, 0.5], [0.5, 1]], (0, 0, 1, 1)).tolist()
    [True, False, False]
    """
    p = np.asarray(xy, dtype=np.float64)
    p = p.reshape(len(p), -1) if p.size else np.empty((0, 2))
    x0, y0, x1, y1 = (float(v) for v in core)
    return (p[:, 0] >= x0) & (p[:, 0] < x1) & (p[:, 1] >= y0) & (p[:, 1] < y1)


def owned(xy: ArrayLike, where: Where) -> np.ndarray:
    """Mask of the points `xy` owned by a chunk: in its core by the engine's own rule.

    `where` is a chunk (its ``core_mask`` decides, the rule the catalog engine
    uses for per-point outputs, so features, reference points and points agree
    at borders), or a plain ``(xmin, ymin, xmax, ymax)`` core (:func:`in_core`).
    """
    p = np.asarray(xy, dtype=np.float64)
    p = p.reshape(len(p), -1) if len(p) else np.empty((0, 2))
    if isinstance(where, Sequence):
        return in_core(p, where)
    mask = getattr(where, "core_mask", None)  # anything with a `core` box will do
    return np.asarray(mask(p), dtype=bool) if mask is not None else in_core(p, where.core)


def _anchors(features: Segments | PointSet) -> np.ndarray:
    if isinstance(features, Segments):
        return 0.5 * (features.start + features.end)
    return features.xyz


def keep_anchored(features: Segments | PointSet, core: Where) -> Segments | PointSet:
    """The features whose anchor (segment midpoint, or point) lies in `core` (see :func:`owned`)."""
    return features.subset(np.flatnonzero(owned(_anchors(features), core)))


def _canonical(features: Segments | PointSet) -> np.ndarray:
    a = np.round(_anchors(features), 9)  # order by anchor, rounded to absorb last-bit noise
    if isinstance(features, Segments):
        keys = [features.end[:, 2], features.end[:, 1], features.end[:, 0],
                features.start[:, 2], features.start[:, 1], features.start[:, 0]]
    else:
        keys = []
    return np.lexsort([*keys, a[:, 2], a[:, 1], a[:, 0]])


def dedupe_points(points: PointSet, *, tolerance: float = 0.05) -> PointSet:
    """Drop points closer than `tolerance` (m, 3D) to an earlier point (in the given order)."""
    n = len(points)
    if n < 2 or tolerance <= 0:
        return points
    pairs = cKDTree(points.xyz).query_pairs(tolerance, output_type="ndarray")
    return points.subset(np.flatnonzero(~_later_of(pairs, n)))


def _later_of(pairs: np.ndarray, n: int) -> np.ndarray:
    """Greedy in index order: a point is dropped if an earlier *kept* point is its duplicate."""
    drop = np.zeros(n, dtype=bool)
    if not len(pairs):
        return drop
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    for i, j in pairs.tolist():  # few pairs: only the duplicates near chunk borders
        if not drop[i]:
            drop[j] = True
    return drop


def dedupe_segments(segments: Segments, *, tolerance: float = 0.05) -> Segments:
    """Drop segments whose two endpoints are both within `tolerance` (m) of an earlier one's.

    Endpoints are compared in either orientation.
    """
    n = len(segments)
    if n < 2 or tolerance <= 0:
        return segments
    mid = 0.5 * (segments.start + segments.end)
    half = 0.5 * segments.lengths
    tree = cKDTree(mid)
    cand = tree.query_pairs(tolerance, output_type="ndarray")  # duplicates have close midpoints
    if len(cand):
        i, j = cand[:, 0], cand[:, 1]
        same = np.maximum(
            np.linalg.norm(segments.start[i] - segments.start[j], axis=1),
            np.linalg.norm(segments.end[i] - segments.end[j], axis=1),
        )
        flip = np.maximum(
            np.linalg.norm(segments.start[i] - segments.end[j], axis=1),
            np.linalg.norm(segments.end[i] - segments.start[j], axis=1),
        )
        close = (np.minimum(same, flip) <= tolerance) & (np.abs(half[i] - half[j]) <= tolerance)
        cand = cand[close]
    return segments.subset(np.flatnonzero(~_later_of(cand, n)))


def merge_vector_parts(
    parts: Sequence[VectorPart | None],
    *,
    tolerance: float = 0.05,
    crs: CRS | None = None,
) -> Segments | PointSet:
    """Concatenate per-chunk features (already anchored), dedupe and number them canonically.

    Parameters
    ----------
    parts : sequence of (chunk_id, Segments or PointSet, ...), or None for a failed chunk
        (more items, such as a :class:`VectorTask` part's summary, are ignored)
    tolerance : float, default 0.05
        Features closer than this (m) are duplicates (see the module docstring).
    crs : pyproj.CRS, optional
        Stored on the result (else the first part's).

    Returns
    -------
    Segments or PointSet
        ids 0..n-1 in anchor order, the parts' attributes and a ``chunk`` column.
    """
    items = [p for p in parts if p is not None]
    if not items:
        raise InvalidPointsError("no chunk produced features (every chunk failed)")
    is_seg = isinstance(items[0][1], Segments)
    # columns in the order the features give them (the single-region command's order)
    names = list(dict.fromkeys(k for p in items for k in p[1].attributes))
    cols: dict[str, list[np.ndarray]] = {k: [] for k in names}
    chunk_col: list[np.ndarray] = []
    geo: list[list[np.ndarray]] = [[], []]
    for cid, f, *_ in items:
        if isinstance(f, Segments) != is_seg:
            raise InvalidPointsError("cannot merge segments with points")
        n = len(f)
        for k in names:
            v = f.attributes.get(k)
            cols[k].append(np.asarray(v) if v is not None else np.full(n, np.nan))
        chunk_col.append(np.full(n, cid, dtype=object))
        if isinstance(f, Segments):
            geo[0].append(f.start)
            geo[1].append(f.end)
        else:
            geo[0].append(f.xyz)
    attrs = {k: np.concatenate(v) for k, v in cols.items()}
    attrs["chunk"] = np.concatenate(chunk_col).astype(str)
    crs = crs if crs is not None else items[0][1].crs
    merged: Segments | PointSet
    if is_seg:
        start, end = np.concatenate(geo[0]), np.concatenate(geo[1])
        segs = Segments(np.arange(len(start)), start, end, attrs, crs)
        merged = dedupe_segments(segs.subset(_canonical(segs)), tolerance=tolerance)
    else:
        xyz = np.concatenate(geo[0])
        pts = PointSet(np.arange(len(xyz)), xyz, attrs, crs)
        merged = dedupe_points(pts.subset(_canonical(pts)), tolerance=tolerance)
    merged.ids = np.arange(len(merged), dtype=np.int64)
    return merged


# ------------------------------------------------------------------ per-chunk work


def fixed_auto_options(
    points: np.ndarray,
    *,
    kind: str = "edges",
    segment_options: Mapping[str, object] | None = None,
    options: Mapping[str, object] | None = None,
) -> tuple[dict[str, object], dict[str, object]]:
    """Fix the data-driven defaults once for a whole catalog.

    Plane segmentation's growing radius (2 x the point spacing), the edges'
    support distance (1.2 x the spacing) and, with step edges, their point
    spacing default to values measured on the
    points at hand; measured per chunk they would differ slightly from chunk to
    chunk, and so would the features. This measures the spacing once on
    `points` (e.g. the selected points of one chunk) and returns copies of
    `segment_options` and `options` with those values filled in where the
    caller left them unset.

    Returns
    -------
    (segment_options, options)
    """
    from .._validate import as_points
    from ..geometry.segmentation import point_spacing

    seg = dict(segment_options or {})
    opts = dict(options or {})
    pts = as_points(points)
    sp = point_spacing(pts) if len(pts) > 10 else float("nan")
    if seg.get("grow_radius") is None:
        seg["grow_radius"] = float(np.clip(2.0 * sp, 0.5, 3.0)) if np.isfinite(sp) else 0.5
    if kind == "edges" and opts.get("near_dist") is None:
        opts["near_dist"] = float(np.clip(1.2 * sp, 0.15, 1.0)) if np.isfinite(sp) else 0.15
    if kind == "edges" and opts.get("steps") and opts.get("point_spacing") is None \
            and np.isfinite(sp):
        opts["point_spacing"] = float(sp)  # the step edges' scale
    return seg, opts


def feature_buffer(
    points: np.ndarray,
    *,
    segment_options: Mapping[str, object] | None = None,
    spacings: float = 4.0,
    cap: float | None = None,
) -> float:
    """The margin (m) a chunk of a planes/edges/corners job reads around its core.

    A feature is kept by the chunk that holds its anchor (plane centroid, edge
    midpoint, corner), and is the same as in one whole-area run when the chunk
    saw its planes whole, and their neighbours: the buffer is the largest
    horizontal extent (bounding-box diagonal) of the planes segmented in
    `points` (the source's central sample window, segmented with the run's
    fixed `segment_options`) plus `spacings` point spacings, at most `cap`
    (default :data:`~lidarqa.tiling.chunks.DEFAULT_BUFFER`, the margin every
    job got before it declared its own) and at least 20 point spacings.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        The selected points of the sample window, x, y, z in metres.
    segment_options : dict, optional
        As :func:`lidarqa.geometry.segmentation.segment_planes` (with the
        growing radius fixed for the run).
    spacings : float, default 4
        Point spacings added to the plane extent.
    cap : float, optional
        Largest margin returned (m).

    Returns
    -------
    float
        The margin, m.
    """
    from .._validate import as_points
    from ..geometry.segmentation import segment_planes
    from .chunks import DEFAULT_BUFFER

    top = float(DEFAULT_BUFFER if cap is None else cap)
    pts = as_points(points) if len(points) else np.zeros((0, 3))
    if len(pts) < 30:
        return top
    seg_kw: dict[str, Any] = dict(segment_options or {})  # checked by segment_planes
    seg = segment_planes(pts, **seg_kw)
    sp = seg.parameters.get("point_spacing")
    sp = float(sp) if sp is not None and np.isfinite(sp) else 1.0
    extent = 0.0
    if seg.n_segments:
        lab = np.asarray(seg.labels)
        ok = lab >= 0
        n = int(seg.n_segments)
        lo = np.full((n, 2), np.inf)
        hi = np.full((n, 2), -np.inf)
        np.minimum.at(lo, lab[ok], pts[ok, :2])
        np.maximum.at(hi, lab[ok], pts[ok, :2])
        extent = float(np.max(np.hypot(*(hi - lo).T)))
    return float(min(top, max(extent + spacings * sp, 20.0 * sp)))



def _planes_pointset(seg: Any, crs: Any) -> PointSet:
    """One point per plane (its centroid) with the columns of ``lidarqa planes``."""
    n = seg.n_segments
    deg = (np.bincount(seg.adjacency.ravel(), minlength=n) if n and len(seg.adjacency)
           else np.zeros(n, dtype=np.int64))
    sn = np.sqrt(np.maximum(np.trace(seg.covariance[:, :3, :3], axis1=1, axis2=2), 0.0))
    return PointSet(ids=np.arange(n, dtype=np.int64), xyz=seg.centroid.copy(), crs=crs, attributes={
        "nx": seg.normal[:, 0], "ny": seg.normal[:, 1], "nz": seg.normal[:, 2], "rho": seg.rho,
        "n_points": seg.n_points, "n_inliers": seg.n_inliers, "rmse": seg.rmse,
        "sigma_rho": seg.sigma_rho, "sigma_normal_deg": np.degrees(sn), "n_adjacent": deg,
        "plane": np.arange(n, dtype=np.int64)})  # the plane_a/b/c of the chunk's edges, corners


def vector_features(
    points: np.ndarray,
    *,
    kind: str,
    core: Where | None = None,
    segment_options: Mapping[str, object] | None = None,
    options: Mapping[str, object] | None = None,
    crs: CRS | None = None,
    box: Sequence[float] | None = None,
    summary: dict[str, object] | None = None,
) -> Segments | PointSet:
    """Planes, edges or corners of (buffered) points, keeping those anchored in `core`.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z (m) of the chunk and its buffer, already selected (e.g. class 6).
    kind : {"planes", "edges", "corners"}
    core : Chunk or (xmin, ymin, xmax, ymax), optional
        The chunk (or its half-open core); None keeps every feature (an in-memory run).
    segment_options : dict, optional
        Passed to :func:`lidarqa.geometry.segmentation.segment_planes`.
    options : dict, optional
        Passed to :func:`~lidarqa.geometry.edges.edges_from_segmentation` /
        :func:`~lidarqa.geometry.corners.corners_from_segmentation` (e.g.
        ``min_angle``, ``min_length``, ``near_dist``).
    box : (xmin, ymin, xmax, ymax), optional
        The box the points were read from (the chunk's buffered box, with the sides
        beyond the catalog set to ±inf). Adds the column ``at_buffer_edge``: 1 when
        one of the feature's planes reaches that box's edge, so the plane (a roof
        wider than the buffer) may be cut and the feature differ from a whole-area run.
    summary : dict, optional
        Filled with what `core` owns, so that chunk summaries add up to the whole
        area's: ``n_points``, ``n_segmented_points``, ``n_planes`` (by centroid),
        ``n_adjacent_pairs`` and ``left_out`` (reason -> count of the plane pairs or
        triples that gave no edge or corner, by their planes' mean centroid), and the
        segmentation's ``parameters``.

    Returns
    -------
    Segments (edges) or PointSet (planes at their centroids, corners)
    """
    from .._validate import as_points, check_choice

    kind = check_choice(kind, KINDS, "kind")
    pts = as_points(points)
    opts: dict[str, Any] = dict(options or {})  # checked by the extractors
    seg_kw: dict[str, Any] = dict(segment_options or {})
    if len(pts) < 3:
        empty: Segments | PointSet = (Segments(np.zeros(0, np.int64), np.zeros((0, 3)),
                                               np.zeros((0, 3)), crs=crs) if kind == "edges"
                                      else PointSet(np.zeros(0, np.int64), np.zeros((0, 3)),
                                                    crs=crs))
        if box is not None:
            empty.attributes["at_buffer_edge"] = np.zeros(0, dtype=np.int64)
        if summary is not None:
            summary.update(_summary(pts, None, [], core))
        return empty
    from ..geometry.segmentation import segment_planes

    seg = segment_planes(pts, **seg_kw)
    left: list[dict[str, Any]] = []
    if kind == "planes":
        feats: Segments | PointSet = _planes_pointset(seg, crs)
    elif kind == "edges":
        from ..geometry.edges import extract_edges

        feats = extract_edges(pts, segmentation=seg, crs=crs, left_out=left, **opts)
    else:
        from ..geometry.corners import extract_corners

        feats = extract_corners(pts, segmentation=seg, crs=crs, left_out=left, **opts)
    if summary is not None:
        summary.update(_summary(pts, seg, left, core))
    if box is not None:
        feats.attributes["at_buffer_edge"] = _at_box_edge(pts, seg, feats, kind, box,
                                                          seg.parameters.get("grow_radius"))
    return feats if core is None else keep_anchored(feats, core)


def _summary(pts: np.ndarray, seg: Any, left: list[dict[str, Any]],
             core: Where | None) -> dict[str, Any]:
    """What `core` owns of a chunk's segmentation (see :func:`vector_features`)."""
    from collections import Counter

    def own(xy: np.ndarray) -> np.ndarray:
        return owned(xy, core) if core is not None else np.ones(len(xy), dtype=bool)

    mine = own(pts)
    if seg is None:
        return {"n_points": int(mine.sum()), "n_segmented_points": 0, "n_planes": 0,
                "n_adjacent_pairs": 0, "left_out": {}, "parameters": {}}
    cen = np.asarray(seg.centroid, dtype=np.float64).reshape(-1, 3)[:, :2]
    adj = np.asarray(seg.adjacency, dtype=np.int64).reshape(-1, 2)
    ids = [r["planes"] if "planes" in r else (r["plane_a"], r["plane_b"]) for r in left]
    left_own = (own(cen[np.asarray(ids, dtype=np.int64)].mean(axis=1)) if ids
                else np.zeros(0, dtype=bool))
    return {"n_points": int(mine.sum()),
            "n_segmented_points": int((mine & (np.asarray(seg.labels) >= 0)).sum()),
            "n_planes": int(own(cen).sum()), "n_adjacent_pairs": int(own(cen[adj].mean(axis=1))
                                                                    .sum()) if len(adj) else 0,
            "left_out": dict(Counter(r["reason"] for r, k in zip(left, left_own, strict=True)
                                     if k)),
            "parameters": dict(seg.parameters)}


def merge_summaries(parts: Sequence[VectorPart | None]) -> dict[str, object]:
    """The whole area's summary: the sum of the parts' summaries (:func:`vector_features`)."""
    from collections import Counter

    counts: Counter[str] = Counter(dict.fromkeys(_COUNTS, 0))
    left: Counter[str] = Counter()
    params: object = {}
    for p in parts:
        if p is None or len(p) < 3:
            continue
        part = cast("dict[str, Any]", p[-1])
        counts.update({k: int(part.get(k, 0)) for k in _COUNTS})
        left.update(part.get("left_out", {}))
        params = params or part.get("parameters", {})  # the first chunk's
    return {**counts, "left_out": dict(left.most_common()), "parameters": params}


_COUNTS = ("n_points", "n_segmented_points", "n_planes", "n_adjacent_pairs")


def _at_box_edge(pts: np.ndarray, seg: Any, feats: Any, kind: str, box: Sequence[float],
                 reach: Any) -> np.ndarray:
    """1 where a feature's plane has points within `reach` of a closed side of `box`.

    Such a plane may continue beyond the points the chunk read (a roof wider than the
    buffer): the feature may then differ from the one a whole-area run finds.
    """
    r = float(reach) if reach is not None and np.isfinite(reach) else 1.0
    x, y = pts[:, 0], pts[:, 1]
    near = ((x - box[0] < r) | (box[2] - x < r) | (y - box[1] < r) | (box[3] - y < r))
    lab = np.asarray(seg.labels)
    n_seg = int(seg.n_segments)
    touching = np.zeros(n_seg + 1, dtype=bool)
    ok = near & (lab >= 0)
    touching[lab[ok]] = True
    if kind == "planes":
        idx = [np.arange(len(feats))]
    else:
        idx = [np.asarray(feats.attributes[k], dtype=np.int64)
               for k in ("plane_a", "plane_b", "plane_c") if k in feats.attributes]
    flag = np.zeros(len(feats), dtype=bool)
    for i in idx:
        flag |= touching[np.clip(i, 0, n_seg)] & (i >= 0) & (i < n_seg)
    return flag.astype(np.int64)


def open_box(box: Sequence[float], bounds: Sequence[float] | None) -> tuple[float, ...]:
    """`box` with its sides at or beyond the catalog `bounds` opened to ±inf (no data there)."""
    b = tuple(float(v) for v in box[:4])
    if bounds is None:
        return b
    return (-np.inf if b[0] <= bounds[0] else b[0], -np.inf if b[1] <= bounds[1] else b[1],
            np.inf if b[2] >= bounds[2] else b[2], np.inf if b[3] >= bounds[3] else b[3])


@dataclass(frozen=True)
class VectorTask:
    """A picklable chunk task for the catalog engine: ``task(chunk_data) -> (chunk_id, features)``.

    Parameters
    ----------
    kind : {"planes", "edges", "corners"}
    classes, source_id : tuple of int, optional
        Point selection (classification codes, point_source_id values).
    segment_options, options : dict
        As in :func:`vector_features`.
    bounds : (xmin, ymin, xmax, ymax), optional
        The catalog's extent (for the ``at_buffer_edge`` column: no data beyond it).
    margin : float, optional
        The buffer the job needs (m, :func:`feature_buffer`); default
        :data:`~lidarqa.tiling.chunks.DEFAULT_BUFFER`.
    """

    kind: str
    classes: tuple[int, ...] | None = None
    source_id: tuple[int, ...] | None = None
    segment_options: dict[str, object] = field(default_factory=dict)
    options: dict[str, object] = field(default_factory=dict)
    bounds: tuple[float, float, float, float] | None = None
    margin: float | None = None

    def buffer(self, source: Tiles) -> float:
        """The margin (m) read around each chunk: :attr:`margin` (see :func:`feature_buffer`)."""
        from .chunks import DEFAULT_BUFFER

        return float(DEFAULT_BUFFER if self.margin is None else self.margin)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise OptionError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}")

    def __call__(self, chunk_data: ChunkData) -> tuple[str, Segments | PointSet,
                                                        dict[str, object]]:
        """Features of one chunk (its buffer read too) anchored in its core, by chunk id.

        The third item is what the chunk owns of its segmentation (see
        :func:`vector_features`'s `summary`).
        """
        cloud = chunk_data.cloud
        if self.classes or self.source_id:
            cloud = cloud.select(classes=self.classes, source_id=self.source_id)
        xyz = cloud.xyz
        f = 1.0
        if cloud.crs is not None:
            from ..io.crs import z_to_metres_factor

            f = z_to_metres_factor(cloud.crs)
            if f != 1.0:
                xyz = xyz.copy()
                xyz[:, 2] *= f
        summary: dict[str, object] = {}
        feats = vector_features(xyz, kind=self.kind, core=chunk_data.chunk,
                                segment_options=self.segment_options, options=self.options,
                                crs=cloud.crs, box=open_box(chunk_data.chunk.buffered,
                                                            self.bounds), summary=summary)
        if f != 1.0:  # back to the cloud's vertical unit, as the single-file commands do
            if isinstance(feats, Segments):
                feats.start[:, 2] /= f
                feats.end[:, 2] /= f
            else:
                feats.xyz[:, 2] /= f
        return chunk_data.chunk.id, feats, summary
