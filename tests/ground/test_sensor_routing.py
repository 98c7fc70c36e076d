"""Airborne or ground-based scan, told from the geometry alone (no scan angle; issue #28).

A ground-based scanner's point density falls steeply with the range from its
trajectory, so most of its points crowd a few cells of the density grid; airborne
strips sample the ground almost evenly. The oracle is the acquisition itself: the
same street is sampled once by a profile scanner driven along it and once evenly
from above, and only the sampling tells them apart.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from datapaths import SHARED, needs_shared

from lidarqa.ground import auto_parameters, classify_ground, measure_cloud
from lidarqa.ground.auto import MLS_CONCENTRATION, MLS_DENSITY
from lidarqa.io.las import read_las
from lidarqa.testing import make_scene, make_strip_scene

HALF_WIDTH = 12.0  # façades at y = ±12 m
HEIGHT = 10.0  # façade height (m)
SENSOR_Z = 2.0  # scanner height above the road (m)


def _street_profile_scan(*, length=40.0, line_step=0.1, n_angles=360, seed=0):
    """A profile scanner on a car driving along x: each scan line sweeps the y-z plane.

    Rays hit the road (z = 0) or the façades (|y| = HALF_WIDTH, up to HEIGHT); rays
    into the sky give no point. Returns the (N, 3) points.
    """
    rng = np.random.default_rng(seed)
    xs = np.arange(0.0, length, line_step)
    phi = np.linspace(-math.pi, math.pi, n_angles, endpoint=False) + 0.3 / n_angles
    x = np.repeat(xs, phi.size) + rng.normal(0, 0.005, xs.size * phi.size)
    p = np.tile(phi, xs.size)
    dy, dz = np.sin(p), np.cos(p)  # phi = 0 points up
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = np.where(dz < 0, -SENSOR_Z / dz, np.inf)
        t_wall = np.where(dy != 0, HALF_WIDTH / np.abs(dy), np.inf)
    t = np.minimum(t_ground, t_wall)
    y = t * dy
    z = SENSOR_Z + t * dz
    hit = np.isfinite(t) & (z <= HEIGHT) & (t < 60.0)
    pts = np.column_stack([x[hit], y[hit], np.maximum(z[hit], 0.0)])
    pts[:, 2] += rng.normal(0, 0.01, len(pts))
    return pts


def _street_from_above(density=20.0, *, length=40.0, seed=0):
    """The same street sampled evenly from above (an airborne strip): road, façade tops."""
    rng = np.random.default_rng(seed)
    n = int(density * length * 2 * (HALF_WIDTH + 3.0))
    xy = np.column_stack(
        [rng.uniform(0, length, n), rng.uniform(-HALF_WIDTH - 3, HALF_WIDTH + 3, n)]
    )
    z = np.where(np.abs(xy[:, 1]) > HALF_WIDTH, HEIGHT, 0.0) + rng.normal(0, 0.01, n)
    return np.column_stack([xy, z])


def test_profile_scan_is_ground_based_and_the_same_street_from_above_is_airborne():
    mls = measure_cloud(_street_profile_scan())
    als = measure_cloud(_street_from_above())
    assert mls.concentration > MLS_CONCENTRATION > als.concentration
    assert mls.concentration > 0.5 and als.concentration < 0.05
    assert mls.sensor == "mls" and als.sensor == "als"
    assert auto_parameters(mls)[2] == "mls"
    assert auto_parameters(als)[2] == "als-dense"


def test_routing_is_a_property_of_the_acquisition_not_of_the_point_count_or_order():
    pts = _street_profile_scan(seed=1)
    rng = np.random.default_rng(2)
    ref = measure_cloud(pts)
    half = measure_cloud(pts[rng.random(len(pts)) < 0.5])  # a sparser scanner, same pattern
    moved = pts[rng.permutation(len(pts))] + [512_345.0, 4_100_000.0, 210.0]
    assert measure_cloud(moved).concentration == pytest.approx(ref.concentration, abs=1e-12)
    assert half.sensor == ref.sensor == "mls"
    assert half.concentration == pytest.approx(ref.concentration, abs=0.1)


@pytest.mark.parametrize(
    "scene",
    [
        # walls sampled as densely as the terrain (an oblique look), cars, trees, 2 strips
        lambda: make_scene(seed=3, returns=True, strips=2),
        lambda: make_scene(seed=4, density=60.0, size=(60.0, 60.0)),
        lambda: make_strip_scene(4),
    ],
    ids=["scene-2-strips", "scene-60-pts", "4-strips"],
)
def test_synthetic_airborne_scenes_stay_airborne(scene):
    s = scene()
    m = measure_cloud(s.points)
    assert m.concentration < 0.5 * MLS_CONCENTRATION
    assert m.sensor == "als" and auto_parameters(m)[2].startswith("als")


def test_reason_names_the_figure_and_a_scan_angle_still_decides_first():
    pts = _street_profile_scan(length=20.0)
    r = classify_ground(pts)
    assert r.regime == "mls"
    assert "crowded cells" in r.regime_reason and "(> 33 %, MLS_CONCENTRATION)" in r.regime_reason
    assert r.to_dict()["measured"]["concentration"] == pytest.approx(r.measures.concentration)
    # an even cloud denser than MLS_DENSITY is still taken for ground-based (a part of a
    # scan far from the scanner), and the reason says which figure chose it
    rng = np.random.default_rng(7)
    even = np.column_stack([rng.uniform(0, 20, (60_000, 2)), rng.normal(0, 0.01, 60_000)])
    m = measure_cloud(even)
    assert m.density > MLS_DENSITY and m.concentration < 0.05 and m.sensor == "mls"
    from lidarqa.ground.auto import regime_reason

    assert "but density > 100 pts/m² (MLS_DENSITY)" in regime_reason(m, "mls")
    assert ", density <= 100" in regime_reason(measure_cloud(even[:8000]), "als-dense")
    # a recorded airborne scan angle is direct evidence and wins over the figure
    narrow = measure_cloud(pts, fields={"scan_angle_rank": np.full(len(pts), 15, np.int8)})
    assert narrow.sensor == "als" and narrow.concentration > MLS_CONCENTRATION


OAKLAND = SHARED / "oakland-mls" / "oakland_part2_ah.laz"


@needs_shared
def test_oakland_mobile_chunk_is_filtered_as_a_mobile_scan():
    # no scan angle, 27 pts/m² median per occupied cell: taken for dense airborne before
    # (4.05 % total error with the thinned, terrain-first filter; CSF 2.53 %). Ground-based
    # scans are thinned like dense airborne clouds but get no terrain-first pass
    pc = read_las(OAKLAND)
    r = classify_ground(pc, evaluate=True)
    assert r.regime == "mls" and r.measures.concentration > 0.5
    assert r.parameters["filter_density"] > 0 and r.parameters["terrain_density"] == 0
    assert r.evaluation.total < 0.03  # 2.52 % measured


@needs_shared
@pytest.mark.parametrize(
    "path",
    [
        # the airborne file with the most crowded cells of those measured (0.17)
        "isprs-filtertest-pdal/samp24-utm.laz",
        # a dense urban tile (its scan angle decides; the figure agrees)
        "ign-lidarhd/test_data_77050_627755_LA93_IGN69.laz",
    ],
)
def test_real_airborne_tiles_are_not_crowded(path):
    from lidarqa.ground import ground_candidates

    pc = read_las(SHARED / path)
    cand = ground_candidates(pc)[0]
    m = measure_cloud(pc.xyz[cand])  # no fields: the geometry alone decides
    assert m.concentration < 0.6 * MLS_CONCENTRATION
    assert m.sensor == "als"
