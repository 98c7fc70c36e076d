"""lidarqa: how accurate is this LiDAR point cloud.

Ground filtering (progressive TIN densification, segment-based PTD), geometry
(planes, edges, corners) and accuracy assessment (line-segment Hausdorff
matching, check points with ASPRS/NSSDA statistics, height error propagation
with w-tests), with LAS/LAZ I/O, a command line and HTML reports.
"""

import os as _os

# numba's parallel kernels run on OpenMP threads that, by default, spin for a while
# after every parallel region: with the many short regions of the ground filter's
# TIN sweeps that spinning doubled the CPU time on 2 shared cores (bcts_2: 14.5 s of
# CPU for 8.2 s of work). Sleeping threads cost no CPU and, for regions of a few
# milliseconds, no measurable wall time. A value the user set is kept; it must be set
# before OpenMP starts (the first parallel kernel), hence here.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ._version import __version__  # noqa: E402
from .errors import LidarQAError  # noqa: E402
from .io import PointCloud, open, read, write  # noqa: A004

__all__ = ["__version__", "LidarQAError", "PointCloud", "read", "write", "open", "open_source",
           "show_versions"]


def __getattr__(name: str):
    if name == "open_source":  # lazy: the tiling package is not needed to read one file
        from .tiling.source import open_source

        return open_source
    raise AttributeError(f"module 'lidarqa' has no attribute {name!r}")


def show_versions() -> dict[str, str | None]:
    """Versions of lidarqa, Python and the libraries it uses (missing ones as None)."""
    import importlib.metadata as md
    import platform

    out: dict[str, str | None] = {
        "lidarqa": __version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }
    for dist in (
        "numpy",
        "scipy",
        "laspy",
        "lazrs",
        "pyproj",
        "numba",
        "startinpy",
        "shapely",
        "pyogrio",
        "matplotlib",
        "click",
        "rich",
        "dask",
        "distributed",
    ):
        try:
            out[dist] = md.version(dist)
        except md.PackageNotFoundError:
            out[dist] = None
    return out
