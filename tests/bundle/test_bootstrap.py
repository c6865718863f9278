"""The smoothed parametric bootstrap of :mod:`identcheck.bundle.bootstrap`: its noise, its motion, and its spread
where the linearised standard error is right."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.bootstrap import noise_draw, sampling_spread, smoothed_state, t95
from identcheck.bundle.model import apply_step, forward, n_const
from identcheck.bundle.uncertainty import covariance, distance_gradients
from tests.bundle.test_noise_dof import LEG
from tests.bundle.test_profile import _fit


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), sigma=st.floats(0.2, 2.0), phi=st.floats(0.0, 0.9))
def test_noise_draw_has_the_stated_sd_and_lag1(seed, sigma, phi):
    """Every coordinate series is AR(1): marginal SD σ and lag-1 correlation φ (pooled over 60 series of 4000
    frames, within 5 and 3 standard errors)."""
    e = noise_draw(np.random.default_rng(seed), (4000, 20, 3), sigma, phi)
    sd = e.std()
    n_eff = e.size * (1 - phi) / (1 + phi)
    assert abs(sd / sigma - 1) < 5 * np.sqrt(1 / (2 * n_eff)) + 0.01
    x = e.reshape(4000, -1)
    lag1 = np.sum(x[1:] * x[:-1]) / np.sum(x[:-1] ** 2)
    assert abs(lag1 - phi) < 3 * np.sqrt((1 - phi ** 2) / x[1:].size) + 0.01


def test_t95_falls_with_the_draws():
    assert t95(8) > t95(20) > t95(100) > 1.96 and abs(t95(20) - 2.093) < 1e-3


def _leg_fit(seed: int, noise: float):
    """The three-markers-a-segment leg simulated over 400 frames and fitted (:func:`tests.bundle.test_profile._fit`)."""
    sim, chain, data, fit, _ = _fit(LEG, seed, frames=400, noise=noise)
    return chain, data, fit, sim.trial.rate_hz


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_smoothing_takes_out_frame_to_frame_jitter_and_keeps_the_constants(seed):
    """The per-frame unknowns of a smooth simulated motion, moved by 1° / 1 mm white jitter in every frame: the
    low-passed state's predicted markers are at least twice nearer the unjittered ones than the jittered ones
    are, and its constants (so its marker distances) are the state's own."""
    chain, data, fit, rate = _leg_fit(seed, 0.0)
    rng = np.random.default_rng(seed)
    R = forward(chain, fit.terms, fit.state)[0]
    k = chain.frame_dof()
    scale = np.full(k, np.radians(1.0))
    scale[3:6] = 1.0                                   # the root's translation, mm
    dq = rng.normal(size=(len(data), k)) * scale
    jittered = apply_step(chain, fit.terms, fit.state, R, dq, np.zeros(n_const(chain, fit.terms)))
    clean = forward(chain, fit.terms, fit.state)[3]
    off_jitter = np.sqrt(np.mean((forward(chain, fit.terms, jittered)[3] - clean) ** 2))
    smooth = smoothed_state(jittered, rate)
    off_smooth = np.sqrt(np.mean((forward(chain, fit.terms, smooth)[3] - clean) ** 2))
    assert off_smooth < off_jitter / 2, (off_smooth, off_jitter)
    assert np.array_equal(smooth.local, jittered.local)


@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_spread_agrees_with_the_standard_error_where_the_linearisation_holds(seed):
    """A leg posed by three markers on every segment, 60° of motion, 0.7 mm white noise: the linearised standard
    errors are right there, and the bootstrap spread of every hip and knee distance over 20 draws is within
    0.6-1.6 of them (an RMS over 20 draws is uncertain by about 16 %); the same seed gives the same spread."""
    chain, data, fit, rate = _leg_fit(seed, 0.7)
    cov = covariance(fit, data)
    grads = distance_gradients(chain, fit.state, len(cov.information))
    found, draws = sampling_spread(fit, data, ["hip", "knee"], cov.sigma_mm, cov.lag1, rate, threads=2)
    assert draws == 20
    for j in ("hip", "knee"):
        for m, (_, g) in grads[j].items():
            assert 0.6 < found[j][m] / cov.se(g) < 1.6, (j, m, found[j][m], cov.se(g))
    again, _ = sampling_spread(fit, data, ["hip"], cov.sigma_mm, cov.lag1, rate, draws=8, threads=1)
    first8, _ = sampling_spread(fit, data, ["hip"], cov.sigma_mm, cov.lag1, rate, draws=8, threads=2)
    assert again == first8
