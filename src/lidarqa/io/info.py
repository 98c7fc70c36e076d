"""A quick description of a point cloud file (``lidarqa info``)."""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .crs import crs_epsg, crs_name, metre_factors, vertical_unit

__all__ = ["CloudInfo", "describe", "describe_cloud", "describe_files"]


@dataclass(frozen=True)
class CloudInfo:
    """Summary of a point cloud; ``to_dict()`` is the ``results`` of ``lidarqa info``."""

    n_points: int
    bounds: dict[str, float | None]
    crs_epsg: int | None
    crs_name: str | None
    vertical_unit: str | None
    classes: dict[str, int]
    point_source_ids: dict[str, int]
    density_per_m2: float | None
    returns: dict[str, Any]
    dimensions: list[str] = field(default_factory=list)
    header: dict[str, Any] = field(default_factory=dict)
    points_read: bool = True

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        from dataclasses import asdict

        return asdict(self)


def _density_cell(mins: Sequence[float] | np.ndarray, maxs: Sequence[float] | np.ndarray,
                  n: int, crs: Any = None) -> float:
    """Cell size for the occupied-area estimate: twice the mean point spacing, 1-50 m.

    In the CRS's units (1 m is 3.28 US survey feet). Rounded to two significant digits
    and laid on a grid anchored at 0, 0, so one file and the folder of its tiles (the
    same bounds and count) count the same cells.
    """
    unit = metre_factors(crs)[0]  # metres per unit
    area = float(max(maxs[0] - mins[0], 1e-9) * max(maxs[1] - mins[1], 1e-9))
    spacing = np.sqrt(area / max(n, 1))
    return float(f"{np.clip(2.0 * spacing, 1.0 / unit, 50.0 / unit):.2g}")


class _Accumulator:
    """The per-region half of ``describe``: counts, extent and occupied cells.

    Pieces are added in any order and summarised once by :func:`_finish`.
    """

    def __init__(self, cell: float = 1.0) -> None:
        self.cell = cell
        self.n = 0
        self.mins = np.full(3, np.inf)
        self.maxs = np.full(3, -np.inf)
        self.classes: Counter = Counter()
        self.psids: Counter = Counter()
        self.cells: list[np.ndarray] = []  # distinct occupied cell keys per piece
        self.rn_present = False
        self.rn_zero = 0
        self.rn_invalid = 0

    def add(self, cloud: Any) -> np.ndarray | None:
        """Add a piece of points; return its distinct point source ids (None without)."""
        xyz = cloud.xyz
        n = len(xyz)
        if n == 0:
            return None
        self.n += n
        self.mins = np.minimum(self.mins, xyz.min(axis=0))
        self.maxs = np.maximum(self.maxs, xyz.max(axis=0))
        ids = None
        for name, counter in (("classification", self.classes), ("point_source_id", self.psids)):
            values = cloud.fields.get(name)
            if values is not None:
                u, c = _value_counts(np.asarray(values))
                counter.update(dict(zip(u.tolist(), c.tolist(), strict=True)))
                ids = u if name == "point_source_id" else ids
        ij = np.floor(xyz[:, :2] / self.cell).astype(np.int64)
        # one int64 key per cell (column in the high 32 bits): a 1-D unique, not rows
        self.cells.append(np.unique((ij[:, 0] << 32) + (ij[:, 1] & 0xFFFFFFFF)))
        rn = cloud.fields.get("return_number")
        nr = cloud.fields.get("number_of_returns")
        if rn is not None and nr is not None:
            self.rn_present = True
            self.rn_zero += int(np.count_nonzero(rn == 0))
            self.rn_invalid += int(np.count_nonzero((rn > nr) | (nr == 0)))
        return ids


def _value_counts(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct values and their counts; a bincount for small unsigned integers."""
    if values.dtype.kind == "u" and values.dtype.itemsize <= 2 and values.size:
        c = np.bincount(values, minlength=0)
        u = np.flatnonzero(c)
        return u.astype(values.dtype), c[u]
    return np.unique(values, return_counts=True)


def _finish(acc: _Accumulator, crs: Any, dims: list[str], header: dict) -> CloudInfo:
    if acc.n == 0:
        bounds = dict.fromkeys(("min_x", "min_y", "min_z", "max_x", "max_y", "max_z"), None)
    else:
        bounds = dict(
            zip(
                ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z"),
                [float(v) for v in (*acc.mins, *acc.maxs)],
                strict=True,
            )
        )
    n_cells = np.unique(np.concatenate(acc.cells)).size if acc.cells else 0
    # the cells are laid in the CRS's units: their area in m² (x, y in feet, say)
    area = float(n_cells) * (acc.cell * metre_factors(crs)[0]) ** 2
    returns: dict[str, Any] = {"present": acc.rn_present}
    if acc.rn_present:
        returns.update(
            n_zero_return_number=acc.rn_zero,
            n_invalid=acc.rn_invalid,
            valid=acc.rn_invalid == 0 and acc.rn_zero == 0,
        )
    else:
        returns["valid"] = False
    return CloudInfo(
        n_points=acc.n,
        bounds=bounds,
        crs_epsg=crs_epsg(crs),
        crs_name=crs_name(crs),
        vertical_unit=vertical_unit(crs)[0],
        classes={str(k): int(v) for k, v in sorted(acc.classes.items())},
        point_source_ids={str(k): int(v) for k, v in sorted(acc.psids.items())},
        density_per_m2=(acc.n / area) if area > 0 else None,
        returns=returns,
        dimensions=dims,
        header=header,
    )


def describe_cloud(cloud: Any) -> CloudInfo:
    """Describe an in-memory :class:`~lidarqa.io.PointCloud`.

    ``density_per_m2`` is the number of points per occupied area in m² (x, y in feet
    included), counted in cells of twice the mean point spacing (at least 1 m), which
    is robust to irregular footprints, unlike points / bounding box.
    """
    xyz = cloud.xyz
    acc = _Accumulator(_density_cell(xyz.min(axis=0), xyz.max(axis=0), len(xyz), cloud.crs)
                       if len(xyz) else 1.0)
    acc.add(cloud)
    return _finish(acc, cloud.crs, ["X", "Y", "Z", *cloud.fields], {})


def describe_files(
    paths: Sequence[str | os.PathLike],
    *,
    crs: Any = None,
    chunk_size: int = 2_000_000,
    ids_per_file: dict[str, list[int]] | None = None,
    headers_only: bool = False,
) -> CloudInfo:
    """Describe LAS/LAZ files as one cloud, streaming each in chunks (constant memory).

    One file and a catalog of tiles are the same job: every file is one region added
    to one summary, with the occupied-area cells fixed by the files' header bounds and
    point count, so a merged file and the folder of its tiles give the same numbers.

    Parameters
    ----------
    paths : sequence of path-like
        LAS/LAZ/COPC files.
    crs : pyproj.CRS, optional
        The CRS of the result (default: the first file's).
    chunk_size : int, default 2 000 000
        Points read at a time.
    headers_only : bool, default False
        Read the headers only (seconds for a delivery that takes hours to decompress):
        point count, bounds, CRS and dimensions; the classes, strips, density and
        returns are then not known (empty, None) and ``points_read`` is False.
    ids_per_file : dict, optional
        Filled with the sorted point source ids of each file, by path.

    Returns
    -------
    CloudInfo
        ``header`` is the first file's header summary for one file, else empty.
    """
    from . import las_header_summary
    from .las import LasReader

    heads = []
    header: dict[str, Any] = {}
    for path in paths:  # the header pass: the cells of the whole area
        with LasReader(path) as r:
            heads.append((r.n_points, r.bounds, r.dimension_names, r.crs))
            if headers_only and len(paths) == 1:
                header = las_header_summary(r)
    lo = np.min([h[1][:3] for h in heads], axis=0) if heads else np.zeros(3)
    hi = np.max([h[1][3:] for h in heads], axis=0) if heads else np.zeros(3)
    acc = _Accumulator(_density_cell(lo, hi, sum(h[0] for h in heads),
                                     crs if crs is not None else (heads[0][3] if heads else None)))
    first = heads[0] if heads else (0, (), [], None)
    if headers_only:
        acc.n = sum(int(h[0]) for h in heads)
        if acc.n:
            acc.mins, acc.maxs = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        out = _finish(acc, crs if crs is not None else first[3], list(first[2]), header)
        return replace(out, density_per_m2=None, returns={}, points_read=False)
    for path in paths:
        ids: set[int] = set()
        with LasReader(path) as r:
            for chunk in r.chunks(chunk_size):
                u = acc.add(chunk)
                ids.update(u.tolist() if u is not None else ())
            header = las_header_summary(r) if len(paths) == 1 else {}  # as read (after points)
        if ids_per_file is not None:
            ids_per_file[str(path)] = sorted(int(i) for i in ids)
    return _finish(acc, crs if crs is not None else first[3], list(first[2]), header)


def describe(
    path: str | os.PathLike,
    *,
    chunk_size: int = 2_000_000,
    crs: Any = None,
    headers_only: bool = False,
) -> CloudInfo:
    """Describe a point cloud file, streaming LAS/LAZ in chunks (constant memory).

    `crs` (a pyproj CRS) stands for the CRS of a file that declares none.
    A point list that is not a cloud (CSV with text ids, GeoPackage, GeoJSON)
    is described by its points. `headers_only`: see :func:`describe_files` (LAS/LAZ
    only).
    """
    from . import read
    from .crs import resolve_crs

    if Path(path).suffix.lower() in {".las", ".laz"}:
        from .las import LasReader

        with LasReader(path) as reader:
            own = resolve_crs(reader.crs, crs, path)
        return describe_files([path], crs=own, chunk_size=chunk_size, headers_only=headers_only)
    from ..errors import OptionError, ReadError

    if headers_only:
        raise OptionError(f"--headers reads LAS/LAZ headers; {path} is a point list, with none")
    from .vector import VECTOR_SUFFIXES, read_points

    try:
        cloud = read(path, crs=crs)
    except ReadError:
        # a point list (check points, corners, residuals) with text ids or a GIS layer
        if Path(path).suffix.lower() not in VECTOR_SUFFIXES:
            raise
        from .pointcloud import PointCloud

        pts = read_points(path, crs=crs)
        cloud = PointCloud(xyz=pts.xyz, crs=pts.crs)
    return describe_cloud(cloud)
