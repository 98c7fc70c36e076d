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
Chunking, retries, progress, Dask (``workers``, ``scheduler`` or an
:class:`~lidarqa.tiling.Engine`) and resuming (``work_dir`` + ``resume``, see
:class:`ChunkStore`) are handled here for every job. Ownership of
per-point or per-feature results on chunk borders is the chunk's own rule
(:meth:`Chunk.core_mask`, used through :func:`~lidarqa.tiling.jobs_vector.owned`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, TypeVar, cast

import numpy as np

if TYPE_CHECKING:
    from ._types import CRSInput, IntsInput, PathInput, PathsInput, Tiles
    from .catalog import Catalog
    from .chunks import Chunk
    from .engine import ChunkOutcome, Engine
    from .reader import ChunkData
    from .source import Source

#: A chunk task's result (a part).
R = TypeVar("R")
#: A run's merged value.
V = TypeVar("V")
V_co = TypeVar("V_co", covariant=True)

__all__ = ["CatalogRun", "ChunkStore", "apply", "chunk_status", "default_work_dir", "engine_for",
           "open_sources", "region_chunks"]


@dataclass(frozen=True, eq=False)
class CatalogRun(Generic[V_co]):
    """A merged catalog job: its ``value`` and how every chunk went.

    Attributes
    ----------
    value : object
        The merged result (Segments/PointSet, VerticalCheckReport, HeightReport,
        list of repeatability rows).
    catalog : Catalog
    chunks : tuple of Chunk
        The chunks that were run.
    outcomes : tuple of ChunkOutcome
        In chunk order.
    extra : dict
        Job-specific details (e.g. the strips' edge sets, the fixed parameters).
    """

    value: V_co
    catalog: Tiles
    chunks: tuple[Chunk, ...]
    outcomes: tuple[ChunkOutcome[Chunk, object], ...]
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def failed(self) -> list[str]:
        """Ids of the chunks that failed after their retries."""
        return [o.chunk.id for o in self.outcomes if not o.ok and not getattr(o, "skipped", False)]

    @property
    def resumed(self) -> list[str]:
        """Ids of the chunks whose parts were re-used from an interrupted run."""
        return [o.chunk.id for o in self.outcomes if getattr(o, "resumed", False)]

    def chunk_status(self) -> list[dict[str, object]]:
        """``[{"chunk", "status", "attempts", "error"}]``; ok, retried, failed, skipped, resumed."""
        return [chunk_status(o) for o in self.outcomes]

    def to_dict(self) -> dict[str, object]:
        """The run as a JSON-ready dict: value, chunk counts by status and each chunk's status."""
        st = self.chunk_status()
        counts = {k: sum(1 for s in st if s["status"] == k)
                  for k in ("ok", "retried", "failed", "skipped", "resumed")}
        if not counts["resumed"]:  # only a resumed run has the key
            del counts["resumed"]
        return {"n_tiles": len(self.catalog.tiles), "n_chunks": len(self.chunks),
                "chunk_status": counts, "failed_chunks": self.failed}


def chunk_status(outcome: ChunkOutcome[Chunk, object]) -> dict[str, object]:
    """One outcome's status: ok, retried (ok after > 1 attempt), failed, skipped or resumed."""
    attempts = int(getattr(outcome, "attempts", 1) or 1)
    if getattr(outcome, "resumed", False):
        status = "resumed"
    elif getattr(outcome, "skipped", False):
        status = "skipped"
    elif outcome.ok:
        status = "retried" if attempts > 1 else "ok"
    else:
        status = "failed"
    return {"chunk": outcome.chunk.id, "status": status, "attempts": attempts,
            "error": outcome.error}


def default_work_dir() -> Path:
    """Where catalog commands keep finished chunks' parts (for ``--resume``).

    ``$LIDARQA_WORK_DIR``, else ``lidarqa/chunks`` in the user cache folder
    (``$XDG_CACHE_HOME`` or ``~/.cache``).
    """
    env = os.environ.get("LIDARQA_WORK_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lidarqa" / "chunks"


def _digest(obj: Any) -> str:
    return hashlib.sha256(pickle.dumps(obj, protocol=4)).hexdigest()


def _fingerprint(source: Any) -> tuple[Any, ...]:
    """What a source's parts depend on: its files (path, size, time), selection and units."""
    if source.catalog is None:
        xyz = np.ascontiguousarray(source.cloud.xyz)
        data: Any = hashlib.sha256(xyz.tobytes()).hexdigest()
    else:
        data = []
        for t in source.catalog.tiles:
            try:
                st = os.stat(t.path)
                data.append((str(t.path), st.st_size, st.st_mtime_ns))
            except OSError:
                data.append((str(t.path), -1, -1))
    return (data, source.selection.to_dict(), source.z_factor, source.xy_factor,
            str(source.native_crs))


class ChunkStore:
    """The finished chunks' parts of one job, kept in a folder so an interrupted run re-uses them.

    Every part is a pickle named by the job (the source's files, selection and
    units, and the task with all its options) and the chunk, so a part is only
    ever re-used by the very same job on the very same chunk; a changed file, option
    or chunk grid recomputes. Parts are written atomically as each chunk finishes
    and removed when the job has no failed chunk.

    Parameters
    ----------
    folder : path-like
        Created when the first part is saved.
    source : Source
    task : picklable
    """

    def __init__(self, folder: PathInput, source: Source, task: object) -> None:
        self.folder = Path(folder)
        self.job = _digest((_fingerprint(source), task))[:24]

    def path(self, chunk: Chunk) -> Path:
        """The file of `chunk`'s part."""
        return self.folder / f"{self.job}-{_digest(chunk)[:16]}.pkl"

    def load(self, chunk: Chunk) -> tuple[bool, object]:
        """``(True, part)`` when `chunk`'s part is kept (and readable), else ``(False, None)``."""
        try:
            with open(self.path(chunk), "rb") as fh:
                return True, pickle.load(fh)
        except Exception:  # missing, truncated or unreadable: compute the chunk again
            return False, None

    def save(self, outcome: ChunkOutcome[Chunk, object]) -> None:
        """Keep a finished chunk's part (atomic: a complete file or none)."""
        if not outcome.ok:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.path(outcome.chunk)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(outcome.result, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)

    def clear(self, chunks: Sequence[Chunk]) -> None:
        """Remove the parts of `chunks`."""
        for c in chunks:
            self.path(c).unlink(missing_ok=True)


def open_sources(sources: PathsInput | Catalog | Source, *, skip_bad: bool = False,
                 crs: CRSInput = None, classes: IntsInput = None, source_id: IntsInput = None,
                 z_to_metres: bool = True) -> Source:
    """A :class:`~lidarqa.tiling.source.Source` (see :func:`~lidarqa.tiling.source.open_source`).

    A Source given keeps its CRS and units and takes the selection given here when
    one is given.
    """
    from .source import Source, open_source

    if isinstance(sources, Source):
        if classes is None and source_id is None:
            return sources
        return sources.select(classes=classes, source_id=source_id)
    return open_source(sources, skip_bad=skip_bad, crs=crs, classes=classes,
                       source_id=source_id, z_to_metres=z_to_metres)


@contextlib.contextmanager
def engine_for(engine: Engine | None = None, *, workers: int | None = None,
               scheduler: str | None = None) -> Iterator[Engine]:
    """The engine to run on, started and closed around the block.

    `engine` as is; else serial (``workers=1`` or nothing given) or a Dask LocalCluster or
    scheduler address.
    """
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


def region_chunks(source: Source, task: object = None, *, chunk_size: float | None = None,
                  buffer: float | None = None, origin: tuple[float, float] = (0.0, 0.0),
                  one_region: bool | None = None) -> list[Chunk]:
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
    source: PathsInput | Catalog | Source,
    task: Callable[[ChunkData], R],
    merge: Callable[[list[R | None]], V] | None = None,
    *,
    chunks: Sequence[Chunk] | None = None,
    chunk_size: float | None = None,
    buffer: float | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    one_region: bool | None = None,
    engine: Engine | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    retries: int = 2,
    skip_failed: bool = False,
    progress: bool = False,
    description: str = "Chunks",
    order_seed: int | None = None,
    extra: dict[str, object] | None = None,
    work_dir: PathInput | None = None,
    resume: bool = False,
) -> CatalogRun[V]:
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
    work_dir : path-like, optional
        Keep every finished chunk's part there (a :class:`ChunkStore`) until the
        job ends with no failed chunk, so that an interrupted or failed run can be
        resumed.
    resume : bool, default False
        Re-use the parts kept in `work_dir` by an earlier run of the same job
        instead of computing those chunks again (their status is ``resumed``).

    Returns
    -------
    CatalogRun
        ``value`` (the merged result), the source, the chunks and their outcomes.
    """
    from .engine import ChunkOutcome, run_chunks

    source = open_sources(source)
    if chunks is None:
        chunks = region_chunks(source, task, chunk_size=chunk_size, buffer=buffer,
                               origin=origin, one_region=one_region)
    chunks = list(chunks)
    store = ChunkStore(work_dir, source, task) if work_dir is not None else None
    done: dict[int, Any] = {}
    if store is not None and resume:
        for i, c in enumerate(chunks):
            found, part = store.load(c)
            if found:
                done[i] = ChunkOutcome(c, True, part, None, 0)
    todo = [c for i, c in enumerate(chunks) if i not in done]
    ran: list[Any] = []
    if todo:
        with engine_for(engine, workers=workers, scheduler=scheduler) as eng:
            ran = run_chunks(source, todo, task, engine=eng, progress=progress,
                             retries=retries, skip_failed=skip_failed,
                             description=description, order_seed=order_seed,
                             on_outcome=store.save if store is not None else None)
    it = iter(ran)
    outcomes = [replace(done[i], resumed=True) if i in done else next(it)
                for i in range(len(chunks))]
    if store is not None and all(o.ok for o in outcomes):
        store.clear(chunks)
    parts = [o.result if o.ok else None for o in outcomes]
    # without `merge` the value is the list of parts (V is then list[R | None])
    value = merge(parts) if merge is not None else cast("V", parts)
    return CatalogRun(value, source, tuple(chunks), tuple(outcomes), dict(extra or {}))
