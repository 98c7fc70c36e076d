"""Ground classification of a whole catalog, chunk by chunk, with the same result as one run.

How it works:

1. Each chunk is read with its buffer (default :func:`ground_buffer`: the filter's
   seed cell, two under a canopy, no wider than the catalog) and filtered with
   :func:`lidarqa.ground.classify_ground`, exactly as ``lidarqa ground`` filters one
   file. Only the labels of the chunk's *core* points are kept: for each tile, the
   record numbers of its core points that are ground, and the number of core points.
2. Each chunk's labels are saved in the work folder ``OUTDIR/.lidarqa-work/`` as soon
   as the chunk is done (``<chunk id>.npz``, written atomically), next to ``run.json``
   which records the catalog, the chunk grid and the filter parameters. ``resume=True``
   re-uses the saved chunks of a run with the same ``run.json`` and computes only the
   missing ones.
3. A final pass writes one output file per input tile (same name, in ``output_dir``):
   every point exactly once, in input order, with all its dimensions, the ground
   points as class 2 and former class-2 points that are not ground as class 1 (the
   rules of single-file ``lidarqa ground``). It checks that the chunks' core points
   add up to each tile's point count. The outputs depend only on the saved labels, so
   they are byte-identical for any number of workers and any completion order.
   Then ``<output_dir>/<name>.vpc`` lists the outputs and the work folder is removed.

Each output file is written atomically: an interrupted run (Ctrl-C, SIGTERM, a
failure) leaves complete files or none, plus the work folder for ``resume``.

With ``evaluate=True`` the ISPRS cross-table counts (reference = the input class 2)
are counted on core points in every chunk and summed, which gives exactly the counts
of one whole-area evaluation.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import threading
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .._arrays import colmin
from ..errors import OptionError, OutputExistsError, TilingError
from .reader import TILE_CACHE_BYTES, shared_tiles, tile_cache, unshare_tile

if TYPE_CHECKING:
    from ..ground.auto import CloudMeasures
    from ..ground.metrics import FilterErrors
    from ._types import PathsInput, Tiles
    from .catalog import Catalog
    from .engine import Engine
    from .reader import ChunkData

__all__ = [
    "GroundTask",
    "ChunkGround",
    "CatalogGroundResult",
    "ground_catalog",
    "catalog_grow_radius",
    "CANOPY_MULTI_RETURN",
    "ground_buffer",
    "WORK_DIR",
]

WORK_DIR = ".lidarqa-work"
_AUTO_FIELDS = ("return_number", "number_of_returns", "scan_angle", "scan_angle_rank")
#: the dimensions the filter reads (returns, classes for the noise and the evaluation)
_CHUNK_FIELDS = (*_AUTO_FIELDS, "classification")
#: bytes a point takes in the tile cache with these fields (xyz, returns, angle, class)
_POINT_BYTES = 24 + 1 + 1 + 2 + 1


@dataclass(frozen=True)
class ChunkGround:
    """Per-chunk result of :class:`GroundTask` (small: ground record numbers only)."""

    chunk_id: str
    tiles: tuple[int, ...]
    n_core: tuple[int, ...]
    ground: tuple[np.ndarray, ...]  # sorted record numbers (uint32/int64) per tile
    n_points_read: int = 0
    counts: tuple[int, int, int, int] | None = None  # a, b, c, d on core points
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class GroundTask:
    """The per-chunk ground job: filter the buffered chunk, keep the core labels."""

    method: str = "segment-ptd"
    last_returns_only: bool = True
    exclude_classes: tuple[int, ...] = (7, 18)
    preset: str | None = None
    params: tuple[tuple[str, object], ...] = ()
    evaluate: bool = False
    ignore_classes: tuple[int, ...] = ()
    #: the dimensions a chunk is read with: a worker keeps its tiles decompressed with
    #: these only, across its chunks (:func:`~lidarqa.tiling.reader.worker_tile_cache`)
    tile_fields: ClassVar[tuple[str, ...]] = _CHUNK_FIELDS
    #: the folder where the processes of this machine share decompressed tiles
    #: (:func:`~lidarqa.tiling.reader.shared_tiles`); None: each decompresses its own
    tile_spill: str | None = None

    def to_dict(self) -> dict[str, object]:
        """The task's parameters as a JSON-ready dict."""
        return {
            "method": self.method,
            "last_returns_only": self.last_returns_only,
            "exclude_classes": list(self.exclude_classes),
            "preset": self.preset,
            "params": dict(self.params),
            "evaluate": self.evaluate,
            "ignore_classes": list(self.ignore_classes),
        }

    def __call__(self, data: ChunkData) -> ChunkGround:
        """Classify the ground of one chunk (with its buffer); the core points' result."""
        from ..errors import DataQualityWarning
        from ..ground import classify_ground

        chunk = data.chunk
        core = data.core
        if not core.any():
            return ChunkGround(chunk.id, (), (), (), len(core))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", DataQualityWarning)
            params: dict[str, Any] = dict(self.params)
            res = classify_ground(
                data.cloud,
                method=self.method,
                last_returns_only=self.last_returns_only,
                exclude_classes=self.exclude_classes,
                preset=self.preset,
                **params,
            )
        ground = np.asarray(res.ground_mask, dtype=bool)
        tiles, n_core, per_tile = [], [], []
        for t in np.unique(data.tile_index[core]).tolist():
            sel = core & (data.tile_index == t)
            idx = data.point_index[sel & ground]
            idx = np.sort(idx)
            if len(idx) and idx[-1] < 2**32:
                idx = idx.astype(np.uint32)
            tiles.append(int(t))
            n_core.append(int(sel.sum()))
            per_tile.append(idx)
        counts = None
        if self.evaluate:
            cls = data.cloud.classification
            if cls is None:
                raise OptionError("evaluate needs a classification in the input tiles")
            ref = np.asarray(cls) == 2
            m = core.copy()
            if self.ignore_classes:
                m &= ~np.isin(np.asarray(cls), np.asarray(self.ignore_classes))
            r, g = ref[m], ground[m]
            counts = (
                int(np.count_nonzero(r & g)),
                int(np.count_nonzero(r & ~g)),
                int(np.count_nonzero(~r & g)),
                int(np.count_nonzero(~r & ~g)),
            )
        return ChunkGround(
            chunk_id=chunk.id,
            tiles=tuple(tiles),
            n_core=tuple(n_core),
            ground=tuple(per_tile),
            n_points_read=len(core),
            counts=counts,
            warnings=tuple(sorted({str(w.message) for w in caught})),
        )


@dataclass(frozen=True)
class CatalogGroundResult:
    """Result of :func:`ground_catalog`."""

    outputs: tuple[str, ...]
    vpc: str | None
    n_points: int
    n_ground: int
    n_chunks: int
    n_chunks_run: int
    n_chunks_resumed: int
    chunk_size: float
    buffer: float
    failed: tuple[tuple[str, str], ...] = ()
    bad: tuple[tuple[str, str], ...] = ()
    evaluation: FilterErrors | None = None
    parameters: dict = field(default_factory=dict)
    chunks: tuple[dict, ...] = ()
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """The result as a JSON-ready dict (outputs, counts, evaluation)."""
        d: dict[str, object] = {
            "outputs": list(self.outputs),
            "vpc": self.vpc,
            "n_points": self.n_points,
            "n_ground": self.n_ground,
            "ground_fraction": self.n_ground / self.n_points if self.n_points else None,
            "n_chunks": self.n_chunks,
            "n_chunks_run": self.n_chunks_run,
            "n_chunks_resumed": self.n_chunks_resumed,
            "chunk_size": self.chunk_size,
            "buffer": self.buffer,
            "failed_chunks": [{"chunk": c, "error": e} for c, e in self.failed],
            "bad_tiles": [{"path": p, "reason": r} for p, r in self.bad],
            "chunks": list(self.chunks),
            "warnings": list(self.warnings),
        }
        if self.evaluation is not None:
            full = self.evaluation.to_dict()
            d.update(
                {
                    k: full[k]
                    for k in ("type_i", "type_ii", "total", "kappa", "n_evaluated", "confusion")
                    if k in full
                }
            )
        return d


# --- work folder ------------------------------------------------------------------------------


def _fingerprint(catalog: Any, chunks: Any, task: GroundTask) -> dict[str, Any]:
    return {
        "version": 1,
        "tiles": [[t.path, t.n_points, list(t.bounds)] for t in catalog.tiles],
        "chunks": [[c.id, list(c.core), list(c.buffered)] for c in chunks],
        "task": task.to_dict(),
    }


def _save_chunk(work: Path, res: ChunkGround) -> None:
    from ..io import atomic_path

    arrays: dict[str, Any] = {
        "tiles": np.asarray(res.tiles, dtype=np.int64),
        "n_core": np.asarray(res.n_core, dtype=np.int64),
        "counts": np.asarray(res.counts if res.counts is not None else (-1, -1, -1, -1)),
    }
    for k, g in enumerate(res.ground):
        arrays[f"g{k}"] = g
    with atomic_path(work / f"{res.chunk_id}.npz", overwrite=True) as tmp:
        with tmp.open("wb") as fh:
            np.savez(fh, **arrays)


def _load_chunk(work: Path, chunk_id: str) -> ChunkGround | None:
    p = work / f"{chunk_id}.npz"
    if not p.is_file():
        return None
    try:
        with np.load(p) as z:
            tiles = tuple(int(v) for v in z["tiles"])
            n_core = tuple(int(v) for v in z["n_core"])
            ground = tuple(np.asarray(z[f"g{k}"]) for k in range(len(tiles)))
            counts_arr = z["counts"]
    except Exception:
        return None  # damaged: recompute
    counts = _counts4(counts_arr)
    return ChunkGround(chunk_id, tiles, n_core, ground, counts=counts)


def _load_counts(work: Path, chunk_id: str) -> tuple[int, int, int, int] | None:
    """The chunk's ISPRS counts (None when it was run without ``evaluate``)."""
    try:
        with np.load(work / f"{chunk_id}.npz") as z:
            c = z["counts"]
    except Exception as exc:
        raise TilingError(f"chunk {chunk_id}: its saved labels are missing or damaged") from exc
    return _counts4(c)


def _counts4(c: np.ndarray) -> tuple[int, int, int, int] | None:
    """Saved ISPRS counts as a 4-tuple (None for the -1 marker of a run without them)."""
    return None if c[0] < 0 else (int(c[0]), int(c[1]), int(c[2]), int(c[3]))


def _assemble_tile(
    src: str, dst: str, tile: int, n_points: int, work: str, chunk_ids: list[str]
) -> int:
    """Write output tile `dst`: `src` with the ground labels saved by its chunks.

    Runs on a worker (one call per tile) or in the calling process; the result
    depends only on the saved labels. Returns the number of ground points.
    """
    from ..ground import relabel_classification
    from ..io.las import rewrite_las_classification

    mask = np.zeros(n_points, dtype=bool)
    covered = 0
    for cid in chunk_ids:
        try:
            with np.load(Path(work) / f"{cid}.npz") as z:
                tiles = [int(v) for v in z["tiles"]]
                if tile not in tiles:
                    continue
                pos = tiles.index(tile)
                covered += int(z["n_core"][pos])
                mask[np.asarray(z[f"g{pos}"], dtype=np.int64)] = True
        except (OSError, KeyError, ValueError) as exc:
            raise TilingError(f"chunk {cid}: its saved labels are missing or damaged") from exc
    if covered != n_points:
        raise TilingError(
            f"{src}: the chunks hold {covered:,} of its {n_points:,} points "
            "(points outside the header bounds?)"
        )

    def new_classes(start: int, cls: np.ndarray) -> np.ndarray:
        return relabel_classification(cls, mask[start : start + len(cls)])

    rewrite_las_classification(src, dst, new_classes, overwrite=True)
    return int(mask.sum())


#: Points aimed at in one buffered chunk of the ground job (other jobs: 3.5 M, see
#: :data:`~lidarqa.tiling.chunks.TARGET_POINTS`): about 1.2 GB of peak memory per worker
#: (measured on a synthetic 25 pts/m² block of eight 216 m tiles: 1.21 GB with 5.95 M points
#: in the buffered chunk, 0.94 GB with 2.8 M). Fewer, larger chunks read less buffer per
#: point kept: 1.75 instead of 2.42 points there, 35 % less CPU for the whole block.
GROUND_TARGET_POINTS = 6_000_000

#: share of the ground candidates from multi-return pulses above which a catalog is
#: taken to lie under a canopy, and the ground job reads two seed cells around each
#: chunk instead of one (see :func:`ground_buffer`): measured 0.07-0.21 on the IGN
#: urban tiles and 0.03 on the synthetic blocks, 0.38-0.42 on the BC and lidR forest
CANOPY_MULTI_RETURN = 0.3


def ground_buffer(
    catalog: Tiles | None = None, *, cell_size: float = 60.0, canopy: bool = False
) -> float:
    """The margin (m) the ground job reads around each chunk of `catalog`.

    One seed cell of the filter (`cell_size`, 60 m by default and in every automatic
    parameter set), two under a canopy. The seed grid is snapped to the catalog's (see
    :func:`make_chunks`), so a chunk holds every complete seed cell next to its core
    and seeds its TIN as one run over the whole catalog would; a roof narrower than a
    seed cell that a chunk border cuts is seen whole. Under a canopy the ground is
    found far from any seed, and what the filter decides reaches about two cells: the
    BC forest tiles bcts_2 and bcts_4 in four 150 m chunks agreed with one whole-tile
    run on 98.39 % and 97.61 % of their labels with one cell, 99.976 % and 100 % with
    two (the differences were spread evenly over the chunks, not along their
    borders). The automatic parameters pass ``canopy=True`` when the share of ground
    candidates from multi-return pulses is at least :data:`CANOPY_MULTI_RETURN`; a
    second cell everywhere would cost every delivery (1 km tiles at 25 pts/m²: 4
    instead of 2.2 points read per point kept). The margin scales with the filter: a
    smaller `cell_size` (``--cell-size``) gives a smaller buffer, hence smaller chunks
    (a chunk is at least :data:`~lidarqa.tiling.chunks.MIN_BUFFERS` buffers wide). It
    is never wider than the catalog's larger side: beyond that a buffer reads nothing
    more.

    Parameters
    ----------
    catalog : Catalog, optional
        The data (its header bounds); None gives the seed cells alone.
    cell_size : float, default 60
        The filter's seed cell, m.
    canopy : bool, default False
        The data lie under a canopy: two seed cells.

    Returns
    -------
    float
        Buffer, m.
    """
    b = (2.0 if canopy else 1.0) * float(cell_size)
    if catalog is not None and getattr(catalog, "tiles", None):
        x0, y0, x1, y1 = catalog.bounds[:4]
        span = max(x1 - x0, y1 - y0)
        if math.isfinite(span) and span > 0:
            b = min(b, float(math.ceil(span)))
    return b


def _tile_pieces(path: str, step: int) -> Iterator[Any]:
    """The points of tile `path` in pieces of `step` (from the tile cache when one is open)."""
    from ..io import PointCloud
    from ..io.las import LasReader
    from .reader import cached_tile

    got = cached_tile(path)
    if got is None:
        with LasReader(path) as r:
            yield from r.chunks(step)
        return
    xyz, fields = got
    for a in range(0, len(xyz), step):
        part = {k: v[a : a + step] for k, v in fields.items()}
        yield PointCloud(xyz=xyz[a : a + step], fields=part)


def _catalog_sample(
    catalog: Tiles,
    *,
    last_returns_only: bool = True,
    exclude_classes: Iterable[int] | None = (7, 18),
    max_points: int = 4_000_000,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Ground candidates (xyz and the fields the auto preset measures) of whole tiles.

    All tiles when they hold at most `max_points` points together, else tiles spread
    evenly over the catalog (by index in path order) up to that many points: a
    deterministic sample that does not depend on the chunking or the workers.
    """
    from ..errors import DataQualityWarning
    from ..ground import ground_candidates

    n = len(catalog.tiles)
    total = catalog.n_points
    if total <= max_points:
        picks = list(range(n))
    else:
        k = max(1, int(n * max_points / total))
        picks = sorted({int(round(v)) for v in np.linspace(0, n - 1, k)})
    parts: list[np.ndarray] = []
    fields: dict[str, list[np.ndarray]] = {}
    budget = max_points
    for t in picks:
        tile = catalog.tiles[t]
        if tile.n_points > budget and parts:
            break
        for piece in _tile_pieces(tile.path, 1_000_000):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataQualityWarning)
                cand, *_ = ground_candidates(
                    piece,
                    last_returns_only=last_returns_only,
                    exclude_classes=exclude_classes,
                )
            parts.append(piece.xyz[cand])
            for fname, v in piece.fields.items():
                if fname in _AUTO_FIELDS:
                    fields.setdefault(fname, []).append(np.asarray(v)[cand])
        budget -= tile.n_points
    xyz = np.concatenate(parts) if parts else np.empty((0, 3))
    joined = {k: np.concatenate(v) for k, v in fields.items() if len(v) == len(parts)}
    return xyz, joined


def catalog_grow_radius(
    catalog: Tiles,
    *,
    last_returns_only: bool = True,
    exclude_classes: Iterable[int] | None = (7, 18),
    factor: float = 2.5,
    max_points: int = 4_000_000,
    sample: np.ndarray | None = None,
    filter_density: float = 0.0,
) -> float:
    """The segment-PTD surface-growing radius of a catalog, estimated once for all chunks.

    :func:`~lidarqa.ground.default_grow_radius` (``factor`` x the mean point spacing,
    from the median point count of grid cells) on the ground candidates of whole
    tiles (:func:`_catalog_sample`, or the candidates given as `sample`).
    Per-chunk estimates differ by a few per cent from chunk to chunk and from a whole
    run, and the radius changes segments far from chunk borders; one value for the
    catalog keeps chunks consistent (on a catalog small enough to be sampled entirely
    it is exactly the whole-area value). With segment-PTD's `filter_density` the
    radius is that of the lowest point per cell, which the filter segments.
    """
    from ..ground import default_grow_radius
    from ..ground.segment_ptd import thin_lowest

    xyz = sample
    if xyz is None:
        xyz, _ = _catalog_sample(
            catalog,
            last_returns_only=last_returns_only,
            exclude_classes=exclude_classes,
            max_points=max_points,
        )
    if filter_density > 0 and len(xyz):
        xyz = xyz[thin_lowest(xyz, 1.0 / math.sqrt(filter_density))[0]]
    if len(xyz) < 3:
        return 0.3
    r0 = default_grow_radius(xyz - colmin(xyz), factor=factor, floor=0.0)
    return float(max(0.3, r0))


def catalog_auto_parameters(
    catalog: Tiles,
    method: str = "segment-ptd",
    *,
    sensor: str = "auto",
    last_returns_only: bool = True,
    exclude_classes: Iterable[int] | None = (7, 18),
    sample: tuple[np.ndarray, dict[str, np.ndarray]] | None = None,
) -> tuple[dict[str, object], CloudMeasures, str]:
    """``preset="auto"`` for a catalog: measure once, choose once, for every chunk.

    :func:`~lidarqa.ground.measure_cloud` on the catalog sample (:func:`_catalog_sample`)
    and :func:`~lidarqa.ground.auto_parameters` on its figures. Measuring chunk by
    chunk would let neighbouring chunks pick different parameter sets (a sparse
    chunk of trees beside a dense one of roofs) and break the seams; one choice
    keeps the catalog run equal to one in-memory run of the same cloud.

    Returns the chosen parameters, the measures and the regime.
    """
    from ..ground.auto import auto_parameters, measure_cloud

    xyz, fields = sample if sample is not None else _catalog_sample(
        catalog, last_returns_only=last_returns_only, exclude_classes=exclude_classes
    )
    measures = measure_cloud(xyz, fields=fields)
    chosen, _, regime = auto_parameters(measures, method, sensor=sensor)
    return chosen, measures, regime


def _ground_grid(
    catalog: Tiles, *, buffer: float, cell: float
) -> tuple[float, tuple[float, float]]:
    """The ground job's default chunk side and grid origin: fewest chunks, fewest borders.

    A chunk reads its buffer on each side of every border between chunks, so the
    points read (and filtered) per point kept grow with the number of borders. The
    side :func:`~lidarqa.tiling.chunks.default_chunk_size` gives (at most
    :data:`GROUND_TARGET_POINTS` in a buffered chunk) is the largest allowed; laid
    from (0, 0) its grid cuts a catalog into more columns and rows than it needs (a
    648 m block into 3 x 2 chunks of 370 m, one column of them 38 m wide: 1.75 points
    read per point kept). Laid from the catalog's south-west corner (the seed grid's
    origin), ``ceil(span / side)`` chunks per axis cover it, of the even side rounded up
    to whole seed cells when that stays within the allowed side (chunk borders on seed
    cell lines: the buffered boxes need no widening to the seed grid): 2 x 2 chunks of
    360 m there, 1.40 points read per point kept.

    Returns
    -------
    (float, (float, float))
        Chunk side and grid origin, in the catalog's units.
    """
    from .chunks import default_chunk_size

    b = np.asarray([t.bounds2d for t in catalog.tiles if t.n_points > 0], dtype=float)
    if not len(b):
        return default_chunk_size(catalog, buffer=buffer, target_points=GROUND_TARGET_POINTS), (
            0.0,
            0.0,
        )
    x0, y0 = float(b[:, 0].min()), float(b[:, 1].min())
    w, h = float(b[:, 2].max()) - x0, float(b[:, 3].max()) - y0
    origin = (x0, y0)
    side = default_chunk_size(
        catalog, buffer=buffer, origin=origin, target_points=GROUND_TARGET_POINTS
    )
    nx, ny = max(1, math.ceil(w / side - 1e-9)), max(1, math.ceil(h / side - 1e-9))
    even = max(w / nx, h / ny, 1e-9)
    for step in (cell, 1.0):
        if step > 0 and math.ceil(even / step) * step <= side:
            return float(math.ceil(even / step) * step), origin
    return float(side), origin


def _plain_name(name: str) -> str:
    """Output name of input tile `name`: a COPC tile is written as a plain LAZ (``.laz``)."""
    from .._atomic import COPC_SUFFIX

    if name.lower().endswith(COPC_SUFFIX):
        return name[: -len(COPC_SUFFIX)] + ".laz"
    return name


def _output_names(catalog: Any, output_dir: Path) -> list[Path]:
    names = [_plain_name(Path(t.path).name) for t in catalog.tiles]
    if len(set(names)) != len(names):
        # same file name in two folders: prefix with the parent folder name
        names = [
            f"{Path(t.path).parent.name}_{_plain_name(Path(t.path).name)}" for t in catalog.tiles
        ]
        if len(set(names)) != len(names):
            names = [
                f"{k:05d}_{_plain_name(Path(t.path).name)}" for k, t in enumerate(catalog.tiles)
            ]
    return [output_dir / n for n in names]


# a tile that the sample and several chunks' buffers read is decompressed once (in this
# process: the serial engine's), with the dimensions the filter reads only
@tile_cache(fields=_CHUNK_FIELDS)
def ground_catalog(
    sources: PathsInput | Catalog,
    output_dir: str | os.PathLike[str],
    *,
    method: str = "segment-ptd",
    preset: str | None = "auto",
    sensor: str = "auto",
    last_returns_only: bool = True,
    exclude_classes: Iterable[int] | None = (7, 18),
    evaluate: bool = False,
    ignore_classes: Iterable[int] | None = None,
    chunk_size: float | None = None,
    buffer: float | None = None,
    origin: tuple[float, float] | None = None,
    engine: Engine | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    skip_bad: bool = False,
    overwrite: bool = False,
    retries: int = 2,
    progress: bool = False,
    vpc_name: str | None = None,
    order_seed: int | None = None,
    **params: object,
) -> CatalogGroundResult:
    """Classify ground over a catalog; write one output file per input tile and a ``.vpc``.

    Parameters
    ----------
    sources : Catalog or anything :func:`open_catalog` accepts
    output_dir : path
        Created if missing. Outputs keep the input file names.
    method, preset, last_returns_only, exclude_classes, evaluate, ignore_classes, **params
        As :func:`lidarqa.ground.classify_ground`.
    chunk_size, buffer, origin
        The chunk grid (:func:`make_chunks`); the default buffer is
        :func:`ground_buffer` (the filter's seed cell; two under a canopy). Without
        `chunk_size` and `origin` the grid is laid from the catalog's south-west corner
        with the fewest chunks no larger than the density allows;
        with `chunk_size` alone it goes through (0, 0).
    engine : Engine, optional
        Otherwise one is made from `scheduler` and `workers` (``workers=1`` without a
        scheduler runs serially in this process).
    resume : bool
        Re-use the chunks saved by an interrupted run with the same settings.
    skip_bad : bool
        Leave bad tiles out (listed in the result) instead of failing.
    overwrite : bool
        Replace existing output files.
    order_seed : int, optional
        Shuffle the chunk submission order (tests of determinism).

    Returns
    -------
    CatalogGroundResult
    """
    from .._validate import check_choice
    from ..ground import METHODS, PRESETS, filter_errors_from_counts
    from ..ground.auto import SENSORS, with_given
    from .catalog import Catalog, open_catalog
    from .chunks import make_chunks
    from .engine import Engine, run_chunks, run_tasks

    if method not in METHODS:
        raise OptionError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    check_choice(sensor, SENSORS, "sensor")
    if preset is not None and preset != "auto" and preset not in PRESETS:
        raise OptionError(
            f"preset must be one of auto, {', '.join(PRESETS)}, got {preset!r}"
        )
    catalog = sources if isinstance(sources, Catalog) else open_catalog(sources, skip_bad=skip_bad)
    own = engine is None
    if engine is None:  # made before anything is written: bad options fail here
        serial = scheduler is None and workers == 1
        engine = Engine("serial") if serial else Engine(scheduler, workers=workers)
        w, h = (catalog.bounds[2] - catalog.bounds[0], catalog.bounds[3] - catalog.bounds[1])
        if catalog.n_points > GROUND_TARGET_POINTS or max(w, h) > (chunk_size or np.inf):
            # two chunks at least: the workers start while this process reads the sample
            engine.start_soon()
    try:
        full_params = dict(params)
        sample = None
        # the filter works in metres (classify_ground scales each chunk by its CRS): the
        # sample it is measured on too, its seed cell and buffer are laid in the tiles' units
        from ..io.crs import metre_factors

        fh, fv = metre_factors(catalog.crs)
        in_metres = fh == 1.0 and fv == 1.0

        def metric_sample() -> tuple[np.ndarray, dict[str, np.ndarray]]:
            xyz, fields = _catalog_sample(
                catalog,
                last_returns_only=bool(last_returns_only),
                exclude_classes=tuple(exclude_classes or ()),
            )
            return (xyz if in_metres else xyz * np.array([fh, fh, fv])), fields

        auto = None
        measures = None
        if preset == "auto":
            # measured once on a sample of whole tiles, then fixed for every chunk
            sample = metric_sample()
            chosen, measures, regime = catalog_auto_parameters(
                catalog, method, sensor=sensor, sample=sample
            )
            auto = {"regime": regime, "measured": measures.to_dict(), "chosen": dict(chosen)}
            full_params = with_given(chosen, full_params)
            preset = None
        # validate the parameters once, here, before any work
        from ..ground import PTD, SegmentPTD

        cls_type = SegmentPTD if method == "segment-ptd" else PTD
        try:
            filt = cls_type(**{**(PRESETS[preset][method] if preset else {}), **full_params})
        except TypeError as exc:
            raise OptionError(f"invalid parameter for method {method!r}: {exc}") from None
        if buffer is None:
            canopy = measures is not None and measures.multi_return_share >= CANOPY_MULTI_RETURN
            buffer = ground_buffer(
                catalog, cell_size=float(filt.cell_size) / fh, canopy=bool(canopy)
            )
        if isinstance(filt, SegmentPTD):  # method segment-ptd
            if sample is None and not in_metres:
                sample = metric_sample()
            # one surface-growing radius for the whole catalog, as one in-memory run would
            # estimate it, instead of one per chunk (see catalog_grow_radius); the same for
            # the terrain pass's radius, estimated on its own cells
            def radius(density: float) -> float:
                return catalog_grow_radius(
                    catalog,
                    last_returns_only=bool(last_returns_only),
                    exclude_classes=tuple(exclude_classes or ()),
                    factor=float(filt.grow_radius_factor),
                    sample=None if sample is None else sample[0],
                    filter_density=density,
                )

            terrain = 0 < filt.terrain_density < filt.filter_density
            if (terrain and filt.terrain_grow_radius is None and filt.grow_radius is None):
                full_params["terrain_grow_radius"] = radius(float(filt.terrain_density))
            if filt.grow_radius is None:
                full_params["grow_radius"] = radius(float(filt.filter_density))
        # Seed cells are laid from the south-west corner of the filter's input: snap every
        # buffered box to the seed grid of the whole catalog (see make_chunks).
        bx, by = catalog.bounds[:2]
        if origin is None:
            origin = (0.0, 0.0)
            if chunk_size is None:
                chunk_size, origin = _ground_grid(
                    catalog, buffer=float(buffer), cell=float(filt.cell_size) / fh
                )
        chunks = make_chunks(
            catalog,
            chunk_size=chunk_size,
            buffer=buffer,
            origin=origin,
            snap=(bx, by, float(filt.cell_size) / fh),
            target_points=GROUND_TARGET_POINTS,
        )
        if not chunks:
            raise TilingError("the catalog holds no point")
        task = GroundTask(
            method=method,
            last_returns_only=bool(last_returns_only),
            exclude_classes=tuple(int(c) for c in (exclude_classes or ())),
            preset=preset,
            params=tuple(sorted(full_params.items())),
            evaluate=bool(evaluate),
            ignore_classes=tuple(int(c) for c in (ignore_classes or ())),
        )
        out_dir = Path(output_dir)
        if out_dir.exists() and not out_dir.is_dir():
            raise OptionError(f"output {out_dir} exists and is not a folder")
        outputs = _output_names(catalog, out_dir)
        inputs = {str(Path(t.path).resolve()) for t in catalog.tiles}
        for o in outputs:
            if str(o.resolve()) in inputs:
                raise OptionError(f"output {o} is also an input; lidarqa never modifies its inputs")
        vpc_path = out_dir / (vpc_name or f"{out_dir.resolve().name or 'ground'}.vpc")
        existing = [o for o in [*outputs, vpc_path] if o.exists()]
        if existing and not (overwrite or resume):
            raise OutputExistsError(
                f"output {existing[0]} exists"
                + (f" (and {len(existing) - 1} more)" if len(existing) > 1 else "")
                + "; pass --overwrite (overwrite=True) to replace, or --resume to finish a run"
            )
        made_dir = not out_dir.exists()
        out_dir.mkdir(parents=True, exist_ok=True)
        work = out_dir / WORK_DIR
        fp = _fingerprint(catalog, chunks, task)
        fp_text = json.dumps(fp, sort_keys=True)
        done: dict[str, ChunkGround] = {}
        if work.exists():
            same = False
            try:
                same = (work / "run.json").read_text(encoding="utf-8") == fp_text
            except OSError:
                same = False
            if resume and same:
                for c in chunks:
                    r = _load_chunk(work, c.id)
                    if r is not None:
                        done[c.id] = r
            else:
                if resume and not same:
                    warnings.warn(
                        "the work folder is from a run with other settings; starting over",
                        stacklevel=2,
                    )
                shutil.rmtree(work)
        work.mkdir(exist_ok=True)
        (work / "run.json").write_text(fp_text, encoding="utf-8")
        todo = [c for c in chunks if c.id not in done]
        messages: set[str] = set()
        per_tile: dict[int, list[str]] = {}
        for c in chunks:
            for t in c.tiles:
                per_tile.setdefault(t, []).append(c.id)

        def write_args(k: int, ids: Iterable[str] | None = None) -> tuple:
            tile = catalog.tiles[k]
            ids = per_tile.get(k, []) if ids is None else sorted(ids)
            return (tile.path, str(outputs[k]), k, tile.n_points, str(work), ids)

        # A tile can be written as soon as the chunks holding its points are done. On a
        # cluster, a worker process that has no chunk left writes such tiles, one at a time
        # (behind any chunk it holds), instead of waiting idle for the last chunks; the
        # other tiles are written after the chunks by every process
        def holds(c: Any, k: int) -> bool:  # chunk c's core may hold points of tile k
            x0, y0, x1, y1 = catalog.tiles[k].bounds2d
            tol = 1e-6 * max(1.0, abs(x0), abs(y0), abs(x1), abs(y1))
            return not (
                c.core[0] > x1 + tol or c.core[2] < x0 - tol
                or c.core[1] > y1 + tol or c.core[3] < y0 - tol
            )

        # (a write that finds a chunk missing fails and is done again after all chunks)
        holding = {k: {c.id for c in chunks if k in c.tiles and holds(c, k)} for k in per_tile}
        waiting = {k: ids - set(done) for k, ids in holding.items()}
        reading = {k: set(ids) - set(done) for k, ids in per_tile.items()}
        ready: list[int] = []
        early: dict[int, Any] = {}
        writes = threading.RLock()
        chunks_done = False

        def write_next(_: Any = None) -> None:
            with writes:
                client = engine.client
                if (chunks_done or not ready or client is None
                        or any(not f.done() for f in early.values())):
                    return
                k = ready.pop(0)
                early[k] = fut = client.submit(
                    _assemble_tile, *write_args(k, holding[k]), pure=False, priority=-10,
                    key=f"lidarqa-write-{k}-{os.getpid()}-{id(early)}",
                )
            fut.add_done_callback(write_next)

        here: dict[int, int | None] = {}

        def write_here() -> bool:  # this process, idle while the workers finish chunks
            with writes:
                if chunks_done or not ready:
                    return False
                k = ready.pop(0)
                here[k] = None
            try:
                here[k] = _assemble_tile(*write_args(k, holding[k]))
            except Exception:  # noqa: S110 - written again after the chunks
                pass
            return True

        def save(oc: Any) -> None:
            if not oc.ok:
                return
            _save_chunk(work, oc.result)
            messages.update(oc.result.warnings)
            with writes:
                for k in oc.chunk.tiles:
                    reading[k].discard(oc.chunk.id)
                    if not reading[k]:  # no chunk left reads it: its shared copy goes
                        unshare_tile(catalog.tiles[k].path)
                    waiting[k].discard(oc.chunk.id)
                    if not waiting[k] and k not in early and k not in ready:
                        ready.append(k)
            write_next()

        # The local processes share the tiles they decompress: without it each would
        # decompress nearly every tile, as every chunk's buffer reaches its neighbours. A
        # serial run whose tiles do not fit in its cache keeps them the same way: the 50-tile
        # block's chunks decompressed 135 tiles through the cache alone (a chunk's
        # neighbourhood is 3 x 3 tiles; the cache holds about 8)
        fits = catalog.n_points * _POINT_BYTES <= TILE_CACHE_BYTES
        local = engine.head_works or (engine.serial and not fits)
        spill = str(work / "tiles") if local and len(todo) > 1 else None
        try:
            with shared_tiles(spill):
                outcomes = run_chunks(
                    catalog,
                    todo,
                    replace(task, tile_spill=spill),
                    engine=engine,
                    progress=progress,
                    retries=retries,
                    skip_failed=True,
                    on_outcome=save,
                    keep_results=False,
                    description="Ground",
                    order_seed=order_seed,
                    idle=write_here,
                )
            failed = tuple((o.chunk.id, o.error or "failed") for o in outcomes if not o.ok)
            if failed:
                from .engine import ChunkFailedError

                raise ChunkFailedError(
                    f"{len(failed)} of {len(chunks)} chunk(s) failed (run again with --resume "
                    "to retry only those): " + "; ".join(f"{c}: {e}" for c, e in failed[:5]),
                    list(outcomes),
                )
            with writes:
                chunks_done = True
        except BaseException as exc:
            with writes:
                chunks_done = True
            # no output of a job that failed: a tile written early goes too (once its write
            # has ended; an interruption does not wait for it)
            for k in here:
                outputs[k].unlink(missing_ok=True)
            for k, fut in early.items():
                if isinstance(exc, Exception):
                    try:
                        fut.result()
                    except Exception:  # noqa: S110 - nothing written
                        pass
                fut.cancel()
                if fut.status == "finished":
                    outputs[k].unlink(missing_ok=True)
            # nothing to resume (no chunk finished): leave nothing behind at the output path
            if not any(work.glob("*.npz")):
                shutil.rmtree(out_dir if made_dir else work, ignore_errors=True)
            raise
        # --- final pass: one output tile per input tile, on the workers too -------------------
        counts = np.zeros(4, dtype=np.int64)
        have_counts = False
        for c in chunks:
            cc = _load_counts(work, c.id)
            if cc is not None:
                counts += np.asarray(cc, dtype=np.int64)
                have_counts = True
        # a LocalCluster that the chunks did not start (one chunk: a catalog of a few
        # million points) would cost more to start than these writes take
        writer = engine if engine.scheduler or engine.client else Engine("serial")
        rest = [k for k in range(len(catalog.tiles)) if k not in early and k not in here]
        n_ground = sum(
            run_tasks(
                _assemble_tile,
                [write_args(k) for k in rest],
                engine=writer,
                progress=progress,
                description="Writing tiles",
                names=[str(catalog.tiles[k].path) for k in rest],
            )
        )
        n_ground += sum(n for n in here.values() if n is not None)
        again = [k for k, n in here.items() if n is None]
        for k, fut in early.items():
            try:
                n_ground += int(fut.result())
            except Exception:  # noqa: PERF203 - written again here, where errors surface
                again.append(k)
        n_ground += sum(
            _assemble_tile(*write_args(k)) for k in again
        )
    finally:
        if own and engine is not None:
            engine.close()
    out_catalog = Catalog(
        tiles=tuple(
            type(t)(
                path=str(outputs[k].resolve()),
                n_points=t.n_points,
                bounds=t.bounds,
                crs_wkt=t.crs_wkt,
                point_format=t.point_format,
                version=t.version,
                is_copc=False,
                file_source_id=t.file_source_id,
            )
            for k, t in enumerate(catalog.tiles)
        ),
        crs=catalog.crs,
    )
    out_catalog.write_vpc(vpc_path, overwrite=True)
    shutil.rmtree(work, ignore_errors=True)
    evaluation = (
        filter_errors_from_counts(*counts.tolist()) if have_counts and counts.sum() else None
    )
    return CatalogGroundResult(
        outputs=tuple(str(o) for o in outputs),
        vpc=str(vpc_path),
        n_points=catalog.n_points,
        n_ground=n_ground,
        n_chunks=len(chunks),
        n_chunks_run=len(todo),
        n_chunks_resumed=len(done),
        chunk_size=chunks[0].size,
        buffer=float(buffer),
        bad=catalog.bad,
        evaluation=evaluation,
        parameters={
            **task.to_dict(),
            "filter": filt.to_dict(),
            **({"auto": auto} if auto is not None else {}),
        },
        chunks=tuple(
            {"id": c.id, "core": list(c.core), "status": "resumed" if c.id in done else "done"}
            for c in chunks
        ),
        warnings=tuple(sorted(messages)),
    )
