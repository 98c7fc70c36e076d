"""Of N local workers, this process is one: N - 1 worker processes, and the head works too."""

from __future__ import annotations

import os
import sys
import time

import pytest

from lidarqa.errors import TilingError
from lidarqa.tiling.engine import Engine, run_tasks

distributed = pytest.importorskip("distributed")
cloudpickle = pytest.importorskip("cloudpickle")


@pytest.fixture
def by_value():
    """Functions of this module travel to the workers by value (the tests are not a package)."""
    module = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(module)
    yield
    cloudpickle.unregister_pickle_by_value(module)


def _pid_after(seconds: float, i: int) -> tuple[int, int]:
    time.sleep(seconds)
    return i, os.getpid()


def _fails_at(i: int, bad: int) -> int:
    if i == bad:
        raise ValueError(f"item {i} is bad")
    return i


def test_two_workers_are_this_process_and_one_worker_process(by_value):
    with Engine(workers=2) as eng:
        eng.start()  # the worker process is up before the items: both surely take some
        (worker_pid,) = eng.client.run(os.getpid).values()
        results = run_tasks(_pid_after, [(0.3, i) for i in range(6)], engine=eng)
    # results come back in item order, whoever ran them
    assert [i for i, _ in results] == list(range(6))
    assert {pid for _, pid in results} == {os.getpid(), worker_pid}


def test_the_head_starts_before_its_workers(by_value):
    with Engine(workers=2) as eng:
        results = run_tasks(_pid_after, [(0.0, i) for i in range(3)], engine=eng)
        n_worker_processes = len(eng.client.scheduler_info()["workers"])
        n_workers = eng.n_workers
    assert (n_worker_processes, n_workers) == (1, 2)
    # the first item runs here while the worker process starts
    assert results[0] == (0, os.getpid())


def test_one_worker_is_a_process_of_its_own(by_value):
    with Engine(workers=1) as eng:
        assert not eng.head_works
        results = run_tasks(_pid_after, [(0.0, i) for i in range(2)], engine=eng)
    assert os.getpid() not in {pid for _, pid in results}


def test_a_failure_here_or_there_names_its_item(by_value):
    items = [(i, 4) for i in range(8)]
    names = [f"tile{i}" for i in range(8)]
    with Engine(workers=2) as eng, pytest.raises(TilingError, match="tile4: ValueError: item 4"):
        run_tasks(_fails_at, items, engine=eng, names=names)
