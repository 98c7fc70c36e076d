"""A catalog of point cloud tiles described from their headers only.

:func:`open_catalog` turns paths, folders, glob patterns and ``.vpc`` files (QGIS/PDAL
virtual point clouds, a STAC ItemCollection) into a :class:`Catalog`: one
:class:`TileInfo` per LAS/LAZ/COPC file with its bounds, point count, CRS and point
format, read from the file header alone (no point is read), so thousands of files are
catalogued in seconds.

Every problem is found before any work starts and named with its file: a missing
file, a file that is not LAS/LAZ (corrupt header, truncated LAS), an empty folder,
the same tile listed twice (same file, or two files with identical header bounds and
point counts) and tiles in different CRSs. With ``skip_bad=True`` the bad files are
left out and listed in :attr:`Catalog.bad` instead (tiles in a CRS other than the
catalog's majority CRS count as bad).
"""

from __future__ import annotations

import glob as _glob
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import CatalogError, CRSMismatchError, ReadError  # noqa: F401

if TYPE_CHECKING:
    from pyproj import CRS

    from ._types import CRSInput, PathsInput

__all__ = ["Catalog", "TileInfo", "open_catalog", "CatalogError", "expand_sources"]

_SUFFIXES = {".las", ".laz"}


@dataclass(frozen=True)
class TileInfo:
    """One file of a catalog, from its header.

    Attributes
    ----------
    path : str
        Absolute path of the file.
    n_points : int
    bounds : tuple of 6 floats
        ``(xmin, ymin, xmax, ymax, zmin, zmax)`` from the header, CRS units.
    crs_wkt : str or None
        WKT of the file's CRS (None when the header declares none).
    point_format : int
    version : str
        LAS version, e.g. ``"1.4"``.
    is_copc : bool
        A Cloud Optimized Point Cloud (spatial queries read only the needed nodes).
    file_source_id : int
        The header's file source id (0 when unset).
    """

    path: str
    n_points: int
    bounds: tuple[float, float, float, float, float, float]
    crs_wkt: str | None
    point_format: int
    version: str
    is_copc: bool = False
    file_source_id: int = 0

    @property
    def name(self) -> str:
        """The file name of the tile (without its folder)."""
        return Path(self.path).name

    @property
    def bounds2d(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the tile's header bounds."""
        return self.bounds[:4]

    @property
    def area(self) -> float:
        """The tile's bounding-box area, in square CRS units."""
        xmin, ymin, xmax, ymax = self.bounds2d
        return max(xmax - xmin, 0.0) * max(ymax - ymin, 0.0)

    def to_dict(self) -> dict[str, object]:
        """The tile as a JSON-ready dict (path, point count, bounds, format)."""
        return {
            "path": self.path,
            "n_points": self.n_points,
            "bounds": list(self.bounds),
            "point_format": self.point_format,
            "version": self.version,
            "is_copc": self.is_copc,
            "file_source_id": self.file_source_id,
        }


@dataclass(frozen=True)
class Catalog:
    """Tiles of one delivery (sorted by path), all in one CRS.

    Attributes
    ----------
    tiles : tuple of TileInfo
        Sorted by path; a chunk refers to tiles by their index here.
    crs : pyproj.CRS or None
    bad : tuple of (path, reason)
        Files left out with ``skip_bad=True``.
    source_ids : tuple of int or None
        Distinct non-zero file source ids of the headers (strips, when the delivery
        is one file per strip), else None. Per-point source ids are not read.
    """

    tiles: tuple[TileInfo, ...]
    crs: CRS | None = None
    bad: tuple[tuple[str, str], ...] = ()
    source_ids: tuple[int, ...] | None = None
    _meta: dict = field(default_factory=dict, compare=False, repr=False)

    def __len__(self) -> int:
        return len(self.tiles)

    @property
    def n_points(self) -> int:
        """Total point count of the tiles (from their headers)."""
        return int(sum(t.n_points for t in self.tiles))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of all tiles."""
        b = np.array([t.bounds2d for t in self.tiles], dtype=float)
        return (
            float(b[:, 0].min()),
            float(b[:, 1].min()),
            float(b[:, 2].max()),
            float(b[:, 3].max()),
        )

    @property
    def zrange(self) -> tuple[float, float]:
        """``(zmin, zmax)`` of the tiles' header bounds."""
        return (min(t.bounds[4] for t in self.tiles), max(t.bounds[5] for t in self.tiles))

    @property
    def area(self) -> float:
        """Sum of the tiles' bounding-box areas, m² (overlaps counted twice)."""
        return float(sum(t.area for t in self.tiles))

    @property
    def density(self) -> float:
        """Points per m² of tile area (header bounds), at least 1e-6."""
        area = self.area
        if area <= 0:
            xmin, ymin, xmax, ymax = self.bounds
            area = max((xmax - xmin) * (ymax - ymin), 1.0)
        return max(self.n_points / area, 1e-6)

    def tile_size(self) -> float:
        """Median tile side (the larger of width and height), m.

        Header bounds are data extents, a little under the nominal tile (999.98 m for a
        1 km tile): a median side within 0.5 % below a whole number of metres is rounded
        up to it, so that default chunks line up with the tiles (a 999.98 m grid from the
        origin drifts metres away from the tile borders at national coordinates).
        """
        sides = [max(t.bounds[2] - t.bounds[0], t.bounds[3] - t.bounds[1]) for t in self.tiles]
        if not sides:
            return 0.0
        med = float(np.median(sides))
        up = float(np.ceil(med - 1e-9))
        return up if up > 0 and up - med <= 0.005 * up else med

    def overlaps(self, *, min_fraction: float = 0.5) -> list[dict[str, object]]:
        """Pairs of tiles whose bounding boxes overlap by at least `min_fraction`.

        Of the smaller one: duplicate coverage, e.g. a tile delivered twice under two names.

        Thin overlaps along tile borders (a few metres, normal in deliveries with a
        buffer) are not reported.
        """
        b = np.array([t.bounds2d for t in self.tiles], dtype=float)
        out: list[dict[str, Any]] = []
        if len(b) < 2:
            return out
        order = np.argsort(b[:, 0], kind="stable")
        for a_pos, i in enumerate(order):
            for j in order[a_pos + 1 :]:
                if b[j, 0] >= b[i, 2]:
                    break
                w = min(b[i, 2], b[j, 2]) - max(b[i, 0], b[j, 0])
                h = min(b[i, 3], b[j, 3]) - max(b[i, 1], b[j, 1])
                if w <= 0 or h <= 0:
                    continue
                inter = w * h
                small = min(self.tiles[i].area, self.tiles[j].area)
                if small > 0 and inter >= min_fraction * small:
                    p, q = sorted((int(i), int(j)))
                    out.append(
                        {
                            "tiles": [self.tiles[p].path, self.tiles[q].path],
                            "area": float(inter),
                            "fraction": float(inter / small),
                        }
                    )
        out.sort(key=lambda d: d["tiles"])
        return out

    def gaps(self, *, cell: float | None = None) -> list[tuple[float, float, float, float]]:
        """Holes in the tile coverage inside the catalog's bounding box.

        The box is cut in square cells of `cell` metres (default: the median tile
        size); a cell no tile's bounding box touches is a gap. Returns the gap cells'
        bounds, sorted by row then column. A delivery along a corridor has "gaps"
        by this definition; they only mean no tile was delivered there.
        """
        if not self.tiles:
            return []
        cell = float(cell or self.tile_size() or 1.0)
        xmin, ymin, xmax, ymax = self.bounds
        # header bounds are data extents, a little smaller than the nominal tiles: a last
        # row/column thinner than 5 % of a cell is not a cell of its own
        nx = max(int(np.ceil((xmax - xmin) / cell - 0.05)), 1)
        ny = max(int(np.ceil((ymax - ymin) / cell - 0.05)), 1)
        if nx * ny > 4_000_000:
            return []
        covered = np.zeros((ny, nx), dtype=bool)
        eps = 1e-6 * cell
        for t in self.tiles:
            c0 = int(np.floor((t.bounds[0] - xmin + eps) / cell))
            c1 = int(np.ceil((t.bounds[2] - xmin - eps) / cell))
            r0 = int(np.floor((t.bounds[1] - ymin + eps) / cell))
            r1 = int(np.ceil((t.bounds[3] - ymin - eps) / cell))
            covered[max(r0, 0) : max(r1, r0 + 1), max(c0, 0) : max(c1, c0 + 1)] = True
        rows, cols = np.nonzero(~covered)
        return [
            (xmin + c * cell, ymin + r * cell, xmin + (c + 1) * cell, ymin + (r + 1) * cell)
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True)
        ]

    def to_dict(self) -> dict[str, object]:
        """The catalog as a JSON-ready dict: extent, CRS, density, gaps, overlaps, tiles."""
        from ..io.crs import crs_epsg, crs_name

        return {
            "n_tiles": len(self.tiles),
            "n_points": self.n_points,
            "bounds": list(self.bounds) if self.tiles else None,
            "zrange": list(self.zrange) if self.tiles else None,
            "crs_epsg": crs_epsg(self.crs),
            "crs_name": crs_name(self.crs),
            "density_per_m2": self.density if self.tiles else None,
            "tile_size": self.tile_size(),
            "n_copc": sum(t.is_copc for t in self.tiles),
            "point_formats": sorted({t.point_format for t in self.tiles}),
            "source_ids": list(self.source_ids) if self.source_ids is not None else None,
            "gaps": [list(g) for g in self.gaps()],
            "overlaps": self.overlaps(),
            "bad": [{"path": p, "reason": r} for p, r in self.bad],
            "tiles": [t.to_dict() for t in self.tiles],
        }

    def write_vpc(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the catalog as a virtual point cloud (``.vpc``) that QGIS and PDAL open.

        See :func:`lidarqa.tiling.vpc.write_vpc`.
        """
        from .vpc import write_vpc

        return write_vpc(self, path, overwrite=overwrite)


# --- building a catalog --------------------------------------------------------------------


def _is_glob(s: str) -> bool:
    return any(ch in s for ch in "*?[")


def expand_sources(sources: PathsInput) -> tuple[list[str], list[tuple[str, str]]]:
    """Files named by `sources` and problems found while expanding them.

    Returns ``(files, problems)``; ``files`` are absolute paths in the order found
    (folders and globs sorted), ``problems`` ``(path, reason)`` pairs (missing
    file, empty folder, glob without match, ``.vpc`` asset missing).
    """
    if isinstance(sources, str | os.PathLike):
        sources = [sources]
    files: list[str] = []
    problems: list[tuple[str, str]] = []
    for src in sources:
        s = os.fspath(src)
        p = Path(s)
        if p.suffix.lower() == ".vpc" and not _is_glob(s):
            if not p.is_file():
                problems.append((s, "virtual point cloud file does not exist"))
                continue
            from .vpc import read_vpc_hrefs

            try:
                hrefs = read_vpc_hrefs(p)
            except CatalogError as exc:
                problems.append((s, str(exc)))
                continue
            if not hrefs:
                problems.append((s, "virtual point cloud lists no files"))
            files.extend(hrefs)
        elif p.is_dir():
            found = sorted(
                str(q.resolve())
                for q in p.iterdir()
                if q.is_file() and q.suffix.lower() in _SUFFIXES
            )
            if not found:
                problems.append((s, "folder holds no .las/.laz file"))
            files.extend(found)
        elif _is_glob(s):
            found = sorted(
                str(Path(q).resolve())
                for q in _glob.glob(s, recursive=True)
                if Path(q).is_file() and Path(q).suffix.lower() in _SUFFIXES
            )
            if not found:
                problems.append((s, "pattern matches no .las/.laz file"))
            files.extend(found)
        else:
            files.append(str(p.resolve()) if p.exists() else s)
    return files, problems


def _read_tile(path: str) -> TileInfo:
    """Header facts of one file; raises CatalogError naming the file."""
    from ..io.las import LasReader

    p = Path(path)
    if not p.exists():
        raise CatalogError(f"{path}: file does not exist")
    if p.suffix.lower() not in _SUFFIXES:
        raise CatalogError(f"{path}: not a .las/.laz file")
    try:
        with LasReader(p) as r:
            h = r.header
            wkt = None
            if r.crs is not None:
                wkt = r.crs.to_wkt()
            is_copc = any(
                str(v.user_id).strip("\x00") == "copc" and int(v.record_id) == 1 for v in h.vlrs
            )
            b = r.bounds
            info = TileInfo(
                path=str(p.resolve()),
                n_points=r.n_points,
                bounds=(b[0], b[1], b[3], b[4], b[2], b[5]),
                crs_wkt=wkt,
                point_format=int(h.point_format.id),
                version=str(h.version),
                is_copc=bool(is_copc),
                file_source_id=int(getattr(h, "file_source_id", 0) or 0),
            )
    except ReadError as exc:
        raise CatalogError(f"{path}: {exc}") from exc
    except Exception as exc:  # laspy header errors
        raise CatalogError(f"{path}: cannot read the LAS/LAZ header ({exc})") from exc
    if info.n_points > 0 and not all(np.isfinite(info.bounds)):
        raise CatalogError(f"{path}: header bounds are not finite")
    if info.n_points > 0 and (info.bounds[2] < info.bounds[0] or info.bounds[3] < info.bounds[1]):
        raise CatalogError(f"{path}: header bounds are inverted (max < min)")
    return info


def _read_tiles(files: Sequence[str]) -> list[TileInfo | Exception]:
    """Headers of many files, read by a few threads (the work is file system latency)."""
    from concurrent.futures import ThreadPoolExecutor

    def safe(f: str) -> TileInfo | Exception:
        try:
            return _read_tile(f)
        except CatalogError as exc:
            return exc

    if len(files) < 16:
        return [safe(f) for f in files]
    with ThreadPoolExecutor(max_workers=8) as ex:
        return list(ex.map(safe, files))


def open_catalog(
    sources: PathsInput,
    *,
    skip_bad: bool = False,
    crs: CRSInput = None,
) -> Catalog:
    """Build a :class:`Catalog` from files, folders, glob patterns or ``.vpc`` files.

    Parameters
    ----------
    sources : path, glob pattern, folder, .vpc file, or a list of those
    skip_bad : bool, default False
        Leave out bad files (missing, unreadable header, duplicate, another CRS) and
        list them in ``Catalog.bad`` instead of raising.
    crs : optional
        CRS to assume for tiles whose header declares none (EPSG code, WKT, pyproj CRS).

    Raises
    ------
    CatalogError
        Without `skip_bad`: the first problem, naming the file (all problems of the
        same kind are listed). Also when no good tile is left.
    CRSMismatchError
        Tiles in different CRSs (the message names the files of each CRS).
    """
    from ..io.crs import parse_crs

    files, problems = expand_sources(sources)
    if problems and not skip_bad:
        raise CatalogError("; ".join(f"{p}: {r}" for p, r in problems))
    bad: list[tuple[str, str]] = list(problems)
    # duplicates by path
    seen: dict[str, int] = {}
    unique: list[str] = []
    for f in files:
        key = str(Path(f).resolve()) if Path(f).exists() else f
        if key in seen:
            if not skip_bad:
                raise CatalogError(f"{f}: the same file is listed twice")
            bad.append((f, "the same file is listed twice"))
            continue
        seen[key] = 1
        unique.append(f)
    infos = _read_tiles(unique)
    tiles: list[TileInfo] = []
    errors = [(f, e) for f, e in zip(unique, infos, strict=True) if isinstance(e, Exception)]
    if errors and not skip_bad:
        shown = "; ".join(str(e) for _, e in errors[:10])
        more = f" (and {len(errors) - 10} more)" if len(errors) > 10 else ""
        head = "" if len(errors) == 1 else f"{len(errors)} bad files: "
        raise CatalogError(
            head + shown + more + "; use --skip-bad (skip_bad=True) to leave them out"
        )
    for f, e in errors:
        bad.append((f, str(e).removeprefix(f + ": ")))
    tiles = sorted((t for t in infos if isinstance(t, TileInfo)), key=lambda t: t.path)
    # duplicate tiles: identical header bounds and point counts under two names
    by_key: dict[tuple, TileInfo] = {}
    kept: list[TileInfo] = []
    for t in tiles:
        dup_key = (t.n_points, t.bounds)
        if t.n_points > 0 and dup_key in by_key:
            msg = f"duplicate of {by_key[dup_key].path} (same bounds and point count)"
            if not skip_bad:
                raise CatalogError(f"{t.path}: {msg}")
            bad.append((t.path, msg))
            continue
        by_key[dup_key] = t
        kept.append(t)
    tiles = kept
    # CRS
    default_crs = parse_crs(crs)
    groups: dict[str | None, list[TileInfo]] = {}
    for t in tiles:
        groups.setdefault(t.crs_wkt, []).append(t)
    named = {k: v for k, v in groups.items() if k is not None}
    if len(named) > 1:
        from pyproj import CRS

        # the same CRS written in two WKT dialects is one CRS
        merged: dict[str, list[TileInfo]] = {}
        reps: list[tuple[CRS, str]] = []
        for k, v in named.items():
            c = CRS.from_wkt(k)
            for rc, rk in reps:
                if rc == c:
                    merged[rk].extend(v)
                    break
            else:
                reps.append((c, k))
                merged[k] = list(v)
        named = merged
    if default_crs is not None and None in groups:
        key = default_crs.to_wkt()
        found = False
        for k in list(named):
            from pyproj import CRS

            if CRS.from_wkt(k) == default_crs:
                named[k].extend(groups[None])
                found = True
        if not found:
            named.setdefault(key, []).extend(groups[None])
        groups.pop(None)
    if len(named) > 1:
        from pyproj import CRS

        ranked = sorted(named.items(), key=lambda kv: (-len(kv[1]), min(t.path for t in kv[1])))
        if not skip_bad:
            desc = "; ".join(
                f"{CRS.from_wkt(k).name}: "
                + ", ".join(t.path for t in sorted(v, key=lambda t: t.path)[:5])
                + (f" (+{len(v) - 5} more)" if len(v) > 5 else "")
                for k, v in ranked
            )
            raise CRSMismatchError(f"the tiles are in different CRSs: {desc}")
        major = ranked[0][0]
        drop = {t.path for k, v in ranked[1:] for t in v}
        for t in tiles:
            if t.path in drop:
                bad.append((t.path, f"CRS differs from the catalog's ({CRS.from_wkt(major).name})"))
        tiles = [t for t in tiles if t.path not in drop]
        named = {major: named[major]}
    if named and None in groups and groups[None]:
        # some tiles declare a CRS, others none: assume they share it, but say so
        pass
    cat_crs = None
    if named:
        from pyproj import CRS

        cat_crs = CRS.from_wkt(next(iter(named)))
    elif default_crs is not None:
        cat_crs = default_crs
    tiles = sorted(tiles, key=lambda t: t.path)
    if not tiles:
        if bad:
            raise CatalogError("no readable tile: " + "; ".join(f"{p}: {r}" for p, r in bad[:5]))
        raise CatalogError(f"no tile found in {sources!s}")
    ids = sorted({t.file_source_id for t in tiles if t.file_source_id})
    return Catalog(
        tiles=tuple(tiles),
        crs=cat_crs,
        bad=tuple(sorted(bad)),
        source_ids=tuple(ids) if ids else None,
    )
