"""Numba's on-disk cache of lidarqa's compiled kernels: is it ready, where is it.

The kernels are compiled with ``cache=True``: the first run after installing
(or upgrading) compiles them, which takes tens of seconds; later runs load the
compiled code from numba's cache. The CLI uses :func:`kernels_cached` to say so
before a run that will compile, and ``lidarqa warmup`` compiles ahead of time
(in a container build, say). numba chooses the cache folder: ``__pycache__``
beside each module when the package folder is writable, else a user-wide folder
(``~/.cache/numba`` on Linux, ``$XDG_CACHE_HOME/numba`` when set), or
``NUMBA_CACHE_DIR`` when that is set. Its entries are keyed by the module's
source stamp, the numba and Python versions and the CPU, so an upgrade or another
machine compiles again. The package ships no compiled code.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
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
        # an index can hold code for another CPU (a shared home folder): this one compiles
        if not any(isinstance(k, tuple) and len(k) > 1 and k[1] == magic for k in index):
            return False
    return True


@dataclass(frozen=True)
class KernelStats:
    """Compile and cache-load counts of lidarqa's numba kernels in this process.

    Attributes
    ----------
    compiled : dict
        Kernel (``module.function``) -> number of signatures compiled (cache misses).
    loaded : dict
        Kernel -> number of signatures loaded from the on-disk cache (cache hits).
    cache_dirs : tuple of str
        The folders numba reads and writes the caches of the kernels used so far in.
    """

    compiled: dict[str, int]
    loaded: dict[str, int]
    cache_dirs: tuple[str, ...]

    def since(self, before: KernelStats) -> KernelStats:
        """The counts accumulated after `before` was taken (folders: all of `self`)."""

        def diff(now: dict[str, int], then: dict[str, int]) -> dict[str, int]:
            out = {k: v - then.get(k, 0) for k, v in now.items()}
            return {k: v for k, v in out.items() if v > 0}

        return KernelStats(
            diff(self.compiled, before.compiled), diff(self.loaded, before.loaded),
            self.cache_dirs,
        )  # fmt: skip


def kernel_stats() -> KernelStats:
    """Counts of compiled and cache-loaded signatures of every imported lidarqa kernel.

    Walks the imported ``lidarqa`` modules for numba dispatchers compiled with
    ``cache=True`` (numba's ``Dispatcher.stats``): the counts are cumulative for
    the process, so take one before and one after the work and use
    :meth:`KernelStats.since`. The cache folders are those of every kernel used
    so far (compiled, or loaded from the cache) in this process.
    """
    compiled: dict[str, int] = {}
    loaded: dict[str, int] = {}
    dirs: set[str] = set()
    for name, module in list(sys.modules.items()):
        if not (name == "lidarqa" or name.startswith("lidarqa.")) or module is None:
            continue
        for attr, obj in list(vars(module).items()):
            stats = _dispatcher_stats(obj)
            if stats is None or getattr(obj, "__module__", None) != name:
                continue
            key = f"{name}.{attr}"
            compiled[key] = sum(stats.cache_misses.values())
            loaded[key] = sum(stats.cache_hits.values())
            if getattr(obj, "overloads", None):  # compiled or loaded in this process
                dirs.add(str(stats.cache_path))
    return KernelStats(compiled, loaded, tuple(sorted(dirs)))


def _dispatcher_stats(obj: Any) -> Any:
    """The compile statistics (numba's) of a dispatcher compiled with ``cache=True``, else None."""
    from numba.core.dispatcher import Dispatcher

    if not isinstance(obj, Dispatcher):
        return None
    try:
        stats = obj.stats
    except Exception:  # noqa: BLE001 - another numba layout: leave it out
        return None
    return stats if getattr(stats, "cache_path", None) else None
