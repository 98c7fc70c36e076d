"""The :class:`PointCloud` container."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InvalidPointsError

__all__ = ["PointCloud"]


@dataclass(eq=False)
class PointCloud:
    """Points with their attributes, CRS and (for LAS/LAZ) the source header.

    Attributes
    ----------
    xyz : ndarray of shape (N, 3), float64
        Scaled coordinates (x = East, y = North, z = up), in the CRS units.
    fields : dict of str to ndarray of shape (N,)
        Every other dimension by its laspy name (``classification``,
        ``intensity``, ``return_number``, ``point_source_id``, extra bytes, ...).
    crs : pyproj.CRS or None
        Coordinate reference system, if the source declared one.
    source : object or None
        Opaque record of the source file (LAS header, VLRs, raw point records)
        that lets :func:`lidarqa.io.write` write the cloud back losslessly. Only
        ``lidarqa.io`` looks inside it.
    path : str or None
        Where the cloud was read from.
    """

    xyz: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    crs: Any = None
    source: Any = field(default=None, repr=False)
    path: str | None = None

    def __post_init__(self) -> None:
        self.xyz = np.asarray(self.xyz, dtype=np.float64)
        if self.xyz.ndim != 2 or self.xyz.shape[1] != 3:
            raise InvalidPointsError(f"xyz must have shape (N, 3), got {self.xyz.shape}")
        n = self.xyz.shape[0]
        for name, arr in self.fields.items():
            if np.shape(arr)[:1] != (n,):
                raise InvalidPointsError(f"field {name!r} has {len(arr)} values for {n} points")

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def n_points(self) -> int:
        """Number of points."""
        return len(self)

    @property
    def x(self) -> np.ndarray:
        """The x coordinates (a view of ``xyz``)."""
        return self.xyz[:, 0]

    @property
    def y(self) -> np.ndarray:
        """The y coordinates (a view of ``xyz``)."""
        return self.xyz[:, 1]

    @property
    def z(self) -> np.ndarray:
        """The z coordinates (a view of ``xyz``)."""
        return self.xyz[:, 2]

    def has(self, name: str) -> bool:
        """Whether the cloud has dimension `name`."""
        return name in self.fields

    def get(self, name: str, default: Any = None) -> Any:
        """Dimension `name`, or `default` when absent."""
        return self.fields.get(name, default)

    @property
    def classification(self) -> np.ndarray | None:
        """The classification codes, or None when the cloud has none."""
        return self.fields.get("classification")

    @property
    def point_source_id(self) -> np.ndarray | None:
        """The point source IDs (flight strips), or None when the cloud has none."""
        return self.fields.get("point_source_id")

    def subset(self, index: Any) -> PointCloud:
        """A new cloud with the points selected by a boolean mask or index array."""
        idx = np.asarray(index)
        if idx.dtype == bool and idx.shape != (len(self),):
            raise InvalidPointsError(f"mask must have shape ({len(self)},), got {idx.shape}")
        src = self.source.subset(idx) if self.source is not None else None
        return PointCloud(
            xyz=self.xyz[idx],
            fields={k: v[idx] for k, v in self.fields.items()},
            crs=self.crs,
            source=src,
            path=self.path,
        )

    __getitem__ = subset

    def select(
        self,
        *,
        classes: Any = None,
        source_id: Any = None,
    ) -> PointCloud:
        """Points whose classification is in `classes` and point_source_id in `source_id`.

        Either selector may be None (no filter), an int or a sequence of ints.
        """
        mask = np.ones(len(self), dtype=bool)
        for name, wanted in (("classification", classes), ("point_source_id", source_id)):
            if wanted is None:
                continue
            values = self.fields.get(name)
            if values is None:
                raise InvalidPointsError(f"cannot select by {name}: the cloud has no {name} field")
            wanted_arr = np.atleast_1d(np.asarray(wanted))
            mask &= np.isin(values, wanted_arr)
        return self.subset(mask)

    def copy(self) -> PointCloud:
        """A deep copy (arrays copied, source shared read-only)."""
        return PointCloud(
            xyz=self.xyz.copy(),
            fields={k: v.copy() for k, v in self.fields.items()},
            crs=self.crs,
            source=self.source,
            path=self.path,
        )
