"""A joint to a one- or two-marker group is typed by whether the group moves on a circle (a hinge) or over a sphere
in the parent's frame, against the markers' noise as that frame sees them: the parent's pose noise grows it (a thigh
posed by three markers along the femur, 12 times at the shank). Against the markers' own noise, the bundled leg's
hinged knee at 0.5 mm of noise was typed a ball joint."""
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
def test_a_small_group_is_a_hinge_when_its_circle_fits_within_twice_the_noise_its_parent_sees(
        sphere, circle, sigma, factor):
    small = SmallFit(sphere, circle, 100.0, 300.0, 200, noise_factor=factor)
    kind = classify_small(small, sigma).type
    floor = max(sphere, sigma * factor)
    if abs(circle - CIRCLE_FACTOR * floor) > 1e-9 * floor:
        assert kind == ("revolute" if circle < CIRCLE_FACTOR * floor else "spherical")
    assert classify_small(small, sigma).evidence["noise_in_parent_mm"] == pytest.approx(sigma * factor)


@pytest.mark.parametrize("seed", [0, 3])
@pytest.mark.parametrize("knee", ["revolute", "spherical"])
def test_the_bundled_legs_knee_is_typed_as_simulated_through_its_two_shank_markers(tmp_path, seed, knee):
    model = tmp_path / "leg.toml"
    text = LEG.read_text()
    if knee == "spherical":
        text = text.replace('type = "revolute"                       # hinge', 'type = "spherical"  # hinge', 1)
    model.write_text(text)
    trial = tmp_path / "leg.trc"
    api.simulate(model, trial, seed=seed, n_frames=300, noise_mm=0.5)
    doc = api.skeleton(trial).to_dict()
    shank = [j for j in doc["joints"] if set(doc["segments"][j["child"]]) == {"RTIB", "RANK"}]
    assert len(shank) == 1 and shank[0]["type"] == knee, shank
