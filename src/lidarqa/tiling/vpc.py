"""Virtual point clouds (``.vpc``): the STAC ItemCollection QGIS and PDAL wrench use.

A ``.vpc`` is a GeoJSON ``FeatureCollection`` of STAC Items, one per file, with the
STAC *pointcloud* (``pc:count``, ``pc:type``, ``pc:encoding``, ``pc:schemas``) and
*projection* (``proj:wkt2``, ``proj:epsg``, ``proj:bbox``, ``proj:geometry``)
extension fields, the file as the ``data`` asset (``href`` relative to the ``.vpc``)
and the footprint in WGS 84 as the item ``geometry``/``bbox``, as PDAL writes them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import TilingError

if TYPE_CHECKING:
    from .catalog import Catalog

__all__ = ["write_vpc", "read_vpc_hrefs", "vpc_document"]

STAC_VERSION = "1.0.0"
PC_EXT = "https://stac-extensions.github.io/pointcloud/v1.0.0/schema.json"
PROJ_EXT = "https://stac-extensions.github.io/projection/v1.1.0/schema.json"


def _ring(xmin: float, ymin: float, xmax: float, ymax: float, z: float) -> list[list[float]]:
    return [[xmin, ymin, z], [xmax, ymin, z], [xmax, ymax, z], [xmin, ymax, z], [xmin, ymin, z]]


def _to_wgs84(crs: Any, xs: list[float], ys: list[float]) -> tuple[list[float], list[float]]:
    from pyproj import Transformer

    t = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon, lat = t.transform(xs, ys)
    return [float(v) for v in lon], [float(v) for v in lat]


def vpc_document(catalog: Catalog, base: str | os.PathLike[str]) -> dict[str, object]:
    """The ``.vpc`` JSON document of `catalog`, with hrefs relative to folder `base`."""
    from ..io.crs import crs_epsg

    crs = catalog.crs
    epsg = crs_epsg(crs)
    horiz = crs.sub_crs_list[0] if crs is not None and crs.is_compound else crs
    features: list[dict[str, Any]] = []
    for t in catalog.tiles:
        xmin, ymin, xmax, ymax, zmin, zmax = t.bounds
        if horiz is not None:
            try:
                lon, lat = _to_wgs84(horiz, [xmin, xmax, xmax, xmin], [ymin, ymin, ymax, ymax])
            except Exception:
                lon, lat = [xmin, xmax, xmax, xmin], [ymin, ymin, ymax, ymax]
        else:
            lon, lat = [xmin, xmax, xmax, xmin], [ymin, ymin, ymax, ymax]
        ring = [[lo, la, zmin] for lo, la in zip(lon, lat, strict=True)]
        ring.append(ring[0])
        href = os.path.relpath(t.path, start=os.fspath(base))
        href = "./" + Path(href).as_posix()
        props: dict[str, Any] = {
            "datetime": "1970-01-01T00:00:00Z",
            "pc:count": int(t.n_points),
            "pc:encoding": "?",
            "pc:schemas": [],
            "pc:type": "lidar",
            "proj:bbox": [xmin, ymin, zmin, xmax, ymax, zmax],
            "proj:geometry": {
                "type": "Polygon",
                "coordinates": [_ring(xmin, ymin, xmax, ymax, zmin)],
            },
            "proj:wkt2": t.crs_wkt or (crs.to_wkt() if crs is not None else None),
        }
        if epsg is not None:
            props["proj:epsg"] = epsg
        features.append(
            {
                "type": "Feature",
                "stac_version": STAC_VERSION,
                "stac_extensions": [PC_EXT, PROJ_EXT],
                "id": Path(t.path).stem,
                "geometry": {"type": "Polygon", "coordinates": [ring]},
                "bbox": [min(lon), min(lat), zmin, max(lon), max(lat), zmax],
                "properties": props,
                "links": [],
                "assets": {"data": {"href": href, "roles": ["data"]}},
            }
        )
    return {"type": "FeatureCollection", "features": features}


def write_vpc(catalog: Catalog, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Write `catalog` as a ``.vpc`` file (atomically); hrefs are relative to its folder."""
    from ..io import atomic_path

    target = Path(path)
    if target.suffix.lower() != ".vpc":
        raise TilingError(f"a virtual point cloud file must end in .vpc, got {target}")
    doc = vpc_document(catalog, target.resolve().parent)
    with atomic_path(target, overwrite=overwrite) as tmp:
        tmp.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return target


def read_vpc_hrefs(path: str | os.PathLike[str]) -> list[str]:
    """Absolute paths of the files a ``.vpc`` lists (its ``data`` assets, else the first asset)."""
    from ..errors import CatalogError

    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CatalogError(f"not a virtual point cloud (JSON): {exc}") from exc
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list):
        raise CatalogError("not a virtual point cloud: no 'features' list")
    out = []
    for k, f in enumerate(feats):
        assets = (f or {}).get("assets") or {}
        asset = assets.get("data") or (next(iter(assets.values())) if assets else None)
        href = (asset or {}).get("href")
        if not href:
            raise CatalogError(f"feature {k} has no data asset href")
        if href.startswith("file://"):
            href = href[len("file://") :]
        q = Path(href)
        if not q.is_absolute():
            q = (p.resolve().parent / q).resolve()
        out.append(str(q))
    return out
