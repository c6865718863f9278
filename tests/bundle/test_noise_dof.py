"""The noise estimate counts only the unknowns the samples determine: σ̂² = RSS / (3n − rank J), the per-frame
unknowns' rank summed frame by frame. A segment's roll and a joint's angle that no weighted sample sees had
counted, and σ̂ came out too large (the hip refitted without the markers below a one-marker thigh: 0.47 mm
against 0.33 simulated)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.uncertainty import covariance, frame_rank
from identcheck.fit.whole_tree import skeleton_of
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

# three markers on each of pelvis, thigh and shank
LEG = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")
SEEN_WITHOUT_ROLL = ["LASI", "RASI", "SACR", "RGT"]     # the thigh's roll and the knee's angle: no sample


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10 ** 5), noise=st.floats(0.3, 1.2))
def test_sigma_is_right_when_weights_leave_unknowns_unseen(seed, noise):
    """Simulated leg, white noise σ: fitted on every marker, and refitted on the pelvis and one thigh marker only,
    σ̂ is within 6 % of σ both times (about 4 standard errors of σ̂ at these sizes; counting every unknown of a
    frame gave 2 σ on the refit)."""
    sim = simulate(LEG, n_frames=500, noise_mm=noise, seed=seed)
    chain = skeleton_of(LEG, sim.trial)
    data = sim.trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_chain(chain, data, initial_state(chain, data), max_iter=100)
        w = np.zeros(data.shape[:2])
        w[:, [chain.labels.index(m) for m in SEEN_WITHOUT_ROLL]] = 1.0
        refit = fit_chain(chain, data, fit.state, weights=w, max_iter=100)
    for f, weights in ((fit, None), (refit, w)):
        sigma = covariance(f, data, weights).sigma_mm
        assert abs(sigma / noise - 1) < 0.06, (sigma, noise)


@given(st.integers(1, 6), st.integers(0, 4), st.integers(0, 2 ** 16))
def test_frame_rank_counts_what_the_samples_see(k, missing, seed):
    """Blocks JᵀJ of random Jacobians with `missing` columns left without samples (and random scales): the rank
    is k − missing in every frame."""
    missing = min(missing, k)
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(5, 3 * k, k)) * 10.0 ** rng.uniform(-3, 3, size=k)
    J[:, :, :missing] = 0.0
    A = np.transpose(J, (0, 2, 1)) @ J
    assert frame_rank(A) == 5 * (k - missing)


@st.composite
def _trees(draw):
    """A random tree of 2-5 segments (each joint's parent among the segments before it), 0-3 markers a segment (the
    root at least one, three on some segment), ball or hinge joints."""
    n = draw(st.integers(2, 5))
    counts = [draw(st.integers(1, 3))] + [draw(st.integers(0, 3)) for _ in range(n - 1)]
    if max(counts) < 3:
        counts[draw(st.integers(0, n - 1))] = 3
    parents = [None] + [draw(st.integers(0, k - 1)) for k in range(1, n)]
    types = [draw(st.sampled_from(["spherical", "revolute"])) for _ in range(n)]
    return Model.from_dict({
        "units": "mm",
        "segments": {f"s{k}": {"markers": [f"m{k}_{i}" for i in range(counts[k])]} for k in range(n)},
        "joints": {f"j{k}": {"type": types[k], "parent": f"s{parents[k]}", "child": f"s{k}"} for k in range(1, n)}})


@settings(max_examples=40, deadline=None)
@given(model=_trees(), seed=st.integers(0, 10 ** 5))
def test_a_fit_counts_the_unknowns_a_frame_determines(model, seed):
    """Random trees, every marker seen: a fit's per-frame parameter count (``frame_dof − frame_free``, frames times)
    is the rank the samples give the per-frame unknowns (:func:`frame_rank`), so that its degrees of freedom are the
    residual's. The free turns of one-marker ends after a ball joint had been counted as parameters."""
    from hypothesis import assume

    from identcheck.bundle.start import start_state
    from identcheck.bundle.uncertainty import frame_scores
    from identcheck.errors import DegenerateError, InputError

    sim = simulate(model, n_frames=40, noise_mm=0.3, seed=seed)
    chain = skeleton_of(model, sim.trial)
    data = sim.trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            state = start_state(model, chain, data, sim.trial.rate_hz)
        except (DegenerateError, InputError, ValueError, np.linalg.LinAlgError):
            assume(False)
        fit = fit_chain(chain, data, state, max_iter=5)
    determined = frame_scores(fit, data)[3]
    assert len(data) * (chain.frame_dof() - chain.frame_free()) == determined
