"""What share of a fitted change the prewhitened criterion keeps: all of it under white noise, (1 − φ)/(1 + φ) of a
change constant in time, more of one that changes from frame to frame; and exactly the whitened sum of squares of
the change over its plain one, samples of weight 0 left out of both."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.hypothesis import Context, whitened_rss
from identcheck.estimate.noise import NoiseFloor


def _context(phi: float) -> Context:
    noise = NoiseFloor(1.0, 1.0, {}, 0.1, 3, 1000, phi)
    return Context(model=None, labels=(), rate_hz=100.0, raw=np.zeros((1, 1, 3)), noise=noise, n_samples=1000)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**16), phi=st.floats(0.05, 0.95))
def test_the_kept_share_is_the_whitened_over_the_plain_sum_of_squares(seed, phi):
    rng = np.random.default_rng(seed)
    ctx = _context(phi)
    F, M = 200, 4
    w = np.where(rng.uniform(size=(F, M)) < 0.1, 0.0, 1.0)
    constant = np.broadcast_to(rng.normal(size=(1, M, 3)), (F, M, 3))
    full = np.ones((F, M))
    # a change constant in time keeps (1 − φ)/(1 + φ), to the runs' first samples (whose terms are not differenced)
    assert abs(ctx.kept_share(constant, full) - ctx.smooth_share) < 2.0 / F
    # an alternating change keeps more than all of it, a smooth one less
    alternating = constant * np.where(np.arange(F) % 2, 1.0, -1.0)[:, None, None]
    assert ctx.kept_share(alternating, full) > 1.0 > ctx.smooth_share
    field = rng.normal(size=(F, M, 3))
    plain = float(np.sum(w[..., None] * field ** 2))
    assert np.isclose(ctx.kept_share(field, w), whitened_rss(field, w, phi) / plain, rtol=1e-12)
    assert _context(0.0).kept_share(field, w) == 1.0
