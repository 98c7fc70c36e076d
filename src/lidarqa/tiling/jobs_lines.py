"""Line repeatability of every flight-strip pair over a whole catalog.

Poreba & Goulette's repeatability compares the edges of each flight strip
(``point_source_id``) with those of every other strip. On a delivery cut
into tiles a strip crosses many tiles and a pair of strips overlaps over
many chunks, so the comparison is done in two steps:

0. once (:func:`strip_samples`, :func:`strip_options`): each strip's
   data-driven defaults (growing radius, support distance) and point spacing,
   measured on the strip's points in the source's central sample window, so
   every chunk uses the same ones and a file (one region) gets them too;
1. per chunk (:class:`StripEdgesTask`): the edges of each strip present in
   the chunk's buffered points, kept by the anchor-in-core rule (the chunk
   whose core holds the segment midpoint, see :mod:`lidarqa.tiling.jobs_vector`);
2. merge (:func:`merge_strip_edges`): per strip, the chunk parts are merged
   into one edge set for the whole block (each edge once), and every pair of
   strips is matched once over the whole block (:func:`strip_pairs`), as one
   in-memory run would.

Edges are small vector data (thousands per km²), so holding every strip's
edges for the matching is cheap even when the points are not.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import combinations
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from ..accuracy.lines_io import with_point_spacing
from ..errors import CRSMismatchError, InvalidPointsError, LidarQAError
from ..io.vector import Segments
from .jobs_vector import merge_vector_parts, vector_features

if TYPE_CHECKING:
    from ._types import Tiles
    from .engine import ChunkData
    from .source import Source

#: A pass's key in :func:`strip_pairs` (a strip id, or any name).
K = TypeVar("K", bound=Hashable)

#: Per strip: (segment options, edge options, point spacing m), see :func:`strip_options`.
StripOptions = dict[int, tuple[dict[str, object], dict[str, object], float]]

__all__ = ["StripEdgesTask", "merge_strip_edges", "strip_options", "strip_pairs",
           "strip_samples"]


def strip_samples(source: Source, *, side: float = 100.0, min_points: int = 100,
                  max_side: float = 1600.0) -> dict[int, np.ndarray]:
    """``{strip id: x, y, z}``: each strip's selected points in the sample window.

    Windows centred on the area (:func:`~lidarqa.tiling.source.sample_boxes`: side
    `side`, doubled until the window covers the area) are read in turn; a strip
    takes the first window holding `min_points` of its points. Growing stops at
    the window that covers the area, or past `max_side` once every strip seen
    has its sample. The windows do not depend on the chunking: a file and a
    folder of its tiles get the same samples.
    """
    from .source import sample_boxes

    out: dict[int, np.ndarray] = {}
    last: dict[int, np.ndarray] = {}
    for box in sample_boxes(source.area_bounds, side=side):
        cloud = source.read_chunk(source.window(box)).cloud
        sid = cloud.point_source_id
        if sid is None:
            raise InvalidPointsError("the source has no point_source_id field: no strips")
        sid = np.asarray(sid)
        xyz = cloud.xyz
        for s in np.unique(sid).tolist():
            if int(s) in out:
                continue
            pts = xyz[sid == s]
            if len(pts) >= min_points:
                out[int(s)] = pts
            else:
                last[int(s)] = pts
        if box[2] - box[0] > max_side and all(k in out for k in last):
            break
    for k, v in last.items():
        out.setdefault(k, v)
    return dict(sorted(out.items()))


def strip_options(samples: dict[int, np.ndarray], *,
                  segment_options: Mapping[str, object] | None = None,
                  edge_options: Mapping[str, object] | None = None,
                  ) -> StripOptions:
    """Per strip: (segment options, edge options, point spacing m) fixed from its sample.

    The growing radius and support distance left unset are measured on the
    strip's sample (:func:`~lidarqa.tiling.jobs_vector.fixed_auto_options`), and
    the point spacing (median distance to the 10th neighbour) bounds the pairs'
    automatic thresholds (:func:`lidarqa.accuracy.lines.sampling_threshold_range`).
    """
    from ..geometry.segmentation import point_spacing
    from .jobs_vector import fixed_auto_options

    out: StripOptions = {}
    for s, pts in samples.items():
        seg, opts = fixed_auto_options(pts, segment_options=segment_options, options=edge_options)
        sp = point_spacing(np.asarray(pts, dtype=np.float64)) if len(pts) else float("nan")
        out[int(s)] = (seg, opts, float(sp))
    return out


@dataclass(frozen=True)
class StripEdgesTask:
    """Chunk task: ``{strip id: edges anchored in the core}`` for the strips in a chunk.

    Parameters
    ----------
    classes : tuple of int, optional
        Points used (e.g. ``(6,)`` for buildings); None = all.
    source_ids : tuple of int, optional
        Only these strips; None = every strip.
    segment_options, edge_options : dict
        As in :func:`lidarqa.tiling.jobs_vector.vector_features`.
    min_points : int, default 30
        A strip with fewer selected points in a chunk gives no edges there.
    strips : dict, optional
        Per strip ``(segment options, edge options, point spacing)`` from
        :func:`strip_options`; a strip not listed measures its defaults on the
        chunk's points.
    margin : float, optional
        The buffer the job needs (m); default
        :data:`~lidarqa.tiling.chunks.DEFAULT_BUFFER`.
    """

    classes: tuple[int, ...] | None = None
    source_ids: tuple[int, ...] | None = None
    segment_options: dict[str, object] = field(default_factory=dict)
    edge_options: dict[str, object] = field(default_factory=dict)
    min_points: int = 30
    strips: StripOptions = field(default_factory=dict)
    margin: float | None = None

    def buffer(self, source: Tiles) -> float:
        """The margin (m) read around each chunk (:attr:`margin`)."""
        from .chunks import DEFAULT_BUFFER

        return float(DEFAULT_BUFFER if self.margin is None else self.margin)

    def __call__(self, chunk_data: ChunkData) -> tuple[str, dict[int, Segments]]:
        """Edges per strip of one chunk (its buffer read too), anchored in its core."""
        from .jobs_vector import fixed_auto_options

        cloud = chunk_data.cloud
        if self.classes:
            cloud = cloud.select(classes=self.classes)
        sid = cloud.point_source_id
        if sid is None:
            raise InvalidPointsError("the catalog has no point_source_id field: no strips")
        strips = np.unique(sid)
        if self.source_ids is not None:
            strips = strips[np.isin(strips, self.source_ids)]
        out: dict[int, Segments] = {}
        core = chunk_data.chunk
        # edges are found and matched with heights in metres (a strip in feet too)
        from ..io.crs import heights_to_metres

        all_xyz = heights_to_metres(cloud.xyz, cloud.crs)
        for s in strips.tolist():
            xyz = all_xyz[sid == s]
            if len(xyz) < self.min_points:
                continue
            fixed = self.strips.get(int(s))
            if fixed is None:
                seg_opts, e_opts = fixed_auto_options(xyz, segment_options=self.segment_options,
                                                      options=self.edge_options)
            else:
                seg_opts, e_opts = fixed[0], fixed[1]
            try:
                seg = vector_features(xyz, kind="edges", core=core, segment_options=seg_opts,
                                      options=e_opts, crs=cloud.crs)
            except LidarQAError:
                continue  # no usable planes for this strip here: no edges
            if len(seg):
                if fixed is None:
                    seg = with_point_spacing(cast(Segments, seg), xyz)
                else:
                    seg.attributes["point_spacing"] = np.full(len(seg), fixed[2])
                out[int(s)] = cast(Segments, seg)
        return chunk_data.chunk.id, out


def merge_strip_edges(
    parts: Sequence[tuple[str, dict[int, Segments]] | None], *, tolerance: float = 0.05
) -> dict[int, Segments]:
    """Per strip, the whole-block edge set (each edge once, canonical order)."""
    by_strip: dict[int, list[tuple[str, Segments]]] = {}
    for p in parts:
        if p is None:
            continue
        cid, strips = p
        for s, seg in strips.items():
            by_strip.setdefault(int(s), []).append((cid, seg))
    return {
        s: cast(Segments, merge_vector_parts(v, tolerance=tolerance))
        for s, v in sorted(by_strip.items())
    }


def strip_pairs(strips: Mapping[K, Segments | Exception], *, shared_threshold: bool = False,
                pairs: Sequence[tuple[K, K]] | None = None,
                **match_options: object) -> list[dict[str, object]]:
    """Match every pair of strips both ways: rows like ``lidarqa repeatability``.

    Parameters
    ----------
    strips : dict of strip id to Segments
        From :func:`merge_strip_edges` (or any passes by name). A pass that is an
        exception (its edges could not be found) gives its pairs an ``error``.
    shared_threshold : bool, default False
        One threshold for every pair: the median of the pairs' automatic
        thresholds (knees) in both directions (``--shared-threshold``).
    **match_options
        Passed to :func:`lidarqa.accuracy.lines.match_segments` (weight,
        sensitivity, threshold, rotate, denominator), and ``auto``:
        ``"sampling"`` (default) bounds each pair's automatic threshold by the
        strips' point spacing (:func:`~lidarqa.accuracy.lines.sampling_threshold_range`),
        ``"knee"`` keeps the plain knee.

    pairs : sequence of (test, model) keys, optional
        The pairs to match (default every pair, in the order of `strips`).

    Returns
    -------
    list of dict
        ``test``, ``model`` (strip ids as text) and the ``LineMatch.to_dict()``
        figures, or ``error`` when a pair cannot be matched. Pairs in the order
        of `pairs`.

    Raises
    ------
    OptionError
        `shared_threshold` with a fixed threshold, or no pair with a knee.
    """
    from ..accuracy.lines import match_segments, match_strips
    from ..errors import OptionError

    opts: dict[str, Any] = dict(match_options)  # checked by match_segments
    pairs = list(combinations(strips, 2)) if pairs is None else list(pairs)
    bad = {k: v for k, v in strips.items() if isinstance(v, Exception)}
    good = [(a, b) for a, b in pairs if a not in bad and b not in bad]
    segs = cast("Mapping[K, Segments]", strips)  # the passes of `good`
    if shared_threshold:
        if opts.get("threshold") is not None:
            raise OptionError("--shared-threshold computes the threshold; do not also give "
                              "--threshold")
        knee_opts = {k: opts[k] for k in ("weight", "sensitivity", "rotate")
                     if k in opts}
        knees = []
        for a, b in good:
            try:
                r0 = match_segments(segs[a], segs[b], **knee_opts)
            except LidarQAError:
                continue
            knees += [t for t, ok in ((r0.threshold_tm, r0.threshold_found_tm),
                                      (r0.threshold_mt, r0.threshold_found_mt)) if ok]
        if not knees:
            raise OptionError("--shared-threshold: no pair has an automatic threshold (no knee)")
        opts = {**opts, "threshold": float(np.median(knees))}
    rows: list[dict[str, object]] = []
    for a, b in pairs:
        row: dict[str, object] = {"test": str(a), "model": str(b)}
        if a in bad or b in bad:
            row["error"] = str(bad.get(a, bad.get(b)))
        else:
            try:
                row.update(match_strips(segs[a], segs[b], **opts))
            except CRSMismatchError:
                raise
            except LidarQAError as exc:
                row.update(p=len(segs[a]), q=len(segs[b]), error=str(exc))
        rows.append(row)
    return rows

