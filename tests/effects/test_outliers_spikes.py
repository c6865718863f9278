"""A gross error under serially correlated noise: the departure of a sample from its neighbours in time
(:func:`identcheck.effects.outliers.spike_residuals`) is the least-squares size of a one-frame error in AR(1) noise.
It moves by the error's full size at its frame and by −c times it beside, whatever the noise; on AR(1) noise alone
its variance is σ²(1 − φ²)/(1 + φ²), a fraction of the residual's, so an error the noise bound cannot tell from the
noise's own tail stands out of it (a 7 mm error at σ 1.3 mm, φ 0.75: 5 standard deviations of the residual, 10 of
the departure; named on held-out draw 41, trial_0040, which the residual alone left unnamed)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.effects.outliers import spike_residuals


def _ar1(rng, n_frames: int, n_markers: int, phi: float, sigma: float) -> np.ndarray:
    e = rng.normal(0.0, sigma * np.sqrt(1 - phi ** 2), (n_frames, n_markers, 3))
    x = np.empty_like(e)
    x[0] = rng.normal(0.0, sigma, (n_markers, 3))
    for t in range(1, n_frames):
        x[t] = phi * x[t - 1] + e[t]
    return x


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.98), st.integers(3, 300), st.integers(1, 5),
       st.floats(-50.0, 50.0))
def test_an_error_moves_its_frame_by_its_size_and_its_neighbours_by_minus_c_times_it(seed, phi, n_frames, n_markers,
                                                                                     size):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, n_frames, n_markers, phi, 1.0)
    seen = rng.random((n_frames, n_markers)) > 0.1
    t, m, k = rng.integers(1, n_frames - 1), rng.integers(n_markers), rng.integers(3)
    seen[t - 1:t + 2, m] = True
    hit = noise.copy()
    hit[t, m, k] += size
    before, has = spike_residuals(noise, seen, phi)
    after, has_after = spike_residuals(hit, seen, phi)
    assert np.array_equal(has, has_after)
    diff = np.where(np.isfinite(after), after - before, 0.0)
    c = phi / (1 + phi * phi)
    want = np.zeros_like(diff)
    want[t, m, k] = size
    for s in (t - 1, t + 1):
        if has[s, m]:
            want[s, m, k] = -c * size
    assert np.allclose(diff, want, atol=1e-9 * max(1.0, abs(size)))
    assert not has[~seen].any()                 # nothing for an unseen sample


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.95))
def test_on_ar1_noise_its_variance_is_the_formula(seed, phi):
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, 4000, 4, phi, 1.3)
    spike, has = spike_residuals(noise, np.ones(noise.shape[:2], bool), phi)
    want = 1.3 ** 2 * (1 - phi ** 2) / (1 + phi ** 2)
    assert abs(np.var(spike[has]) / want - 1.0) < 0.1
    assert np.var(spike[has]) <= np.var(noise) * 1.1      # never wider than the residual it comes from
