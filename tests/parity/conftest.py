"""Shared data of the parity tests: a cloud with heights in US survey feet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

FT = 1200.0 / 3937.0  # US survey foot, m
CRS_FT = "EPSG:26915+6360"  # UTM 15N (m) + NAVD88 height (US survey feet)


@pytest.fixture(scope="module")
def feet(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A synthetic scene with heights in US survey feet (EPSG:26915+6360), as a file and as four
    tiles (``file``, ``folder``), its check points (z in feet: ``chk``; in metres: ``chk_m``),
    the same scene in metres (``metres``) and a map of points (``map``)."""
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs
    from lidarqa.testing import make_scene, sample_checkpoints

    scene = make_scene(seed=3, size=(80.0, 80.0), density=4.0, returns=True,
                       origin=(500_000.0, 4_000_000.0, 100.0))
    base = tmp_path_factory.mktemp("feet_drift")
    xyz = np.round(np.asarray(scene.points, dtype=np.float64), 3)
    fields = {"classification": np.asarray(scene.classification, dtype=np.uint8),
              **{k: np.asarray(v) for k, v in scene.fields.items()}}
    ft = xyz.copy()
    ft[:, 2] = np.round(ft[:, 2] / FT, 3)
    lidarqa.write(PointCloud(ft, dict(fields), crs=parse_crs(CRS_FT)), base / "ft.laz")
    lidarqa.write(PointCloud(xyz, dict(fields), crs=parse_crs("EPSG:26915")), base / "m.laz")
    folder = base / "tiles_ft"
    folder.mkdir()
    gi = np.floor((xyz[:, 0] - 500_000.0) / 40.0)
    gj = np.floor((xyz[:, 1] - 4_000_000.0) / 40.0)
    for i in range(2):
        for j in range(2):
            sel = (gi == i) & (gj == j)
            lidarqa.write(PointCloud(ft[sel], {k: v[sel] for k, v in fields.items()},
                                     crs=parse_crs(CRS_FT)), folder / f"t_{i}_{j}.laz")
    cp = sample_checkpoints(scene, 25, seed=5)
    (base / "chk_ft.csv").write_text("id,x,y,z\n" + "\n".join(
        f"{i},{x:.3f},{y:.3f},{z / FT:.4f}" for i, (x, y, z) in zip(cp.ids, cp.xyz, strict=True)))
    (base / "chk_m.csv").write_text("id,x,y,z\n" + "\n".join(
        f"{i},{x:.3f},{y:.3f},{z:.4f}" for i, (x, y, z) in zip(cp.ids, cp.xyz, strict=True)))
    g = np.meshgrid(np.arange(500_005.0, 500_080.0, 9.0), np.arange(4_000_005.0, 4_000_080.0, 9.0))
    rng = np.random.default_rng(9)  # jittered: a regular grid's Delaunay TIN is not unique
    gx, gy = g[0] + rng.uniform(-2, 2, g[0].shape), g[1] + rng.uniform(-2, 2, g[1].shape)
    (base / "map.csv").write_text("id,x,y\n" + "\n".join(
        f"M{i},{x:.3f},{y:.3f}" for i, (x, y) in enumerate(zip(gx.ravel(), gy.ravel(),
                                                               strict=True))))
    return {"dir": base, "file": base / "ft.laz", "folder": folder, "metres": base / "m.laz",
            "chk": base / "chk_ft.csv", "chk_m": base / "chk_m.csv", "map": base / "map.csv"}
