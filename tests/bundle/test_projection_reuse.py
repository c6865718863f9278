"""The refit's projection is built once for a run of score tests at one fit (:func:`projection`), and built again as
soon as anything it was built from is another object or has changed: its moments are then those of a projection
built afresh."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.score_test import RefitProjection, projection, score_moments
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")


def _fit(seed: int, hidden: float):
    rng = np.random.default_rng(seed)
    data = simulate(MODEL, n_frames=100, noise_mm=0.5, seed=seed % 1000).trial.select(MODEL.markers).as_array()
    chain = Skeleton.from_model(MODEL)
    w = np.where(rng.uniform(size=data.shape[:2]) < hidden, 0.0, 1.0)
    return data, w, fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=40)


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**16), hidden=st.floats(0.0, 0.3))
def test_reused_at_the_same_fit_and_built_again_for_another(seed, hidden):
    data, w, fit = _fit(seed, hidden)
    first = projection(fit, w)
    assert projection(fit, w) is first                               # the same objects: reused
    other_w = w.copy()
    other_w[0, 0] = 1.0 - other_w[0, 0]                               # other weights: built again
    assert projection(fit, other_w) is not first
    moved = replace(fit, rss=fit.rss + 1.0)                           # another fit object
    assert projection(moved, w) is not projection(fit, w)
    again = projection(fit, w)
    fit.state.term_params = list(fit.state.term_params)                # the state's terms replaced in place
    assert projection(fit, w) is not again
    again = projection(fit, w)
    w[0, 0] += 0.5                                                    # the weights changed in place, sum kept
    w[0, 1] -= 0.5
    assert projection(fit, w) is not again


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 2**16), hidden=st.floats(0.0, 0.3))
def test_a_reused_projection_gives_the_moments_of_a_fresh_one(seed, hidden):
    data, w, fit = _fit(seed, hidden)
    fields = [np.random.default_rng(seed + k).normal(size=data.shape) for k in range(3)]
    residual = fit.pred - data
    first = projection(fit, w)                                         # built, then reused below
    (n, G), = score_moments(fit, w, residual, [fields])
    assert projection(fit, w) is first
    fresh = RefitProjection(fit, w)
    parts = [fresh.pieces(v) for v in fields]
    G2 = np.array([[fresh.inner(parts[min(i, j)], parts[max(i, j)]) for j in range(3)] for i in range(3)])
    np.testing.assert_allclose(G, G2, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(G2))))


def test_the_projection_is_let_go_with_its_fit():
    """Nothing keeps a finished fit's projection: the entry goes when the fit does."""
    import gc

    from identcheck.bundle import score_test

    data, w, fit = _fit(7, 0.1)
    projection(fit, w)
    other = _fit(8, 0.1)[2]
    projection(other, w)                                              # the last entry is now the other fit's
    del fit
    gc.collect()
    assert score_test._LAST[0] is not None                           # another fit going does not drop it
    del other
    gc.collect()
    assert score_test._LAST[0] is None
