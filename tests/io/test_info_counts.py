"""``lidarqa info``'s counts against independent NumPy oracles."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from lidarqa.io import PointCloud
from lidarqa.io.info import _value_counts, describe_cloud


@settings(max_examples=60, deadline=None)
@given(arrays(st.sampled_from([np.uint8, np.uint16, np.int32]), st.integers(1, 300),
              elements=st.integers(0, 255)))
def test_value_counts_equal_numpy_unique(values):
    u, c = _value_counts(values)
    eu, ec = np.unique(values, return_counts=True)
    np.testing.assert_array_equal(u, eu)
    np.testing.assert_array_equal(c, ec)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(-5e6, 5e6), st.floats(-5e6, 5e6))
def test_occupied_area_equals_a_count_of_distinct_cells(seed, ox, oy):
    # negative and large coordinates: the packed cell key must not merge distinct cells
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(0, 80, 500) + ox, rng.uniform(0, 40, 500) + oy,
                           rng.normal(0, 1, 500)])
    info = describe_cloud(PointCloud(xyz))
    span = xyz.max(axis=0) - xyz.min(axis=0)
    cell = float(f"{np.clip(2.0 * np.sqrt(span[0] * span[1] / 500), 1.0, 50.0):.2g}")
    cells = np.unique(np.floor(xyz[:, :2] / cell), axis=0)
    assert info.density_per_m2 is not None
    np.testing.assert_allclose(info.density_per_m2, 500 / (len(cells) * cell**2), rtol=1e-12)
