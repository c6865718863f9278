"""What ``fit`` says of a joint's motion is what the markers measure.

The fitted angles of a joint beside a segment with fewer than three markers of its own follow the joint's fitted
geometry, which is what the data leave open when the advice is given: a static knee trial with one shank marker
near the fitted axis had "moved 346 deg about its hinge". The advice reports instead how far the markers of the
segment that is not posed by itself move in the frame of the one that is (:func:`excursion_mm`), and says "hardly
moved" when that is no more than the noise or a few mm."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

import identcheck as ic
from identcheck.bundle.practical import HARDLY_MOVED_MM, excursion_mm
from identcheck.fit.workflow import fit_trial
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).parents[2] / "examples"
SPARSE = Model.from_toml(EXAMPLES / "sparse_leg.toml")     # 3 pelvis, 1 thigh, 1 shank marker
LEG = Model.from_toml(EXAMPLES / "leg.toml")               # 3 pelvis, 3 thigh, 2 shank, 2 foot markers


def _true_excursion(sim, frame_segment: str, markers: list) -> float:
    """The same quantity as excursion_mm, from the simulation's exact positions and poses."""
    pose = sim.truth.segments[frame_segment].poses                       # (F, 4, 4) world from segment
    R, t = pose[:, :3, :3], pose[:, :3, 3]
    world = sim.clean.select(markers).as_array()                         # (F, k, 3)
    local = np.einsum("fji,fkj->fki", R, world - t[:, None])
    dist = np.linalg.norm(local - np.median(local, axis=0), axis=2)
    return float(np.max(np.percentile(dist, 95.0, axis=0)))


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), rom=st.floats(0.0, 70.0), noise=st.floats(0.1, 1.5))
def test_excursion_is_the_markers_own_movement_in_the_posed_segment(seed, rom, noise):
    sim = simulate(SPARSE, n_frames=400, seed=seed, rom_deg=rom, noise_mm=noise)
    got = {}
    fit_trial(SPARSE, sim.trial, on_fit=lambda trial, fit, offset: got.setdefault("fit", fit))
    fit = got["fit"]
    (got,), (amplification,) = excursion_mm(fit.chain, fit, "pelvis", "thigh_r")
    truth = _true_excursion(sim, "pelvis", ["RTHI"])
    assert abs(got - truth) <= 3.0 * noise * amplification + 0.05 * truth, (got, truth, amplification)


def _advice(result: dict) -> dict:
    return {name: j["practical"]["motion_advice"] for name, j in result["joints"].items()
            if j["practical"]["verdict"] != "determined"}


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.floats(0.2, 1.0))
def test_a_static_sparse_leg_is_said_to_have_hardly_moved_and_no_angle_is_claimed(seed, noise):
    sim = simulate(SPARSE, n_frames=300, seed=seed, rom_deg=0.2, noise_mm=noise)
    joints = ic.fit(SPARSE, sim.trial).to_dict()["joints"]
    hip = joints["hip_r"]
    # before: 'determined', RTHI 5.9 +- 1.2 mm from the centre (510 mm in truth) at seed 0, 1 mm noise
    assert hip["practical"]["verdict"] == "undetermined" and not hip["unique"], hip["practical"]
    # a static trial leaves the fit crawling along its free directions: where the restarts' 10 s budget runs out
    # first (seed 3694 at 0.4 mm, on two busy cores), the answer says so instead, and claims no interval either
    assert (hip["practical"]["reason"].startswith("hip_r hardly moved")
            or "did not converge" in hip["practical"]["reason"]), hip["practical"]
    assert all(hi is None for _, hi in hip["marker_distances_ci95"].values())
    # neither thigh (1 marker) nor shank (1 marker) is posed by its own markers: no range of angles is claimed
    assert joints["knee_r"]["practical"]["verdict"] != "determined"
    assert "deg" not in joints["knee_r"]["practical"]["motion_advice"], joints["knee_r"]["practical"]


def test_a_moving_sparse_leg_reports_millimetres_not_degrees():
    sim = simulate(SPARSE, n_frames=600, seed=3, rom_deg=50.0, noise_mm=0.5)
    advice = _advice(ic.fit(SPARSE, sim.trial).to_dict())
    truth = _true_excursion(sim, "pelvis", ["RTHI"])
    assert truth > 4 * HARDLY_MOVED_MM                                  # a trial that moves
    for name, text in advice.items():
        assert "about its hinge" not in text and "hardly" not in text, (name, text)
    if "hip_r" in advice:
        moved = float(advice["hip_r"].split("move up to ")[1].split(" mm")[0])
        assert abs(moved - truth) <= 0.05 * truth + 2.0, (moved, truth)


def test_a_static_hip_between_posed_segments_hardly_turned(tmp_path):
    """Both segments of the hip posed by their own markers: the fitted rotation is measured, and a static trial
    is undetermined and the advice is to record the joint's movement (it had been 'turned mostly about one
    axis')."""
    path = tmp_path / "hip.toml"
    path.write_text('units = "mm"\n[segments.pelvis]\nmarkers = ["LASI", "RASI", "SACR"]\n'
                    '[segments.thigh_r]\nmarkers = ["RGT", "RTHI", "RKNE"]\nlength_mm = 420\n'
                    '[joints.hip_r]\ntype = "spherical"\nparent = "pelvis"\nchild = "thigh_r"\n')
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=300, seed=5, rom_deg=0.3, noise_mm=0.5)
    hip = ic.fit(model, sim.trial).to_dict()["joints"]["hip_r"]
    assert hip["practical"]["verdict"] == "undetermined"
    advice = hip["practical"]["motion_advice"]
    assert advice == "record the joint's movement through its range", hip["practical"]
    assert hip["practical"]["reason"].startswith("hip_r ")


def test_a_static_joint_between_two_unposed_segments_hardly_moved(tmp_path):
    """Neither segment posed by its own markers (a two-marker shank and a two-marker foot): their markers keep every
    distance across the joint, so they move as one body and the joint did not move (a static ankle of this kind had
    been 'determined' 111-196 mm off on the near-static held-out draw)."""
    text = (EXAMPLES / "leg.toml").read_text().replace('markers = ["RGT", "RTHI", "RKNE"]', 'markers = ["RTHI"]')
    path = tmp_path / "leg_mixed.toml"
    path.write_text(text)
    model = Model.from_toml(path)
    sim = simulate(model, n_frames=300, seed=4, rom_deg=0.0, noise_mm=0.5)
    joints = ic.fit(model, sim.trial).to_dict()["joints"]
    assert all(j["practical"]["verdict"] != "determined" for j in joints.values()), joints
    ankle = joints["ankle_r"]["practical"]
    assert ankle["verdict"] == "undetermined" and ankle["reason"].startswith("ankle_r hardly moved: every distance")
