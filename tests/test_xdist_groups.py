"""The test grouping of tests/conftest.py reaches pytest-xdist's scheduler."""

from __future__ import annotations

import os

import pytest


def test_the_group_of_this_module_reaches_the_scheduler(request: pytest.FixtureRequest) -> None:
    # pytest-xdist (--dist loadgroup) tells the scheduler a test's group by a suffix on its
    # node id; when the suffix is missing (our hook ran after xdist's, or a pytest that
    # ignores the suffix: pytest-xdist#1386) tests are spread one by one and each worker
    # builds the module and session fixtures again, silently (about 10 % of the suite's time)
    # (on a worker, pytest-xdist keeps `--dist loadgroup` as the `loadgroup` option)
    if "PYTEST_XDIST_WORKER" not in os.environ or not getattr(
        request.config.option, "loadgroup", False
    ):
        pytest.skip("runs under pytest-xdist with --dist loadgroup (the default addopts)")
    assert request.node.nodeid.endswith("@tests/test_xdist_groups.py"), request.node.nodeid
