"""A translating joint's part linear in its angle (``θ a``, along a hinge's axis) moves the joint's centre in its
parent and turns with the parent as fitted, not as the round's fit had it: a field frozen from the fitted rotations
carries the noise of the frames they were fitted to, and beside a term that turns with the fit (skin on the child's
markers, linear in the same angle) their difference fits that noise."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from identcheck.bundle.hypothesis import angle_basis, driving_angles
from identcheck.bundle.model import Terms
from identcheck.diagnose.workflow import score, start
from identcheck.effects.base import Proposal
from identcheck.effects.joint_translation import linear_fields
from identcheck.effects.registry import EFFECTS
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml"


@lru_cache(maxsize=None)
def _model() -> Model:
    return Model.from_toml(MODEL)


@pytest.mark.parametrize("seed", [3, 4])
def test_a_translation_along_the_axis_beside_skin_explains_only_noise_on_a_rigid_leg(seed):
    """A rigid leg (no effect), white noise 0.5 mm, 1 500 frames. Skin on the shank's markers as one cluster, linear
    and quadratic in the knee's (smoothed) angle, is fitted; then the translation's linear field is added by the
    effect's own ``apply`` (no quadratic or cubic functions) and fitted on. With nothing to explain, it explains at
    most the 0.999 quantile of χ² with one parameter. Built in the world from the rigid fit's parent rotations, the
    same field explained 1 957 and 2 834 criterion units (seeds 3 and 4)."""
    model = _model()
    sim = simulate(model, n_frames=1500, seed=seed, rom_deg=40.0, noise_mm=0.5)
    ctx, h = start(model, sim.trial.recentred()[0])
    h = h.polish(60)
    angles = driving_angles(h, ctx.rate_hz)["knee"]
    (field,) = linear_fields(h, "knee", angles)
    shank = [h.chain.labels.index(m) for m in model.segments["shank"].markers]
    skin = h.refit(terms=h.terms + Terms(markers=[(shank, angle_basis(angles))]), max_iter=100)
    proposal = Proposal("joint_translation", {"joint": "knee"}, 1.0,
                        {"joint": "knee", "basis": np.zeros((len(field), 0)), "linear": [field]})
    moved = EFFECTS["joint_translation"].apply(ctx, skin, proposal).polish(100)
    assert moved.n_params() == skin.n_params() + 1
    per_param = ctx.bic_gain(0.0, -1)                        # what the criterion charges a parameter
    gained = score(ctx, moved, h) - score(ctx, skin, h) + per_param
    assert gained < chi2.ppf(0.999, 1), gained


def _knee_screw(frames: int, size_mm: float):
    """The leg with its knee's centre moving along the knee's axis by `size_mm` times the knee angle scaled to a
    range of 1 (a screw), white noise 0.5 mm: (ctx, rigid hypothesis, the knee's linear proposal, true RMS, mm)."""
    model = _model()
    sim = simulate(model, n_frames=frames, seed=3, rom_deg=40.0, noise_mm=0.5)
    data = sim.trial.select(model.markers).as_array()
    theta = np.deg2rad(np.asarray(sim.truth.joints["knee"].angles_deg, dtype=float))
    profile = size_mm * (theta - theta.mean()) / np.ptp(theta)
    below = Skeleton.from_model(model).downstream["knee"]
    data[:, below] += profile[:, None, None] * sim.truth.axis_world("knee")[:, None]
    ctx, h = start(model, sim.trial.select(model.markers).replace(xyz=data).recentred()[0])
    (field,) = linear_fields(h, "knee", driving_angles(h, ctx.rate_hz)["knee"])
    proposal = Proposal("joint_translation", {"joint": "knee"}, 1.0,
                        {"joint": "knee", "basis": np.zeros((len(field), 0)), "linear": [field]})
    return ctx, h, proposal, float(np.std(profile))


def test_a_screw_in_the_data_is_fitted_and_read_at_its_size():
    """A knee screwing 20 mm over its range (5.1 mm RMS), 400 frames: the translation's linear part, as the effect
    applies it, gains more than a thousand criterion units and reads the centre's motion within 10 % of the truth."""
    ctx, h, proposal, true_rms = _knee_screw(400, 20.0)
    effect = EFFECTS["joint_translation"]
    moved = effect.apply(ctx, h, proposal).polish(40)
    assert len(moved.terms.screws) == 1 and not moved.terms.world
    assert score(ctx, moved, h) > 1000.0
    (read,) = effect.modelled_motion(proposal, moved)
    assert read.rms_mm == pytest.approx(true_rms, rel=0.1)


def test_a_hinge_carrying_a_screw_is_not_offered_as_a_ball_and_a_ball_proposal_is_no_screw():
    """Declared a ball, a hinge's screw would have no axis to run along: the extra degree of freedom offers only
    second rotations for it (a search had stopped with a KeyError). A proposal made for a ball joint and fitted again
    on the joint declared a hinge (a search going back over its steps) is fitted as world terms, not screws."""
    ctx, h, proposal, _ = _knee_screw(200, 20.0)
    moved = EFFECTS["joint_translation"].apply(ctx, h, proposal)
    def as_balls(hyp):
        return [p for p in EFFECTS["extra_dof"].propose(ctx, hyp)
                if p.where.get("joint") == "knee" and p.where.get("needs") == "spherical"]
    assert as_balls(h) and not as_balls(moved)
    as_ball = Proposal("joint_translation", {"joint": "knee"}, 1.0, {**proposal.payload, "proposed_for": "spherical"})
    again = EFFECTS["joint_translation"].apply(ctx, h, as_ball)
    assert not again.terms.screws and len(again.terms.world) == 1
