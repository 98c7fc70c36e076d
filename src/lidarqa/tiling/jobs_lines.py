"""Line repeatability of every flight-strip pair over a whole catalog.

Poreba & Goulette's repeatability compares the edges of each flight strip
(``point_source_id``) with those of every other strip. On a delivery cut
into tiles a strip crosses many tiles and a pair of strips overlaps over
many chunks, so the comparison is done in two steps:

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

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations
from typing import Any, cast

import numpy as np

from ..accuracy._lines_io import with_point_spacing
from ..errors import CRSMismatchError, InvalidPointsError, LidarQAError
from ..io.vector import Segments
from .jobs_vector import merge_vector_parts, vector_features

__all__ = ["StripEdgesTask", "merge_strip_edges", "strip_pairs"]


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
    """

    classes: tuple[int, ...] | None = None
    source_ids: tuple[int, ...] | None = None
    segment_options: dict[str, Any] = field(default_factory=dict)
    edge_options: dict[str, Any] = field(default_factory=dict)
    min_points: int = 30

    def __call__(self, chunk_data: Any) -> tuple[str, dict[int, Segments]]:
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
        for s in strips.tolist():
            xyz = cloud.xyz[sid == s]
            if len(xyz) < self.min_points:
                continue
            try:
                seg = vector_features(xyz, kind="edges", core=core,
                                      segment_options=self.segment_options,
                                      options=self.edge_options, crs=cloud.crs)
            except LidarQAError:
                continue  # no usable planes for this strip here: no edges
            if len(seg):
                out[int(s)] = with_point_spacing(cast(Segments, seg), xyz)
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


def strip_pairs(strips: dict[int, Segments], **match_options: Any) -> list[dict[str, Any]]:
    """Match every pair of strips both ways: rows like ``lidarqa repeatability``.

    Parameters
    ----------
    strips : dict of strip id to Segments
        From :func:`merge_strip_edges`.
    **match_options
        Passed to :func:`lidarqa.accuracy.lines.match_segments` (weight,
        sensitivity, threshold, rotate, denominator), and ``auto``:
        ``"sampling"`` (default) bounds each pair's automatic threshold by the
        strips' point spacing (:func:`~lidarqa.accuracy.lines.sampling_threshold_range`),
        ``"knee"`` keeps the plain knee.

    Returns
    -------
    list of dict
        ``test``, ``model`` (strip ids as text) and the ``LineMatch.to_dict()``
        figures, or ``error`` when a pair cannot be matched. Pairs in
        increasing strip order.
    """
    from ..accuracy.lines import match_strips

    rows: list[dict[str, Any]] = []
    for a, b in combinations(sorted(strips), 2):
        row: dict[str, Any] = {"test": str(a), "model": str(b)}
        try:
            row.update(match_strips(strips[a], strips[b], **match_options))
        except CRSMismatchError:
            raise
        except LidarQAError as exc:
            row.update(p=len(strips[a]), q=len(strips[b]), error=str(exc))
        rows.append(row)
    return rows
