"""Spreadsheet CSV dialects: decimal commas are read, the rest get a hint (issue #16)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import lidarqa
from lidarqa.cli.main import cli
from lidarqa.errors import DataQualityWarning, ReadError
from lidarqa.io.text import dialect_hint
from lidarqa.io.vector import read_points


def test_semicolons_with_decimal_commas_are_read(tmp_path):
    p = tmp_path / "eu.csv"
    p.write_bytes("\ufeffid;x;y;z\nA;770500,05;6277500,10;20,5\nB;770510;6277510;21\n".encode())
    pts = read_points(p)
    np.testing.assert_allclose(pts.xyz, [[770500.05, 6277500.1, 20.5], [770510, 6277510, 21]])
    assert pts.ids.tolist() == ["A", "B"]
    c = tmp_path / "cloud.csv"
    c.write_text("x;y;z\n1,5;2,5;3,5\n4;5;6\n")
    np.testing.assert_allclose(lidarqa.read(c).xyz, [[1.5, 2.5, 3.5], [4, 5, 6]])


def test_decimal_commas_in_comma_separated_file_get_a_hint(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("id,x,y,z\nA,770500,05,6277500,10,20,5\n")
    with pytest.raises(ReadError, match="decimal commas"):
        read_points(p)
    r = CliRunner().invoke(cli, ["checkpoints", str(p), str(p)])
    assert r.exit_code == 1 and "decimal commas" in r.output and "Traceback" not in r.output


def test_not_utf8_and_utf16_hints(tmp_path):
    latin = tmp_path / "latin.csv"
    latin.write_bytes("x,y,z,name\n1,2,3,\xe9t\xe9\n".encode("latin-1"))
    assert "UTF-8" in dialect_hint(latin)
    u16 = tmp_path / "u16.csv"
    u16.write_bytes("x,y,z\n1,2,3\n".encode("utf-16"))
    assert "UTF-16" in dialect_hint(u16)
    # point lists: Latin-1 is read with a warning, never an internal error
    named = tmp_path / "named.csv"
    named.write_bytes("id,x,y,z\n\xe9t\xe91,1,2,3\n".encode("latin-1"))
    with pytest.warns(DataQualityWarning, match="Latin-1"):
        assert read_points(named).ids.tolist() == ["\xe9t\xe91"]


def test_plain_csv_gets_no_hint(tmp_path):
    p = tmp_path / "ok.csv"
    p.write_text("id,x,y,z\n" + "".join(f"{i},1.5,2.5,abc\n" for i in range(5)))
    assert dialect_hint(p) == ""
    with pytest.raises(ReadError) as err:
        read_points(p)
    assert "not numeric" in str(err.value) and "'abc'" in str(err.value)
