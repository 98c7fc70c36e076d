"""lidarqa makes numba's OpenMP threads sleep, not spin, between parallel regions."""

from __future__ import annotations

import os
import subprocess
import sys


def _policy(env_value: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if env_value is not None:
        env["OMP_WAIT_POLICY"] = env_value
    code = "import os, lidarqa; print(os.environ.get('OMP_WAIT_POLICY'))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_passive_by_default():
    assert _policy(None) == "PASSIVE"


def test_user_setting_is_kept():
    assert _policy("ACTIVE") == "ACTIVE"
