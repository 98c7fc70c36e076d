"""File vs catalog parity of ground labels (issue #26: >= 99.9 % of the labels equal).

One in-memory run of a file against the catalog run of the same points cut into chunks
(``--chunk-size`` smaller than the area, the default buffer: one seed cell). Measured
when written: the six IGN 50 m tiles as a folder in chunks of 100 m or 50 m (6 chunks:
0 of 405,937 labels differ) agree on >= 99.99 % of the labels; a 100 x 100 m forest block
of ``lasR-bcts/bcts_2`` in 4 chunks of 50 m (each chunk's buffer reaches the whole block)
on 100 %: it was 98.8 % while the terrain pass of a catalog grew its surfaces with the
fine radius scaled and the in-memory run with its own estimate (the catalog now gives
both radii). All of bcts_2 in 4 chunks of 150 m agrees on 98.39 %, short of the
issue's 99.9 %: there segment-PTD's segments and TIN densification under canopy reach
beyond a chunk's buffer (one segment of the terrain pass spans most of the tile, and
its decision flips with the part a chunk sees). That test records the floor and is an
expected failure against the target until the filter is made local.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from datapaths import SHARED, ign_block, needs_shared

from lidarqa.cli.main import cli

pytestmark = [needs_shared, pytest.mark.slow]

TARGET = 0.999  # issue #26: ground labels >= 99.9 % equal


def _ground(tmp: Path, src: Path, *extra: object) -> np.ndarray:
    """The ground mask (class 2 in the outputs) of ``lidarqa ground SRC``, in input order."""
    import laspy

    out = tmp / ("o" if Path(src).is_dir() or extra else "o.laz")
    res = CliRunner().invoke(cli, ["-q", "ground", str(src), "-o", str(out),
                                   *[str(e) for e in extra]])
    assert res.exit_code == 0, res.output
    files = sorted(out.glob("*.laz")) if out.is_dir() else [out]
    return np.concatenate([np.asarray(laspy.read(f).classification) == 2 for f in files])


def test_ground_labels_of_the_ign_file_and_the_chunked_folder_agree(tmp_path):
    folder, merged, _ = ign_block(tmp_path)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _ground(tmp_path / "a", merged)
    b = _ground(tmp_path / "b", folder, "--chunk-size", "100", "--workers", "1")
    assert len(a) == len(b) == 405937
    assert 0.2 < a.mean() < 0.6  # a real ground/non-ground split
    agree = float(np.mean(a == b))
    assert agree >= TARGET, f"{agree:.5f} of the labels equal ({int((a != b).sum())} differ)"


def test_ground_labels_of_a_forest_block_and_its_chunks(tmp_path):
    """bcts_2 (BC forest), a 100 x 100 m block in memory and in 4 chunks of 50 m."""
    import laspy

    las = laspy.read(SHARED / "lasR-bcts" / "bcts_2.laz")
    x, y = np.asarray(las.x), np.asarray(las.y)
    keep = (x < 885100.0) & (y < 629500.0)
    block = laspy.LasData(las.header)
    block.points = las.points[keep]
    block.update_header()
    block.write(tmp_path / "block.laz")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _ground(tmp_path / "a", tmp_path / "block.laz")
    b = _ground(tmp_path / "b", tmp_path / "block.laz", "--chunk-size", "50", "--workers", "1")
    assert len(a) == len(b) == int(keep.sum()) > 50_000
    assert 0.02 < a.mean() < 0.5  # a real ground/non-ground split
    agree = float(np.mean(a == b))
    assert agree >= TARGET, f"{agree:.5f} of the labels equal ({int((a != b).sum())} differ)"


def test_ground_labels_of_a_forest_tile_and_its_four_chunks(tmp_path):
    """All of bcts_2 (BC forest, 193 x 300 m) in memory and in 4 chunks of 150 m."""
    src = SHARED / "lasR-bcts" / "bcts_2.laz"
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _ground(tmp_path / "a", src)
    b = _ground(tmp_path / "b", src, "--chunk-size", "150", "--workers", "1")
    assert len(a) == len(b) > 800_000
    agree = float(np.mean(a == b))
    # 98.39 % with one seed cell of buffer; under a canopy (41 % of the last returns from
    # multi-return pulses) the ground job reads two
    assert agree >= TARGET, f"{agree:.5f} of the labels equal ({int((a != b).sum())} differ)"
