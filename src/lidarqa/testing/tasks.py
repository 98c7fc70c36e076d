"""Tiny picklable tasks for tests of the engine (they travel to Dask workers by reference).

A function defined in a test module travels by reference to a module the workers cannot
import (the tests are not installed): the worker cannot load the task and the job fails.
"""

from __future__ import annotations

import os
import time


def pid_after(seconds: float, i: int) -> tuple[int, int]:
    """``(i, pid)`` of the process that ran it, after sleeping `seconds`."""
    time.sleep(seconds)
    return i, os.getpid()


def fails_at(i: int, bad: int) -> int:
    """`i`, or a ValueError when ``i == bad``."""
    if i == bad:
        raise ValueError(f"item {i} is bad")
    return i
