"""glibc's allocation thresholds for lidarqa's own processes: the CLI and its local workers.

By default glibc maps every allocation above 128 KiB (rising with use) with ``mmap``,
returns it to the system when it is freed, and trims the heap above 128 KiB free. The
ground filter allocates and frees arrays of tens to hundreds of megabytes in each of its
passes, so each pass faulted its pages in again: 0.5–1.0 s of system time on a
2 M-point scene (the CLI, whole process), against 0.24–0.35 s with the thresholds of
:data:`ENV`, where freed arrays stay in the heap for the next pass; peak memory
745 → 783–795 MB. Set for the console script and the LocalCluster workers it starts,
never on ``import lidarqa`` (a library does not change its host's allocator), and only
when the user set none of glibc's ``MALLOC_*`` variables. Elsewhere than glibc, nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

__all__ = ["ENV", "tune_process"]

#: the thresholds (bytes): arrays below 512 MiB come from the heap; up to 1 GiB of free
#: heap is kept for the next allocation instead of being returned
ENV = {"MALLOC_MMAP_THRESHOLD_": str(512 << 20), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters


def tune_process() -> bool:
    """Apply :data:`ENV` to this process (``mallopt``) and to the processes it starts.

    Returns True when applied: Linux with glibc, and no ``MALLOC_*`` variable set.
    """
    if not sys.platform.startswith("linux") or any(k.startswith("MALLOC_") for k in os.environ):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl or another libc: no mallopt
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    if not (mallopt(_M_MMAP_THRESHOLD, int(ENV["MALLOC_MMAP_THRESHOLD_"]))
            and mallopt(_M_TRIM_THRESHOLD, int(ENV["MALLOC_TRIM_THRESHOLD_"]))):
        return False
    os.environ.update(ENV)  # the children (LocalCluster workers) read them at start
    return True
