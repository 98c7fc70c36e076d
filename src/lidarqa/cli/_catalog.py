"""Catalog inputs of the command line: telling a catalog from one file, and the catalog runs."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator, Sequence
from typing import Any

import click

from ._common import Steps, echo, finish

__all__ = ["bad_lines", "is_catalog", "info_on_catalog", "sigterm_as_interrupt"]


def is_catalog(paths: Sequence[str]) -> bool:
    """True for several paths, a folder, a glob pattern or a ``.vpc`` file."""
    from ..tiling.source import is_catalog_input

    return is_catalog_input(list(paths))


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM into KeyboardInterrupt while a catalog job runs.

    So the same cleanup happens (atomic outputs removed, cluster shut down, work folder
    kept for --resume).
    """

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    try:
        old = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def bad_lines(bad: Sequence[tuple[str, str]]) -> None:
    if bad:
        click.echo(f"Skipped {len(bad)} bad input(s):", err=True)
        for p, r in bad:
            click.echo(f"  {p}: {r}", err=True)


def _strip_counts(catalog: Any) -> tuple[dict[int, int], dict[str, list[int]]]:
    """Points per point source id over the catalog, and the ids of each tile (streamed)."""
    import numpy as np

    from ..io.las import LasReader

    total: dict[int, int] = {}
    per_tile: dict[str, list[int]] = {}
    for t in catalog.tiles:
        ids: set[int] = set()
        with LasReader(t.path) as r:
            for piece in r.chunks(1_000_000):
                psid = piece.fields.get("point_source_id")
                if psid is None:
                    continue
                u, c = np.unique(np.asarray(psid), return_counts=True)
                for k, n in zip(u.tolist(), c.tolist(), strict=True):
                    total[int(k)] = total.get(int(k), 0) + int(n)
                ids.update(int(k) for k in u.tolist())
        per_tile[t.path] = sorted(ids)
    return dict(sorted(total.items())), per_tile


def open_catalog_checked(paths: Sequence[str], *, skip_bad: bool = False, crs: Any = None) -> Any:
    """The catalog of `paths` with `crs` (``--crs``) for tiles that declare none.

    A tile whose own CRS contradicts it is an error naming both (as for one file).
    """
    from ..tiling.source import open_source

    with Steps()(f"Reading the headers of {', '.join(paths)}"):
        return open_source(list(paths), skip_bad=skip_bad, crs=crs, z_to_metres=False).catalog


def info_on_catalog(paths: Sequence[str], *, skip_bad: bool = False, strips: bool = False,
                    crs: Any = None) -> None:
    from ..tiling import make_chunks

    catalog = open_catalog_checked(paths, skip_bad=skip_bad, crs=crs)
    bad_lines(catalog.bad)
    d = catalog.to_dict()
    chunks = make_chunks(catalog)
    d["default_chunks"] = {
        "n_chunks": len(chunks),
        "chunk_size": chunks[0].size if chunks else None,
        "buffer": float(chunks[0].buffered[2] - chunks[0].core[2]) if chunks else None,
    }
    if strips:
        with Steps()(f"Reading the point source ids of {len(catalog.tiles)} tile(s)"):
            d["strips"], d["strips_per_tile"] = _strip_counts(catalog)
    b = d["bounds"]
    echo(", ".join(paths))
    echo(f"  tiles           {d['n_tiles']:,}" + (f" ({d['n_copc']} COPC)" if d["n_copc"] else ""))
    echo(f"  points          {d['n_points']:,}")
    echo(f"  x               {b[0]:.3f} .. {b[2]:.3f}")
    echo(f"  y               {b[1]:.3f} .. {b[3]:.3f}")
    echo(f"  z               {d['zrange'][0]:.3f} .. {d['zrange'][1]:.3f}")
    echo(
        f"  CRS             {d['crs_name'] or 'none'}"
        + (f" (EPSG:{d['crs_epsg']})" if d["crs_epsg"] else "")
    )
    echo(f"  density         {d['density_per_m2']:.1f} pts/m² (points / tile area)")
    echo(f"  tile size       {d['tile_size']:g} m (median)")
    echo("  point formats   " + ", ".join(str(f) for f in d["point_formats"]))
    if strips:
        echo(
            "  strips          "
            + (", ".join(f"{k}: {v:,}" for k, v in d["strips"].items()) or "none")
            + " (point source ids: points)"
        )
    elif d["source_ids"]:
        echo(
            "  strips          " + ", ".join(str(i) for i in d["source_ids"]) + " (file source ids)"
        )
    else:
        echo("  strips          not recorded in the headers (--strips reads them)")
    echo(f"  gaps            {len(d['gaps'])} missing tile cell(s)")
    echo(f"  overlaps        {len(d['overlaps'])} duplicate overlap(s)")
    for o in d["overlaps"][:10]:
        echo(f"    {o['tiles'][0]} / {o['tiles'][1]}: {100 * o['fraction']:.0f} %")
    dc = d["default_chunks"]
    if dc["n_chunks"]:
        echo(
            f"  chunks          {dc['n_chunks']} of {dc['chunk_size']:g} m (default), "
            f"buffer {dc['buffer']:g} m"
        )
    if d["bad"]:
        echo(f"  bad inputs      {len(d['bad'])}")
    finish("info", inputs={"paths": list(paths)}, parameters={"catalog": True}, results=d)
