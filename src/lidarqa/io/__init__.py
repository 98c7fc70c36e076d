"""Reading and writing point clouds and vector data.

``read`` dispatches on the file extension: ``.las``/``.laz`` through laspy,
``.csv``/``.txt``/``.xyz``/``.pts`` as text tables, ``.ply`` as PLY.
"""

import os
from pathlib import Path
from typing import Any

from .._atomic import atomic_path, check_distinct, check_output
from ..errors import ReadError, WriteError
from .las import LasReader, las_header_summary, read_las, write_las
from .pointcloud import PointCloud
from .text import read_text, write_text

__all__ = [
    "PointCloud",
    "LasReader",
    "read",
    "write",
    "open",
    "read_las",
    "write_las",
    "read_text",
    "write_text",
    "atomic_path",
    "check_output",
    "check_distinct",
    "las_header_summary",
    "CLOUD_SUFFIXES",
]

_LAS = {".las", ".laz"}
_TEXT = {".csv", ".txt", ".xyz", ".pts"}
_PLY = {".ply"}
CLOUD_SUFFIXES = _LAS | _TEXT | _PLY


def read(path: str | os.PathLike, *, z_to_metres: bool = False, crs: Any = None) -> PointCloud:
    """Read a point cloud (LAS/LAZ, CSV/XYZ text, PLY) into a :class:`PointCloud`.

    Parameters
    ----------
    path : str or path-like
        The format follows the extension.
    z_to_metres : bool, default False
        Convert heights to metres when the CRS declares another vertical unit
        (e.g. US survey feet in a compound CRS). The converted cloud keeps only
        the horizontal part of a compound CRS and is detached from its LAS
        source scaling: writing it creates new records.
    crs : pyproj.CRS, optional
        The CRS of a file that declares none (e.g. ``--crs``); a file whose
        own CRS differs raises :class:`CRSMismatchError` naming both.

    Examples
    --------
    >>> import lidarqa
    >>> cloud = lidarqa.read("tests/data/samp24-utm.laz")  # doctest: +SKIP
    >>> cloud.xyz.shape  # doctest: +SKIP
    (7492, 3)
    """
    suffix = Path(path).suffix.lower()
    if suffix in _LAS:
        cloud = read_las(path)
    elif suffix in _TEXT:
        cloud = read_text(path)
    elif suffix in _PLY:
        from .ply import read_ply

        cloud = read_ply(path)
    else:
        raise ReadError(
            f"cannot tell the format of {path}: expected one of {', '.join(sorted(CLOUD_SUFFIXES))}"
        )
    if crs is not None:
        from .crs import resolve_crs

        cloud.crs = resolve_crs(cloud.crs, crs, path)
    if z_to_metres:
        from .crs import z_to_metres_factor

        factor = z_to_metres_factor(cloud.crs)
        if factor != 1.0:
            cloud.xyz = cloud.xyz.copy()
            cloud.xyz[:, 2] *= factor
            # The source scaling and the vertical CRS no longer describe z: keep the horizontal
            # CRS only, and write new records if the cloud is saved.
            cloud.source = None
            if cloud.crs is not None and cloud.crs.is_compound:
                cloud.crs = cloud.crs.sub_crs_list[0]
    return cloud


def write(cloud: PointCloud, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a cloud; the format follows the extension (``.las``, ``.laz``, ``.csv``).

    Any cloud that was read can be written: a cloud read from LAS/LAZ keeps its header,
    VLRs, EVLRs and every dimension; a COPC input is written as a plain LAZ (its COPC
    info VLR and hierarchy EVLR dropped), a LAS 1.0 input as LAS 1.2 with the same point
    format. COPC output (``*.copc.laz``) is refused with a
    :class:`~lidarqa.errors.WriteError` before anything is written.
    """
    suffix = Path(path).suffix.lower()
    if suffix in _LAS:
        return write_las(cloud, path, overwrite=overwrite)
    if suffix in {".csv", ".txt", ".xyz"}:
        return write_text(cloud, path, overwrite=overwrite)
    raise WriteError(f"cannot write point clouds as {suffix!r}: use .las, .laz or .csv")


def open(path: str | os.PathLike) -> LasReader:  # noqa: A001 - mirrors laspy.open
    """Open a LAS/LAZ file for chunked reading: ``for chunk in r.chunks(n)``."""
    if Path(path).suffix.lower() not in _LAS:
        raise ReadError(f"chunked reading needs a .las or .laz file, got {path}")
    return LasReader(path)
