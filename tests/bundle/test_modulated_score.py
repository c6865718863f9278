"""The moments of fields that are a function of time times a per-frame displacement (a joint's second rotation: a
smooth angle times the turn of the markers below the joint), computed carrier by carrier, are the moments of the
fields themselves: the same score test, without forming K times as many fields."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.hypothesis import time_basis
from identcheck.bundle.score_test import modulated_score_moments, score_moments
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**16), carriers=st.integers(1, 3), functions=st.integers(1, 5),
       hidden=st.floats(0.0, 0.3))
def test_the_moments_of_modulated_fields_are_those_of_the_fields(seed, carriers, functions, hidden):
    """Random carriers (some samples NaN), random functions of time and a share of the samples unweighted: ``n`` and
    ``G`` agree with :func:`score_moments` of the formed fields ``b_k · u_e`` (ordered carrier by carrier) to
    rounding, and G is symmetric positive semi-definite."""
    rng = np.random.default_rng(seed)
    data = simulate(MODEL, n_frames=120, noise_mm=0.5, seed=seed % 1000).trial.select(MODEL.markers).as_array()
    chain = Skeleton.from_model(MODEL)
    w = np.where(rng.uniform(size=data.shape[:2]) < hidden, 0.0, 1.0)
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=60)
    residual = fit.pred - data
    us = [np.where(rng.uniform(size=data.shape) < 0.05, np.nan, rng.normal(size=data.shape)) for _ in range(carriers)]
    basis = rng.normal(size=(len(data), functions))
    (n, G), = modulated_score_moments(fit, w, residual, us, [basis])
    formed = [basis[:, k, None, None] * u for u in us for k in range(functions)]
    (n2, G2), = score_moments(fit, w, residual, [formed])
    scale = float(np.max(np.abs(G2)))
    np.testing.assert_allclose(n, n2, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(n2))))
    np.testing.assert_allclose(G, G2, rtol=1e-7, atol=1e-8 * scale)
    assert np.allclose(G, G.T) and np.min(np.linalg.eigvalsh(G)) >= -1e-8 * scale


def test_several_smooth_bases_at_once():
    """The detector's own bases (cubic B-splines in time, knots 0.2 and 1 s apart) on a longer trial, both from one
    call: each agrees with the moments of its own formed fields."""
    data = simulate(MODEL, n_frames=300, noise_mm=0.5, seed=3).trial.select(MODEL.markers).as_array()
    chain = Skeleton.from_model(MODEL)
    w = np.ones(data.shape[:2])
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=60)
    bases = [time_basis(len(data), 100.0, spacing) for spacing in (0.2, 1.0)]
    us = [np.random.default_rng(3 + e).normal(size=data.shape) for e in range(2)]
    both = modulated_score_moments(fit, w, fit.pred - data, us, bases)
    assert [len(n) for n, _ in both] == [2 * b.shape[1] for b in bases]
    for (n, G), basis in zip(both, bases):
        (n2, G2), = score_moments(fit, w, fit.pred - data,
                                  [[basis[:, k, None, None] * u for u in us for k in range(basis.shape[1])]])
        np.testing.assert_allclose(n, n2, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(n2))))
        np.testing.assert_allclose(G, G2, rtol=1e-7, atol=1e-8 * float(np.max(np.abs(G2))))
