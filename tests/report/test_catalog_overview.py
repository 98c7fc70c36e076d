"""The report's catalog overview map and per-chunk status table."""

from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from lidarqa.report.catalog_overview import (  # noqa: E402
    STATUS_COLOURS,
    catalog_section,
    plot_catalog_overview,
)
from lidarqa.tiling.jobs_api import CatalogRun  # noqa: E402


def _fake_run(failed=("c0001_r0000",), retried=("c0000_r0001",), strips=None, resumed=()):
    tiles = tuple(SimpleNamespace(path=f"/data/t_{i}_{j}.laz", n_points=1000,
                                  bounds=(i * 50.0, j * 50.0, i * 50.0 + 50, j * 50.0 + 50, 0, 9))
                  for j in range(2) for i in range(3))
    cat = SimpleNamespace(tiles=tiles, n_points=6000, bounds=(0.0, 0.0, 150.0, 100.0),
                          bad=(("/data/broken.laz", "not a LAS file"),))
    chunks = tuple(SimpleNamespace(id=f"c{c:04d}_r{r:04d}", core=(c * 25.0, r * 25.0,
                                                                   c * 25.0 + 25, r * 25.0 + 25))
                   for r in range(4) for c in range(6))
    outs = []
    for ch in chunks:
        if ch.id in failed:
            outs.append(SimpleNamespace(chunk=ch, ok=False, error="MemoryError", attempts=3))
        else:
            outs.append(SimpleNamespace(chunk=ch, ok=True, error=None, resumed=ch.id in resumed,
                                        attempts=2 if ch.id in retried else 1))
    return CatalogRun(None, cat, chunks, tuple(outs), {"strip_chunks": strips or {}})


def _has_colour(png: bytes, hex_colour: str) -> bool:
    import matplotlib.image as mpimg

    img = mpimg.imread(io.BytesIO(png))[..., :3]
    rgb = np.array([int(hex_colour[k:k + 2], 16) for k in (1, 3, 5)]) / 255.0
    return bool((np.abs(img - rgb).max(axis=2) < 0.02).sum() > 50)


def test_section_counts_lists_failed_first_and_names_bad_tiles():
    sec = catalog_section(_fake_run(), title="Tiles")
    r = sec["results"]
    assert r["n_chunks"] == 24 and r["n_tiles"] == 6
    assert r["chunk_status"] == {"ok": 22, "retried": 1, "failed": 1, "skipped": 0}
    assert r["failed_chunks"] == ["c0001_r0000"]
    status = sec["tables"][0]
    assert [row[1] for row in status.rows[:2]] == ["failed", "retried"]
    assert status.rows[0][3] == "MemoryError"
    assert any("broken.laz" in n for n in sec["notes"])
    assert any("c0001_r0000" in n for n in sec["notes"])
    assert "1 failed" in sec["headline"]


def test_section_gives_the_figures_of_the_json_record():
    """Regression (issue #26): the section recounted the chunks (without ``resumed``)."""
    run = _fake_run(resumed=("c0002_r0000", "c0003_r0000"))
    r = catalog_section(run)["results"]
    assert r["chunk_status"] == {"ok": 20, "retried": 1, "failed": 1, "skipped": 0, "resumed": 2}
    for k, v in run.to_dict().items():
        assert r[k] == v, k


def test_overview_map_shows_the_status_colours():
    png = catalog_section(_fake_run())["figures"][0].png
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert _has_colour(png, STATUS_COLOURS["failed"])
    assert _has_colour(png, STATUS_COLOURS["ok"])
    clean = catalog_section(_fake_run(failed=(), retried=()))["figures"][0].png
    assert not _has_colour(clean, STATUS_COLOURS["failed"])
    assert not _has_colour(clean, STATUS_COLOURS["retried"])


def test_overview_map_gives_resumed_chunks_their_own_style_and_legend(monkeypatch):
    """Regression (issue #26): a resumed chunk was drawn white, as a chunk not run, unlisted."""
    import lidarqa.report.plots as plots

    figures, png_of = [], plots._png
    monkeypatch.setattr(plots, "_png", lambda fig: figures.append(fig) or png_of(fig))
    run = _fake_run(failed=(), retried=(), resumed=("c0002_r0000", "c0003_r0000"))
    png = catalog_section(run)["figures"][0].png
    assert _has_colour(png, STATUS_COLOURS["resumed"])
    assert STATUS_COLOURS["resumed"] not in (STATUS_COLOURS[s] for s in STATUS_COLOURS
                                             if s != "resumed")
    legend = [t.get_text() for t in figures[0].axes[0].get_legend().get_texts()]
    assert legend[:2] == ["chunk ok", "chunk resumed (from an earlier run)"]


def test_overview_map_draws_strips():
    tiles = [("t", (0.0, 0.0, 100.0, 100.0))]
    chunks = [(f"c{i}", (i * 50.0, 0.0, i * 50.0 + 50, 50.0)) for i in range(2)]
    status = {"c0": "ok", "c1": "ok"}
    plain = plot_catalog_overview(tiles, chunks, status)
    with_strips = plot_catalog_overview(tiles, chunks, status, strips={7: ["c0", "c1"]})
    assert not _has_colour(plain, "#1f77b4")
    assert _has_colour(with_strips, "#1f77b4")  # first strip colour
