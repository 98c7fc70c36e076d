"""Of N local workers, this process is one: N - 1 worker processes, and the head works too."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import time

import pytest

from lidarqa.errors import TilingError
from lidarqa.testing.tasks import fails_at, pid_after
from lidarqa.tiling import open_catalog
from lidarqa.tiling.engine import Engine, run_tasks, run_tiles

pytest.importorskip("distributed")


def test_two_workers_are_this_process_and_one_worker_process():
    with Engine(workers=2) as eng:
        eng.start()  # the worker process is up before the items: both surely take some
        (worker_pid,) = eng.client.run(os.getpid).values()
        results = run_tasks(pid_after, [(0.3, i) for i in range(6)], engine=eng)
    # results come back in item order, whoever ran them
    assert [i for i, _ in results] == list(range(6))
    assert {pid for _, pid in results} == {os.getpid(), worker_pid}


def test_the_head_starts_before_its_workers():
    with Engine(workers=2) as eng:
        results = run_tasks(pid_after, [(0.0, i) for i in range(3)], engine=eng)
        n_worker_processes = len(eng.client.scheduler_info()["workers"])
        n_workers = eng.n_workers
    assert (n_worker_processes, n_workers) == (1, 2)
    # the first item runs here while the worker process starts
    assert results[0] == (0, os.getpid())


def test_one_worker_is_a_process_of_its_own():
    with Engine(workers=1) as eng:
        assert not eng.head_works
        results = run_tasks(pid_after, [(0.0, i) for i in range(2)], engine=eng)
    assert os.getpid() not in {pid for _, pid in results}


def test_a_failure_here_or_there_names_its_item():
    items = [(i, 4) for i in range(8)]
    names = [f"tile{i}" for i in range(8)]
    with Engine(workers=2) as eng, pytest.raises(TilingError, match="tile4: ValueError: item 4"):
        run_tasks(fails_at, items, engine=eng, names=names)


# --- a task whose code the workers cannot import ---------------------------------------


def _here_only(i, seconds=0.5):
    """A task of this module, which the Dask workers cannot import (see `unloadable`)."""
    time.sleep(seconds)
    return i


@pytest.fixture
def unloadable(monkeypatch):
    """`_here_only` as a function of a module only this process has.

    Under the ``pytest`` command the workers cannot import this test module anyway; under
    ``python -m pytest`` the working directory (and so ``tests``) is on their path too: the
    task names a module that no worker has, whatever ran the tests.
    """
    monkeypatch.setitem(sys.modules, "lidarqa_tests_only", sys.modules[__name__])
    monkeypatch.setattr(_here_only, "__module__", "lidarqa_tests_only")
    return _here_only


@contextlib.contextmanager
def _deadline(seconds: int):
    """Fail (instead of hanging the test run) when the block is still running after `seconds`."""

    def expired(*_):
        pytest.fail(f"still running after {seconds} s: the job hangs")

    before = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, before)


def test_a_task_the_workers_cannot_load_fails_the_job_naming_the_item(unloadable):
    names = [f"tile{i}" for i in range(8)]
    with _deadline(60), Engine(workers=2) as eng:
        eng.start()  # the worker process is up: it surely gets items while this one works
        t0 = time.monotonic()
        with pytest.raises(TilingError, match=r"tile\d: a Dask worker cannot load the task "
                           r"\(ModuleNotFoundError: No module named 'lidarqa_tests_only'\)"):
            run_tasks(unloadable, [(i,) for i in range(8)], engine=eng, names=names)
        # at once: this process had not worked through the items before the job failed
        assert time.monotonic() - t0 < 8 * 0.5


def test_a_chunk_task_the_workers_cannot_load_fails_the_job(scene_tiles, unloadable):
    _, paths = scene_tiles
    catalog = open_catalog([str(p) for p in paths])
    with _deadline(60), Engine(workers=2) as eng:
        eng.start()
        # run_tiles keeps going past a tile that fails; one the workers cannot load is fatal
        with pytest.raises(TilingError, match=r"\.laz: a Dask worker cannot load the task"):
            run_tiles(catalog, unloadable, engine=eng, progress=False)


def test_a_scheduler_whose_workers_run_another_lidarqa_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the workers of a --scheduler cluster must run this lidarqa: checked once, at connect
    distributed = pytest.importorskip("distributed")
    import lidarqa
    from lidarqa.errors import TilingError
    from lidarqa.tiling.engine import Engine

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", host="127.0.0.1") as cluster:
        with Engine(cluster.scheduler_address) as eng:  # same version: connects
            assert eng.client is not None
        monkeypatch.setattr(lidarqa, "__version__", "0.0.0+other")
        with pytest.raises(TilingError, match=r"run lidarqa .* and this process 0\.0\.0\+other"):
            Engine(cluster.scheduler_address).start()


def test_the_head_does_other_work_while_the_workers_finish():
    # _drive with a stand-in cluster of one worker whose items take 1 s: this process runs
    # its items, then, with none left and the worker still busy, calls idle() (here: two
    # pieces of work, then none) instead of waiting; every item is settled once
    from concurrent.futures import ThreadPoolExecutor

    from lidarqa.tiling.engine import _drive

    pool = ThreadPoolExecutor(1)

    class Future:
        def __init__(self, inner):
            self.inner = inner

        @property
        def status(self):
            return "finished" if self.inner.done() else "pending"

        def result(self):
            return self.inner.result()

        def add_done_callback(self, fn):
            self.inner.add_done_callback(lambda _: fn(self))

        def release(self):
            pass

        def cancel(self):
            self.inner.cancel()

    class Cluster:
        scheduler = None
        serial = False
        head_works = True
        client = object()
        dashboard_link = None

        def runs_here(self, n):
            return False

        def start(self):
            return self

        def _n_local(self):
            return 2

    def on_worker(i):
        time.sleep(1.0)
        return ("worker", i)

    settled: dict[int, object] = {}
    pieces: list[float] = []
    t0 = time.monotonic()

    def idle():
        if len(pieces) == 2:
            return False
        pieces.append(time.monotonic() - t0)
        return True

    def settle(i, ok, value):
        assert ok and i not in settled
        settled[i] = value
        return False

    _drive(Cluster(), list(range(4)), lambda i: ("here", i),
           lambda i: Future(pool.submit(on_worker, i)), settle, progress=False,
           description="x", name=str, idle=idle)
    pool.shutdown()
    assert sorted(settled) == [0, 1, 2, 3]
    assert {v[0] for v in settled.values()} == {"here", "worker"}
    assert len(pieces) == 2 and max(pieces) < 0.9  # while the worker's item ran
