"""Synthetic test/model segment sets with a known pairing (tests, benchmarks of line matching)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..io.vector import Segments

__all__ = ["SegmentPair", "make_segment_sets"]


@dataclass(frozen=True, eq=False)
class SegmentPair:
    """A model set, a test set derived from it, and the true pairs (test index, model index)."""

    model: Segments
    test: Segments
    truth: np.ndarray  # (k, 2) int64: test index, model index
    params: dict

    def truth_ids(self) -> list[tuple]:
        return [(self.test.ids[i], self.model.ids[j]) for i, j in self.truth]


def _rot(angles_deg: np.ndarray) -> np.ndarray:
    ax, ay, az = np.radians(angles_deg)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def make_segment_sets(
    *,
    n_model: int = 300,
    seed: int = 0,
    spacing: float = 12.0,
    length_range: tuple[float, float] = (2.0, 20.0),
    rotation_deg: tuple[float, float, float] = (0.01, 0.01, 0.05),
    translation: tuple[float, float, float] = (0.08, -0.05, 0.03),
    noise: float = 0.02,
    fragment_rate: float = 0.2,
    drop_rate: float = 0.05,
    extra_rate: float = 0.05,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SegmentPair:
    """Building-edge-like model segments and a test set with a known pairing.

    Model: `n_model` segments on a jittered grid (one per `spacing`² m² cell,
    mostly horizontal, some vertical), lengths uniform in `length_range` (m).
    Test: the model after a small rigid motion (rotation about the scene centre,
    degrees; translation, m), Gaussian end-point noise (`noise`, m), a fraction of
    segments cut into 2–3 pieces with gaps, a fraction dropped, and a fraction of
    extra random segments with no counterpart.
    """
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_model)))
    gx, gy = np.meshgrid(np.arange(side), np.arange(side))
    cells = np.column_stack([gx.ravel(), gy.ravel()])[:n_model].astype(float)
    centre = (cells + 0.5 + rng.uniform(-0.15, 0.15, cells.shape)) * spacing
    z = rng.uniform(3.0, 30.0, n_model)
    length = rng.uniform(*length_range, n_model)
    az = rng.uniform(0, np.pi, n_model)
    vertical = rng.random(n_model) < 0.1
    slope = np.where(vertical, np.pi / 2, rng.choice([0.0, 0.0, 0.0, np.radians(30)], n_model))
    u = np.column_stack([np.cos(az) * np.cos(slope), np.sin(az) * np.cos(slope), np.sin(slope)])
    c = np.column_stack([centre, z])
    mstart = c - 0.5 * length[:, None] * u
    mend = c + 0.5 * length[:, None] * u
    o = np.asarray(origin, float)
    model = Segments(ids=np.arange(n_model), start=mstart + o, end=mend + o)

    # test: pieces of kept model segments
    keep = rng.random(n_model) >= drop_rate
    starts: Any = []  # lists, then arrays
    ends: Any = []
    src: Any = []
    for j in np.flatnonzero(keep):
        if rng.random() < fragment_rate and length[j] >= 4.0:
            k = int(rng.integers(2, 4))
            cuts = np.sort(rng.uniform(0.2, 0.8, k - 1))
            edges = np.concatenate([[0.0], cuts, [1.0]])
            for a, b in zip(edges[:-1], edges[1:], strict=True):
                gap = min(0.3, 0.25 * (b - a) * length[j]) / length[j]
                a2, b2 = a + (gap if a > 0 else 0), b - (gap if b < 1 else 0)
                if (b2 - a2) * length[j] < 0.8:
                    continue
                starts.append(mstart[j] + a2 * (mend[j] - mstart[j]))
                ends.append(mstart[j] + b2 * (mend[j] - mstart[j]))
                src.append(j)
        else:
            starts.append(mstart[j])
            ends.append(mend[j])
            src.append(j)
    starts = np.asarray(starts)
    ends = np.asarray(ends)
    src = np.asarray(src, dtype=np.int64)
    # rigid motion about the scene centre, then noise
    r = _rot(np.asarray(rotation_deg, float))
    pivot = np.array([side * spacing / 2, side * spacing / 2, 15.0])
    t = np.asarray(translation, float)
    starts = (starts - pivot) @ r.T + pivot + t + rng.normal(0, noise, starts.shape)
    ends = (ends - pivot) @ r.T + pivot + t + rng.normal(0, noise, ends.shape)
    # extra segments anywhere in the scene, with no counterpart
    n_extra = int(round(extra_rate * n_model))
    ec = np.column_stack(
        [rng.uniform(0, side * spacing, (n_extra, 2)), rng.uniform(3, 30, n_extra)]
    )
    el = rng.uniform(*length_range, n_extra)
    ea = rng.uniform(0, np.pi, n_extra)
    eu = np.column_stack([np.cos(ea), np.sin(ea), np.zeros(n_extra)])
    starts = np.concatenate([starts, ec - 0.5 * el[:, None] * eu])
    ends = np.concatenate([ends, ec + 0.5 * el[:, None] * eu])
    # shuffle the test set so indices carry no information
    perm = rng.permutation(len(starts))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    test = Segments(ids=np.arange(len(starts)) + 100000, start=starts[perm] + o, end=ends[perm] + o)
    truth = np.column_stack([inv[: len(src)], src])
    truth = truth[np.lexsort((truth[:, 1], truth[:, 0]))]
    params = dict(
        n_model=n_model,
        seed=seed,
        spacing=spacing,
        noise=noise,
        fragment_rate=fragment_rate,
        drop_rate=drop_rate,
        extra_rate=extra_rate,
        rotation_deg=rotation_deg,
        translation=translation,
        n_extra=n_extra,
        n_dropped=int((~keep).sum()),
    )
    return SegmentPair(model=model, test=test, truth=truth, params=params)
