"""``--resume`` for every catalog job (issue #26 item 3): the engine keeps finished chunks'
parts, and a resumed run re-uses them (not recomputed) and gives the same answer."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from lidarqa.tiling.source import Source, open_source


class _Reads:
    """Counts Source.read_chunk calls; raises KeyboardInterrupt at call `stop_at` (1-based)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, stop_at: int | None = None) -> None:
        self.n = 0
        self.stop_at = stop_at
        original = Source.read_chunk

        def read_chunk(source: Source, chunk: object) -> object:
            self.n += 1
            if self.stop_at is not None and self.n == self.stop_at:
                raise KeyboardInterrupt
            return original(source, chunk)

        monkeypatch.setattr(Source, "read_chunk", read_chunk)


@dataclass(frozen=True)
class SumTask:
    """Points and summed heights of a chunk's core."""

    scale: float = 1.0

    def __call__(self, data: object) -> tuple[int, float]:
        z = data.cloud.xyz[data.core, 2]  # type: ignore[attr-defined]
        return int(len(z)), float(np.sum(z) * self.scale)


def _merge(parts: list) -> tuple[int, float]:
    return sum(p[0] for p in parts), sum(p[1] for p in parts)


def test_apply_resumes_an_interrupted_run(scene_tiles, tmp_path, monkeypatch):
    from lidarqa.tiling.apply import apply

    _, paths = scene_tiles
    src = open_source([str(p) for p in paths])
    work = tmp_path / "work"
    opts = {"chunk_size": 30.0, "buffer": 5.0}
    fresh = apply(src, SumTask(), _merge, **opts)
    n = len(fresh.chunks)
    assert n >= 8
    reads = _Reads(monkeypatch, stop_at=4)
    with pytest.raises(KeyboardInterrupt):
        apply(src, SumTask(), _merge, work_dir=work, **opts)
    assert len(list(work.glob("*.pkl"))) == 3  # the three chunks finished before the stop
    reads.n, reads.stop_at = 0, None
    run = apply(src, SumTask(), _merge, work_dir=work, resume=True, **opts)
    assert reads.n == n - 3  # the kept chunks were not read nor computed again
    assert len(run.resumed) == 3 and run.to_dict()["chunk_status"]["resumed"] == 3
    assert run.value == fresh.value
    assert not list(work.glob("*.pkl"))  # a run with no failed chunk removes its parts


def test_a_kept_part_is_only_reused_by_the_same_job(scene_tiles, tmp_path, monkeypatch):
    from lidarqa.tiling.apply import apply

    _, paths = scene_tiles
    src = open_source([str(p) for p in paths])
    work = tmp_path / "work"
    opts = {"chunk_size": 30.0, "buffer": 5.0}
    reads = _Reads(monkeypatch, stop_at=3)
    with pytest.raises(KeyboardInterrupt):
        apply(src, SumTask(), _merge, work_dir=work, **opts)
    kept = len(list(work.glob("*.pkl")))
    assert kept == 2
    reads.n, reads.stop_at = 0, None
    # another option, another selection, another grid: nothing re-used
    for s, task, o in ((src, SumTask(scale=2.0), opts), (src.select(classes=[2]), SumTask(), opts),
                       (src, SumTask(), {"chunk_size": 40.0, "buffer": 5.0})):
        reads.n = 0
        run = apply(s, task, _merge, work_dir=tmp_path / "other", resume=True, **o)
        assert not run.resumed and reads.n == len(run.chunks)
    assert len(list(work.glob("*.pkl"))) == kept
    # without --resume the kept parts are computed again (and then removed)
    reads.n = 0
    run = apply(src, SumTask(), _merge, work_dir=work, **opts)
    assert not run.resumed and reads.n == len(run.chunks)


# ------------------------------------------------------------------ every catalog command


def _invoke(args: list[str]) -> object:
    from lidarqa.cli.main import cli

    return CliRunner().invoke(cli, ["-q", *[str(a) for a in args]])


@pytest.fixture(scope="module")
def checks(scene_tiles, tmp_path_factory) -> Path:
    from lidarqa.testing import sample_checkpoints

    scene, _ = scene_tiles
    cp = sample_checkpoints(scene, 30, seed=2)
    path = tmp_path_factory.mktemp("chk") / "chk.csv"
    path.write_text("id,x,y,z\n" + "\n".join(
        f"{i},{x:.3f},{y:.3f},{z:.4f}" for i, (x, y, z) in zip(cp.ids, cp.xyz, strict=True)))
    return path


COMMANDS = {
    "planes": lambda folder, chk, out: ["planes", folder, "--classes", "6", "-o", out / "p.csv"],
    "checkpoints": lambda folder, chk, out: ["checkpoints", folder, chk, "--vertical"],
    "heights": lambda folder, chk, out: ["heights", folder, chk, chk, "--classes", "2",
                                         "--max-radius", "4"],
}


@pytest.mark.parametrize("name", sorted(COMMANDS))
@pytest.mark.slow  # ~14 s over the commands: each job run, interrupted and resumed
def test_every_catalog_command_resumes(name, scene_tiles, checks, tmp_path, monkeypatch):
    _, paths = scene_tiles
    folder = paths[0].parent
    monkeypatch.setenv("LIDARQA_WORK_DIR", str(tmp_path / "work"))
    base = [*COMMANDS[name](folder, checks, tmp_path), "--chunk-size", "30", "--workers", "1",
            "--overwrite"]

    def results(*extra: str) -> dict:
        out = tmp_path / "r.json"
        res = _invoke([*base, *extra, "--json", out])
        assert res.exit_code == 0, res.output
        d = json.loads(out.read_text())["results"]
        return d

    reads = _Reads(monkeypatch)
    fresh = results()
    n_fresh = reads.n
    assert n_fresh >= 4
    reads.n, reads.stop_at = 0, max(3, n_fresh // 2)
    res = _invoke(base)
    assert res.exit_code != 0  # interrupted
    kept = len(list((tmp_path / "work").glob("*.pkl")))
    assert kept >= 2
    reads.n, reads.stop_at = 0, None
    resumed = results("--resume")
    assert reads.n == n_fresh - kept  # kept chunks not recomputed
    # (a job of two passes, e.g. the ground spacing then the check points, reports its last)
    assert 0 < resumed["catalog"]["chunk_status"].get("resumed", 0) <= kept or name == "checkpoints"
    for d in (fresh, resumed):
        d.pop("catalog")
    assert resumed == fresh
    assert not list((tmp_path / "work").glob("*.pkl"))
