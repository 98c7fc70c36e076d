"""A synthetic LiDAR delivery with known first-return density and planted defects."""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Delivery", "make_delivery", "DEFECTS"]

#: The defects :func:`make_delivery` can plant, each in its own tile, and the ``qc`` check
#: that must find it.
DEFECTS: dict[str, str] = {
    "void": "voids",
    "sparse": "density",
    "las12": "point_format",
    "returns": "return_numbers",
    "class": "classes",
    "duplicates": "duplicates",
    "bounds": "header",
}


@dataclass(frozen=True)
class Delivery:
    """What :func:`make_delivery` wrote, with its truth.

    Attributes
    ----------
    paths : tuple of Path
        The tiles, sorted by name.
    defects : dict
        Defect name -> path of the tile that holds it.
    density : float
        First returns per m² of one swath (the ANPD of every clean tile).
    sparse_density : float
        First returns per m² of the ``"sparse"`` tile.
    void : tuple of 4 floats or None
        ``(xmin, ymin, xmax, ymax)`` of the planted void.
    crs : str
    tile_size : float
    """

    paths: tuple[Path, ...]
    defects: dict[str, Path]
    density: float
    sparse_density: float
    void: tuple[float, float, float, float] | None
    crs: str
    tile_size: float
    n_points: dict[str, int] = field(default_factory=dict)

    @property
    def clean(self) -> tuple[Path, ...]:
        """Tiles without a planted defect."""
        bad = set(self.defects.values())
        return tuple(p for p in self.paths if p not in bad)

    @property
    def void_area(self) -> float:
        """m² of the planted void (0 without one)."""
        if self.void is None:
            return 0.0
        x0, y0, x1, y1 = self.void
        return (x1 - x0) * (y1 - y0)


def _terrain(xy: np.ndarray) -> np.ndarray:
    return 120.0 + 6.0 * np.sin(xy[:, 0] / 70.0) + 4.0 * np.cos(xy[:, 1] / 55.0)


def make_delivery(
    folder: str | os.PathLike,
    *,
    nx: int = 3,
    ny: int = 3,
    tile_size: float = 100.0,
    density: float = 4.0,
    defects: Sequence[str] = (),
    seed: int = 0,
    origin: Sequence[float] = (500_000.0, 4_000_000.0),
    crs: str = "EPSG:26915+5703",
    overlap_width: float = 20.0,
    flag_overlap: bool = True,
    void_side: float = 12.0,
    sparse_density: float = 1.0,
    suffix: str = ".laz",
) -> Delivery:
    """Write a block of ``nx x ny`` LAS 1.4 / PDRF 6 tiles with known density and defects.

    Two swaths (point source ids 1 and 2) split the block at its middle column and
    overlap over `overlap_width` m; the points of swath 2 in the overlap carry the LAS
    overlap flag (``flag_overlap``). Each swath holds `density` pulses per m², uniformly
    spread; 30 % of pulses have a second return (lower, classified ground, class 2) and
    first returns are class 1. GPS times are adjusted standard; the CRS (horizontal +
    vertical) is written as WKT.

    Parameters
    ----------
    folder : path-like
        Created if missing.
    nx, ny : int
        Tiles across and up.
    tile_size : float, default 100
        Tile side, m.
    density : float, default 4
        First returns per m² of one swath (the true ANPD).
    defects : sequence of str
        Defects to plant, each in its own tile (in order from the second tile): ``"void"``
        (a `void_side` square without any return), ``"sparse"`` (`sparse_density` pulses
        per m²), ``"las12"`` (LAS 1.2, point format 1), ``"returns"`` (return number >
        number of returns), ``"class"`` (class 0, which the LBS forbids),
        ``"duplicates"`` (100 records written twice), ``"bounds"`` (header max x and y
        30 m beyond the data).
    seed : int
    origin : (float, float)
        South-west corner of the block.
    crs : str
    overlap_width : float, default 20
    flag_overlap : bool, default True
    void_side : float, default 12
    sparse_density : float, default 1
    suffix : {".laz", ".las"}

    Returns
    -------
    Delivery
    """
    from ..io import PointCloud
    from ..io.crs import parse_crs
    from ..io.las import write_las

    unknown = [d for d in defects if d not in DEFECTS]
    if unknown:
        raise ValueError(f"unknown defect(s) {unknown}; known: {sorted(DEFECTS)}")
    if len(defects) > nx * ny - 1:
        raise ValueError("more defects than tiles (the first tile stays clean)")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    crs_obj = parse_crs(crs)
    ox, oy = float(origin[0]), float(origin[1])
    mid = ox + 0.5 * nx * tile_size
    tiles = [(i, j) for j in range(ny) for i in range(nx)]
    planted: dict[tuple[int, int], str] = {}
    for k, d in enumerate(defects):
        planted[tiles[1 + k]] = d
    paths: list[Path] = []
    where: dict[str, Path] = {}
    counts: dict[str, int] = {}
    void_box = None
    t0 = 3.0e8
    for (i, j) in tiles:
        x0, y0 = ox + i * tile_size, oy + j * tile_size
        x1, y1 = x0 + tile_size, y0 + tile_size
        d = planted.get((i, j), "")
        dens = sparse_density if d == "sparse" else density
        parts = []
        # swath 1 covers x < mid + w/2, swath 2 x >= mid - w/2
        for sid, (a, b) in ((1, (-np.inf, mid + overlap_width / 2)),
                            (2, (mid - overlap_width / 2, np.inf))):
            lo, hi = max(x0, a), min(x1, b)
            if hi <= lo:
                continue
            n = int(round(dens * (hi - lo) * (y1 - y0)))
            xy = np.column_stack([rng.uniform(lo, hi, n), rng.uniform(y0, y1, n)])
            ov = np.zeros(n, dtype=np.uint8)
            if sid == 2 and flag_overlap:
                ov[xy[:, 0] < mid + overlap_width / 2] = 1
            parts.append((sid, xy, ov))
        xs, rn, nr, cls, sids, ovs = [], [], [], [], [], []
        for sid, xy, ov in parts:
            n = len(xy)
            two = rng.random(n) < 0.3
            z1 = _terrain(xy) + np.where(two, rng.uniform(2.0, 15.0, n), 0.0)
            xs.append(np.column_stack([xy, z1]))
            rn.append(np.ones(n, np.uint8))
            nr.append(np.where(two, 2, 1).astype(np.uint8))
            cls.append(np.where(two, 1, 2).astype(np.uint8))
            sids.append(np.full(n, sid, np.uint16))
            ovs.append(ov)
            m = int(two.sum())
            xy2 = xy[two] + rng.normal(0.0, 0.05, (m, 2))
            xs.append(np.column_stack([xy2, _terrain(xy2)]))
            rn.append(np.full(m, 2, np.uint8))
            nr.append(np.full(m, 2, np.uint8))
            cls.append(np.full(m, 2, np.uint8))
            sids.append(np.full(m, sid, np.uint16))
            ovs.append(ov[two])
        xyz = np.concatenate(xs)
        # returns stay inside their tile (the jitter of second returns could push one out)
        xyz[:, 0] = np.clip(xyz[:, 0], x0, x1 - 0.001)
        xyz[:, 1] = np.clip(xyz[:, 1], y0, y1 - 0.001)
        xyz = np.round(xyz, 3)
        f: dict[str, np.ndarray] = {
            "return_number": np.concatenate(rn),
            "number_of_returns": np.concatenate(nr),
            "classification": np.concatenate(cls),
            "point_source_id": np.concatenate(sids),
            "overlap": np.concatenate(ovs),
            "intensity": rng.integers(100, 4000, len(xyz)).astype(np.uint16),
        }
        order = np.argsort(xyz[:, 1] * 1e4 + xyz[:, 0], kind="stable")  # scan-like order
        xyz = xyz[order]
        f = {k: v[order] for k, v in f.items()}
        f["gps_time"] = t0 + np.arange(len(xyz)) * 1e-5
        t0 += 100.0
        if d == "void":
            cx, cy = x0 + 0.5 * tile_size, y0 + 0.5 * tile_size
            void_box = (cx - void_side / 2, cy - void_side / 2, cx + void_side / 2,
                        cy + void_side / 2)
            keep = ~((xyz[:, 0] >= void_box[0]) & (xyz[:, 0] < void_box[2])
                     & (xyz[:, 1] >= void_box[1]) & (xyz[:, 1] < void_box[3]))
            xyz = xyz[keep]
            f = {k: v[keep] for k, v in f.items()}
        elif d == "returns":
            bad = rng.choice(len(xyz), 50, replace=False)
            f["return_number"][bad] = 3
            f["number_of_returns"][bad] = 2
        elif d == "class":
            f["classification"][rng.choice(len(xyz), 40, replace=False)] = 0
        elif d == "duplicates":
            dup = np.sort(rng.choice(len(xyz), 100, replace=False))
            xyz = np.concatenate([xyz, xyz[dup]])
            f = {k: np.concatenate([v, v[dup]]) for k, v in f.items()}
        kw: dict[str, Any] = {"adjusted_gps_time": True}
        if d == "las12":
            f.pop("overlap")
            kw = {"point_format": 1, "version": "1.2", "adjusted_gps_time": True}
        name = f"tile_{int(round(x0))}_{int(round(y0))}{suffix}"
        path = folder / name
        tile_crs = crs_obj
        if d == "las12" and crs_obj is not None and crs_obj.is_compound:
            tile_crs = crs_obj.sub_crs_list[0]  # GeoTIFF keys of LAS 1.2: horizontal only
        write_las(PointCloud(xyz=xyz, fields=f, crs=tile_crs), path, overwrite=True, **kw)
        if d == "bounds":
            _lie_about_bounds(path, 30.0)
        paths.append(path)
        counts[name] = len(xyz)
        if d:
            where[d] = path
    return Delivery(tuple(sorted(paths)), where, float(density), float(sparse_density),
                    void_box, crs, float(tile_size), counts)


def _lie_about_bounds(path: Path, by: float) -> None:
    """Move the header's max x and max y `by` metres beyond the data (bytes 179-203)."""
    with path.open("r+b") as fh:
        fh.seek(179)
        max_x = struct.unpack("<d", fh.read(8))[0]
        fh.seek(179)
        fh.write(struct.pack("<d", max_x + by))
        fh.seek(195)
        max_y = struct.unpack("<d", fh.read(8))[0]
        fh.seek(195)
        fh.write(struct.pack("<d", max_y + by))
