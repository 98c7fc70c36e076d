"""A quick description of a point cloud file (``lidarqa info``)."""

from __future__ import annotations

import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .crs import crs_epsg, crs_name, vertical_unit

__all__ = ["CloudInfo", "describe", "describe_cloud"]


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

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        from dataclasses import asdict

        return asdict(self)


def _density_cell(mins: np.ndarray, maxs: np.ndarray, n: int) -> float:
    """Cell size for the occupied-area estimate: twice the mean point spacing, >= 1 m."""
    area = float(max(maxs[0] - mins[0], 1e-9) * max(maxs[1] - mins[1], 1e-9))
    spacing = np.sqrt(area / max(n, 1))
    return float(np.clip(2.0 * spacing, 1.0, 50.0))


class _Accumulator:
    def __init__(self, cell: float = 1.0) -> None:
        self.cell = cell
        self.n = 0
        self.mins = np.full(3, np.inf)
        self.maxs = np.full(3, -np.inf)
        self.classes: Counter = Counter()
        self.psids: Counter = Counter()
        self.cells: set[tuple[int, ...]] = set()
        self.rn_present = False
        self.rn_zero = 0
        self.rn_invalid = 0
        self.origin: np.ndarray | None = None

    def add(self, cloud: Any) -> None:
        xyz = cloud.xyz
        n = len(xyz)
        if n == 0:
            return
        self.n += n
        self.mins = np.minimum(self.mins, xyz.min(axis=0))
        self.maxs = np.maximum(self.maxs, xyz.max(axis=0))
        for name, counter in (("classification", self.classes), ("point_source_id", self.psids)):
            values = cloud.fields.get(name)
            if values is not None:
                u, c = np.unique(values, return_counts=True)
                counter.update(dict(zip(u.tolist(), c.tolist(), strict=True)))
        if self.origin is None:
            self.origin = np.floor(xyz[0, :2])
        ij = np.floor((xyz[:, :2] - self.origin) / self.cell).astype(np.int64)
        keys = np.unique(ij, axis=0)
        self.cells.update(map(tuple, keys.tolist()))
        rn = cloud.fields.get("return_number")
        nr = cloud.fields.get("number_of_returns")
        if rn is not None and nr is not None:
            self.rn_present = True
            self.rn_zero += int(np.count_nonzero(rn == 0))
            self.rn_invalid += int(np.count_nonzero((rn > nr) | (nr == 0)))


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
    area = float(len(acc.cells)) * acc.cell**2 if acc.cells else 0.0
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

    ``density_per_m2`` is the number of points per occupied area, counted in
    cells of twice the mean point spacing (at least 1 m), which is robust to
    irregular footprints, unlike points / bounding box.
    """
    acc = _Accumulator(
        _density_cell(cloud.xyz.min(axis=0), cloud.xyz.max(axis=0), len(cloud))
        if len(cloud)
        else 1.0
    )
    acc.add(cloud)
    return _finish(acc, cloud.crs, ["X", "Y", "Z", *cloud.fields], {})


def describe(
    path: str | os.PathLike, *, chunk_size: int = 2_000_000, crs: Any = None
) -> CloudInfo:
    """Describe a point cloud file, streaming LAS/LAZ in chunks (constant memory).

    `crs` (a pyproj CRS) stands for the CRS of a file that declares none.
    A point list that is not a cloud (CSV with text ids, GeoPackage, GeoJSON)
    is described by its points.
    """
    from . import las_header_summary, read
    from .crs import resolve_crs
    from .las import LasReader

    if Path(path).suffix.lower() in {".las", ".laz"}:
        with LasReader(path) as reader:
            b = reader.bounds
            acc = _Accumulator(_density_cell(np.array(b[:3]), np.array(b[3:]), reader.n_points))
            for chunk in reader.chunks(chunk_size):
                acc.add(chunk)
            own = resolve_crs(reader.crs, crs, path)
            return _finish(acc, own, reader.dimension_names, las_header_summary(reader))
    from ..errors import ReadError
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
