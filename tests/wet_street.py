"""A dense street scan with a layer of multipath echoes under a wet band (known truth)."""

from __future__ import annotations

import numpy as np


def street_over_echoes(
    seed: int, *, size: float = 20.0, band: tuple[float, float] = (6.0, 14.0),
    origin: tuple[float, float, float] = (1000.0, 2000.0, 50.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Points of a `size` m square street (200 pts/m², 2 % grade, 1 cm noise) and the echo mask.

    In the band ``band[0] <= x < band[1]`` every 0.5 m cell holds one multipath echo
    0.25-0.35 m below the road: a lower layer a ground filter accepts. Coordinates are
    rounded to the millimetre, like a LAS file's.
    """
    rng = np.random.default_rng(seed)
    n = int(200 * size * size)
    xy = rng.uniform(0, size, (n, 2))
    z = 0.02 * xy[:, 0] + rng.normal(0, 0.01, n)
    cx, cy = np.meshgrid(np.arange(band[0] + 0.25, band[1], 0.5), np.arange(0.25, size, 0.5))
    e_xy = np.column_stack([cx.ravel(), cy.ravel()]) + rng.uniform(-0.2, 0.2, (cx.size, 2))
    e_z = 0.02 * e_xy[:, 0] - rng.uniform(0.25, 0.35, cx.size)
    p = np.vstack([np.column_stack([xy, z]), np.column_stack([e_xy, e_z])])
    return np.round(p + origin, 3), np.r_[np.zeros(n, bool), np.ones(cx.size, bool)]
