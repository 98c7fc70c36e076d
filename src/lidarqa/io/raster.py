"""Single-band GeoTIFF output (rasterio, imported lazily: the ``raster`` extra)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_path
from .._validate import require

__all__ = ["write_geotiff", "NODATA"]

#: nodata value written in float rasters (NaN cells of the array).
NODATA = -9999.0


def write_geotiff(
    path: str | os.PathLike,
    array: np.ndarray,
    *,
    x0: float,
    y1: float,
    cell_size: float,
    crs: Any = None,
    nodata: float = NODATA,
    overwrite: bool = False,
) -> Path:
    """Write a 2-D float array as a one-band float32 GeoTIFF, atomically.

    Parameters
    ----------
    path : path-like
    array : ndarray of shape (rows, cols)
        Row 0 is the north edge; NaN cells are written as `nodata`.
    x0, y1 : float
        West and north edges of the raster (CRS units).
    cell_size : float
        Square pixel size (CRS units).
    crs : pyproj.CRS or None
        The horizontal part of a compound CRS is written (by EPSG code when it has one).
    nodata : float, default -9999
    overwrite : bool, default False

    Returns
    -------
    Path
    """
    rasterio = require("rasterio", "raster")
    from rasterio.transform import Affine

    data = np.where(np.isfinite(array), array, nodata).astype(np.float32)
    profile = dict(
        driver="GTiff",
        height=data.shape[0],
        width=data.shape[1],
        count=1,
        dtype="float32",
        nodata=nodata,
        transform=Affine(cell_size, 0.0, x0, 0.0, -cell_size, y1),
        compress="deflate",
    )
    if crs is not None:
        if getattr(crs, "is_compound", False) and crs.sub_crs_list:
            crs = crs.sub_crs_list[0]  # a raster of height differences: the horizontal CRS
        epsg = crs.to_epsg()
        profile["crs"] = (
            rasterio.crs.CRS.from_epsg(epsg) if epsg else rasterio.crs.CRS.from_wkt(crs.to_wkt())
        )
    with atomic_path(path, overwrite=overwrite) as tmp, rasterio.open(tmp, "w", **profile) as ds:
        ds.write(data, 1)
    return Path(path)
