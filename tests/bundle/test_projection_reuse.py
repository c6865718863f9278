"""A hypothesis keeps the refit's projection its score tests use (:attr:`Hypothesis.projection`): built once, given to
every score test at that hypothesis, and the moments it gives are those of a projection built afresh; a refitted
hypothesis has its own, and one let go of is built again when asked for."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.hypothesis import Hypothesis
from identcheck.bundle.score_test import RefitProjection, score_moments
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")


def _hypothesis(seed: int, hidden: float) -> Hypothesis:
    rng = np.random.default_rng(seed)
    data = simulate(MODEL, n_frames=100, noise_mm=0.5, seed=seed % 1000).trial.select(MODEL.markers).as_array()
    chain = Skeleton.from_model(MODEL)
    w = np.where(rng.uniform(size=data.shape[:2]) < hidden, 0.0, 1.0)
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=40)
    return Hypothesis(chain, fit.terms, data, w, fit)


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 2**16), hidden=st.floats(0.0, 0.3))
def test_the_kept_projection_gives_the_moments_of_a_fresh_one(seed, hidden):
    h = _hypothesis(seed, hidden)
    assert h.projection is h.projection                                   # built once
    assert h.refit(max_iter=1).projection is not h.projection              # a refitted hypothesis: its own
    fields = [np.random.default_rng(seed + k).normal(size=h.data.shape) for k in range(3)]
    (n, G), = score_moments(h.fit, h.weights, h.residuals(), [fields], h.projection)
    (n2, G2), = score_moments(h.fit, h.weights, h.residuals(), [fields], RefitProjection(h.fit, h.weights))
    np.testing.assert_allclose(n, n2, rtol=1e-12)
    np.testing.assert_allclose(G, G2, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(G2))))
    kept = h.projection
    h.forget_projection()                                                 # let go of: built again when asked for
    assert "projection" not in vars(h)
    assert h.projection is not kept and h.projection is h.projection
