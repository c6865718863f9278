"""The information taken at estimated per-frame poses overstates what the motion showed the joint (the poses carry
the noise); :func:`identcheck.bundle.uncertainty.widening` puts back the variance that hid, from a SIMEX
extrapolation of the information (:func:`identcheck.bundle.uncertainty.simex_information`)."""
from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, information_at, initial_state
from identcheck.bundle.model import Fit, apply_step, forward
from identcheck.bundle.uncertainty import (SIMEX_LEFT, chain_inverse, determined_directions, distance_gradients,
                                           frame_scores, jacobi_scaled, simex_information, widening)
from identcheck.fit.whole_tree import skeleton_of
from identcheck.simulate.rigid import simulate
from tests.bundle.test_noise_dof import LEG, SEEN_WITHOUT_ROLL


def _spd_with_null(rng, n: int, null: int) -> tuple[np.ndarray, np.ndarray]:
    """A random positive semi-definite matrix (n, n) of rank n − null, and an orthonormal basis of its range."""
    Q = np.linalg.qr(rng.normal(size=(n, n)))[0]
    vals = 10.0 ** rng.uniform(-2, 2, size=n - null)
    U = Q[:, :n - null]
    return (U * vals) @ U.T, U


@given(st.integers(0, 2 ** 32 - 1), st.integers(2, 8), st.integers(0, 2))
def test_widening_is_the_inverse_difference_on_the_range_and_never_negative(seed, n, null):
    """For S of rank n − null and S̄ = S + Δ with Δ a positive semi-definite share of S's range (at most half of it
    in every direction), ``widening`` equals ``(S − Δ)⁺ − S⁺`` and is positive semi-definite; with S̄ ≤ S it is 0."""
    rng = np.random.default_rng(seed)
    S, U = _spd_with_null(rng, n, null)
    inv = np.linalg.pinv(S, rcond=1e-12, hermitian=True)
    L = np.linalg.cholesky(U.T @ S @ U)
    share = rng.uniform(0, 0.5, size=n - null)
    Qs = np.linalg.qr(rng.normal(size=(n - null, n - null)))[0]
    Delta = U @ L @ (Qs * share) @ Qs.T @ L.T @ U.T          # L⁻¹ Δ L⁻ᵀ has eigenvalues `share` on the range
    D = widening(S, S + Delta, inv)
    direct = np.linalg.pinv(S - Delta, rcond=1e-12, hermitian=True) - inv
    scale = np.max(np.abs(direct)) + np.max(np.abs(inv))
    assert np.allclose(D, direct, atol=1e-7 * scale)
    assert np.min(np.linalg.eigvalsh((D + D.T) / 2)) >= -1e-9 * scale
    assert np.allclose(widening(S, S - Delta, inv), 0.0, atol=1e-9 * scale)


@given(st.integers(0, 2 ** 32 - 1), st.integers(2, 6))
def test_widening_is_capped_where_the_noise_made_up_all_of_a_direction(seed, n):
    """A direction whose whole information the per-frame noise made up (Δ = S there) is widened by at most the
    factor ``1 / SIMEX_LEFT`` in variance, not infinitely."""
    rng = np.random.default_rng(seed)
    S, U = _spd_with_null(rng, n, 0)
    inv = np.linalg.inv(S)
    v = rng.normal(size=n)
    v /= np.linalg.norm(v)
    g = S @ v                                   # gᵀ S⁻¹ g = vᵀ S v: the variance along S's own direction v
    Delta = np.outer(g, g) / float(v @ S @ v)   # all of S's information along v
    D = widening(S, S + Delta, inv)
    base = float(g @ inv @ g)
    assert float(g @ (inv + D) @ g) <= base / SIMEX_LEFT * (1 + 1e-6)
    assert float(g @ (inv + D) @ g) >= base * 10


def _sparse_hip(seed: int):
    """The leg's pelvis and one thigh marker, the rest weighted out, fitted to its noise-free simulation."""
    sim = simulate(LEG, n_frames=400, noise_mm=0.0, seed=seed, rom_deg=15.0)
    chain = skeleton_of(LEG, sim.trial)
    data = sim.trial.select(chain.labels).as_array()
    w = np.zeros(data.shape[:2])
    w[:, [chain.labels.index(m) for m in SEEN_WITHOUT_ROLL]] = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_chain(chain, data, initial_state(chain, data), max_iter=200)
        fit = fit_chain(chain, data, fit.state, weights=w, max_iter=200)
    return chain, data, w, fit


def test_no_noise_no_widening():
    """With σ = 0 the draws do not move the poses: S̄ is S exactly and nothing is widened."""
    chain, data, w, fit = _sparse_hip(3)
    _, S, _, _, A, ww = frame_scores(fit, data, w)
    S_bar = simex_information(fit, A, ww, 0.0)
    assert np.array_equal(S_bar, S)
    assert np.all(widening(S, S_bar, chain_inverse(chain, fit.state, S)[0]) == 0.0)


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_simex_takes_the_information_back_towards_the_true_poses(seed):
    """The sparse hip's information at its true poses, at poses moved by draws of their estimation error (σ 1 mm:
    what an estimate carries), and that extrapolated by SIMEX: over three such 'estimates' the hip distances'
    variances from the corrected information are nearer those at the true poses than the uncorrected ones are
    (mean absolute log ratio)."""
    chain, data, w, fit = _sparse_hip(seed)
    _, S_true, _, _, A, ww = frame_scores(fit, data, w)
    grads = [g for m, (_, g) in distance_gradients(chain, fit.state, len(S_true))["hip"].items()
             if m in SEEN_WITHOUT_ROLL]
    scaled, d = jacobi_scaled(A)
    vals, V = np.linalg.eigh(scaled)
    keep = determined_directions(vals)
    R = forward(chain, fit.terms, fit.state)[0]
    true_inv = chain_inverse(chain, fit.state, S_true)[0]
    errors = {"noisy": [], "corrected": []}
    for k in range(3):
        rng = np.random.default_rng([seed, k])
        z = np.where(keep, rng.standard_normal(vals.shape) / np.sqrt(np.maximum(vals, 1e-300)), 0.0)
        moved = apply_step(chain, fit.terms, fit.state, R, 1.0 * np.einsum("fij,fj->fi", V, z) / d,
                           np.zeros(len(S_true)))
        estimate = Fit(chain, fit.terms, moved, fit.pred, fit.rss, fit.n_samples, fit.n_params, 0, True)
        S = information_at(chain, fit.terms, moved, ww)
        A_moved = frame_scores(estimate, data, w)[4]
        inv = chain_inverse(chain, fit.state, S)[0]
        corrected = inv + widening(S, simex_information(estimate, A_moved, ww, 1.0, seed=k), inv)
        for g in grads:
            truth = float(g @ true_inv @ g)
            errors["noisy"].append(abs(np.log(float(g @ inv @ g) / truth)))
            errors["corrected"].append(abs(np.log(float(g @ corrected @ g) / truth)))
    assert np.mean(errors["corrected"]) < np.mean(errors["noisy"]), errors
