"""Plots for the assessment report (matplotlib, imported lazily, Agg backend).

Every function returns the figure as PNG bytes, so the HTML report can embed
it as a ``data:`` URI and nothing touches the display or the network.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._plotting import png as _png
from .._plotting import pyplot as _plt

__all__ = [
    "CLASS_NAMES",
    "SIGMA_CLASSES",
    "plot_categories",
    "plot_values",
    "plot_ground_maps",
    "plot_matrix",
    "plot_threshold_curve",
    "plot_matched_segments",
    "plot_segments",
    "plot_residual_vectors",
    "plot_residual_histograms",
    "plot_sigma_classes",
    "plot_w_histogram",
    "plot_histogram",
]

#: ASPRS / IGN class names used in legends.
CLASS_NAMES = {
    0: "never classified",
    1: "unclassified",
    2: "ground",
    3: "low vegetation",
    4: "medium vegetation",
    5: "high vegetation",
    6: "building",
    7: "low point (noise)",
    9: "water",
    17: "bridge deck",
    18: "high noise",
    64: "other (64)",
    65: "artefact (65)",
    66: "virtual (66)",
    67: "other (67)",
}
_CLASS_COLOURS = {
    0: "#9e9e9e",
    1: "#bdbdbd",
    2: "#a0522d",
    3: "#b5d99c",
    4: "#6cbf5a",
    5: "#2e7d32",
    6: "#e53935",
    7: "#ff00ff",
    9: "#1e88e5",
    17: "#8e24aa",
    18: "#ff80ff",
    64: "#fdd835",
    65: "#ffb300",
    66: "#00acc1",
}
_CYCLE = [
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
]

#: Oude Elberink & Vosselman (2009) §5.1/Fig. 6: predicted σ of map-point heights in three classes.
SIGMA_CLASSES = (
    (0.20, "σ < 20 cm", "#2e7d32"),
    (0.50, "20–50 cm", "#f9a825"),
    (np.inf, "σ > 50 cm", "#c62828"),
)

_MAX_PLOT_POINTS = 80_000


def _thin(n: int, limit: int = _MAX_PLOT_POINTS, seed: int = 0) -> np.ndarray:
    """Indices of at most `limit` of `n` points (deterministic)."""
    if n <= limit:
        return np.arange(n)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(n, size=limit, replace=False))


def _map_axes(ax: Any, xy: np.ndarray | None = None) -> tuple[float, float]:
    """Equal-aspect map axes in coordinates relative to a rounded origin (labelled)."""
    ax.set_aspect("equal", adjustable="datalim")
    if xy is None or len(xy) == 0:
        return 0.0, 0.0
    x0 = float(np.floor(np.min(xy[:, 0]) / 10.0) * 10.0)
    y0 = float(np.floor(np.min(xy[:, 1]) / 10.0) * 10.0)
    ax.set_xlabel(f"x − {x0:,.0f} (m)")
    ax.set_ylabel(f"y − {y0:,.0f} (m)")
    return x0, y0


def _raster_grid(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, tuple]:
    """Pixel indices of points on a top-view raster (cell ≈ spacing, ≤ 500 pixels across)."""
    lo = xy.min(axis=0)
    hi = xy.max(axis=0)
    ext = np.maximum(hi - lo, 1e-6)
    spacing = float(np.sqrt(ext[0] * ext[1] / max(len(xy), 1)))
    cell = max(spacing * 1.6, float(ext.max()) / 500)
    shape = (int(ext[1] // cell) + 1, int(ext[0] // cell) + 1)
    col = ((xy[:, 0] - lo[0]) / cell).astype(np.int64)
    row = ((xy[:, 1] - lo[1]) / cell).astype(np.int64)
    extent = (lo[0], lo[0] + shape[1] * cell, lo[1], lo[1] + shape[0] * cell)
    return row, col, cell, (shape, extent)


def _top_order(z: np.ndarray | None, n: int) -> np.ndarray:
    """Drawing order: lowest first, so the highest point of a pixel wins (a top view)."""
    return np.arange(n) if z is None else np.argsort(z, kind="stable")


def plot_categories(
    xy: np.ndarray,
    values: np.ndarray,
    title: str,
    *,
    names: dict | None = None,
    colours: dict | None = None,
    size: float = 0.6,
    order: Sequence[Any] | None = None,
    z: np.ndarray | None = None,
) -> bytes:
    """Top view of points coloured by a categorical value (class, strip, ...).

    Large point sets are drawn as a raster (one pixel ≈ one point spacing; the
    highest point of a pixel wins when `z` is given), small ones as markers.
    """
    plt = _plt()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    xy = np.asarray(xy, dtype=float)[:, :2]
    values = np.asarray(values)
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    x0, y0 = _map_axes(ax, xy)
    cats = list(order) if order is not None else sorted(np.unique(values).tolist())
    cols = [(colours or {}).get(c, _CYCLE[i % len(_CYCLE)]) for i, c in enumerate(cats)]
    handles = []
    for c, colour in zip(cats, cols, strict=True):
        n = int(np.sum(values == c))
        if n:
            handles.append(Patch(color=colour, label=f"{(names or {}).get(c, str(c))} ({n:,})"))
    if len(xy) > 5000:
        code = np.full(len(values), -1)
        for k, c in enumerate(cats):
            code[values == c] = k
        row, col, _, (shape, extent) = _raster_grid(xy)
        img = np.full(shape, -1, dtype=np.int64)
        o = _top_order(z, len(xy))
        o = o[code[o] >= 0]
        if order is not None and z is None:  # later categories in `order` are drawn on top
            o = o[np.argsort(code[o], kind="stable")]
        img[row[o], col[o]] = code[o]
        masked = np.ma.masked_less(img, 0)
        ax.imshow(
            masked,
            origin="lower",
            extent=(extent[0] - x0, extent[1] - x0, extent[2] - y0, extent[3] - y0),
            cmap=ListedColormap(cols),
            vmin=-0.5,
            vmax=len(cats) - 0.5,
            interpolation="nearest",
        )
    else:
        for c, colour in zip(cats, cols, strict=True):
            m = values == c
            if m.any():
                ax.scatter(xy[m, 0] - x0, xy[m, 1] - y0, s=max(size, 4.0), c=colour, linewidths=0)
    ax.set_title(title)
    ax.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.12),
        fontsize=8,
        frameon=False,
        ncol=min(3, max(len(handles), 1)),
    )
    return _png(fig)


def plot_classes(
    xy: np.ndarray, classification: np.ndarray, title: str, *, z: np.ndarray | None = None
) -> bytes:
    """Top view coloured by ASPRS class."""
    return plot_categories(
        xy, classification, title, names=CLASS_NAMES, colours=_CLASS_COLOURS, z=z
    )


def plot_values(
    xy: np.ndarray,
    values: np.ndarray,
    title: str,
    *,
    label: str = "",
    cmap: str = "viridis",
    size: float = 0.6,
    z: np.ndarray | None = None,
    symmetric: bool = False,
) -> bytes:
    """Top view coloured by a continuous value (height, distance, ...); a raster for large sets."""
    plt = _plt()
    xy = np.asarray(xy, dtype=float)[:, :2]
    values = np.asarray(values, dtype=float)
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    x0, y0 = _map_axes(ax, xy)
    finite = np.isfinite(values)
    lo, hi = np.percentile(values[finite], [1, 99]) if finite.any() else (0.0, 1.0)
    if symmetric:
        lim = max(abs(lo), abs(hi), 1e-9)
        lo, hi = -lim, lim
    if len(xy) > 5000:
        row, col, _, (shape, extent) = _raster_grid(xy)
        img = np.full(shape, np.nan)
        o = _top_order(z, len(xy))
        o = o[finite[o]]
        img[row[o], col[o]] = values[o]
        im = ax.imshow(
            img,
            origin="lower",
            extent=(extent[0] - x0, extent[1] - x0, extent[2] - y0, extent[3] - y0),
            cmap=cmap,
            vmin=lo,
            vmax=hi,
            interpolation="nearest",
        )
    else:
        im = ax.scatter(
            xy[:, 0] - x0,
            xy[:, 1] - y0,
            s=max(size, 4.0),
            c=values,
            cmap=cmap,
            vmin=lo,
            vmax=hi,
            linewidths=0,
        )
    fig.colorbar(im, ax=ax, label=label, shrink=0.8)
    ax.set_title(title)
    return _png(fig)


def plot_ground_maps(
    xy: np.ndarray,
    predicted: np.ndarray,
    reference: np.ndarray | None,
    evaluated: np.ndarray | None = None,
) -> tuple[bytes, bytes | None]:
    """Ground classification map and (with a reference) the error map.

    The error map shows type I errors (ground rejected as object) in red,
    type II errors (object accepted as ground) in blue, and correct points grey.
    """
    pred = np.asarray(predicted, dtype=bool)
    names = {1: "ground", 0: "object"}
    cmap = plot_categories(
        xy,
        pred.astype(int),
        "Ground filter result",
        names=names,
        colours={1: "#a0522d", 0: "#90a4ae"},
        order=[1, 0],
    )
    if reference is None:
        return cmap, None
    ref = np.asarray(reference, dtype=bool)
    ev = np.ones(len(ref), bool) if evaluated is None else np.asarray(evaluated, dtype=bool)
    cat = np.full(len(ref), 3)  # not evaluated
    cat[ev & (ref == pred)] = 0
    cat[ev & ref & ~pred] = 1
    cat[ev & ~ref & pred] = 2
    err = plot_categories(
        xy,
        cat,
        "Errors against the reference classes",
        names={
            0: "correct",
            1: "type I (ground → object)",
            2: "type II (object → ground)",
            3: "not evaluated",
        },
        colours={0: "#cfd8dc", 1: "#d32f2f", 2: "#1565c0", 3: "#fff59d"},
        order=[0, 3, 1, 2],
        size=0.8,
    )
    return cmap, err


def plot_matrix(
    matrix: np.ndarray,
    title: str,
    *,
    label: str = "",
    binary: bool = False,
) -> bytes:
    """Heatmap of a (p, q) matrix (similarity distances, or a 0/1 correspondence)."""
    plt = _plt()
    m = np.asarray(matrix, dtype=float)
    fig, ax = plt.subplots(figsize=(6.0, 5.2))
    if m.size == 0:
        ax.text(0.5, 0.5, "empty", ha="center", va="center", transform=ax.transAxes)
    elif binary:
        ax.imshow(m > 0, cmap="Greys", interpolation="nearest", aspect="auto")
        ax.text(
            0.99,
            0.01,
            f"{int((m > 0).sum()):,} pairs",
            ha="right",
            va="bottom",
            transform=ax.transAxes,
            fontsize=9,
            color="#1565c0",
        )
    else:
        finite = np.isfinite(m)
        hi = np.percentile(m[finite], 95) if finite.any() else 1.0
        im = ax.imshow(
            np.where(finite, m, np.nan),
            cmap="viridis_r",
            vmin=0,
            vmax=hi,
            interpolation="nearest",
            aspect="auto",
        )
        fig.colorbar(im, ax=ax, label=label, shrink=0.85)
    ax.set_xlabel("model segments")
    ax.set_ylabel("test segments")
    ax.set_title(title)
    return _png(fig)


def plot_threshold_curve(curves: Sequence[dict[str, Any]]) -> bytes:
    """Sorted nearest distances, their second differences and the chosen peak.

    Each curve is a dict with ``label``, ``sorted`` (ascending nearest
    distances), optionally ``second_diff`` and ``peak_index`` and ``threshold``.
    """
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(6.4, 6.0), sharex=True)
    for i, c in enumerate(curves):
        colour = _CYCLE[i % len(_CYCLE)]
        d = np.asarray(c.get("sorted", []), dtype=float)
        if len(d) == 0:
            continue
        k = np.arange(len(d))
        axes[0].plot(k, d, ".-", color=colour, ms=3, lw=1, label=c.get("label", ""))
        thr = c.get("threshold")
        if thr is not None and np.isfinite(thr):
            axes[0].axhline(thr, color=colour, ls="--", lw=1)
        sd = c.get("second_diff")
        if sd is not None and len(sd):
            sd = np.asarray(sd, dtype=float)
            off = c.get("second_diff_offset", 1)
            axes[1].plot(np.arange(len(sd)) + off, sd, ".-", color=colour, ms=3, lw=1)
        pk = c.get("peak_index")
        if pk is not None and 0 <= int(pk) < len(d):
            axes[0].plot([int(pk)], [d[int(pk)]], "o", mfc="none", mec="k", ms=9)
            if sd is not None and len(sd):
                j = int(pk) - off
                if 0 <= j < len(sd):
                    axes[1].plot([int(pk)], [sd[j]], "o", mfc="none", mec="k", ms=9)
    axes[0].set_ylabel("nearest distance d")
    axes[0].set_title("Automatic threshold")
    axes[0].legend(fontsize=8, frameon=False)
    axes[1].set_ylabel("second difference")
    axes[1].set_xlabel("rank (sorted)")
    axes[1].axhline(0, color="#999", lw=0.5)
    return _png(fig)


def plot_segments(groups: Sequence[tuple[np.ndarray, np.ndarray, str]], title: str) -> bytes:
    """Top view of one or more segment sets: ``(start, end, label)`` each."""
    plt = _plt()
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    allxy = np.concatenate(
        [np.vstack([s[:, :2], e[:, :2]]) for s, e, _ in groups if len(s)] or [np.zeros((0, 2))]
    )
    x0, y0 = _map_axes(ax, allxy)
    off = np.array([x0, y0])
    for i, (s, e, label) in enumerate(groups):
        if len(s) == 0:
            continue
        segs = np.stack([s[:, :2] - off, e[:, :2] - off], axis=1)
        ax.add_collection(
            LineCollection(
                list(segs),
                colors=_CYCLE[i % len(_CYCLE)],
                linewidths=1.2,
                label=f"{label} ({len(s)})",
            )
        )
    ax.autoscale_view()
    ax.set_title(title)
    if any(len(s) for s, _, _ in groups):
        ax.legend(fontsize=8, frameon=False)
    else:
        ax.text(0.5, 0.5, "no segments", ha="center", va="center", transform=ax.transAxes)
    return _png(fig)


def plot_matched_segments(
    test: tuple[np.ndarray, np.ndarray],
    model: tuple[np.ndarray, np.ndarray],
    test_distance: np.ndarray,
    title: str,
) -> bytes:
    """Model segments in grey, test segments coloured by their distance to the matched one.

    Unmatched test segments are dashed black.
    """
    plt = _plt()
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(6.8, 5.6))
    ts, te = test
    ms, me = model
    allxy = np.vstack([a[:, :2] for a in (ts, te, ms, me) if len(a)] or [np.zeros((0, 2))])
    x0, y0 = _map_axes(ax, allxy)
    off = np.array([x0, y0])
    if len(ms):
        ax.add_collection(
            LineCollection(
                list(np.stack([ms[:, :2] - off, me[:, :2] - off], axis=1)),
                colors="#b0bec5",
                linewidths=3.0,
                label=f"model ({len(ms)})",
            )
        )
    d = np.asarray(test_distance, dtype=float)
    matched = np.isfinite(d)
    if (~matched).any():
        ax.add_collection(
            LineCollection(
                list(np.stack([ts[~matched, :2] - off, te[~matched, :2] - off], axis=1)),
                colors="k",
                linewidths=0.8,
                linestyles="dashed",
                label=f"test, unmatched ({int((~matched).sum())})",
            )
        )
    if matched.any():
        lc = LineCollection(
            list(np.stack([ts[matched, :2] - off, te[matched, :2] - off], axis=1)),
            cmap="plasma",
            linewidths=1.6,
            label=f"test, matched ({int(matched.sum())})",
        )
        lc.set_array(d[matched])
        lc.set_clim(0, max(float(np.percentile(d[matched], 95)), 1e-6))
        ax.add_collection(lc)
        fig.colorbar(lc, ax=ax, label="distance d", shrink=0.8)
    ax.autoscale_view()
    ax.set_title(title)
    ax.legend(fontsize=8, frameon=False, loc="upper left")
    return _png(fig)


def plot_residual_vectors(
    xyz: np.ndarray, residuals: np.ndarray, title: str = "Residuals"
) -> bytes:
    """Horizontal residual vectors as arrows, coloured by the vertical residual."""
    plt = _plt()
    xyz = np.asarray(xyz, dtype=float)
    r = np.asarray(residuals, dtype=float)
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    x0, y0 = _map_axes(ax, xyz)
    rz = r[:, 2]
    finite = np.isfinite(rz)
    lim = float(np.nanmax(np.abs(rz))) if finite.any() else 1.0
    lim = lim if lim > 0 else 1.0
    horiz = np.isfinite(r[:, :2]).all(axis=1) & (np.abs(r[:, :2]).sum(axis=1) > 0)
    sc = ax.scatter(
        xyz[:, 0] - x0,
        xyz[:, 1] - y0,
        c=np.where(finite, rz, np.nan),
        cmap="RdBu_r",
        vmin=-lim,
        vmax=lim,
        s=40,
        edgecolors="k",
        linewidths=0.4,
        zorder=3,
    )
    if horiz.any():
        ax.quiver(
            xyz[horiz, 0] - x0,
            xyz[horiz, 1] - y0,
            r[horiz, 0],
            r[horiz, 1],
            angles="xy",
            color="#333",
            width=0.004,
            zorder=4,
        )
        scale_note = "arrows: horizontal residual (auto-scaled)"
    else:
        scale_note = "no horizontal residuals (vertical check)"
    fig.colorbar(sc, ax=ax, label="vertical residual (m)", shrink=0.8)
    ax.set_title(title + "\n" + scale_note, fontsize=10)
    return _png(fig)


def plot_residual_histograms(residuals: np.ndarray) -> bytes:
    """Histograms of residual components (one panel each, NaN-only components skipped)."""
    plt = _plt()
    r = np.asarray(residuals, dtype=float).reshape(len(residuals), -1)
    cols = [
        i
        for i in range(r.shape[1])
        if np.isfinite(r[:, i]).any() and np.nanmax(np.abs(r[:, i])) > 0
    ]
    cols = cols or [r.shape[1] - 1]
    fig, axes = plt.subplots(1, len(cols), figsize=(3.2 * len(cols) + 0.4, 3.2), squeeze=False)
    for ax, i in zip(axes[0], cols, strict=True):
        v = r[np.isfinite(r[:, i]), i]
        ax.hist(v, bins=max(5, min(30, len(v) // 2 or 5)), color="#5c6bc0", edgecolor="white")
        ax.axvline(0, color="k", lw=0.8)
        if len(v):
            ax.axvline(
                float(np.mean(v)), color="#d32f2f", lw=1, ls="--", label=f"mean {np.mean(v):+.3f}"
            )
            ax.legend(fontsize=8, frameon=False)
        ax.set_xlabel(f"residual {'xyz'[i] if i < 3 else i} (m)")
    axes[0][0].set_ylabel("count")
    fig.suptitle("Residual distributions")
    return _png(fig)


def plot_histogram(values: np.ndarray, title: str, *, xlabel: str, bins: int = 40) -> bytes:
    """A plain histogram."""
    plt = _plt()
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    ax.hist(v, bins=bins, color="#5c6bc0", edgecolor="white")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.set_title(title)
    return _png(fig)


def sigma_class(sigma: np.ndarray) -> np.ndarray:
    """Class index 0/1/2 (< 20 cm, 20–50 cm, > 50 cm); -1 for NaN (failed map points)."""
    s = np.asarray(sigma, dtype=float)
    out = np.full(s.shape, -1, dtype=int)
    ok = np.isfinite(s)
    out[ok] = np.searchsorted(np.array([b for b, _, _ in SIGMA_CLASSES[:-1]]), s[ok], side="right")
    return out


def plot_sigma_classes(
    xy: np.ndarray,
    sigma: np.ndarray,
    background: np.ndarray | None = None,
) -> bytes:
    """Map points coloured in the paper's three σ classes (green < 20 cm ≤ yellow ≤ 50 cm < red)."""
    plt = _plt()
    xy = np.asarray(xy, dtype=float)
    cls = sigma_class(sigma)
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    x0, y0 = _map_axes(ax, xy if background is None or not len(background) else background)
    if background is not None and len(background):
        b = np.asarray(background)[_thin(len(background), 40_000)]
        ax.scatter(
            b[:, 0] - x0,
            b[:, 1] - y0,
            s=0.3,
            c="#cfd8dc",
            linewidths=0,
            rasterized=True,
            label="laser points",
        )
    for k, (_, label, colour) in enumerate(SIGMA_CLASSES):
        m = cls == k
        ax.scatter(
            xy[m, 0] - x0,
            xy[m, 1] - y0,
            s=14,
            c=colour,
            edgecolors="k",
            linewidths=0.3,
            label=f"{label} ({int(m.sum())})",
            zorder=3,
        )
    m = cls < 0
    if m.any():
        ax.scatter(
            xy[m, 0] - x0,
            xy[m, 1] - y0,
            s=18,
            marker="x",
            c="k",
            label=f"not fitted ({int(m.sum())})",
            zorder=3,
        )
    ax.set_title("Predicted σ of map points")
    ax.legend(
        loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, markerscale=1.2
    )
    return _png(fig)


def plot_w_histogram(
    w: np.ndarray, *, critical: float | None = None, title: str = "w-tests against N(0, 1)"
) -> bytes:
    """Histogram of w = Δh / σ_Δh (density) with the standard normal density."""
    plt = _plt()
    v = np.asarray(w, dtype=float)
    v = v[np.isfinite(v)]
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    lim = max(4.0, float(np.percentile(np.abs(v), 99.5)) if len(v) else 4.0)
    lim = min(lim, 12.0)
    bins = np.linspace(-lim, lim, 49)
    ax.hist(
        np.clip(v, -lim, lim),
        bins=bins,
        density=True,
        color="#90caf9",
        edgecolor="white",
        label=f"w ({len(v):,} points)",
    )
    x = np.linspace(-lim, lim, 400)
    ax.plot(x, np.exp(-0.5 * x * x) / np.sqrt(2 * np.pi), color="#d32f2f", lw=1.5, label="N(0, 1)")
    if critical is not None and np.isfinite(critical):
        for s in (-1, 1):
            ax.axvline(s * critical, color="k", ls="--", lw=0.8)
        ax.text(critical, ax.get_ylim()[1] * 0.9, f" k = {critical:.2f}", fontsize=8)
    if len(v):
        ax.set_title(
            f"{title}\nstd(w) = {np.std(v):.2f}, |w| < 1: {np.mean(np.abs(v) < 1):.0%}, "
            f"|w| < 2: {np.mean(np.abs(v) < 2):.0%}",
            fontsize=10,
        )
    else:
        ax.set_title(title)
    ax.set_xlabel("w")
    ax.set_ylabel("density")
    ax.legend(fontsize=8, frameon=False)
    return _png(fig)
