"""Skin moved by a muscle that spans two joints: a shank marker moving on its shank with the hip's flexion (the
hamstrings, rectus femoris) is a place ``soft_tissue`` proposes and ``diagnose`` names; before, the shank's skin was
only ever driven by the knee's angle, and such a marker was named as a run of slips."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.diagnose.workflow import diagnose
from identcheck.effects.soft_tissue import drivers
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")


def test_each_segment_is_driven_by_its_own_joints_and_those_one_segment_away():
    chain = Skeleton.from_model(MODEL)
    places = set(drivers(chain))
    assert {("shank", ("knee",)), ("thigh", ("hip",)), ("thigh", ("knee",)), ("thigh", ("hip", "knee"))} <= places
    assert {("shank", ("hip",)), ("pelvis", ("knee",))} <= places            # across the joint in between
    assert all(len(j) == 1 for s, j in places if s in ("shank", "pelvis"))    # one joint of their own: no pairs


@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_shank_marker_moving_with_the_hips_flexion_is_named_skin_driven_by_the_hip(seed):
    rng = np.random.default_rng(seed)
    sim = simulate(MODEL, n_frames=800, seed=seed, rom_deg=40.0)
    clean = sim.clean.as_array()
    hip = sim.truth.joints["hip"]
    flex = hip.angles_deg @ hip.motion_axes[:, 0]
    a = 2 * (flex - flex.min()) / np.ptp(flex) - 1                                  # the hip's flexion, scaled to ±1
    col = sim.clean.index("RTIB")
    R = sim.truth.segments["shank"].poses[:, :3, :3]
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    clean[:, col] += np.einsum("fij,fj->fi", R, np.outer(8.0 * a, u))             # 16 mm peak to peak on the shank
    trial = Trial(clean + rng.normal(scale=0.5, size=clean.shape), sim.clean.labels, sim.clean.rate_hz)
    first = diagnose(MODEL, trial, max_steps=1).steps[0]
    assert first.name == "soft_tissue"
    assert first.where["segment"] == "shank" and "RTIB" in first.where["markers"]
    assert "hip" in first.where.get("joints", [first.where["joint"]])
