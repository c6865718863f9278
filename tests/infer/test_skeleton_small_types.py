"""A joint to a one- or two-marker group is typed by whether the group moves on a circle (a hinge) or over a sphere
in the parent's frame: a hinge when the circle fits within the markers' own noise, a ball joint when it does not fit
within the noise that frame sees (the parent's pose noise grows it: a thigh posed by three markers along the femur,
12 times at the shank), and between the two neither can be told: spherical, the general type, at confidence 0.5. The
bundled leg's hinged knee at 0.5 mm of noise had been typed a ball joint at full confidence."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck import api
from identcheck.infer.joint_types import CIRCLE_FACTOR, classify_small
from identcheck.infer.tree import SmallFit

LEG = Path(__file__).resolve().parents[2] / "examples" / "leg.toml"


@settings(max_examples=80, deadline=None)
@given(sphere=st.floats(0.05, 20.0), circle=st.floats(0.05, 60.0), sigma=st.floats(0.05, 2.0),
       factor=st.floats(1.0, 20.0))
def test_a_small_group_is_a_hinge_a_ball_or_not_told_apart_by_its_circle_against_the_noise(
        sphere, circle, sigma, factor):
    small = SmallFit(sphere, circle, 100.0, 300.0, 200, noise_factor=factor)
    typed = classify_small(small, sigma)
    own, seen = CIRCLE_FACTOR * max(sphere, sigma), CIRCLE_FACTOR * max(sphere, sigma * factor)
    if circle < own * (1 - 1e-9):
        assert typed.type == "revolute"
    elif circle > seen * (1 + 1e-9):
        assert typed.type == "spherical" and "over a sphere" in typed.evidence["rule"]
    elif circle > own * (1 + 1e-9) and circle < seen * (1 - 1e-9):
        assert typed.type == "spherical" and typed.confidence == 0.5 and "cannot be told" in typed.evidence["rule"]
    assert typed.evidence["noise_in_parent_mm"] == pytest.approx(sigma * factor)


@settings(max_examples=40, deadline=None)
@given(sphere=st.floats(0.05, 5.0), sigma=st.floats(0.05, 2.0), factor=st.floats(1.5, 20.0))
def test_the_confidence_of_a_ball_joint_grows_from_one_half_past_the_noise_its_parent_sees(sphere, sigma, factor):
    """Just past the line where a circle no longer fits within the parent-frame noise, a ball joint is called at about
    the confidence 0.5 of 'cannot be told apart' just inside it, not at full confidence (it had jumped from 0.5 to
    1.0 there), and the confidence grows with the circle's misfit."""
    wide = CIRCLE_FACTOR * max(sphere, sigma * factor)
    if wide <= CIRCLE_FACTOR * max(sphere, sigma) * 1.05:
        return                                        # (no zone between the two lines)
    inside = classify_small(SmallFit(sphere, wide * 0.999, 100.0, 300.0, 200, noise_factor=factor), sigma)
    past = classify_small(SmallFit(sphere, wide * 1.001, 100.0, 300.0, 200, noise_factor=factor), sigma)
    far = classify_small(SmallFit(sphere, wide * 5.0, 100.0, 300.0, 200, noise_factor=factor), sigma)
    assert inside.type == past.type == far.type == "spherical"
    assert inside.confidence == 0.5 and abs(past.confidence - 0.5) < 0.05 and far.confidence > past.confidence


@pytest.mark.parametrize("seed", [0, 3])
@pytest.mark.parametrize("knee", ["revolute", "spherical"])
def test_the_bundled_legs_knee_through_its_two_shank_markers_is_never_typed_wrong_with_confidence(tmp_path, seed, knee):
    """The knee hinged: a hinge, or (its thigh posed along the femur) hinge and ball not told apart, at confidence
    0.5; a ball joint: a ball joint."""
    model = tmp_path / "leg.toml"
    text = LEG.read_text()
    if knee == "spherical":
        text = text.replace('type = "revolute"                       # hinge', 'type = "spherical"  # hinge', 1)
    model.write_text(text)
    trial = tmp_path / "leg.trc"
    api.simulate(model, trial, seed=seed, n_frames=300, noise_mm=0.5)
    doc = api.skeleton(trial).to_dict()
    shank = [j for j in doc["joints"] if set(doc["segments"][j["child"]]) == {"RTIB", "RANK"}]
    assert len(shank) == 1
    joint = shank[0]
    if knee == "spherical":
        assert joint["type"] == "spherical" and joint["confidence"] > 0.5, joint
    else:
        assert joint["type"] == "revolute" or (joint["confidence"] == 0.5
                                               and "cannot be told" in joint["evidence"]["type"]["rule"]), joint
