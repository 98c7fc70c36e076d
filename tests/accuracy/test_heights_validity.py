"""Validity of the predicted precision on synthetic data with known noise (issue #7).

The whole chain is simulated as the model assumes: a planar surface, laser
points with point noise E1 plus one laser-block error (E2, E3, E4) per map-point
neighbourhood, map points far enough apart that neighbourhoods do not overlap
(so TIN vertices are independent: ρ = 0), and reference points with σ_ref noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lidarqa.accuracy import heights as H

OFFSET = np.array([500_000.0, 5_200_000.0])


def _true(xy):
    return 0.03 * (xy[:, 0] - OFFSET[0]) - 0.02 * (xy[:, 1] - OFFSET[1]) + 12.0


def simulate_chain(
    seed, *, n=60, spacing=10.0, density=1.0, sigma_z=0.08, sigma_ref=0.09, n_ref=5000, jitter=1.0
):
    rng = np.random.default_rng(seed)
    g = np.arange(n) * spacing
    gx, gy = np.meshgrid(g, g, indexing="ij")
    mxy = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(-jitter, jitter, (n * n, 2))
    mxy += OFFSET
    lo, hi = mxy.min(axis=0) - 6, mxy.max(axis=0) + 6
    xy = rng.uniform(lo, hi, (rng.poisson(density * np.prod(hi - lo)), 2))
    _, cell = cKDTree(mxy).query(xy)  # the map-point group each laser point belongs to
    block = rng.normal(0.0, H.laser_block_sigma(), len(mxy))
    z = _true(xy) + block[cell] + rng.normal(0.0, sigma_z, len(xy))
    rxy = rng.uniform(mxy.min(axis=0) + 5, mxy.max(axis=0) - 5, (n_ref, 2))
    rz = _true(rxy) + rng.normal(0.0, sigma_ref, n_ref)
    return np.column_stack([xy, z]), mxy, np.column_stack([rxy, rz])


@pytest.fixture(scope="module")
def chain_default():
    pts, mxy, ref = simulate_chain(11, sigma_ref=0.09)
    return H.assess_heights(pts, mxy, ref, sigma_ref=0.09, curvature=0.0, correlation=0.0)


@pytest.fixture(scope="module")
def chain_precise_reference():
    # σ_ref 2 cm: the TIN-propagated model σ dominates σ_Δh, so the test is sharp
    pts, mxy, ref = simulate_chain(12, sigma_ref=0.02)
    return pts, mxy, ref, H.assess_heights(pts, mxy, ref, sigma_ref=0.02, curvature=0.0)


def _check_w(rep):
    d = rep.to_dict()
    assert d["comparison"]["n"] >= 2000
    assert 0.95 <= d["w"]["std"] <= 1.05
    assert abs(d["w"]["frac_lt1"] - 0.683) <= 0.03
    assert abs(d["w"]["frac_lt2"] - 0.954) <= 0.03
    assert d["map_points"]["n_failed"] == 0
    return d


def test_w_distribution_paper_sigma_ref(chain_default):
    d = _check_w(chain_default)
    assert abs(d["comparison"]["mean"]) < 0.01


def test_w_distribution_precise_reference(chain_precise_reference):
    pts, mxy, ref, rep = chain_precise_reference
    d = _check_w(rep)
    # the empirical model σ recovers the predicted TIN σ (RMS over the reference points)
    predicted = np.sqrt(np.nanmean(rep.tin.sigma**2))
    assert d["comparison"]["sigma_model_empirical"] == pytest.approx(predicted, rel=0.05)
    # a wrong stochastic model is detected: ρ = 1 overstates σ (std(w) well below 1),
    # and dropping the laser-block term understates it (std(w) well above 1)
    wrong_rho = H.assess_heights(pts, mxy, ref, sigma_ref=0.02, curvature=0.0, correlation=1.0)
    assert wrong_rho.to_dict()["w"]["std"] < 0.85
    no_block = H.assess_heights(
        pts, mxy, ref, sigma_ref=0.02, curvature=0.0, sigma_gps=0, sigma_ins=0, sigma_strip=0
    )
    assert no_block.to_dict()["w"]["std"] > 1.3


@pytest.mark.slow  # ~6 s: a Monte Carlo calibration
def test_sigma_plane_matches_monte_carlo():
    """Predicted σ_plane vs the spread of fitted heights over 300 noise draws.

    Patchy laser coverage makes the radius grow and the map points extrapolate
    (s up to ~25 m), with correlated x, y, which eq. 8 gets wrong. Each draw is
    shifted 1 km in x so one batched call handles all of them.
    """
    rng = np.random.default_rng(7)
    side, trials = 200.0, 300
    xy = rng.uniform(0, side, (int(0.3 * side * side), 2))
    xy = xy[np.sin(xy[:, 0] / 12) + np.sin(xy[:, 1] / 17) > 0.3]
    mxy = rng.uniform(10, side - 10, (150, 2))
    shift = np.column_stack([np.arange(trials) * 1000.0, np.zeros(trials)])[:, None, :]
    all_xy = (xy[None] + shift).reshape(-1, 2)
    all_m = (mxy[None] + shift).reshape(-1, 2)

    def truth(p):
        return 0.05 * np.mod(p[:, 0], 1000.0) - 0.01 * p[:, 1] + 3.0

    pts = np.column_stack([all_xy, truth(all_xy) + rng.normal(0, 0.08, len(all_xy))])
    kw = dict(radius=2.0, min_points=6, sigma_gps=0, sigma_ins=0, sigma_strip=0, curvature=0)
    mp = H.map_point_heights(pts, all_m, **kw)
    assert not mp.failed.any()
    assert np.ptp(mp.radius[:150]) > 0 and np.nanmax(mp.distance[:150]) > 10
    err = (mp.height - truth(all_m)).reshape(trials, -1)
    predicted = mp.sigma_plane[:150]
    np.testing.assert_allclose(
        mp.sigma_plane.reshape(trials, -1), predicted[None].repeat(trials, 0)
    )
    pooled = np.std(err / predicted)
    assert pooled == pytest.approx(1.0, abs=0.03)
    ratio = err.std(axis=0) / predicted
    assert np.median(ratio) == pytest.approx(1.0, abs=0.03)
    # the paper's eq. 8 is not exact here
    eq8 = H.map_point_heights(pts, all_m, eq8_diagonal=True, **kw)
    assert abs(np.std(err / eq8.sigma_plane[:150]) - 1.0) > 0.05
