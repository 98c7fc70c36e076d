"""Synthetic overlapping flight strips with known offsets and noise.

:func:`make_strip_scene` lays parallel strips (flown along x) over a gently
sloping ground with hip roofs (four-sided pyramids: faces of four aspects, so
horizontal offsets show up as height differences on the faces). Every strip
samples the true surface uniformly at random, then its coordinates are moved
by the strip's offset (x, y, z) and its heights get Gaussian noise. The truth
needed by exact tests is kept: offsets, noise and the surface function.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["StripScene", "make_strip_scene", "strip_surface_z"]


def strip_surface_z(
    xy: np.ndarray,
    *,
    z0: float = 100.0,
    ground_slope: float = 0.01,
    roof_spacing: float = 25.0,
    roof_size: float = 12.0,
    eave_height: float = 6.0,
    pitch: float = 30.0,
) -> np.ndarray:
    """Height of the strip scene's true surface at `xy` (m).

    Ground z = z0 + ground_slope·x; a hip roof (square pyramid of side
    `roof_size`, faces at `pitch` degrees, eaves at `eave_height` above the
    ground) is centred in every `roof_spacing` square.
    """
    x, y = xy[:, 0], xy[:, 1]
    ground = z0 + ground_slope * x
    u = np.mod(x, roof_spacing) - 0.5 * roof_spacing
    v = np.mod(y, roof_spacing) - 0.5 * roof_spacing
    r = np.maximum(np.abs(u), np.abs(v))
    half = 0.5 * roof_size
    roof = ground + eave_height + (half - r) * np.tan(np.radians(pitch))
    return np.where(r < half, roof, ground)


@dataclass(frozen=True)
class StripScene:
    """Points of several strips with the truth they were made from."""

    points: np.ndarray = field(repr=False)  # (N, 3)
    strip: np.ndarray = field(repr=False)  # (N,) int strip ids
    strip_ids: tuple[int, ...]
    offsets: np.ndarray  # (S, 3): each strip's coordinates minus the truth (m)
    noise: float  # σ of the height noise (m)
    params: dict[str, Any] = field(default_factory=dict)

    def offset(self, a: int, b: int) -> np.ndarray:
        """True offset of strip `b` relative to strip `a` (b − a), shape (3,)."""
        ia, ib = self.strip_ids.index(a), self.strip_ids.index(b)
        return self.offsets[ib] - self.offsets[ia]


def make_strip_scene(
    n_strips: int = 2,
    *,
    offsets: Any = None,
    noise: float = 0.02,
    density: float = 16.0,
    length: float = 100.0,
    strip_width: float = 60.0,
    overlap: float = 0.5,
    first_id: int = 1,
    seed: int = 0,
    **surface: Any,
) -> StripScene:
    """Parallel overlapping strips over ground and hip roofs.

    Parameters
    ----------
    n_strips : int, default 2
    offsets : array_like of shape (n_strips, 3), optional
        Each strip's shift (dx, dy, dz) in metres; default all zero.
    noise : float, default 0.02
        σ of the Gaussian height noise of every point (m).
    density : float, default 16.0
        Points per m² of one strip.
    length, strip_width : float
        Strip length along x and width across (m).
    overlap : float, default 0.5
        Fraction of a strip's width shared with the next strip.
    first_id : int, default 1
        Strip ids are first_id, first_id + 1, ...
    seed : int
    **surface
        Passed to :func:`strip_surface_z`.

    Returns
    -------
    StripScene
    """
    rng = np.random.default_rng(seed)
    off = np.zeros((n_strips, 3)) if offsets is None else np.asarray(offsets, dtype=float)
    if off.shape != (n_strips, 3):
        raise ValueError(f"offsets must have shape ({n_strips}, 3), got {off.shape}")
    step = strip_width * (1.0 - overlap)
    n = int(round(density * length * strip_width))
    pts, ids = [], []
    for s in range(n_strips):
        xy = rng.uniform((0.0, s * step), (length, s * step + strip_width), size=(n, 2))
        z = strip_surface_z(xy, **surface)
        p = np.column_stack([xy, z]) + off[s]
        p[:, 2] += rng.normal(0.0, noise, n)
        pts.append(p)
        ids.append(np.full(n, first_id + s, dtype=np.int64))
    return StripScene(
        points=np.vstack(pts),
        strip=np.concatenate(ids),
        strip_ids=tuple(range(first_id, first_id + n_strips)),
        offsets=off,
        noise=float(noise),
        params=dict(
            n_strips=n_strips,
            density=density,
            length=length,
            strip_width=strip_width,
            overlap=overlap,
            seed=seed,
            **surface,
        ),
    )
