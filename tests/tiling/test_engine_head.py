"""Of N local workers, this process is one: N - 1 worker processes, and the head works too."""

from __future__ import annotations

import os

import pytest

from lidarqa.errors import TilingError
from lidarqa.testing.tasks import fails_at, pid_after
from lidarqa.tiling.engine import Engine, run_tasks

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
