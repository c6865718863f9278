"""``identify`` on a ball joint (spherical (3,q)) whose child hardly moves in its parent's frame: a sphere through a
point that stays put is a tiny sphere around it, so the exact solver's one joint is no answer. A static trial, one
turned by a fraction of a degree, or one whose child markers move by no more than the noise is degenerate (exit 1
with what to record); a joint that turns is identified as before, near the truth."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from pathlib import Path

from identcheck import api
from identcheck.errors import DegenerateError

HIP = Path(__file__).resolve().parents[2] / "examples" / "hip_31.toml"


def _trial(tmp_path, seed: int, rom_deg: float, noise_mm: float):
    out = tmp_path / f"h_{seed}_{rom_deg:.3f}_{noise_mm:.3f}.trc"
    sim = api.simulate(HIP, out, seed=seed, rom_deg=rom_deg, noise_mm=noise_mm)
    return sim, api.read_trial(out)


def _true_distances(sim) -> dict:
    return {m: d for j in sim.truth.joints for m, d in sim.truth.marker_distances(j).items()}


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0.0, 1.0), st.sampled_from([0.0, 0.3, 1.0]))
def test_a_ball_joint_that_hardly_turns_is_degenerate_not_unique(tmp_path_factory, seed, rom_deg, noise_mm):
    _, trial = _trial(tmp_path_factory.mktemp("still"), seed, rom_deg, noise_mm)
    with pytest.raises(DegenerateError, match="hardly moves"):
        api.identify(HIP, trial)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([0.0, 0.3]))
def test_a_ball_joint_that_turns_is_identified_near_the_truth(tmp_path_factory, seed, noise_mm):
    sim, trial = _trial(tmp_path_factory.mktemp("moving"), seed, 60.0, noise_mm)
    result = api.identify(HIP, trial)
    (joint,) = result.joints
    assert joint.unique
    truth = _true_distances(sim)
    found = joint.candidates[0]["marker_distances"]
    assert all(abs(found[m] - truth[m]) < 5.0 + 100 * noise_mm for m in found if m in truth)
