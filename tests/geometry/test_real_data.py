"""Planes and roof edges on real IGN LiDAR HD tiles (buildings, class 6, per flight strip)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lidarqa
from lidarqa.geometry import extract_corners, extract_edges, segment_planes
from lidarqa.geometry.edges import edges_from_segmentation


def _strip_edges(path: Path, strip: int):
    cloud = lidarqa.read(path).select(classes=6, source_id=strip)
    seg = segment_planes(cloud.xyz)
    edges, _ = edges_from_segmentation(cloud.xyz, seg, crs=cloud.crs)
    return cloud, seg, edges


def _horizontal(edges) -> np.ndarray:
    d = (edges.end - edges.start) / edges.lengths[:, None]
    return np.abs(d[:, 2]) < 0.1


def _match_distance(a, b, max_angle: float = 5.0, max_dist: float = 1.0) -> np.ndarray:
    """Distance of each edge midpoint of `a` to the nearest parallel, overlapping edge of `b`."""
    out = []
    ub = (b.end - b.start) / b.lengths[:, None]
    for i in range(len(a)):
        ua = (a.end[i] - a.start[i]) / a.lengths[i]
        mid = (a.start[i] + a.end[i]) / 2
        ok = np.degrees(np.arccos(np.clip(np.abs(ub @ ua), 0, 1))) <= max_angle
        t0 = np.einsum("ij,ij->i", a.start[i] - b.start, ub)
        t1 = np.einsum("ij,ij->i", a.end[i] - b.start, ub)
        ok &= (np.minimum(np.maximum(t0, t1), b.lengths) - np.maximum(np.minimum(t0, t1), 0)) > 0
        w = mid - b.start
        d = np.linalg.norm(w - np.einsum("ij,ij->i", w, ub)[:, None] * ub, axis=1)
        d = np.where(ok, d, np.inf)
        if d.min() <= max_dist:
            out.append(d.min())
    return np.array(out)


def test_demo_tile_roof_planes_and_edges(demo_tile: Path) -> None:
    cloud = lidarqa.read(demo_tile).select(classes=6)
    seg = segment_planes(cloud.xyz)
    assert seg.n_segments >= 10
    assert (seg.labels >= 0).mean() > 0.7
    assert np.median(seg.rmse) < 0.10  # roof planes of two ALS strips together: cm to dm
    e = extract_edges(cloud.xyz, segmentation=seg)
    assert len(e) >= 10
    assert _horizontal(e).sum() >= 5  # ridges and eaves
    assert np.isfinite(e.start).all() and np.isfinite(e.end).all()
    # cm-level lines; a short edge between shallow-angled planes may reach ~0.11 m (which
    # one depends on how ties in the segmentation's order fall)
    assert np.quantile(e.attributes["sigma_line"], 0.95) < 0.1
    assert (e.attributes["sigma_line"] < 0.15).all()
    c = extract_corners(cloud.xyz, segmentation=seg)
    assert np.isfinite(c.xyz).all()


@pytest.mark.parametrize("tile", ["77050_627755", "77055_627755", "77060_627755"])
def test_ign_strips_give_matching_roof_edges(shared_data: Path, tile: str) -> None:
    path = shared_data / "ign-lidarhd" / f"test_data_{tile}_LA93_IGN69.laz"
    _, s706, e706 = _strip_edges(path, 706)
    _, s707, e707 = _strip_edges(path, 707)
    assert len(e706) >= 5 and len(e707) >= 5
    assert _horizontal(e706).sum() >= 5 and _horizontal(e707).sum() >= 5
    assert e706.crs is not None and e706.crs.to_epsg() == 2154
    d = _match_distance(e706, e707)
    assert len(d) >= 3  # the same ridges/eaves are found in both strips
    # ... and lie within decimetres of each other (a median of 5-7 matches: 0.05-0.31 m)
    assert np.median(d) < 0.35


def test_cli_edges_per_strip(shared_data: Path, tmp_path: Path) -> None:
    from click.testing import CliRunner

    from lidarqa.cli.main import cli
    from lidarqa.io.vector import read_segments

    path = shared_data / "ign-lidarhd" / "test_data_77060_627755_LA93_IGN69.laz"
    found = {}
    for strip in (706, 707):
        out = tmp_path / f"edges_{strip}.gpkg"
        r = CliRunner().invoke(cli, ["-q", "edges", str(path), "-o", str(out), "--classes", "6",
                                     "--source-id", str(strip)])
        assert r.exit_code == 0, r.output
        found[strip] = read_segments(out)
        assert found[strip].crs is not None and found[strip].crs.to_epsg() == 2154
        assert _horizontal(found[strip]).sum() >= 5
    d = _match_distance(found[706], found[707])
    assert len(d) >= 3 and np.median(d) < 0.3
