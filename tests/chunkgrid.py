"""A minimal in-memory stand-in for the catalog engine's chunks (tests only).

It follows the chunk contract of ``lidarqa.tiling`` (``Chunk.id/core/buffered``,
``ChunkData.cloud/core/chunk``) so that chunk tasks can be tested on a cloud in
memory without files: a regular grid of half-open cores, each read with its
buffer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lidarqa.io import PointCloud


@dataclass(frozen=True)
class FakeChunk:
    id: str
    row: int
    col: int
    core: tuple[float, float, float, float]
    buffered: tuple[float, float, float, float]


@dataclass(frozen=True, eq=False)
class FakeChunkData:
    cloud: PointCloud
    core: np.ndarray
    chunk: FakeChunk


def _inside(xy, box):
    x0, y0, x1, y1 = box
    return (xy[:, 0] >= x0) & (xy[:, 0] < x1) & (xy[:, 1] >= y0) & (xy[:, 1] < y1)


def grid_chunks(cloud: PointCloud, size: float, buffer: float, origin=(0.0, 0.0)):
    """Every chunk of a `size` grid aligned on `origin` over the cloud, in row-major order."""
    xy = cloud.xyz[:, :2]
    o = np.asarray(origin, dtype=float)
    lo = np.floor((xy.min(0) - o) / size).astype(int)
    hi = np.floor((xy.max(0) - o) / size).astype(int)
    out = []
    for r in range(lo[1], hi[1] + 1):
        for c in range(lo[0], hi[0] + 1):
            x0, y0 = o[0] + c * size, o[1] + r * size
            core = (x0, y0, x0 + size, y0 + size)
            buf = (x0 - buffer, y0 - buffer, x0 + size + buffer, y0 + size + buffer)
            out.append(FakeChunk(f"c{c:04d}_r{r:04d}", r, c, core, buf))
    return out


def read_fake(cloud: PointCloud, chunk: FakeChunk) -> FakeChunkData:
    sel = np.flatnonzero(_inside(cloud.xyz, chunk.buffered))
    sub = cloud.subset(sel)
    return FakeChunkData(sub, _inside(sub.xyz, chunk.core), chunk)


def run_fake(cloud: PointCloud, chunks, task):
    """Serial run of `task` over the chunks (outcome order = chunk order)."""
    return [task(read_fake(cloud, c)) for c in chunks]
