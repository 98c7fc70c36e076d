"""One engine entry point: a per-region task over a source, and a merge (lidR's ``catalog_apply``).

:func:`apply` is what every area job runs::

    run = apply(source, task, merge, chunk_size=None, buffer=None, workers=2)

* `source` is a :class:`~lidarqa.tiling.source.Source` (or anything
  :func:`~lidarqa.tiling.source.open_source` opens): its CRS, units and selection
  are applied while each region is read;
* `task` is a picklable callable ``task(chunk_data) -> part`` (the per-region half
  of a kernel); it may declare the margin it needs with a method
  ``buffer(source) -> float`` (m), used when no `buffer` is given;
* `merge` turns the parts (in chunk order, None for a failed chunk) into the
  result (the summary half of the kernel).

A single file (not a catalog) with no chunk option is **one region**: the whole
area in one chunk, read once, so a file run and a catalog run are the same code.
Chunking, retries, progress and Dask (``workers``, ``scheduler`` or an
:class:`~lidarqa.tiling.Engine`) are handled here for every job. Ownership of
per-point or per-feature results on chunk borders is the chunk's own rule
(:meth:`Chunk.core_mask`, used through :func:`owned`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

__all__ = ["apply", "engine_for", "owned", "region_chunks"]


def owned(xy: Any, chunk: Any) -> np.ndarray:
    """Mask of the points `xy` (N, 2+) whose owner is `chunk` (its half-open core rule).

    Every point of the plane is owned by exactly one chunk of a grid, whatever
    floating point rounding does at cell borders: per-point results, reference
    points and feature anchors are kept by their owner only.
    """
    from .jobs_vector import owned as _owned

    return _owned(xy, chunk)


@contextlib.contextmanager
def engine_for(engine: Any = None, *, workers: int | None = None,
               scheduler: str | None = None) -> Iterator[Any]:
    """The engine to run on: `engine` as is, else serial (``workers=1`` or nothing given)
    or a Dask LocalCluster / scheduler address, started and closed around the block."""
    from .engine import Engine

    if engine is not None:
        yield engine
        return
    if scheduler is None and (workers is None or workers == 1):
        eng = Engine("serial")
    else:
        eng = Engine(scheduler, workers=workers)
    with eng:
        yield eng


def region_chunks(source: Any, task: Any = None, *, chunk_size: float | None = None,
                  buffer: float | None = None, origin: tuple[float, float] = (0.0, 0.0),
                  one_region: bool | None = None) -> list[Any]:
    """The regions a job reads: one whole-area chunk for a single file, else the chunk grid.

    Parameters
    ----------
    source : Source
    task : optional
        Asked for its margin (``task.buffer(source)``) when `buffer` is None.
    chunk_size, buffer, origin
        As :func:`~lidarqa.tiling.make_chunks`.
    one_region : bool, optional
        Force one region (True) or the chunk grid (False); default: one region for
        a single file without `chunk_size` and `buffer`.
    """
    if one_region is None:
        one_region = not source.is_catalog and chunk_size is None and buffer is None
    if one_region:
        return [source.whole_chunk()]
    if buffer is None and task is not None and hasattr(task, "buffer"):
        buffer = float(task.buffer(source))
    return source.chunks(chunk_size=chunk_size, buffer=buffer, origin=origin)


def apply(
    source: Any,
    task: Callable[[Any], Any],
    merge: Callable[[list[Any]], Any] | None = None,
    *,
    chunks: Sequence[Any] | None = None,
    chunk_size: float | None = None,
    buffer: float | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    one_region: bool | None = None,
    engine: Any = None,
    workers: int | None = None,
    scheduler: str | None = None,
    retries: int = 2,
    skip_failed: bool = False,
    progress: bool = False,
    description: str = "Chunks",
    order_seed: int | None = None,
    extra: dict[str, Any] | None = None,
) -> Any:
    """Run `task` on every region of `source` and `merge` the parts.

    Parameters
    ----------
    source : Source, Catalog, path, folder, glob, .vpc or list of those
    task : callable
        ``task(chunk_data) -> part``; pure and picklable.
    merge : callable, optional
        ``merge(parts) -> value`` (parts in chunk order, None for failed chunks);
        default: the list of parts.
    chunks : sequence of Chunk, optional
        The regions (default :func:`region_chunks`).
    chunk_size, buffer, origin, one_region
        See :func:`region_chunks`.
    engine, workers, scheduler
        Where to run (see :func:`engine_for`); default serial.
    retries, skip_failed, progress, description, order_seed
        As :func:`~lidarqa.tiling.run_chunks`.
    extra : dict, optional
        Stored on the returned run.

    Returns
    -------
    CatalogRun
        ``value`` (the merged result), the source, the chunks and their outcomes.
    """
    from .engine import run_chunks
    from .jobs_api import CatalogRun, open_sources

    source = open_sources(source)
    if chunks is None:
        chunks = region_chunks(source, task, chunk_size=chunk_size, buffer=buffer,
                               origin=origin, one_region=one_region)
    chunks = list(chunks)
    outcomes: list[Any] = []
    if chunks:
        with engine_for(engine, workers=workers, scheduler=scheduler) as eng:
            outcomes = run_chunks(source, chunks, task, engine=eng, progress=progress,
                                  retries=retries, skip_failed=skip_failed,
                                  description=description, order_seed=order_seed)
    parts = [o.result if o.ok else None for o in outcomes]
    value = merge(parts) if merge is not None else parts
    return CatalogRun(value, source, tuple(chunks), tuple(outcomes), dict(extra or {}))
