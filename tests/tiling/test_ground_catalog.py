"""Ground classification on a catalog: every point once, deterministic, resumable, exact counts."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.errors import OutputExistsError
from lidarqa.tiling import open_catalog
from lidarqa.tiling.engine import ChunkFailedError
from lidarqa.tiling.ground import WORK_DIR, GroundTask, ground_catalog


def _digests(paths) -> list[str]:
    return [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths]


def _merged(paths):
    clouds = [lidarqa.read(p) for p in paths]
    xyz = np.concatenate([c.xyz for c in clouds])
    fields = {k: np.concatenate([c.fields[k] for c in clouds]) for k in clouds[0].fields}
    return lidarqa.io.PointCloud(xyz, fields)


@pytest.fixture(scope="module")
def serial_run(scene_tiles, tmp_path_factory):
    _, paths = scene_tiles
    out = tmp_path_factory.mktemp("ground") / "serial"
    # default buffer (60 m): the tiled = untiled check needs it
    return ground_catalog(paths, out, chunk_size=60.0, workers=1, evaluate=True)


def test_outputs_hold_every_point_once_in_input_order(scene_tiles, serial_run):
    from lidarqa.ground import relabel_classification

    _, paths = scene_tiles
    res = serial_run
    assert res.n_chunks >= 4 and res.n_chunks_run == res.n_chunks
    assert [Path(p).name for p in res.outputs] == [p.name for p in paths]
    n_ground = 0
    for src, out in zip(paths, res.outputs, strict=True):
        a, b = lidarqa.read(src), lidarqa.read(out)
        np.testing.assert_array_equal(a.xyz, b.xyz)
        assert a.fields.keys() == b.fields.keys()
        for k in a.fields:
            if k != "classification":
                np.testing.assert_array_equal(a.fields[k], b.fields[k])
        g = b.fields["classification"] == 2
        n_ground += int(g.sum())
        np.testing.assert_array_equal(
            b.fields["classification"], relabel_classification(a.fields["classification"], g)
        )
    assert n_ground == res.n_ground
    assert not (Path(res.outputs[0]).parent / WORK_DIR).exists()
    vpc = open_catalog(res.vpc)
    assert [t.path for t in vpc.tiles] == [str(Path(p).resolve()) for p in res.outputs]


def test_tiled_equals_untiled_on_a_synthetic_scene(scene_tiles, serial_run):
    from lidarqa.ground import classify_ground

    scene, paths = scene_tiles
    whole = _merged(paths)
    untiled = classify_ground(whole).ground_mask
    tiled = _merged(serial_run.outputs).fields["classification"] == 2
    agree = float(np.mean(tiled == untiled))
    assert agree >= 0.995, agree
    # and the filter is right on this scene (known truth): tiling does not spoil it
    truth = np.concatenate([lidarqa.read(p).fields["classification"] for p in paths]) == 2
    assert np.mean(tiled == truth) > 0.9


def test_evaluation_counts_from_chunks_equal_whole_area_counts(scene_tiles, serial_run):
    from lidarqa.ground import filter_errors

    _, paths = scene_tiles
    ref = np.concatenate([lidarqa.read(p).fields["classification"] for p in paths]) == 2
    pred = _merged(serial_run.outputs).fields["classification"] == 2
    whole = filter_errors(ref, pred)
    e = serial_run.evaluation
    assert (e.a, e.b, e.c, e.d) == (whole.a, whole.b, whole.c, whole.d)
    assert e.kappa == whole.kappa and e.total == whole.total


def test_byte_identical_for_shuffled_order_and_two_workers(scene_tiles, small_runs, tmp_path):

    _, paths = scene_tiles
    ref, two = small_runs["serial"], small_runs["two"]
    shuffled = ground_catalog(
        paths, tmp_path / "shuffled", workers=1, order_seed=3, **small_runs["opts"]
    )
    assert _digests(shuffled.outputs) == _digests(ref.outputs)
    assert _digests(two.outputs) == _digests(ref.outputs)
    assert two.evaluation == ref.evaluation
    vpc = Path(two.vpc).read_text().replace("two", "X")
    assert vpc == Path(ref.vpc).read_text().replace("serial", "X")


def test_failed_chunk_is_reported_and_resume_runs_only_the_missing(
    scene_tiles, small_runs, tmp_path, monkeypatch
):
    _, paths = scene_tiles
    out = tmp_path / "out"
    original = GroundTask.__call__

    def flaky(self, data):
        if data.chunk.id == "c0001_r0001":
            raise RuntimeError("disk on fire")
        return original(self, data)

    monkeypatch.setattr(GroundTask, "__call__", flaky)
    with pytest.raises(ChunkFailedError, match="c0001_r0001.*disk on fire") as info:
        ground_catalog(
            paths, out, chunk_size=60.0, buffer=10.0, cell_size=20.0, workers=1, retries=1
        )
    failed = [o for o in info.value.outcomes if not o.ok]
    assert [o.chunk.id for o in failed] == ["c0001_r0001"] and failed[0].attempts == 2
    assert not any(out.glob("*.laz"))  # nothing assembled from an incomplete run
    saved = sorted(p.stem for p in (out / WORK_DIR).glob("*.npz"))
    assert "c0001_r0001" not in saved and len(saved) == len(info.value.outcomes) - 1
    monkeypatch.setattr(GroundTask, "__call__", original)
    res = ground_catalog(
        paths, out, chunk_size=60.0, buffer=10.0, cell_size=20.0, workers=1, resume=True
    )
    assert res.n_chunks_run == 1 and res.n_chunks_resumed == len(saved)
    # the uninterrupted serial run with the same options (shared; its `evaluate` adds counts
    # to the result, not to the files)
    ref = small_runs["serial"]
    same = {"chunk_size": 60.0, "buffer": 10.0, "cell_size": 20.0, "evaluate": True}
    assert small_runs["opts"] == same
    assert _digests(res.outputs) == _digests(ref.outputs)
    with pytest.raises(OutputExistsError):
        ground_catalog(paths, out, chunk_size=60.0, buffer=10.0, cell_size=20.0, workers=1)


@pytest.mark.slow  # ~5 s: the ground filter on a folder through the CLI
def test_cli_ground_on_a_folder(scene_tiles, tmp_path):
    from lidarqa.cli.main import cli

    _, paths = scene_tiles
    out = tmp_path / "cli"
    doc = tmp_path / "g.json"
    args = ["ground", str(paths[0].parent), "-o", str(out), "--workers", "1", "--chunk-size", "60"]
    args += ["--buffer", "10", "--cell-size", "20"]
    r = CliRunner().invoke(cli, [*args, "--evaluate", "--json", str(doc), "-q"])
    assert r.exit_code == 0, r.output
    d = json.loads(doc.read_text())["results"]
    assert d["n_points"] == sum(t.n_points for t in open_catalog(paths).tiles)
    assert d["n_chunks"] == len(d["chunks"]) and "kappa" in d
    assert sorted(p.name for p in out.glob("*.laz")) == sorted(p.name for p in paths)
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 1 and "exists" in r.output
    # two explicit files are a catalog too
    r = CliRunner().invoke(
        cli,
        ["ground", str(paths[0]), str(paths[1]), "-o", str(tmp_path / "two"), "--workers", "1"]
        + ["--buffer", "10", "--cell-size", "20", "--chunk-size", "60"],
    )
    assert r.exit_code == 0, r.output
    assert len(list((tmp_path / "two").glob("*.laz"))) == 2
    # a corrupt tile: refused naming it before any work; --skip-bad processes the others
    bad = tmp_path / "bad"
    bad.mkdir()
    for q in paths[:2]:
        shutil.copy(q, bad / q.name)
    (bad / "broken.laz").write_bytes(b"not a las file" * 30)
    args = ["ground", str(bad), "--workers", "1", "--buffer", "10", "--cell-size", "20"]
    r = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "b1")])
    assert r.exit_code == 1 and "broken.laz" in r.output
    assert not (tmp_path / "b1").exists() or not any((tmp_path / "b1").glob("*.laz"))
    doc = tmp_path / "b2.json"
    r = CliRunner().invoke(
        cli, [*args, "-o", str(tmp_path / "b2"), "--skip-bad", "--json", str(doc)]
    )
    assert r.exit_code == 0, r.output
    assert "broken.laz" in r.output
    d = json.loads(doc.read_text())["results"]
    assert [Path(b["path"]).name for b in d["bad_tiles"]] == ["broken.laz"]
    assert sorted(p.name for p in (tmp_path / "b2").glob("*.laz")) == sorted(
        q.name for q in paths[:2]
    )


@pytest.mark.parametrize("bad", [
    {"workers": -1},
    # ~20 s: the client tries the address until its 20 s connection timeout
    pytest.param({"scheduler": "tcp://127.0.0.1:1"}, marks=pytest.mark.slow),
])
def test_bad_engine_options_leave_nothing_at_the_output(scene_tiles, tmp_path, bad):
    """Found by the fuzz suite: --workers -1 left OUT/.lidarqa-work/run.json behind."""
    from lidarqa.errors import LidarQAError

    _, paths = scene_tiles
    out = tmp_path / "out"
    with pytest.raises(LidarQAError):
        ground_catalog(paths, out, **bad)
    assert not out.exists()


def test_dense_street_over_echoes_tiled_equals_untiled(tmp_path):
    # a ground-based scan (200 pts/m²) whose wet band leaves one multipath echo under every
    # 0.5 m cell: the surface rule (each cell filtered on its lowest return that starts a
    # surface) must give the same labels in chunks as in one run, and keep the road
    from wet_street import street_over_echoes

    from lidarqa.ground import classify_ground

    xyz, echo = street_over_echoes(3, size=24.0, band=(8.0, 16.0), origin=(7e5, 54e5, 30.0))
    cls = np.where(echo, 1, 2).astype(np.uint8)  # the echoes are not the road
    tile = ((xyz[:, :2] - [700000.0, 5400000.0]) // 12).astype(int)
    paths = []
    for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)):
        m = (tile[:, 0] == i) & (tile[:, 1] == j)
        paths.append(tmp_path / f"tile_{i}{j}.laz")
        lidarqa.write(lidarqa.io.PointCloud(xyz[m], {"classification": cls[m]}), paths[-1])
    res = ground_catalog(paths, tmp_path / "out", chunk_size=12.0, workers=1)
    assert res.n_chunks >= 4
    whole = _merged(paths)
    tiled = _merged(res.outputs).fields["classification"] == 2
    untiled = classify_ground(whole).ground_mask
    assert np.mean(tiled == untiled) >= 0.999
    road = whole.fields["classification"] == 2
    assert tiled[road].mean() >= 0.999 and not tiled[~road].any()


def test_a_one_chunk_catalog_starts_no_cluster_to_write(scene_tiles, tmp_path, monkeypatch):
    # --workers 2 on a catalog that fits one chunk: the chunk runs here, and so do the
    # writes (a LocalCluster started only for them costs more than they take)
    from lidarqa.tiling.engine import Engine

    def no_start(self):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(Engine, "start", no_start)
    _, paths = scene_tiles
    res = ground_catalog(paths, tmp_path / "one", chunk_size=1000.0, workers=2)
    assert res.n_chunks == 1
    assert [len(lidarqa.read(o)) for o in res.outputs] == [len(lidarqa.read(p)) for p in paths]


def test_tiles_are_written_while_the_last_chunks_run(scene_tiles, tmp_path, monkeypatch):
    # two local workers, chunks inside the 60 m tiles: this process holds its first chunk
    # until the worker process has written a tile whose chunks are all done (it waits at
    # most 60 s, which fails the test when the writes wait for every chunk); the outputs
    # are those of a serial run
    pytest.importorskip("distributed")
    import time

    _, paths = scene_tiles
    opts = {"chunk_size": 30.0, "origin": (1000.0, 2000.0), "buffer": 10.0, "cell_size": 20.0}
    serial = ground_catalog(paths, tmp_path / "serial", workers=1, **opts)
    out = tmp_path / "two"
    real = GroundTask.__call__
    seen: list[bool] = []

    def held(self, data):
        if not seen:
            deadline = time.monotonic() + 60.0
            while not list(out.glob("*.laz")) and time.monotonic() < deadline:
                time.sleep(0.05)
            seen.append(bool(list(out.glob("*.laz"))))
        return real(self, data)

    monkeypatch.setattr(GroundTask, "__call__", held)
    two = ground_catalog(paths, out, workers=2, **opts)
    assert seen == [True]
    assert _digests(two.outputs) == _digests(serial.outputs)
    assert not (out / WORK_DIR).exists()


def test_a_serial_run_too_big_for_its_cache_decompresses_each_tile_once(
    scene_tiles, tmp_path, monkeypatch
):
    # a catalog whose tiles do not fit in the tile cache (here: a cache of one tile): the
    # serial run keeps what it decompresses in its work folder and maps it again, instead
    # of decompressing a tile for every chunk that reads it; the outputs are the same
    import lidarqa.tiling.ground as ground
    from lidarqa.tiling import reader

    _, paths = scene_tiles
    opts = {"chunk_size": 30.0, "origin": (1000.0, 2000.0), "buffer": 10.0, "cell_size": 20.0}
    plain = ground_catalog(paths, tmp_path / "plain", workers=1, **opts)
    one_tile = max(lidarqa.read(p).xyz.nbytes for p in paths) * 2
    monkeypatch.setattr(ground, "TILE_CACHE_BYTES", one_tile)
    seen: list[str] = []
    real = reader._decompress

    def counting(path, fields):
        if reader._active().spill is not None:  # after the automatic parameters' sample
            seen.append(path)
        return real(path, fields)

    monkeypatch.setattr(reader, "_decompress", counting)
    with reader.tile_cache(one_tile, fields=ground._CHUNK_FIELDS):  # the job's own, smaller
        small = ground_catalog.__wrapped__(paths, tmp_path / "small", workers=1, **opts)
    assert _digests(small.outputs) == _digests(plain.outputs)
    assert seen and len(set(seen)) == len(seen)  # once each at most
    assert not (tmp_path / "small" / WORK_DIR).exists()
