"""Inputs of line matching: segment files, or clouds whose edges are extracted (I/O, no kernel).

What ``lidarqa lines``, the ``lines`` analysis of ``lidarqa assess`` and the catalog
job share: :func:`load_segments` (a segment file, or the edges of a cloud's
selected points), :func:`load_passes` / :func:`pool_passes` (one pass per file or
per flight strip), :func:`read_pairs` (the ``test_id,model_id`` pairs file) and
:func:`with_point_spacing` (the sampling the automatic threshold is bounded by).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import ProgressCallback, report, stage
from ..errors import (
    EdgeExtractionUnavailableError,
    InvalidPointsError,
    LidarQAError,
    MissingDependencyError,
    ReadError,
)
from ..io.vector import Segments, read_segments

__all__ = [
    "is_segment_file",
    "load_segments",
    "load_passes",
    "pool_passes",
    "read_pairs",
    "extract_segments",
    "with_point_spacing",
]

_VECTOR_ONLY = {".gpkg", ".geojson", ".json"}
_SEGMENT_COLUMNS = {"x1", "y1", "z1", "x2", "y2", "z2"}


def is_segment_file(path: str | os.PathLike) -> bool:
    """True for GeoPackage/GeoJSON, and for CSV files with x1,y1,z1,x2,y2,z2 columns."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in _VECTOR_ONLY:
        return True
    if suffix != ".csv" or not p.is_file():
        return False
    with p.open("r", encoding="utf-8-sig", newline="") as fh:
        first = ""
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                first = line
                break
    delim = ";" if first.count(";") > first.count(",") else ","
    header = {h.strip().lower() for h in first.split(delim)}
    return _SEGMENT_COLUMNS <= header


def extract_segments(points: np.ndarray, *, crs: Any = None, **options: Any) -> Segments:
    """Edges of a cloud with the geometry defaults (``lidarqa.geometry.edges.extract_edges``)."""
    try:
        from ..geometry.edges import extract_edges
    except ImportError as exc:
        raise EdgeExtractionUnavailableError(
            "point-cloud input needs edge extraction (lidarqa.geometry.edges.extract_edges), "
            "which is not available in this build; pass segment files "
            "(CSV id,x1,y1,z1,x2,y2,z2, GPKG, GeoJSON)"
        ) from exc
    seg = extract_edges(points, **options)
    if crs is not None and getattr(seg, "crs", None) is None:
        seg.crs = crs
    return with_point_spacing(seg, points)


def with_point_spacing(seg: Segments, points: np.ndarray) -> Segments:
    """`seg` with a ``point_spacing`` attribute (m): the sampling of the points it came from.

    The median distance of a point to its 10th neighbour, the same for every
    segment of the set; the automatic threshold between two flight strips is
    bounded by it (:func:`lidarqa.accuracy.lines.sampling_threshold_range`).
    """
    from ..geometry.segmentation import point_spacing

    sp = point_spacing(np.asarray(points, dtype=np.float64)) if len(points) else float("nan")
    seg.attributes["point_spacing"] = np.full(len(seg), sp, dtype=np.float64)
    return seg


def _read_cloud(path: str | os.PathLike, classes: Any, crs: Any = None) -> Any:
    from ..io import read

    cloud = read(path, crs=crs)
    if classes is not None:
        cloud = cloud.select(classes=classes)
    return cloud


def load_segments(
    path: str | os.PathLike,
    *,
    classes: Any = None,
    source_id: Any = None,
    edge_options: dict | None = None,
    crs: Any = None,
    progress: ProgressCallback | None = None,
) -> Segments:
    """Segments from a segment file, or the edges of the selected points of a cloud.

    `classes` and `source_id` (int or list of ints) select points of a cloud; for a
    segment file, which has no points, they raise :class:`InvalidPointsError`.
    `crs` (a pyproj CRS) is the CRS of an input that declares none. `progress`
    receives the fraction done of the edge extraction (plane segmentation).
    """
    if is_segment_file(path):
        if classes is not None or source_id is not None:
            raise InvalidPointsError(
                f"{path} is a segment file: --classes / --source-id select points of a cloud only"
            )
        return read_segments(path, crs=crs)
    cloud = _read_cloud(path, classes, crs)
    if source_id is not None:
        cloud = cloud.select(source_id=source_id)
    if len(cloud) == 0:
        raise InvalidPointsError(
            f"{path}: no points in the selection (classes {classes}, source ids {source_id})"
        )
    return extract_segments(cloud.xyz, crs=cloud.crs, progress=progress, **(edge_options or {}))


def load_passes(
    paths: list[str],
    *,
    by_source_id: bool = False,
    classes: Any = None,
    source_id: Any = None,
    edge_options: dict | None = None,
    crs: Any = None,
    progress: ProgressCallback | None = None,
) -> list[tuple[str, str, Any]]:
    """``[(group, name, Segments or LidarQAError)]``: one pass per file, or per strip.

    Without `by_source_id` every file is a pass and all files form one group.
    With it, every point_source_id (restricted to `source_id` if given) of each
    cloud is a pass and each file is its own group, so strips are compared
    within a file (merge tiles first to pool them). A strip whose edges cannot be
    extracted is kept as the error, to be reported. `progress` receives the
    fraction done (files, then strips within a file).
    """
    out: list[tuple[str, str, Any]] = []
    n = len(paths)
    for i, path in enumerate(paths):
        file_progress = stage(progress, i / n, (i + 1) / n)
        stem = Path(path).name
        if not by_source_id:
            seg_or_edges = load_segments(
                path, classes=classes, edge_options=edge_options, crs=crs, progress=file_progress
            )
            out.append(("", stem, seg_or_edges))
            continue
        if is_segment_file(path):
            raise InvalidPointsError(f"--by-source-id needs point clouds; {path} is a segment file")
        cloud = _read_cloud(path, classes, crs)
        sid = cloud.point_source_id
        if sid is None:
            raise InvalidPointsError(f"{path} has no point_source_id field for --by-source-id")
        wanted = np.unique(sid)
        if source_id is not None:
            wanted = wanted[np.isin(wanted, np.atleast_1d(source_id))]
        k = max(len(wanted), 1)
        for j, s in enumerate(wanted.tolist()):
            sub = cloud.subset(sid == s)
            strip_progress = stage(file_progress, j / k, (j + 1) / k)
            try:
                seg: Any = extract_segments(
                    sub.xyz, crs=cloud.crs, progress=strip_progress, **(edge_options or {})
                )
            except MissingDependencyError:
                raise
            except LidarQAError as exc:  # a strip without usable edges is reported, not fatal
                seg = exc
            out.append((stem, str(s), seg))
    report(progress, 1.0)
    return out


def pool_passes(passes: list[tuple[str, str, Any]]) -> list[tuple[str, str, Any]]:
    """Join the passes of the same strip across files: ``[("", strip, Segments or error)]``.

    Strips with the same point_source_id in neighbouring tiles are one flight
    line, so their edges are pooled into one pass (ids become ``"file:id"``;
    only the attributes every part has are kept). A tile cuts both strips along
    the same border, so pooling adds no false edges between them. A strip whose
    edges failed in every file keeps the first error; failures in some files
    are skipped.
    """
    names: dict[str, list] = {}
    for group, name, seg in passes:
        names.setdefault(name, []).append((group, seg))
    out: list[tuple[str, str, Any]] = []
    for name, parts in names.items():
        good = [(g, s) for g, s in parts if not isinstance(s, Exception)]
        if not good:
            out.append(("", name, parts[0][1]))
            continue
        keys = set.intersection(*(set(s.attributes) for _, s in good))
        out.append(
            (
                "",
                name,
                Segments(
                    ids=np.concatenate(
                        [
                            np.array([f"{g}:{i}" for i in s.ids.tolist()], dtype=object)
                            for g, s in good
                        ]
                    ),
                    start=np.concatenate([s.start for _, s in good]),
                    end=np.concatenate([s.end for _, s in good]),
                    attributes={
                        k: np.concatenate([np.asarray(s.attributes[k]) for _, s in good])
                        for k in sorted(keys)
                    },
                    crs=good[0][1].crs,
                ),
            )
        )
    return out


def read_pairs(path: str | os.PathLike) -> list[tuple[str, str]]:
    """``(test_id, model_id)`` pairs from a CSV with columns ``test_id,model_id``."""
    p = Path(path)
    if not p.is_file():
        raise ReadError(f"input {p} does not exist")
    with p.open("r", encoding="utf-8-sig", newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise ReadError(f"input {p} has no rows")
    header = [h.strip().lower() for h in rows[0]]
    if "test_id" not in header or "model_id" not in header:
        raise ReadError(f"input {p} lacks columns test_id,model_id; has: {', '.join(header)}")
    a, b = header.index("test_id"), header.index("model_id")
    out = []
    for k, r in enumerate(rows[1:], start=2):
        if len(r) <= max(a, b):
            raise ReadError(f"input {p} line {k}: too few values")
        out.append((r[a].strip(), r[b].strip()))
    return out
