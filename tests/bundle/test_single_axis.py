"""A ball joint that turned about one axis only leaves its centre free along that axis, however small the
quadratic standard error the noise's own curvature gives: ``single_axis`` says so (random subjects, noise
levels and trial lengths), and neither ``fit`` nor ``diagnose`` then bounds the joint's marker distances."""
from __future__ import annotations

from pathlib import Path

from hypothesis import given, settings, strategies as st

import identcheck as ic
from identcheck.bundle.practical import single_axis
from identcheck.diagnose.workflow import diagnose, start
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), n_axes=st.sampled_from([1, 2, 3]), noise=st.floats(0.2, 2.0),
       frames=st.integers(200, 900))
def test_single_axis_tells_a_one_axis_hip_from_a_two_or_three_axis_one(seed, n_axes, noise, frames):
    sim = simulate(MODEL, n_frames=frames, seed=seed, n_axes=n_axes, noise_mm=noise)
    ctx, h = start(MODEL, sim.trial)
    one, second_deg, noise_deg = single_axis(h.chain, h.fit, ctx.noise.sigma_mm, "hip")
    assert one == (n_axes == 1), (second_deg, noise_deg)
    assert not single_axis(h.chain, h.fit, ctx.noise.sigma_mm, "knee")[0]      # a hinge needs one axis


def test_a_one_axis_hip_is_undetermined_and_unbounded_in_fit_and_diagnose():
    sim = simulate(MODEL, n_frames=600, seed=1, n_axes=1, noise_mm=0.5)
    for result in (ic.fit(MODEL, sim.trial).to_dict(), diagnose(MODEL, sim.trial).to_dict()):
        hip = result["joints"]["hip"]
        assert hip["practical"]["verdict"] == "undetermined" and not hip["unique"]
        assert all(hi is None for _, hi in hip["marker_distances_ci95"].values())


SPARSE = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml").to_dict()


def _two_marker_thigh(model_dict: dict, dropped: str) -> Model:
    """The nine-marker leg with one thigh marker taken off (two left, beside a three-marker pelvis)."""
    d = {**model_dict, "segments": {k: dict(v) for k, v in model_dict["segments"].items()}}
    d["segments"]["thigh"]["markers"] = [m for m in d["segments"]["thigh"]["markers"] if m != dropped]
    d["segments"]["thigh"].pop("local", None)
    return Model.from_dict(d)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000), n_axes=st.sampled_from([2, 3]), noise=st.floats(0.3, 1.5),
       frames=st.integers(300, 900))
def test_a_hip_turning_about_several_axes_beside_a_two_marker_thigh_is_never_read_as_one(seed, n_axes, noise, frames):
    """Two thigh markers (the greater trochanter's and the thigh wand's), whose fitted rotation the noise rolls
    about their line, beside a three-marker pelvis: a hip turned about two or three axes never has them within 3σ
    of circles (:func:`identcheck.bundle.practical.single_axis_by_circles`; the simulator's came out 5.7σ and
    above, 24 of 24 at 1 mm)."""
    sim = simulate(MODEL, n_frames=frames, seed=seed, n_axes=n_axes, noise_mm=noise)
    ctx, h = start(_two_marker_thigh(SPARSE, "RKNE"), sim.trial)
    one, second_deg, noise_deg = single_axis(h.chain, h.fit, ctx.noise.sigma_mm, "hip")
    assert not one, (second_deg, noise_deg)


def test_a_one_axis_hip_beside_a_two_marker_thigh_is_read_as_one_in_half_the_trials():
    """The same thigh, the hip turned about one axis (1 mm noise, 600 frames, 12 subjects and motions): its
    markers within 3σ of circles in 6 of 12 (measured; asserted at 5). The others come out 3.4-6.3σ off, most
    likely from the pelvis's pose noise, which moves markers far from its centroid by more than their own noise and
    which the threshold does not count (counting it flagged hips turning about several axes in an independent
    session's trials); those joints are judged as before. (An independent session's flexion-only hips with two
    thigh markers, called determined 65-82 mm from the truth, lie within 1.8-2.7σ.)"""
    found = 0
    for seed in range(12):
        sim = simulate(MODEL, n_frames=600, seed=seed, n_axes=1, noise_mm=1.0)
        ctx, h = start(_two_marker_thigh(SPARSE, "RKNE"), sim.trial)
        found += single_axis(h.chain, h.fit, ctx.noise.sigma_mm, "hip")[0]
    assert found >= 5
