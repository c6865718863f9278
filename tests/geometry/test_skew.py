"""The cross-product matrix shared by the fits' Jacobian and seed 001's covariances: [v]× x = v × x, antisymmetric,
for stacks of any shape."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.geometry.rotations import skew


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), shape=st.lists(st.integers(1, 4), max_size=2))
def test_skew_is_the_cross_product(seed, shape):
    rng = np.random.default_rng(seed)
    v, x = rng.normal(size=tuple(shape) + (3,)), rng.normal(size=tuple(shape) + (3,))
    S = skew(v)
    assert S.shape == tuple(shape) + (3, 3)
    np.testing.assert_allclose((S @ x[..., None])[..., 0], np.cross(v, x), atol=1e-12)
    np.testing.assert_array_equal(S, -np.swapaxes(S, -1, -2))
