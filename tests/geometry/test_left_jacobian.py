"""How a rotation Exp(v) turns as its rotation vector moves: ``Exp(v + εu) Exp(v)ᵀ ≈ Exp(ε J_l(v) u)``, checked
by central differences at random v (from zero, where the series is used, to beyond π) and random u."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.geometry.rotations import left_jacobian_times, rotvec_matrix


def _turn_by_differences(v: np.ndarray, u: np.ndarray, h: float = 1e-6) -> np.ndarray:
    W = (rotvec_matrix(v + h * u) - rotvec_matrix(v - h * u)) / (2 * h) @ np.swapaxes(rotvec_matrix(v), 1, 2)
    return 0.5 * np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], axis=1)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([0.0, 1e-9, 1e-5, 1e-3, 0.3, 1.0, 2.5, 3.5]))
def test_left_jacobian_is_how_the_rotation_turns(seed, size):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(5, 3))
    v *= size / np.linalg.norm(v, axis=1, keepdims=True)
    u = rng.normal(size=(5, 3))
    np.testing.assert_allclose(left_jacobian_times(v, u), _turn_by_differences(v, u), atol=1e-7)
    # along v it is u itself, and one u (3,) serves every frame
    along = v * (1.0 / max(size, 1e-300))
    np.testing.assert_allclose(left_jacobian_times(v, along), along, atol=1e-12)
    np.testing.assert_allclose(left_jacobian_times(v, u[0]), left_jacobian_times(v, np.tile(u[0], (5, 1))))
