"""The whole-chain Levenberg-Marquardt steps: doubling an accepted step along its direction only ever lowers
the cost, and it leaves the minimum where plain Gauss-Newton finds it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import identcheck.bundle.chain as chain_mod
from identcheck.bundle.chain import _cost, _extend, _prepare, fit_chain, initial_state
from identcheck.bundle.jacobian import dense_jacobians, jacobian_blocks
from identcheck.bundle.model import Terms, apply_step, forward
from identcheck.bundle.normal import eliminate_frames
from identcheck.bundle.profile import distance_penalty
from identcheck.bundle.uncertainty import covariance, distance_gradients
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), scale=st.floats(1e-3, 3.0))
def test_extending_a_step_never_raises_the_cost(seed, scale):
    """From a perturbed state, a random step taken (or not) and then extended: the returned cost is the cost of
    the returned state, and never above the taken step's."""
    sim = simulate(MODEL, n_frames=60, noise_mm=0.5, seed=seed)
    chain = Skeleton.from_model(MODEL)
    y, w = _prepare(sim.trial.as_array(), None)
    s = initial_state(chain, sim.trial.as_array())
    R, t, centre, pred = forward(chain, Terms(), s)
    rng = np.random.default_rng(seed)
    P = 3 * chain.n_markers + sum(6 + (5 if chain.types[j] == "revolute" else 0) for j in chain.joints)
    dq = rng.normal(0, 1e-3 * scale, (60, chain.frame_dof()))
    dc = rng.normal(0, scale, P)
    first = apply_step(chain, Terms(), s, R, dq, dc)
    out = forward(chain, Terms(), first)
    taken = (first, *out, _cost(out[-1], y, w))
    best = _extend(chain, Terms(), s, R, dq, dc, y, w, lambda st: 0.0, taken)
    assert best[-1] <= taken[-1]
    assert np.isclose(_cost(forward(chain, Terms(), best[0])[-1], y, w), best[-1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_extended_iteration_reaches_the_same_minimum(seed, monkeypatch):
    """With and without the extension the fit converges to one minimum (RSS within 1e-6), in no more iterations."""
    sim = simulate(MODEL, n_frames=300, noise_mm=0.7, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    state = initial_state(chain, data)
    extended = fit_chain(chain, data, state, max_iter=500)
    monkeypatch.setattr(chain_mod, "_extend", lambda *args: args[-1])
    plain = fit_chain(chain, data, state, max_iter=500)
    assert extended.converged and plain.converged
    assert abs(extended.rss - plain.rss) <= 1e-6 * plain.rss
    assert extended.iterations <= plain.iterations


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.floats(0.2, 2.0), frames=st.integers(80, 400))
def test_stopping_on_a_fast_rate_leaves_the_cost_within_tolerance(seed, noise, frames):
    """Stopping where the geometric rate says the rest of the decrease is below the tolerance: the cost is within
    a few times REL_TOL of the cost reached when every fit runs until a step itself falls below it, and no more
    iterations are taken."""
    sim = simulate(MODEL, n_frames=frames, noise_mm=noise, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    state = initial_state(chain, data)
    early = fit_chain(chain, data, state, max_iter=500)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(chain_mod, "FAST_RATE", 0.0)                     # no step counts as fast: the plain rule alone
        plain = fit_chain(chain, data, state, max_iter=500)
    assert early.converged and plain.converged
    assert early.rss <= plain.rss * (1 + 3 * chain_mod.REL_TOL)
    assert early.iterations <= plain.iterations


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_past_deadline_stops_after_one_iteration_and_each_iteration_is_reported(seed):
    """``deadline`` bounds a fit in time (no new iteration after it), ``on_iteration`` hears every iteration with the
    cost it ended at: a long fit can say where it is, and stop when its budget is spent."""
    import time

    sim = simulate(MODEL, n_frames=200, noise_mm=0.5, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    state = initial_state(chain, data)
    heard = []
    fit = fit_chain(chain, data, state, max_iter=50, on_iteration=lambda it, cost: heard.append((it, cost)),
                    deadline=time.monotonic() - 1.0)
    assert fit.iterations == 1 and [it for it, _ in heard] == [1]
    assert np.isclose(heard[0][1], fit.rss)
    full = fit_chain(chain, data, state, max_iter=50, on_iteration=lambda it, cost: heard.append((it, cost)))
    costs = [c for _, c in heard[1:]]
    assert len(costs) == full.iterations and all(b <= a for a, b in zip(costs, costs[1:]))


def test_converged_fit_keeps_to_its_budget_and_says_where_it_is(monkeypatch):
    """A start that has not converged after its iterations goes on for at most CONVERGE_BUDGET_S (it had gone on for
    a whole further batch of iterations, 60 s on the 16-marker body, while saying "at most 10 s more"), and a fit
    longer than ITERATION_REPORT_S says its iteration and cost."""
    import time

    import identcheck.bundle.converge as W

    sim = simulate(MODEL, n_frames=300, noise_mm=0.5, seed=3)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    state = initial_state(chain, data)
    monkeypatch.setattr(W, "MAX_ITER", 1)
    monkeypatch.setattr(W, "CONVERGE_BUDGET_S", 0.0)
    monkeypatch.setattr(W, "ITERATION_REPORT_S", 0.0)
    lines: list = []
    fit = W.converged_fit(chain, data, state, progress=lines.append)
    assert fit.iterations == 1 and not fit.converged
    assert any("whole-tree fit: iteration 1," in line for line in lines), lines
    monkeypatch.setattr(W, "CONVERGE_BUDGET_S", 0.2)
    t0 = time.monotonic()
    W.converged_fit(chain, data, state, progress=lines.append)
    assert time.monotonic() - t0 < 2.0
    assert any("going on (at most" in line for line in lines), lines
    monkeypatch.setattr(W, "MAX_ITER", 500)          # the first batch stops at its time budget, with no restart
    monkeypatch.setattr(W, "START_BUDGET_S", 0.0)
    fit = W.converged_fit(chain, data, state)
    assert fit.iterations == 1 and not fit.converged


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), lam=st.floats(1e-8, 1.0), spread=st.floats(1e-3, 0.05))
def test_the_promised_drop_is_the_linearised_models_drop(seed, lam, spread):
    """For a damped step solved as the fit solves it, :func:`promised_drop` (from the gradients and the damping
    alone) equals the cost minus the linearised residual's cost ``Σ w |r + J dq + G dc|²``, with J and G written
    out: the ratio the damping is adjusted by compares the actual drop with what the model truly promised."""
    sim = simulate(MODEL, n_frames=30, noise_mm=0.5, seed=seed)
    chain = Skeleton.from_model(MODEL)
    rng = np.random.default_rng(seed)
    y, w = _prepare(sim.trial.as_array(), rng.uniform(0.2, 1.0, sim.trial.as_array().shape[:2]))
    s = initial_state(chain, sim.trial.as_array())
    s.root_t += rng.normal(0, 100 * spread, s.root_t.shape)
    R, _t, centre, pred = forward(chain, Terms(), s)
    A, B, C, g, h = chain_mod._normal(chain, Terms(), s, R, centre, pred, y, w)
    k = A.shape[1]
    damp_q = lam * np.diagonal(A, axis1=1, axis2=2) + 1e-9 * np.trace(A, axis1=1, axis2=2)[:, None] / k
    damp_c = lam * np.diag(C)
    S, reduced, back = eliminate_frames(A + damp_q[..., None] * np.eye(k), B, C + np.diag(damp_c), g, h)
    dc = chain_mod._solve_constants(S, -reduced)
    dq = -back(dc)
    lay, blocks = jacobian_blocks(chain, Terms(), s, R, centre, pred)
    J, G = dense_jacobians(lay, blocks, chain.n_markers)
    r = np.where(w[..., None] > 0, pred - y, 0.0)
    lin = r + np.einsum("fmak,fk->fma", J, dq) + np.einsum("fmap,p->fma", G, dc)
    model_drop = _cost(pred, y, w) - float(np.sum(w[..., None] * lin ** 2))
    promised = chain_mod.promised_drop(g, h, dq, dc, damp_q, damp_c)
    assert promised > 0
    assert np.isclose(promised, model_drop, rtol=1e-6, atol=1e-9 * _cost(pred, y, w))


@settings(max_examples=30, deadline=None)
@given(promised=st.floats(1e-6, 1e6), share=st.floats(0.0, 1.0))
def test_the_damping_follows_how_much_of_its_promise_a_step_kept(promised, share):
    """A step that kept most of its promise is undamped by ten, one that kept little damped twice as hard, and in
    between the damping stays; a step can never be undamped more than a step that kept more of its promise."""
    factor = chain_mod.damping_factor(share * promised, promised)
    if share > chain_mod.GOOD_STEP:
        assert factor == 0.1
    elif share < chain_mod.POOR_STEP:
        assert factor == 2.0
    else:
        assert factor == 1.0
    assert chain_mod.damping_factor(min(1.0, share + 0.3) * promised, promised) <= factor


def _wrong_way_spring(chain, fit, P, pull_mm):
    """A spring on a marker distance whose Jacobian points the wrong way: every step the normal equations propose
    raises its cost, so no damping lowers the cost (a stall)."""
    joint = chain.joints[0]
    marker, (d0, _) = next(iter(distance_gradients(chain, fit.state, P)[joint].items()))
    right = distance_penalty(chain, joint, marker, d0 + pull_mm, 1.0, P)

    def wrong(state):
        r, D = right(state)
        return r, -D
    return wrong


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), pull=st.floats(5.0, 40.0))
def test_a_fit_no_damping_can_move_is_converged_only_at_a_minimum(seed, pull):
    """From the minimum of a leg's fit, a spring on a marker distance whose Jacobian points the wrong way: every
    step the normal equations propose raises the cost, so the first iteration finds no lower cost and the fit stops
    there. Pulling the distance `pull` mm away, the step promised a drop it could not deliver: a stall, not
    converged."""
    sim = simulate(MODEL, n_frames=120, noise_mm=0.5, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.select(chain.labels).as_array()
    fit = fit_chain(chain, data, initial_state(chain, data), max_iter=300)
    assert fit.converged
    again = fit_chain(chain, data, fit.state, max_iter=5)
    assert again.converged and again.iterations <= 2          # from a minimum: converged at once
    P = len(covariance(fit, data).information)
    stalled = fit_chain(chain, data, fit.state, max_iter=5, penalty=_wrong_way_spring(chain, fit, P, pull))
    assert stalled.iterations == 1 and not stalled.converged


@given(cost=st.floats(1e-3, 1e9), tol=st.floats(1e-12, 1e-3), share=st.floats(0.0, 10.0))
def test_a_fit_that_cannot_move_is_at_a_minimum_when_its_step_promised_at_most_the_tolerance(cost, tol, share):
    """Where no damping lowers the cost, the fit is converged exactly when the least damped step promised to lower
    it by at most `tol` times it (what is left is below what it was asked to resolve)."""
    promise = share * tol * cost
    assert chain_mod.stalled_at_minimum(promise, cost, tol) == (share <= 1.0 or promise <= tol * cost)
