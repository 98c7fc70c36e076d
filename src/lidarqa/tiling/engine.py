"""Running a task on every chunk: serially, on a local Dask cluster or on any Dask cluster.

:class:`Engine` owns the compute resources; :func:`run_chunks` reads each chunk on a
worker, runs a pure task on it and gives back one :class:`ChunkOutcome` per chunk,
**in chunk order** whatever the order in which chunks completed, so that everything
assembled from the outcomes is the same for 1, 2 or N workers.

Modes (``Engine(scheduler=...)``):

- ``None`` (default): a ``dask.distributed.LocalCluster``: ``workers`` processes
  (default: one per CPU core), one thread each, each with a memory limit
  (``memory_limit``, default: the machine's memory divided among the workers). Of
  two or more workers, this process is one: it starts on the first chunk while the
  others start (it has imported everything and holds the tiles it sampled).
- ``"serial"``: no Dask, every chunk in this process, one after the other (debugging,
  small jobs, or when Dask is not installed).
- ``"tcp://host:port"``: connect to a running scheduler (``dask scheduler`` +
  ``dask worker``, or any Dask deployment). The workers must be able to read the
  tiles at the same paths.

A chunk that raises is retried ``retries`` times (a worker lost mid-chunk counts as
one failure); when it still fails its outcome says so, with the error, and the other
chunks are not affected. ``skip_failed=False`` (the default) then raises a
:class:`ChunkFailedError` naming the failed chunks once every chunk has finished.

A task travels to a Dask worker pickled, and the worker loads it as the first step of
running it: a worker that cannot load it (its code is not importable there) fails the
job at once with a :class:`TilingError` naming the item. (Dask itself would load the
task while reading the scheduler's message: the worker then loses its connection and
the task is neither run nor failed, so the job waits forever.)
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, Generic, TypeVar, cast

from ..errors import ChunkFailedError, MissingDependencyError, OptionError, TilingError

if TYPE_CHECKING:
    from ._types import Tiles
    from .catalog import Catalog, TileInfo
    from .chunks import Chunk
    from .reader import ChunkData

#: What a task returns for one chunk (or tile).
R = TypeVar("R")
R_co = TypeVar("R_co", covariant=True)
#: A unit of work: a :class:`~lidarqa.tiling.Chunk` or a :class:`TileRef`.
C = TypeVar("C", bound="Chunk | TileRef")
C_co = TypeVar("C_co", bound="Chunk | TileRef", covariant=True)

__all__ = [
    "Engine",
    "ChunkOutcome",
    "ChunkFailedError",
    "TileRef",
    "run_chunks",
    "run_task",
    "run_tasks",
    "run_tile_task",
    "run_tiles",
]


@dataclass(frozen=True)
class ChunkOutcome(Generic[C_co, R_co]):
    """What became of one chunk (or tile: `chunk` is then a :class:`TileRef`)."""

    chunk: C_co
    ok: bool
    result: R_co | None = None
    error: str | None = None
    attempts: int = 1
    skipped: bool = False
    resumed: bool = False

    def to_dict(self) -> dict[str, object]:
        """The outcome as a JSON-ready dict (chunk id, status, timing, error; not the result)."""
        return {
            "chunk": self.chunk.id,
            "ok": self.ok,
            "error": self.error,
            "attempts": self.attempts,
            "skipped": self.skipped,
        }


# RAYON_NUM_THREADS: the LAZ codec (lazrs) decompresses with one thread per core too
_THREAD_VARS = (
    "NUMBA_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "RAYON_NUM_THREADS",
)


def _dask():
    try:
        import dask  # noqa: F401
        import distributed
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingDependencyError(
            "parallel runs need Dask: pip install 'lidarqa[dask]' (or use --workers 1 / serial)"
        ) from exc
    return distributed


class Engine:
    """Where chunks run. Use as a context manager (``with Engine() as eng: ...``).

    Parameters
    ----------
    scheduler : None, "serial" or str
        None: a LocalCluster; "serial": in this process; else a scheduler address.
    workers : int, optional
        LocalCluster workers (default: the number of CPU cores). ``workers=1``
        still uses one worker process unless `scheduler` is "serial".
    memory_limit : str or int, optional
        Per-worker memory limit of the LocalCluster (bytes or e.g. "2GB"); default
        the machine's memory divided by the workers.
    """

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        memory_limit: str | int | None = None,
    ) -> None:
        if workers is not None and int(workers) < 1:
            raise OptionError(f"workers must be >= 1, got {workers}")
        self.scheduler = scheduler
        self.workers = None if workers is None else int(workers)
        self.memory_limit = memory_limit
        self.client: Any = None
        self.cluster: Any = None
        self._starting = threading.Lock()
        self._starter: threading.Thread | None = None
        self._start_error: BaseException | None = None

    @property
    def serial(self) -> bool:
        """True when chunks run one after the other in this process."""
        return self.scheduler == "serial"

    @property
    def head_works(self) -> bool:
        """True when this process is one of the workers (a LocalCluster of two or more).

        Of N workers, N - 1 are processes of the LocalCluster and this process is the
        N-th: it runs items as soon as a job starts, while the others import and load
        their kernels. With ``workers=1`` the one worker is a process of its own.
        """
        return self.scheduler is None and self._n_local() >= 2

    def _n_local(self) -> int:
        return self.workers or (os.cpu_count() or 1)

    @property
    def n_workers(self) -> int:
        """How many items run at once (1 when serial; this process counts when it works)."""
        if self.serial:
            return 1
        if self.client is not None:
            try:
                n = len(self.client.scheduler_info().get("workers", {}))
            except Exception:
                n = 1
            return max(n + int(self.head_works), 1)
        return self._n_local()

    @property
    def dashboard_link(self) -> str | None:
        """The dask dashboard's address, or None (serial, not started, no dashboard)."""
        if self.client is None:
            return None
        try:
            link = self.client.dashboard_link
        except Exception:
            return None
        return link or None

    def start_soon(self) -> None:
        """Start the LocalCluster in a thread, while this process goes on (when the head works).

        For the serial work a job does before its chunks (reading a sample, choosing the
        parameters): the worker processes import and start on the core this process
        leaves idle. :meth:`start` waits for it; an error is raised there.
        """
        if not self.head_works or self.client is not None or self._starter is not None:
            return

        def start() -> None:
            try:
                self.start()
            except BaseException as exc:
                self._start_error = exc

        self._starter = threading.Thread(target=start, name="lidarqa-cluster-start", daemon=True)
        self._starter.start()

    def start(self) -> Engine:
        """Start the dask cluster (nothing to do when serial or already started); returns self."""
        starter = self._starter
        if starter is not None and starter is not threading.current_thread():
            starter.join()
            self._starter = None
            if self._start_error is not None:
                error, self._start_error = self._start_error, None
                raise error
        with self._starting:
            return self._start()

    def _start(self) -> Engine:
        if self.serial or self.client is not None:
            return self
        distributed = _dask()
        if self.scheduler:
            try:
                self.client = distributed.Client(self.scheduler, timeout="20s")
            except Exception as exc:
                raise TilingError(
                    f"cannot connect to the Dask scheduler {self.scheduler}: {exc}"
                ) from exc
            self._check_workers()
            return self
        import dask

        n = self._n_local() - 1 if self.head_works else self._n_local()
        with dask.config.set({
            "distributed.worker.daemon": False,
            # glibc's own allocation thresholds in the workers, as in a serial run. Dask's
            # default MALLOC_TRIM_THRESHOLD_=65536 pins glibc's mmap threshold at 128 KiB,
            # so every array a chunk allocates is mapped, unmapped and its pages faulted in
            # again for the next: 4x the page faults and 16 % more CPU for the ground filter
            # (measured on 2 M points), more again with two workers sharing memory bandwidth
            "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": os.environ.get(
                "MALLOC_TRIM_THRESHOLD_"),  # the CLI's (lidarqa._malloc), else glibc's
            # the dashboard's statistical profiler samples each worker's task thread every
            # 10 ms (it takes the GIL to walk the stack); nobody reads it behind the CLI
            "distributed.worker.profile.enabled": False,
        }):
            self.cluster = distributed.LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                memory_limit=self.memory_limit if self.memory_limit is not None else "auto",
                dashboard_address=":0",
                host="127.0.0.1",
                silence_logs=40,
                # one single-threaded worker per core: compiled kernels must not start
                # one thread per core in every worker
                env={k: "1" for k in _THREAD_VARS},
            )
        self.client = distributed.Client(self.cluster)
        return self

    def _check_workers(self) -> None:
        """The workers of a ``--scheduler`` cluster run this version of lidarqa.

        A worker that cannot import lidarqa cannot load any task (the job would wait
        forever: see the module docstring), and another version may give other results.
        Workers that join later are not checked.
        """
        from .. import __version__

        assert self.client is not None
        try:  # a lambda travels by value: it loads where lidarqa does not
            got = self.client.run(lambda: __import__("lidarqa").__version__)
        except Exception as exc:
            self.close()
            raise TilingError(
                f"the Dask workers of {self.scheduler} cannot import lidarqa "
                f"({_error_text(exc)}): install lidarqa {__version__} where they run"
            ) from None
        other = sorted({str(v) for v in got.values()} - {__version__})
        if other:
            self.close()
            raise TilingError(
                f"the Dask workers of {self.scheduler} run lidarqa {', '.join(other)} and this "
                f"process {__version__}: install the same version where they run"
            )

    def close(self) -> None:
        """Shut the dask client and cluster down (when this engine started them)."""
        if self._starter is not None:
            self._starter.join()
            self._starter = None
        if self.client is not None:
            try:
                self.client.close()
            except Exception:
                pass
        if self.cluster is not None:
            try:
                self.cluster.close()
            except Exception:
                pass
        self.client = None
        self.cluster = None

    def __enter__(self) -> Engine:
        # a scheduler address is connected to at once (a bad address fails before any
        # work); a LocalCluster starts when a job first has two or more items to run
        return self.start() if self.scheduler not in (None, "serial") else self

    def runs_here(self, n_items: int) -> bool:
        """True when `n_items` run in this process rather than on Dask workers.

        Serial engines always; a LocalCluster not yet started for one item (starting
        worker processes costs seconds, one item gains nothing from them). The results
        are the same either way.
        """
        return self.serial or (
            n_items <= 1 and self.scheduler is None and self.client is None
        )

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_task(catalog: Tiles, chunk: Chunk, task: Callable[[ChunkData], R]) -> R:
    """Read `chunk` and run `task` on it (what a worker does for one chunk).

    `catalog` is a :class:`~lidarqa.tiling.Catalog` (every point) or a
    :class:`~lidarqa.tiling.source.Source` (its selection and units applied at read time).
    """
    from .reader import read_chunk, worker_tile_cache

    reader = getattr(catalog, "read_chunk", None)
    if reader is None:  # a Catalog
        reader = partial(read_chunk, cast("Catalog", catalog))
    fields = getattr(task, "tile_fields", None)
    if fields is None:
        return task(reader(chunk))
    # a task that reads a few dimensions: the worker keeps its tiles decompressed
    # across chunks (a serial run's own cache, if one is active, is used instead), and
    # shares them with the other processes of its machine when the task names a folder
    with worker_tile_cache(fields, spill=getattr(task, "tile_spill", None)):
        data = reader(chunk)
    return task(data)


@dataclass(frozen=True)
class TileRef:
    """One tile of a catalog as a unit of work for :func:`run_tiles` (a chunk-like item).

    Attributes
    ----------
    id : str
        The tile's file name (unique in a catalog: its paths are).
    index : int
        Index into ``catalog.tiles``.
    tiles : tuple of int
        ``(index,)``, so that the engine's size estimate works as for chunks.
    buffered : tuple of 4 floats
        The tile's header bounds ``(xmin, ymin, xmax, ymax)``.
    """

    id: str
    index: int
    tiles: tuple[int, ...]
    buffered: tuple[float, ...]


def run_tile_task(catalog: Tiles, ref: TileRef, task: Callable[[TileInfo], R]) -> R:
    """Run ``task(tile_info)`` on one tile (what a worker does for one tile)."""
    return task(catalog.tiles[ref.index])


class _NotLoaded(TilingError):
    """A Dask worker could not load a task (raised there; fatal to the job here)."""


def _pickled(*parts: object) -> bytes:
    """``(func, *tail)`` as a worker loads them in :func:`_loaded` (cloudpickle, as Dask)."""
    import cloudpickle

    return cast(bytes, cloudpickle.dumps(parts))


def _loaded(blob: bytes, *args: Any) -> Any:
    """What a Dask worker runs: ``func(*args, *tail)`` of the pickled ``(func, *tail)``."""
    import pickle

    try:
        func, *tail = pickle.loads(blob)
    except Exception as exc:
        raise _NotLoaded(
            f"a Dask worker cannot load the task ({_error_text(exc)}): its code must be "
            "importable on every worker"
        ) from None
    return func(*args, *tail)


def _error_text(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}: {text}"[:300] if text else type(exc).__name__


class _Progress:
    def __init__(self, total: int, enabled: bool, description: str, link: str | None) -> None:
        self.enabled = enabled and total > 0
        self._p = None
        if not self.enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TaskProgressColumn,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        console = Console(stderr=True)
        if link:
            console.print(f"Dask dashboard: {link}")
        self._p = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TaskProgressColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
        )
        self._p.start()
        self._task = self._p.add_task(description, total=total)

    def link(self, link: str | None) -> None:
        """Show the Dask dashboard's address once the cluster is up."""
        if self._p is not None and link:
            self._p.console.print(f"Dask dashboard: {link}")

    def advance(self) -> None:
        if self._p is not None:
            self._p.advance(self._task)

    def close(self) -> None:
        if self._p is not None:
            self._p.stop()
            self._p = None


def run_chunks(
    catalog: Tiles,
    chunks: Sequence[C],
    task: Callable[..., R],
    *,
    engine: Engine | None = None,
    progress: bool = True,
    retries: int = 2,
    skip_failed: bool = False,
    on_outcome: Callable[[ChunkOutcome[C, R]], object] | None = None,
    keep_results: bool = True,
    description: str = "Chunks",
    order_seed: int | None = None,
    runner: Callable[..., R] = run_task,
    idle: Callable[[], bool] | None = None,
) -> list[ChunkOutcome[C, R]]:
    """Run ``task(read_chunk(catalog, chunk))`` on every chunk.

    Parameters
    ----------
    catalog : Catalog
    chunks : sequence of Chunk
    task : callable
        Pure and picklable: ``task(chunk_data) -> result`` (picklable); it must not
        write files (the caller persists results, e.g. in `on_outcome`).
    engine : Engine, optional
        Default: a serial engine (in this process).
    progress : bool, default True
        A progress bar over chunks (%, ETA) on stderr, with the Dask dashboard link.
    retries : int, default 2
        Extra attempts for a chunk that raised.
    skip_failed : bool, default False
        Return failed outcomes instead of raising :class:`ChunkFailedError`.
    on_outcome : callable, optional
        Called in this process with each outcome as soon as its chunk is done (in
        completion order), e.g. to save per-chunk results for ``--resume``.
    keep_results : bool, default True
        Keep results in the returned outcomes (False: ``result=None``, saves memory
        when `on_outcome` persisted them).
    order_seed : int, optional
        Submit the chunks in a shuffled order (seeded); tests use it to check that
        results do not depend on the completion order.
    runner : callable, default :func:`run_task`
        What a worker runs for one item: ``runner(catalog, item, task)``.
        :func:`run_tiles` passes :func:`run_tile_task` (whole tiles, no chunk read).
    idle : callable, optional
        What this process does, when it runs chunks beside the workers, while it has
        no chunk left to take and the workers still run theirs: ``idle()`` does one
        piece of other work and returns True, or returns False when it has none (it is
        asked again when a chunk ends). The ground job writes the tiles whose chunks
        are done.

    Returns
    -------
    list of ChunkOutcome
        In the order of `chunks`.
    """
    if retries < 0:
        raise OptionError(f"retries must be >= 0, got {retries}")
    chunks = list(chunks)
    ids = [c.id for c in chunks]
    if len(set(ids)) != len(ids):
        raise TilingError("chunk ids must be unique")
    order = list(range(len(chunks)))
    if order_seed is not None:
        import random

        random.Random(order_seed).shuffle(order)
    elif engine is not None and not engine.serial:
        # biggest chunks first (their estimated point count; ties in chunk order): the
        # small ones at the block's edges then fill the workers' last gaps instead of one
        # big chunk running alone at the end. Results never depend on the order.
        from .chunks import estimated_points

        size = [estimated_points(catalog, c) for c in chunks]
        order.sort(key=lambda i: -size[i])
    own = engine is None
    engine = engine or Engine("serial")
    outcomes: dict[int, ChunkOutcome] = {}
    attempts: dict[int, int] = {}

    def settle(i: int, ok: bool, value: Any) -> bool:
        attempts[i] = attempts.get(i, 0) + 1
        if not ok and attempts[i] <= retries:
            return True
        oc = (
            ChunkOutcome(chunks[i], True, value, None, attempts[i])
            if ok
            else ChunkOutcome(chunks[i], False, None, _error_text(value), attempts[i])
        )
        if on_outcome is not None:
            on_outcome(oc)
        if not keep_results and oc.result is not None:
            oc = ChunkOutcome(oc.chunk, oc.ok, None, oc.error, oc.attempts, oc.skipped)
        outcomes[i] = oc
        return False

    token = f"{os.getpid()}-{time.monotonic_ns()}"
    sent: list[Any] = []  # the catalog (sent to every worker once) and the pickled task

    def submit(i: int) -> Any:
        if not sent:
            sent.append(engine.client.scatter(catalog, broadcast=True, hash=False))
            sent.append(_pickled(runner, task))
        return engine.client.submit(
            _loaded,
            sent[1],
            sent[0],
            chunks[i],
            key=f"lidarqa-chunk-{chunks[i].id}-{token}-{attempts.get(i, 0) + 1}",
            pure=False,
        )

    try:
        _drive(engine, order, lambda i: runner(catalog, chunks[i], task), submit, settle,
               progress=progress, description=description, name=lambda i: chunks[i].id,
               idle=idle)
        if engine.client is not None and getattr(task, "tile_fields", None) is not None:
            _free_worker_caches(engine.client)
    finally:
        if own:
            engine.close()
    result = [outcomes[i] for i in range(len(chunks))]
    failed = [o for o in result if not o.ok]
    if failed and len(result) == 1 and not skip_failed:  # one region (one file): its own error
        raise ChunkFailedError(str(failed[0].error).split(": ", 1)[-1], result)
    if failed and not skip_failed:
        raise ChunkFailedError(
            f"{len(failed)} of {len(result)} chunk(s) failed: "
            + "; ".join(f"{o.chunk.id}: {o.error}" for o in failed[:5])
            + (" ..." if len(failed) > 5 else ""),
            result,
        )
    return result


def _attempt(call: Callable[[int], Any], i: int) -> tuple[bool, Any]:
    try:
        return True, call(i)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:
        return False, exc


def _landed(fut: Any) -> tuple[bool, Any]:
    """A finished Dask future as ``(ok, result or exception)``."""
    if fut.status == "finished":
        try:
            return True, fut.result()
        except Exception as exc:  # lost while fetching
            return False, exc
    error = fut.exception() if fut.status == "error" else None
    return False, error if error is not None else TilingError(f"the task was {fut.status}")


def _drive(
    engine: Engine,
    order: Sequence[int],
    call: Callable[[int], Any],
    submit: Callable[[int], Any],
    settle: Callable[[int, bool, Any], bool],
    *,
    progress: bool,
    description: str,
    name: Callable[[int], str],
    idle: Callable[[], bool] | None = None,
) -> None:
    """Run every item of `order`: here, on the Dask workers, or both (the head works).

    ``call(i)`` runs item i in this process; ``submit(i)`` sends it to the cluster and
    returns its future; ``settle(i, ok, result_or_exception)`` records an attempt and
    returns True when the item must run again (a retry). Items are taken in `order`.
    A worker that cannot load an item's task fails the job, naming it by ``name(i)``.

    When this process is one of the workers (:attr:`Engine.head_works`) the cluster
    starts in a thread while this process already runs the first items, and each
    worker process holds at most two items at a time (one when fewer remain): the
    rest stay here, where whoever is free takes the next. While none is left here and
    the workers still run theirs, this process calls ``idle()`` (see :func:`run_chunks`).
    """
    from collections import deque

    pending = deque(order)
    remaining = set(order)
    bar = _Progress(len(remaining), progress, description, engine.dashboard_link)
    cond = threading.Condition(threading.RLock())
    flying: dict[Any, int] = {}
    failed: list[BaseException] = []
    window = 0  # items the worker processes may hold (0 until the cluster is up)
    here = engine.runs_here(len(remaining))
    head = here or engine.head_works

    def settled(i: int, ok: bool, value: Any) -> None:  # under `cond`
        if settle(i, ok, value):
            pending.appendleft(i)
        else:
            remaining.discard(i)
            bar.advance()
        cond.notify_all()

    def room() -> int:
        # a worker process holds a second item (queued behind its first, so that it never
        # waits for this process to hand it one) only while every process can still get
        # two: near the end an item queued on a worker would leave this process idle
        n = window
        return n if not engine.head_works or len(pending) >= n + 2 else n // 2

    def feed() -> None:
        with cond:
            while pending and not failed and len(flying) < room():
                i = pending.popleft()
                fut = submit(i)
                flying[fut] = i
                fut.add_done_callback(landed)  # run in Dask's callback thread

    def landed(fut: Any) -> None:
        try:
            with cond:
                i = flying.pop(fut, None)
                if i is None:  # cancelled
                    return
                ok, value = _landed(fut)
                fut.release()
                if isinstance(value, _NotLoaded):
                    raise TilingError(f"{name(i)}: {value}")
                settled(i, ok, value)
            feed()
        except BaseException as exc:
            with cond:
                failed.append(exc)
                cond.notify_all()

    def start() -> None:
        nonlocal window
        try:
            fresh = engine.client is None
            engine.start()
            if fresh:
                bar.link(engine.dashboard_link)
            with cond:
                window = 2 * (engine._n_local() - 1) if engine.head_works else len(order)
            feed()
        except BaseException as exc:
            with cond:
                failed.append(exc)
                cond.notify_all()

    starter = threading.Thread(target=start, name="lidarqa-cluster-start", daemon=True)
    try:
        if engine.head_works and not here:
            starter.start()  # this process works meanwhile
        elif not here:
            start()
        with _one_thread() if head and not here else contextlib.nullcontext():
            # with nothing here to take, try idle() once per wake-up (a chunk settled)
            try_idle = idle is not None and head
            while True:
                with cond:
                    while not failed and remaining and not (head and pending) and not try_idle:
                        cond.wait(0.5)
                        try_idle = idle is not None and head
                    if failed:
                        raise failed[0]
                    if not remaining:
                        break
                    i = pending.popleft() if head and pending else None
                if i is None:
                    assert idle is not None
                    try_idle = idle()  # False: no other work until the next wake-up
                    continue
                ok, value = _attempt(call, i)
                with cond:
                    settled(i, ok, value)
    except BaseException:
        with cond:
            for fut in list(flying):
                fut.cancel()
            flying.clear()
        raise
    finally:
        if starter.is_alive():
            starter.join()
        bar.close()


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """Compiled kernels run on one thread in this process, as in each worker process."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)



def _free_worker_caches(client: Any) -> None:
    """Free the tiles the workers kept for a job (a cluster may outlive it: ``--scheduler``)."""
    from .reader import clear_worker_tile_cache

    try:
        client.run(clear_worker_tile_cache)
    except Exception:  # a worker gone: its cache went with it
        pass


def run_tiles(
    catalog: Tiles,
    task: Callable[[TileInfo], R],
    *,
    tiles: Sequence[int] | None = None,
    engine: Engine | None = None,
    progress: bool = True,
    retries: int = 1,
    description: str = "Tiles",
    order_seed: int | None = None,
) -> list[ChunkOutcome[TileRef, R]]:
    """Run ``task(tile_info)`` on every tile of `catalog` (a job whose unit is the file).

    For per-file work that streams a tile itself (header checks, per-tile grids): the
    worker gets the :class:`~lidarqa.tiling.TileInfo`, not a chunk of points, so memory
    is what the task keeps while it streams. Failures are isolated as in
    :func:`run_chunks` with ``skip_failed=True``: a tile that raises after its retries
    gets a failed outcome (``ok=False`` and the error) and the others run on.

    Parameters
    ----------
    catalog : Catalog
    task : callable
        Pure and picklable: ``task(tile_info) -> result``.
    tiles : sequence of int, optional
        Indices into ``catalog.tiles`` (default: every tile).
    engine, progress, retries, description, order_seed
        As for :func:`run_chunks`.

    Returns
    -------
    list of ChunkOutcome
        In the order of `tiles`; ``outcome.chunk`` is a :class:`TileRef`.
    """
    idx = range(len(catalog.tiles)) if tiles is None else [int(i) for i in tiles]
    refs = [
        TileRef(
            id=catalog.tiles[i].path,
            index=i,
            tiles=(i,),
            buffered=tuple(float(v) for v in catalog.tiles[i].bounds2d),
        )
        for i in idx
    ]
    return run_chunks(
        catalog,
        refs,
        task,
        engine=engine,
        progress=progress,
        retries=retries,
        skip_failed=True,
        description=description,
        order_seed=order_seed,
        runner=run_tile_task,
    )


def run_tasks(
    func: Callable[..., R],
    items: Sequence[tuple[object, ...]],
    *,
    engine: Engine | None = None,
    progress: bool = False,
    description: str = "Tasks",
    names: Sequence[str] | None = None,
) -> list[R]:
    """Run ``func(*item)`` for every item, on the engine's workers; results in item order.

    For the work that follows the chunks (e.g. writing one output tile per input
    tile): each call must be independent and deterministic, and may read and write
    files that every worker can reach. The first failure cancels the calls not yet
    started and is raised as a :class:`TilingError` naming the item (``names``).
    A worker lost mid-call is handled by Dask (the call runs again elsewhere).
    """
    items = list(items)
    names = list(names) if names is not None else [str(i) for i in range(len(items))]
    own = engine is None
    engine = engine or Engine("serial")
    results: list[Any] = [None] * len(items)
    token = f"{os.getpid()}-{time.monotonic_ns()}"

    def settle(i: int, ok: bool, value: Any) -> bool:
        if not ok:
            if isinstance(value, TilingError):
                raise value
            raise TilingError(f"{names[i]}: {_error_text(value)}") from value
        results[i] = value
        return False

    def submit(i: int) -> Any:
        return engine.client.submit(
            _loaded, _pickled(func, *items[i]), key=f"lidarqa-task-{i}-{token}", pure=False
        )

    try:
        _drive(engine, range(len(items)), lambda i: func(*items[i]), submit, settle,
               progress=progress, description=description, name=names.__getitem__)
    finally:
        if own:
            engine.close()
    return results
