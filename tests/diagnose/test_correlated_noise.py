"""``diagnose`` under serially correlated noise (a low-pass filtered export): the noise model's lag-1
coefficient and marginal level are recovered from within-segment distances, the prewhitened residual sum of
squares has the expectation of white noise's, and a clean trial with AR(1) noise is called clean."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.bundle.hypothesis import whitened_rss
from identcheck.diagnose.workflow import diagnose
from identcheck.estimate.noise import noise_floor
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


def ar1(rng, shape, phi: float, sigma: float) -> np.ndarray:
    """Stationary AR(1) noise along axis 0 with marginal standard deviation sigma."""
    e = rng.normal(scale=sigma * np.sqrt(1 - phi ** 2), size=shape)
    out = np.empty(shape)
    out[0] = rng.normal(scale=sigma, size=shape[1:])
    for t in range(1, shape[0]):
        out[t] = phi * out[t - 1] + e[t]
    return out


def correlated_trial(seed: int, phi: float, sigma: float, n_frames: int = 800) -> Trial:
    sim = simulate(MODEL, n_frames=n_frames, seed=seed)
    clean = sim.clean.as_array()
    noisy = clean + ar1(np.random.default_rng(seed + 1), clean.shape, phi, sigma)
    return Trial(noisy, sim.clean.labels, sim.clean.rate_hz)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), phi=st.floats(0.0, 0.9), sigma=st.floats(0.3, 1.5))
def test_noise_floor_recovers_the_lag1_coefficient_and_the_marginal_sigma(seed, phi, sigma):
    trial = correlated_trial(seed, phi, sigma, n_frames=1500)
    nf = noise_floor(trial.select(MODEL.markers).as_array(), MODEL.markers,
                     {s: MODEL.segments[s].markers for s in MODEL.segments})
    assert nf.lag1 == pytest.approx(phi, abs=0.08)
    assert nf.sigma_mm == pytest.approx(sigma, rel=0.2)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), phi=st.floats(0.0, 0.95), sigma=st.floats(0.1, 3.0))
def test_whitened_rss_of_ar1_noise_is_sigma_squared_per_coordinate(seed, phi, sigma):
    rng = np.random.default_rng(seed)
    e = ar1(rng, (3000, 4, 3), phi, sigma)
    w = np.ones((3000, 4))
    w[rng.random((3000, 4)) < 0.05] = 0.0                 # gaps break the runs
    n = 3 * int(w.sum())
    assert whitened_rss(e, w, phi) / (n * sigma ** 2) == pytest.approx(1.0, abs=0.06)
    assert whitened_rss(e, w, 0.0) == pytest.approx(float(np.sum(w[..., None] * e ** 2)))


@pytest.mark.slow
@pytest.mark.parametrize("seed, phi", [(3, 0.7), (11, 0.9)])
def test_a_clean_trial_with_correlated_noise_is_clean(seed, phi):
    diag = diagnose(MODEL, correlated_trial(seed, phi, 0.6))
    assert not diag.steps, [s.name for s in diag.steps]
    assert diag.ctx.noise.lag1 == pytest.approx(phi, abs=0.1)
