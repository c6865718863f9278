"""The misfit test: residuals that follow the joint angles are found; noise of any serial correlation is not
mistaken for them."""
from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.misfit import NOISE_CEILING_MM, RATIO, MarkerMisfit, angle_dependence, model_error_sd
from identcheck.effects.registry import inject_effect
from identcheck.fit.whole_tree import skeleton_of
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate


def _ar1(rng, shape, sd, phi):
    out = np.empty(shape)
    out[0] = rng.normal(0, sd, shape[1:])
    e = rng.normal(0, sd * np.sqrt(1 - phi ** 2), shape)
    for f in range(1, shape[0]):
        out[f] = phi * out[f - 1] + e[f]
    return out


def _fit(model, trial):
    chain = skeleton_of(model, trial)
    data = trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_chain(chain, data, initial_state(chain, data), max_iter=100), data


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10 ** 5), phi=st.sampled_from([0.0, 0.5, 0.9]), sd=st.floats(0.3, 1.2))
def test_noise_of_any_correlation_is_not_misfit(examples, seed, phi, sd):
    """Rigid leg, white or AR(1) noise: no marker's ratio exceeds the threshold, no model error."""
    model = Model.from_toml(examples / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    noisy = sim.trial.replace(xyz=sim.trial.as_array() + _ar1(rng, sim.trial.as_array().shape, sd, phi))
    fit, data = _fit(model, noisy)
    mis = angle_dependence(fit, data)
    assert max(m.ratio for m in mis.values()) < RATIO, {k: round(m.ratio, 1) for k, m in mis.items()}
    assert all(model_error_sd(fit, j, mis) == 0 for j in fit.chain.joints)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_skin_motion_is_found_on_its_marker(examples, seed):
    """A marker that wobbles with its joint's angle (the simulator's soft tissue, 5-10 mm): its ratio is far
    above the threshold, and its joint gets a model error."""
    model = Model.from_toml(examples / "diagnose_leg.toml")
    sim = inject_effect(simulate(model, n_frames=600, noise_mm=0.5, seed=seed), "soft_tissue", seed=seed)
    where = sim.settings["effect"]["where"]
    marker = where["markers"][0]
    fit, data = _fit(model, sim.trial)
    mis = angle_dependence(fit, data)
    assert mis[marker].moves, {k: round(m.ratio, 1) for k, m in mis.items()}
    assert model_error_sd(fit, where["joint"], mis) > 0


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10 ** 5))
def test_smoothest_simulated_noise_stays_below_the_ceiling(examples, seed):
    """The most extreme simulated capture the ceiling is set against (1.5 mm AR(1) noise of lag-1 0.95 over 300
    frames, so few effectively independent frames that the ratio test has little power): no marker's
    angle-following part reaches :data:`NOISE_CEILING_MM`, and none is said to move."""
    model = Model.from_toml(examples / "diagnose_leg.toml")
    sim = simulate(model, n_frames=300, noise_mm=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    noisy = sim.trial.replace(xyz=sim.trial.as_array() + _ar1(rng, sim.trial.as_array().shape, 1.5, 0.95))
    fit, data = _fit(model, noisy)
    mis = angle_dependence(fit, data)
    assert max(m.explained_mm for m in mis.values()) < NOISE_CEILING_MM, {
        k: round(m.explained_mm, 1) for k, m in mis.items()}



@given(explained=st.floats(0.0, 50.0), ratio=st.floats(0.0, 100.0))
def test_a_motion_larger_than_noise_reaches_moves_whatever_its_ratio(explained, ratio):
    """Above :data:`NOISE_CEILING_MM` a marker moves with the angles even when the ratio test has no power;
    below it the ratio alone decides."""
    m = MarkerMisfit("M", "seg", explained, ratio, 0.99)
    assert m.moves == (ratio > RATIO or explained > NOISE_CEILING_MM)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10 ** 5), size=st.floats(0.3, 20.0), on=st.sampled_from(["pelvis", "thigh", "shank"]))
def test_motion_an_effect_fits_counts_as_motion_seen(examples, seed, size, on):
    """A motion with the angles that diagnose's effect terms fit (skin on a segment, a centre moving) gives each joint
    the model error the same motion seen in the residual would: skin on a segment counts for the joints beside it
    and no other, a moving centre for its own joint only and as 1.5 times its motion (its distances are to the centre's
    mean place); none leaves the model error at 0."""
    from identcheck.bundle.misfit import ModelledMotion

    model = Model.from_toml(examples / "diagnose_leg.toml")
    fit, data = _fit(model, simulate(model, n_frames=300, noise_mm=0.3, seed=seed).trial)
    chain = fit.chain
    seen = {"X": MarkerMisfit("X", on, size, 1e6, 0.0)}
    skin = (ModelledMotion((on,), size),)
    for j in chain.joints:
        beside = on in (chain.parent[j], chain.child[j])
        assert model_error_sd(fit, j, {}, skin) == model_error_sd(fit, j, seen)
        assert (model_error_sd(fit, j, {}, skin) > 0) == beside
        assert model_error_sd(fit, j, {}, skin) >= (1.5 * size if beside else 0.0)
        assert model_error_sd(fit, j, {}) == 0
    for j in chain.joints:
        centre = (ModelledMotion((chain.parent[j], chain.child[j]), size, joint=j),)
        own = [1.5 * size * (k == j) for k in chain.joints]
        assert [model_error_sd(fit, k, {}, centre) for k in chain.joints] == own


def test_a_moving_centre_does_not_widen_another_joint_beside_a_segment_with_few_markers(examples, tmp_path):
    """With a shank of two markers (it cannot show its own skin motion), skin fitted anywhere counts for the knee as
    if it might be on the shank unseen, but the hip's moving centre is the hip's alone: the knee takes no model error
    from it."""
    from identcheck.bundle.misfit import ModelledMotion

    toml = (examples / "diagnose_leg.toml").read_text().replace('["RTIB", "RTIB2", "RANK"]', '["RTIB", "RANK"]')
    path = tmp_path / "sparse.toml"
    path.write_text(toml)
    model = Model.from_toml(path)
    from identcheck.diagnose.workflow import start

    fit = start(model, simulate(model, n_frames=300, noise_mm=0.3, seed=2).trial)[1].fit  # posed through its joints
    centre = (ModelledMotion(("pelvis", "thigh"), 6.0, joint="hip"),)
    skin_on_pelvis = (ModelledMotion(("pelvis",), 6.0),)
    assert model_error_sd(fit, "hip", {}, centre) > 0 and model_error_sd(fit, "knee", {}, centre) == 0
    assert model_error_sd(fit, "knee", {}, skin_on_pelvis) > 0          # may be on the two-marker shank, unseen
