"""lidarqa: how accurate is this LiDAR point cloud.

Ground filtering (progressive TIN densification, segment-based PTD), geometry
(planes, edges, corners) and accuracy assessment (line-segment Hausdorff
matching, check points with ASPRS/NSSDA statistics, height error propagation
with w-tests), with LAS/LAZ I/O, a command line and HTML reports.
"""

from ._version import __version__
from .errors import LidarQAError
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
