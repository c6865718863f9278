"""A revolute joint seen from two parent markers, on a trial where the child does not move relative to them: the
least squares would chase the noise to a hinge of any size (a perfectly still trial gave marker distances of
1e40 mm, "< 5.9e40 mm" of required travel), so the estimator refuses with the travel it saw."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import DegenerateError
from identcheck.estimate.joint import MIN_TRAVEL_MM, pair_revolute


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.0, 0.3), st.integers(20, 300))
def test_a_child_that_hardly_moves_is_too_little_motion_not_a_hinge(seed, noise_mm, frames):
    """Parent markers 150-300 mm apart, the child marker within 300 mm of them, noise up to 0.3 mm: the pose
    noise moves the child at most a few mm in the parent's frame."""
    rng = np.random.default_rng(seed)
    a1 = rng.normal(scale=50.0, size=3)
    u, v = rng.normal(size=(2, 3))
    a2 = a1 + rng.uniform(150.0, 300.0) * u / np.linalg.norm(u)
    b = a1 + rng.uniform(50.0, 300.0) * v / np.linalg.norm(v)
    pose = rng.normal(scale=300.0, size=(frames, 1, 3))                 # the whole body moves, rigidly
    X = np.stack([a1, a2, b])[None] + pose + rng.normal(scale=noise_mm, size=(frames, 3, 3))
    with pytest.raises(DegenerateError, match=rf"too little motion: .* \(< {MIN_TRAVEL_MM:g} mm\)"):
        pair_revolute(X[:, 0], X[:, 1], X[:, 2:3], "revolute(2,1)")
