"""Whole deliveries: catalogs of tiles, chunks with buffers, and a Dask engine.

- :func:`open_catalog` describes many LAS/LAZ/COPC files (paths, folders, globs,
  ``.vpc``) from their headers;
- :func:`make_chunks` cuts the catalog area into a regular grid of chunks with buffers;
- :func:`read_chunk` streams the points of one chunk plus its buffer;
- :class:`Engine` and :func:`run_chunks` run a pure task on every chunk, serially, on a
  local Dask cluster or on any Dask cluster, with results in chunk order;
  :func:`run_tiles` runs a per-file task (one whole tile each) on the same engine;
- :func:`ground_catalog` classifies ground over a whole catalog (output tiles = input
  tiles, every point once, resumable, byte-identical for any number of workers).

Dask is imported only when a non-serial engine starts.
"""

from .catalog import Catalog, CatalogError, TileInfo, open_catalog
from .chunks import DEFAULT_BUFFER, Chunk, default_chunk_size, make_chunks
from .engine import ChunkFailedError, ChunkOutcome, Engine, TileRef, run_chunks, run_tiles
from .reader import ChunkData, read_chunk

__all__ = [
    "Catalog",
    "CatalogError",
    "TileInfo",
    "open_catalog",
    "Chunk",
    "make_chunks",
    "default_chunk_size",
    "DEFAULT_BUFFER",
    "ChunkData",
    "read_chunk",
    "Engine",
    "ChunkOutcome",
    "ChunkFailedError",
    "run_chunks",
    "run_tiles",
    "TileRef",
    "ground_catalog",
]


def __getattr__(name: str):
    if name == "ground_catalog":
        from .ground import ground_catalog

        return ground_catalog
    raise AttributeError(name)
