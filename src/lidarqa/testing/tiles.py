"""Synthetic deliveries: scenes cut into LAS/LAZ tiles, for catalog tests and benchmarks."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["write_tiles", "write_block"]


def write_tiles(
    scene: Any,
    folder: str | os.PathLike,
    *,
    tile_size: float,
    origin: Sequence[float] = (0.0, 0.0),
    crs: Any = "EPSG:2154",
    prefix: str = "tile",
    suffix: str = ".laz",
    overwrite: bool = False,
    clip: Sequence[float] | None = None,
) -> list[Path]:
    """Cut `scene` into square tiles of `tile_size` m (grid through `origin`) and write them.

    Each tile holds the scene points whose ``floor((x - ox) / tile_size)`` (and y) is the
    tile's, in scene order, with ``classification``, ``point_source_id`` and, when the
    scene has them, return numbers. Tiles are named ``{prefix}_{xmin}_{ymin}{suffix}``
    (integer metres). Points outside `clip` ``(xmin, ymin, xmax, ymax)`` (half-open),
    if given, are left out. Returns the paths sorted by name.
    """
    from ..io import PointCloud, write
    from ..io.crs import parse_crs

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ox, oy = float(origin[0]), float(origin[1])
    xyz = np.asarray(scene.points, dtype=np.float64)
    # Round to the LAS scale first so that tile membership is decided on stored values.
    xyz = np.round(xyz, 3)
    keep = np.ones(len(xyz), dtype=bool)
    if clip is not None:
        keep = (
            (xyz[:, 0] >= clip[0])
            & (xyz[:, 0] < clip[2])
            & (xyz[:, 1] >= clip[1])
            & (xyz[:, 1] < clip[3])
        )
    gi = np.floor((xyz[:, 0] - ox) / tile_size).astype(np.int64)
    gj = np.floor((xyz[:, 1] - oy) / tile_size).astype(np.int64)
    fields = {
        "classification": np.asarray(scene.classification, dtype=np.uint8),
        **{k: np.asarray(v) for k, v in scene.fields.items()},
    }
    crs_obj = parse_crs(crs)
    paths = []
    keys = np.unique(np.column_stack([gi, gj]), axis=0)
    for i, j in keys.tolist():
        sel = np.nonzero((gi == i) & (gj == j) & keep)[0]
        if len(sel) == 0:
            continue
        x0, y0 = ox + i * tile_size, oy + j * tile_size
        name = f"{prefix}_{int(round(x0))}_{int(round(y0))}{suffix}"
        cloud = PointCloud(xyz=xyz[sel], fields={k: v[sel] for k, v in fields.items()}, crs=crs_obj)
        paths.append(write(cloud, folder / name, overwrite=overwrite))
    return sorted(paths)


def write_block(
    folder: str | os.PathLike,
    *,
    nx: int = 2,
    ny: int = 2,
    tile_size: float = 100.0,
    density: float = 10.0,
    seed: int = 0,
    origin: Sequence[float] = (500_000.0, 6_000_000.0),
    crs: Any = "EPSG:2154",
    suffix: str = ".laz",
    **scene_options: Any,
) -> list[Path]:
    """A block of ``nx * ny`` tiles, each a separate seeded :func:`make_scene` of one tile.

    Points of a scene outside its tile are dropped. Neighbouring tiles are independent
    scenes (terrain is not continuous across tile borders), which is fine for throughput
    benchmarks but not for tiled-vs-untiled comparisons (use :func:`write_tiles` on one
    scene for those). Memory holds one tile at a time. Returns the paths.
    """
    from .scenes import make_scene

    folder = Path(folder)
    out: list[Path] = []
    for j in range(ny):
        for i in range(nx):
            x0 = float(origin[0]) + i * tile_size
            y0 = float(origin[1]) + j * tile_size
            scene = make_scene(
                seed=seed * 100_003 + j * nx + i,
                size=(tile_size, tile_size),
                density=density,
                origin=(x0, y0, 0.0),
                **scene_options,
            )
            out.extend(
                write_tiles(
                    scene,
                    folder,
                    tile_size=tile_size,
                    origin=(x0, y0),
                    crs=crs,
                    prefix="block",
                    suffix=suffix,
                    clip=(x0, y0, x0 + tile_size, y0 + tile_size),
                )
            )
            del scene
    return sorted(out)
