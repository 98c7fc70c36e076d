"""The peers the benchmarks compare with, run as their users run them."""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

#: where the timed processes keep their bytecode (see :func:`timed_env`)
PYCACHE = Path(tempfile.gettempdir()) / "lidarqa-bench-pycache"


def timed_env(**extra: str) -> dict[str, str]:
    """The environment of a timed process: modules load from bytecode, as installed.

    An installed package imports from the bytecode pip compiled at install time, and a
    checkout installed in editable mode from the ``__pycache__`` Python writes on the
    first import. A development shell often forbids writing bytecode
    (``PYTHONDONTWRITEBYTECODE``) or redirects it (``PYTHONPYCACHEPREFIX``, to keep the
    checkout free of ``__pycache__``); either way every timed process would compile the
    modules of the checkout from source again (lidarqa's filter: 0.07 CPU-s a process
    on the 2-core machine), and a prefix where nothing is written makes it compile the
    standard library and every installed package too (2.1 s instead of 0.7 s).

    The timed processes therefore write and read their bytecode under one prefix of the
    benchmarks' own (:data:`PYCACHE`, in the temporary folder, outside the checkout).
    The first process to import a module compiles it there: time a process only after
    an untimed one has imported the same modules (:func:`warm_up`). `extra` variables
    are set on top.
    """
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("PYTHONPYCACHEPREFIX", "PYTHONDONTWRITEBYTECODE")
    }
    env["PYTHONPYCACHEPREFIX"] = str(PYCACHE)
    env.update(extra)
    return env


def warm_up(cmd: list[str], env: dict[str, str]) -> None:
    """Run `cmd` once, untimed: its bytecode (and numba's cache) is then in place."""
    subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)


def last_returns(cloud) -> np.ndarray:
    """PDAL ``filters.csf``'s points: last and single returns, noise (7, 18) left out.

    The rule of :func:`lidarqa.ground.ground_candidates` (a point with a return number
    or number of returns 0 counts as a last return, as on real IGN tiles; all zero
    means not recorded), in NumPy: a PDAL process does not import lidarqa's filter, so
    the peer's timed process does not either (importing it, numba and SciPy, is 0.4
    CPU-s: a third of CSF's whole run on an 824 k-point forest tile).
    """
    n = len(cloud)
    mask = np.ones(n, dtype=bool)
    rn = cloud.fields.get("return_number")
    nr = cloud.fields.get("number_of_returns")
    if rn is not None and nr is not None and n:
        rn, nr = np.asarray(rn), np.asarray(nr)
        zero = (rn == 0) | (nr == 0)
        if not zero.all():
            mask &= zero | (rn >= nr)
    cls = cloud.fields.get("classification")
    if cls is not None:
        mask &= ~np.isin(np.asarray(cls), (7, 18))
    return mask


def relabel(classification, ground: np.ndarray) -> np.ndarray:
    """Ground -> 2, former ground -> 1, the rest kept (``relabel_classification``, in NumPy)."""
    cls = np.asarray(classification)
    return np.where(ground, 2, np.where(cls == 2, 1, cls)).astype(cls.dtype)


def csf_ground(cloud, *, cloth: float = 1.0, smooth: bool = True) -> np.ndarray:
    """CSF (cloth-simulation-filter wheel) at PDAL ``filters.csf``'s defaults.

    Last and single returns only, noise classes (7, 18) left out, as PDAL runs it; cloth
    resolution 1 m, rigidness 3, time step 0.65, threshold 0.5, 500 iterations, slope
    smoothing on. `cloth` and `smooth` change those two for the variants some tables
    print. Returns the ground mask of every point of `cloud`.
    """
    import CSF

    idx = np.flatnonzero(last_returns(cloud))
    xyz = cloud.xyz[idx]
    csf = CSF.CSF()
    csf.params.bSloopSmooth = smooth
    csf.params.cloth_resolution = cloth
    csf.params.rigidness = 3
    csf.params.time_step = 0.65
    csf.params.class_threshold = 0.5
    csf.params.interations = 500
    csf.setPointCloud(xyz - xyz.min(axis=0))
    g, ng = CSF.VecInt(), CSF.VecInt()
    csf.do_filtering(g, ng, exportCloth=False)
    ground = np.zeros(len(cloud), dtype=bool)
    ground[idx[np.asarray(g, dtype=np.int64)]] = True
    return ground
