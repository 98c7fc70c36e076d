"""Terrain profiles with a known ground truth, for tests of break lines and perched surfaces.

:func:`ground_profile` samples a 60 × 60 m scene on a jittered grid:

- ``"deck"``: flat ground with a `width` m wide deck 5 m above it across the whole
  scene (a bridge deck or a long roof: vertical drops on both sides, nothing
  sampled beneath it). The deck is not ground.
- ``"terrace"``: ground that steps up 3 m along a straight wall (one-sided drop).
- ``"embankment"``: a 5 m high dam with an 8 m crest and 1:1.5 (33.7°) side slopes.
- ``"slope"``: a plane rising at 45°.

In every kind but ``"deck"`` all points are ground.
"""

from __future__ import annotations

import math

import numpy as np

from .._validate import check_choice

__all__ = ["ground_profile", "PROFILE_KINDS"]

PROFILE_KINDS = ("deck", "terrace", "embankment", "slope")


def ground_profile(
    kind: str, *, seed: int = 0, spacing: float = 1.0, noise: float = 0.02, width: float = 4.0
) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and their truth (True = ground) of one profile scene.

    Parameters
    ----------
    kind : {"deck", "terrace", "embankment", "slope"}
    seed : int
    spacing : float
        Grid spacing (m); each point is jittered by up to a third of it.
    noise : float
        Standard deviation of the height noise (m).
    width : float
        Width of the deck (m), ``"deck"`` only.
    """
    check_choice(kind, PROFILE_KINDS, "kind")
    rng = np.random.default_rng(seed)
    g = np.arange(0.0, 60.0, spacing)
    x, y = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    x = x + rng.uniform(-spacing / 3, spacing / 3, x.size)
    y = y + rng.uniform(-spacing / 3, spacing / 3, y.size)
    truth = np.ones(x.size, dtype=bool)
    if kind == "deck":
        on = np.abs(y - 30.0) <= width / 2
        z = np.where(on, 5.0, 0.0)
        truth = ~on
    elif kind == "terrace":
        z = np.where(y >= 30.0, 3.0, 0.0)
    elif kind == "embankment":
        grade = 1.0 / 1.5
        z = np.clip(5.0 - (np.abs(y - 30.0) - 4.0) * grade, 0.0, 5.0)
    else:
        z = y * math.tan(math.radians(45.0))
    z = z + rng.normal(0.0, noise, x.size)
    return np.column_stack([x, y, z]), truth
