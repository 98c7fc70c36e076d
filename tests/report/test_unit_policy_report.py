"""report.json follows the unit policy of lidarqa.units (issue #16)."""

from __future__ import annotations

import json

from lidarqa.units import undefined_units


def test_every_number_in_report_json_has_a_unit(demo_run):
    assert demo_run["result"].exit_code == 0, demo_run["result"].output
    doc = json.loads((demo_run["out"] / "report.json").read_text(encoding="utf-8"))
    missing = undefined_units({k: v for k, v in doc.items() if k != "lidarqa_version"})
    assert missing == [], "\n".join(missing)


def test_every_output_of_the_demo_carries_its_crs(demo_run):
    """GeoPackage/LAZ outputs hold the CRS; CSV outputs have a .prj next to them (issue #16)."""
    import pytest

    import lidarqa
    from lidarqa.io.vector import read_points, read_segments

    pyogrio = pytest.importorskip("pyogrio")
    out = demo_run["out"] / "outputs"
    files = [p for p in out.rglob("*") if p.suffix in {".gpkg", ".csv", ".laz"}]
    assert files
    for p in files:
        if p.suffix == ".gpkg":
            assert pyogrio.read_info(p)["crs"] == "EPSG:2154", p
        elif p.suffix == ".laz":
            assert lidarqa.read(p).crs.to_epsg() == 2154, p
        else:
            assert p.with_suffix(".prj").is_file(), p
            header = p.read_text(encoding="utf-8").splitlines()[0]
            reader = read_segments if "x1" in header.split(",") else read_points
            if "x" in header.split(",") or "x1" in header.split(","):
                assert reader(p).crs.to_epsg() == 2154, p
