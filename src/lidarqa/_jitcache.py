"""Is numba's on-disk cache ready for a set of compiled kernels?

The kernels are compiled with ``cache=True``: the first run after installing
(or upgrading) compiles them, which takes tens of seconds; later runs load the
compiled code from numba's cache. The CLI uses :func:`kernels_cached` to say so
before a run that will compile. It asks numba's own cache locator where each
kernel's index lives (next to the source, in the user cache directory when the
install is read-only, or under ``NUMBA_CACHE_DIR``) and whether that index holds
entries for the current source (an upgrade invalidates them) and this CPU.

The package ships the caches of the kernels that ``lidarqa demo`` runs, built with
``scripts/jit_cache.py`` (numba keys them by source content, numba version, Python
version and CPU): where all of these match, the first run loads compiled code instead
of compiling it; anywhere else numba compiles on first use, as without them.
"""

from __future__ import annotations

from typing import Any


def kernels_cached(*dispatchers: Any) -> bool:
    """True when every dispatcher has valid cached code on disk.

    Unknown cache layouts (another numba version) count as cached: the caller
    only uses this to print a notice, and a missing notice is better than a
    false one on every run.
    """
    for disp in dispatchers:
        try:
            cache_file = disp._cache._cache_file
            index = cache_file._load_index()
        except (AttributeError, OSError, EOFError, ValueError):
            continue
        except Exception:  # noqa: BLE001 - a corrupt index: numba will recompile
            return False
        if not index:
            return False
        try:
            magic = disp.targetctx.codegen().magic_tuple()
        except Exception:  # noqa: BLE001 - another numba layout: trust the index
            continue
        # shipped caches hold code for the CPU they were built on: another CPU compiles
        if not any(isinstance(k, tuple) and len(k) > 1 and k[1] == magic for k in index):
            return False
    return True
