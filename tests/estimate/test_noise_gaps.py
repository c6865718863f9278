"""The noise floor from distances within segments, frame to frame: where gaps leave too few runs of consecutive
frames (every other frame empty) it is taken over the frames seen, in order, as in the same trial at half the rate,
not lost (``skeleton`` had then skipped its check for groups that may be two segments and called the trial
settled)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.estimate.noise import noise_floor
from identcheck.infer.result import SkeletonResult


def _rigid_cluster(rng, n: int, sigma: float) -> np.ndarray:
    """Four markers on one rigid body moving smoothly, with white noise sigma (mm): (n, 4, 3)."""
    local = rng.normal(0.0, 60.0, (4, 3))
    t = np.arange(n) / 100.0
    angle = 0.6 * np.sin(2 * np.pi * 0.5 * t)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return np.einsum("fij,mj->fmi", R, local) + rng.normal(0.0, sigma, (n, 4, 3))


@settings(max_examples=15, deadline=None)
@given(n=st.integers(60, 400), sigma=st.floats(0.2, 2.0), seed=st.integers(0, 10_000))
def test_every_other_frame_empty_gives_the_half_rate_trials_noise(n, sigma, seed):
    data = _rigid_cluster(np.random.default_rng(seed), n, sigma)
    labels = ["A", "B", "C", "D"]
    gappy = data.copy()
    gappy[1::2] = np.nan
    a = noise_floor(gappy, labels, {"body": labels})
    b = noise_floor(data[::2], labels, {"body": labels})
    assert a.sigma_mm == pytest.approx(b.sigma_mm, rel=1e-12) and a.lag1 == pytest.approx(b.lag1, abs=1e-12)
    assert 0.5 * sigma < a.sigma_mm < 2.0 * sigma


@pytest.mark.parametrize("source, settled", [("inferred", False), ("given", True)])
def test_an_inferred_skeleton_without_a_noise_estimate_is_not_settled(source, settled):
    """Whether a group may be two segments is judged against the noise: without it the check did not run."""
    doc = {"segments": {"a": ["A", "B", "C"], "b": ["D", "E", "F"]}, "joints": [{"name": "a_b"}],
           "grouping": {"source": source, "widened": []}, "noise": None, "may_be_two_segments": []}
    assert SkeletonResult.from_dict(doc).ok is settled
    doc["noise"] = {"sigma_mm": 0.5, "lag1": 0.0, "n_pairs": 6}
    assert SkeletonResult.from_dict(doc).ok
