"""The CLI's glibc allocation thresholds (lidarqa._malloc)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from lidarqa._malloc import ENV

_PROBE = (
    "import os; from lidarqa._malloc import tune_process; "
    "print(tune_process(), os.environ.get('MALLOC_TRIM_THRESHOLD_'), "
    "os.environ.get('MALLOC_MMAP_THRESHOLD_'))"
)


def _probe(**extra: str) -> list[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env.update(extra)
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.split()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_applied_and_passed_on_to_child_processes() -> None:
    assert _probe() == ["True", ENV["MALLOC_TRIM_THRESHOLD_"], ENV["MALLOC_MMAP_THRESHOLD_"]]


def test_a_users_malloc_setting_is_left_alone() -> None:
    # any MALLOC_* variable the user set wins: nothing applied, nothing added
    assert _probe(MALLOC_ARENA_MAX="2") == ["False", "None", "None"]
    assert _probe(MALLOC_TRIM_THRESHOLD_="131072") == ["False", "131072", "None"]


def test_the_console_script_applies_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import lidarqa._malloc
    from lidarqa.cli import main as cli_main

    calls: list[int] = []
    monkeypatch.setattr(cli_main, "_STANDALONE", False)  # main() sets it; restored after
    monkeypatch.setattr(lidarqa._malloc, "tune_process", lambda: calls.append(1) or False)
    with pytest.raises(SystemExit) as exc:
        cli_main.main(["--version"])
    assert exc.value.code == 0
    assert calls == [1]


def test_local_workers_get_the_processes_thresholds(monkeypatch: pytest.MonkeyPatch) -> None:
    # the thresholds reach the LocalCluster workers through the environment (Dask's own
    # MALLOC_TRIM_THRESHOLD_=65536 is not imposed, nor a user's value removed)
    pytest.importorskip("distributed")
    from lidarqa.tiling.engine import Engine

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "123456")
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "654321")
    names = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")
    with Engine(workers=2) as eng:
        eng.start()
        got = eng.client.run(lambda: [os.environ.get(k) for k in names])
    assert list(got.values()) == [["123456", "654321"]]
