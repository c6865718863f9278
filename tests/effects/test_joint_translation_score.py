"""The joint-translation detector's score statistic: a knee whose centre rolls back with flexion (the shape of a
real knee, odd and even in the angle) is proposed with the strength a refit with the translation earns, where
regressing the residual on the angles read almost nothing (the rigid fit's shifted axis and angles take most of it
up first); and the diagnosis then names it, or a skin cluster no data could tell from it, never both."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.hypothesis import Context, Hypothesis, angle_basis, joint_angles
from identcheck.effects.base import seen_mean
from identcheck.effects.joint_translation import JointTranslation, linear_fields
from identcheck.effects.injection import rotate, rotations, subtree_columns, unit_vectors
from identcheck.effects.soft_tissue import explained
from identcheck.estimate.noise import noise_floor
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _rolling_knee(seed: int, frames: int, noise_mm: float, roll_mm: float):
    """The bundled nine-marker leg with its knee centre moving in the thigh by ``A (u₁ sin θ + u₂ (1 − cos θ))``,
    θ the knee angle from its smallest value, u₁ ⟂ u₂ random directions, peak `roll_mm`; white noise; fitted by
    the rigid chain to convergence. (context, hypothesis)."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=frames, noise_mm=0.0, seed=seed, rom_deg=80.0)
    data = sim.trial.select(model.markers).as_array()
    rng = np.random.default_rng(seed)
    u1, u2 = unit_vectors(rng, 2)
    u2 = u2 - (u2 @ u1) * u1
    u2 /= np.linalg.norm(u2)
    theta = np.radians(sim.truth.joints["knee"].angles_deg)
    theta = theta - theta.min()
    shift = np.outer(np.sin(theta), u1) + np.outer(1 - np.cos(theta), u2)
    shift *= roll_mm / np.linalg.norm(shift, axis=1).max()
    cols = subtree_columns(sim, "shank")
    data[:, cols] += rotate(rotations(sim, "thigh"), shift)[:, None]
    data = data + rng.normal(0, noise_mm, data.shape)
    chain = Skeleton.from_model(model)
    w = np.ones(data.shape[:2])
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=80)
    seen = np.all(np.isfinite(data), axis=2)
    noise = noise_floor(data, model.markers, {s: model.segments[s].markers for s in model.segments})
    ctx = Context(model, tuple(model.markers), 100.0, data, noise, int(seen.sum()))
    return ctx, Hypothesis(chain, fit.terms, data, w, fit)


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**16), st.floats(4.0, 12.0), st.floats(0.3, 1.0))
def test_the_proposal_s_strength_is_what_the_refit_earns(seed, roll_mm, noise_mm):
    """Knee roll-back of 4-12 mm at its largest, white noise 0.3-1 mm, 600 frames: the knee's proposal strength
    is within 15 % (plus 15 in the criterion's units) of the criterion gain of the refit it proposes, to first
    order the same number; and never less than the regression of the markers' mean residual, the detector's
    earlier reading."""
    ctx, h = _rolling_knee(seed % 1000, 600, noise_mm, roll_mm)
    eff = JointTranslation()
    knee = next(p for p in eff.propose(ctx, h) if p.where["joint"] == "knee")
    new = eff.apply(ctx, h, knee).polish(60)
    earned = ctx.bic_gain(h.rss - new.rss, new.n_params() - h.n_params())   # (not prewhitened: nor is the score)
    assert abs(knee.strength - earned) <= 0.15 * abs(earned) + 15.0
    ch, angles = h.chain, joint_angles(h)
    idx = ch.downstream["knee"]
    seen = np.einsum("fji,fkj->fki", h.fit.seg_R[ch.parent["knee"]], h.residuals()[:, idx])
    basis = angle_basis(angles["knee"], linear=False, cubic=True)
    lin = linear_fields(h, "knee", angles["knee"])
    regression = ctx.bic_gain(len(idx) * explained(seen_mean(seen, axis=1), basis, lin), 3 * basis.shape[1] + len(lin))
    assert knee.strength >= regression - 1e-6 * abs(regression)
    h.release()


@pytest.mark.slow
def test_a_rolling_knee_is_named_once():
    """10 mm of roll-back under 0.5 mm noise, 1500 frames: ``diagnose`` names the knee's centre moving (or the
    shank's cluster moving as one, which the data cannot tell from it, with the other named as indistinguishable),
    and nothing else: not both as two effects."""
    from identcheck.diagnose.workflow import diagnose
    from identcheck.trial import Trial

    ctx, h = _rolling_knee(11, 1500, 0.5, 10.0)
    trial = Trial.from_array(h.data, list(ctx.labels), rate_hz=100.0, source="rolling knee")
    diag = diagnose(ctx.model, trial)
    names = [st.name for st in diag.steps]
    assert names, "nothing named"
    first = diag.steps[0]
    told = {first.name} | {n for n, _w in first.equivalents()}
    assert "joint_translation" in told
    assert len(names) == 1, names
