"""The simulator: its truth must satisfy the joint constraints exactly, and its options work."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.io.model import JOINT_TYPES, Model
from identcheck.api import simulate_file
from identcheck.simulate.rigid import MARKER_RANGE_MM, Simulation, load_truth, simulate
from identcheck.trial import Trial

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
LEG = Model.from_toml(EXAMPLES / "leg.toml")
KNEE = Model.from_toml(EXAMPLES / "knee_21.toml")


def world(sim: Simulation, segment: str) -> np.ndarray:
    """Clean positions of a segment's markers, shape (n_frames, k, 3)."""
    return sim.clean.select(sim.model.segments[segment].markers).xyz


def assert_joint_constraints(sim: Simulation, tol=1e-9):
    """Spherical: every adjacent marker keeps its distance to the world centre. Revolute: its
    distance to the world hinge axis and its position along it. Both: the centre (and axis)
    computed from the parent and from the child agree."""
    truth = sim.truth
    for name, j in truth.joints.items():
        centre = truth.centre_world(name)
        pose_c = truth.segments[j.child].poses
        np.testing.assert_allclose(pose_c[:, :3, :3] @ j.centre_child + pose_c[:, :3, 3], centre,
                                   atol=tol, rtol=0)
        xyz = np.concatenate([world(sim, j.parent), world(sim, j.child)], axis=1)
        d = xyz - centre[:, None]
        if j.type == "spherical":
            dist = np.linalg.norm(d, axis=2)
            assert np.ptp(dist, axis=0).max(initial=0) < tol
        else:
            axis = truth.axis_world(name)
            np.testing.assert_allclose(pose_c[:, :3, :3] @ j.axis_child, axis, atol=1e-12, rtol=0)
            along = np.einsum("fmi,fi->fm", d, axis)
            radial = np.linalg.norm(d - along[..., None] * axis[:, None], axis=2)
            assert np.ptp(along, axis=0).max(initial=0) < tol
            assert np.ptp(radial, axis=0).max(initial=0) < tol
        expected = truth.marker_distances(name)
        got = np.linalg.norm(d, axis=2)[0] if j.type == "spherical" else radial[0]
        np.testing.assert_allclose(got, list(expected.values()), atol=tol)


def assert_truth_consistent(sim: Simulation):
    """Clean trial == poses applied to the local marker positions; shapes as documented."""
    n = sim.clean.n_frames
    for seg in sim.truth.segments.values():
        assert seg.poses.shape == (n, 4, 4)
        rot = seg.poses[:, :3, :3]
        np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (n, 3, 3)), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)
        np.testing.assert_array_equal(seg.poses[:, 3], np.broadcast_to([0, 0, 0, 1.0], (n, 4)))
        for marker, local in seg.marker_local.items():
            assert local.shape == (3,)
            np.testing.assert_allclose(sim.clean.marker(marker), rot @ local + seg.poses[:, :3, 3], atol=1e-9)
    for j in sim.truth.joints.values():
        assert j.centre_parent.shape == j.centre_child.shape == (3,)
        if j.type == "revolute":
            assert np.linalg.norm(j.axis_parent) == pytest.approx(1.0)
            assert np.linalg.norm(j.axis_child) == pytest.approx(1.0)
            assert j.angles_deg.shape == (n,)
        else:
            assert j.axis_parent is None and j.axis_child is None
            assert j.angles_deg.shape == (n, 3)


# ---------------------------------------------------------------------- examples
@pytest.mark.parametrize("model", [LEG, KNEE], ids=["leg", "knee_21"])
def test_examples_satisfy_constraints(model):
    sim = simulate(model, seed=4)
    assert sim.trial.labels == model.markers
    assert sim.trial.xyz.shape == (200, len(model.markers), 3)
    assert_truth_consistent(sim)
    assert_joint_constraints(sim)


def test_knee_21_uses_the_given_geometry():
    sim = simulate(KNEE, seed=11)
    knee = sim.truth.joints["knee_r"]
    np.testing.assert_array_equal(knee.axis_parent, [0, 1, 0])
    np.testing.assert_array_equal(knee.centre_parent, [0, 0, -400])
    np.testing.assert_array_equal(knee.centre_child, [0, 0, 0])
    np.testing.assert_array_equal(sim.truth.segments["thigh_r"].marker_local["RTH2"], [30, -75, -320])
    np.testing.assert_array_equal(sim.truth.segments["shank_r"].marker_local["RTIB"], [50, -40, -150])
    # the geometry is fixed by the file: another seed moves differently but is the same subject
    other = simulate(KNEE, seed=12)
    assert other.truth.marker_distances("knee_r") == pytest.approx(sim.truth.marker_distances("knee_r"))
    assert not np.allclose(other.clean.xyz, sim.clean.xyz)
    # distance of RTIB to the hinge axis (y) through the shank origin
    assert sim.truth.marker_distances("knee_r")["RTIB"] == pytest.approx(np.hypot(50, 150))


def assert_plausible(sim: Simulation):
    """Drawn markers: 30-200 mm from the nearest joint centre on their segment and no closer
    than 30 mm to any, apart from each other, off every hinge axis, not collinear."""
    for seg, truth in sim.truth.segments.items():
        local = np.array(list(truth.marker_local.values())).reshape(-1, 3)
        centres = [j.centre_parent for j in sim.truth.joints.values() if j.parent == seg]
        centres += [j.centre_child for j in sim.truth.joints.values() if j.child == seg]
        if len(local) and centres:
            dist = np.linalg.norm(local[:, None] - np.array(centres)[None], axis=2)
            assert dist.min() >= MARKER_RANGE_MM[0]
            assert dist.min(axis=1).max() <= MARKER_RANGE_MM[1]
        if len(local) > 1:
            gaps = np.linalg.norm(local[:, None] - local[None], axis=2) + np.eye(len(local)) * 1e9
            assert gaps.min() > 20.0
        if len(local) > 2:
            assert np.linalg.svd(local - local.mean(axis=0), compute_uv=False)[1] >= 10.0
        assert 150 <= truth.length_mm <= 450
    for name, j in sim.truth.joints.items():
        if j.type == "revolute" and sim.truth.marker_distances(name):
            assert min(sim.truth.marker_distances(name).values()) >= 20.0, "no marker on a hinge axis"


def test_drawn_geometry_is_plausible():
    assert_plausible(simulate(LEG, seed=2))


def test_revolute_centre_is_axis_point_nearest_child_origin():
    sim = simulate(LEG, seed=5)
    for name in ("knee_r", "ankle_r"):
        j = sim.truth.joints[name]
        assert j.centre_child @ j.axis_child == pytest.approx(0.0, abs=1e-9)
        assert np.linalg.norm(j.centre_child) > 1.0  # random technical frames: not trivially 0


# ---------------------------------------------------------------------- options
def test_same_seed_same_result_other_seed_differs():
    a, b, c = simulate(LEG, seed=7), simulate(LEG, seed=7), simulate(LEG, seed=8)
    np.testing.assert_array_equal(a.trial.xyz, b.trial.xyz)
    assert not np.allclose(a.clean.xyz, c.clean.xyz)


def test_noise_and_gaps_leave_the_clean_trial_alone():
    base = simulate(LEG, seed=3)
    noisy = simulate(LEG, seed=3, noise_mm=2.0, occlusion=0.2)
    np.testing.assert_array_equal(base.clean.xyz, noisy.clean.xyz)
    diff = (noisy.trial.xyz - noisy.clean.xyz)[~noisy.gaps]
    assert diff.std() == pytest.approx(2.0, rel=0.1)
    assert abs(diff.mean()) < 0.2
    np.testing.assert_array_equal(base.trial.xyz, base.clean.xyz)


@pytest.mark.parametrize("occlusion", [0.0, 0.05, 0.3, 1.0])
def test_occlusion_fraction_and_contiguous_gaps(occlusion):
    sim = simulate(LEG, seed=9, occlusion=occlusion, n_frames=300)
    np.testing.assert_array_equal(np.isnan(sim.trial.xyz).any(axis=2), sim.gaps)
    np.testing.assert_array_equal(np.isnan(sim.trial.xyz).all(axis=2), sim.gaps)
    assert sim.gaps.any(axis=1).sum() == round(occlusion * 300)
    assert not np.isnan(sim.clean.xyz).any()
    if occlusion:
        # runs, not isolated frames: most gap samples have a gap neighbour in time
        g = sim.gaps
        neighbour = np.zeros_like(g)
        neighbour[1:] |= g[:-1]
        neighbour[:-1] |= g[1:]
        assert (neighbour & g).sum() >= 0.8 * g.sum()


def test_rom_sets_the_revolute_range():
    sim = simulate(LEG, seed=1, rom_deg=40.0)
    for name in ("knee_r", "ankle_r"):
        assert np.ptp(sim.truth.joints[name].angles_deg) == pytest.approx(40.0)
    hip = sim.truth.joints["hip_r"]
    np.testing.assert_allclose(np.ptp(hip.angles_deg @ hip.motion_axes, axis=0), 40.0)


@pytest.mark.parametrize("n_axes", [1, 2, 3])
def test_n_axes_limits_the_spherical_motion(n_axes):
    sim = simulate(LEG, seed=6, n_axes=n_axes)
    hip = sim.truth.joints["hip_r"]
    assert hip.n_axes == n_axes and hip.motion_axes.shape == (3, n_axes)
    # the relative rotation seen in the poses is the stated one ...
    poses = sim.truth.segments
    rel = poses["pelvis"].poses[:, :3, :3].transpose(0, 2, 1) @ poses["thigh_r"].poses[:, :3, :3]
    expm = Rotation.from_rotvec(np.deg2rad(hip.angles_deg)).as_matrix()
    np.testing.assert_allclose(rel @ rel[0].T, expm @ expm[0].T, atol=1e-12)
    # ... and it spans exactly n_axes directions
    sv = np.linalg.svd(hip.angles_deg, compute_uv=False)
    assert (sv > 1e-6 * sv[0]).sum() == n_axes


def test_no_root_motion_keeps_the_root_still():
    sim = simulate(LEG, seed=2, root_motion=False)
    poses = sim.truth.segments["pelvis"].poses
    np.testing.assert_array_equal(poses, np.broadcast_to(poses[0], poses.shape))
    moving = simulate(LEG, seed=2).truth.segments["pelvis"].poses
    assert np.ptp(moving[:, :3, 3], axis=0).min() > 50.0


def test_single_frame_and_empty_segments():
    model = Model.from_dict({"segments": {"a": {"markers": []}, "b": {"markers": ["B1"]},
                                          "c": {"markers": ["C1", "C2", "C3", "C4"]}},
                             "joints": {"ab": {"type": "spherical", "parent": "a", "child": "b"},
                                        "bc": {"type": "revolute", "parent": "b", "child": "c"}}})
    sim = simulate(model, n_frames=1, seed=0)
    assert sim.trial.xyz.shape == (1, 5, 3)
    assert_truth_consistent(sim)


def test_bad_arguments_all_listed():
    with pytest.raises(InputError) as info:
        simulate(LEG, n_frames=0, rate_hz=-1, n_axes=4, noise_mm=-1, occlusion=2)
    assert len(info.value.problems) == 5
    assert "n_axes must be None, 1, 2 or 3" in str(info.value)


# ---------------------------------------------------------------------- files
def test_save_and_load_truth(tmp_path):
    sim = simulate(LEG, seed=3, n_frames=20)
    sim.save_truth(tmp_path / "truth.json")
    doc = json.loads((tmp_path / "truth.json").read_text())
    assert doc["settings"]["seed"] == 3 and doc["labels"] == list(LEG.markers)
    assert doc["joints"]["knee_r"]["type"] == "revolute"
    assert set(doc["joints"]["hip_r"]["marker_distances"]) == {"LASI", "RASI", "SACR", "RGT", "RTHI", "RKNE"}
    back = load_truth(tmp_path / "truth.json")
    for name, j in sim.truth.joints.items():
        np.testing.assert_array_equal(back.joints[name].centre_parent, j.centre_parent)
        np.testing.assert_array_equal(back.joints[name].angles_deg, j.angles_deg)
    np.testing.assert_array_equal(back.segments["shank_r"].poses, sim.truth.segments["shank_r"].poses)


@pytest.mark.parametrize("ext, atol", [(".trc", 1e-6), (".c3d", 1e-3)])
def test_simulate_file_writes_a_readable_trial(tmp_path, ext, atol):
    out = tmp_path / f"leg{ext}"
    sim = simulate_file(EXAMPLES / "leg.toml", out, seed=5, noise_mm=0.5, occlusion=0.1, n_frames=50)
    back = Trial.from_file(out)
    assert back.labels == sim.trial.labels and back.rate_hz == pytest.approx(100.0)
    np.testing.assert_array_equal(np.isnan(back.xyz), np.isnan(sim.trial.xyz))
    np.testing.assert_allclose(back.xyz, sim.trial.xyz, atol=atol, rtol=0)


def test_simulate_file_rejects_unknown_extension_before_work(tmp_path):
    with pytest.raises(InputError, match=r"leg\.csv: unknown trial file extension"):
        simulate_file(EXAMPLES / "leg.toml", tmp_path / "leg.csv")
    assert not (tmp_path / "leg.csv").exists()
    with pytest.raises(InputError, match="file not found"):
        simulate_file(tmp_path / "missing.toml", tmp_path / "x.trc")


# ---------------------------------------------------------------------- random models
@st.composite
def models(draw):
    n = draw(st.integers(1, 5))
    parents = [draw(st.integers(0, i - 1)) for i in range(1, n)]
    segments = {f"s{i}": {"markers": [f"s{i}m{k}" for k in range(draw(st.integers(0, 4)))]}
                for i in range(n)}
    joints = {f"j{i}": {"type": draw(st.sampled_from(JOINT_TYPES)), "parent": f"s{parents[i - 1]}",
                        "child": f"s{i}"} for i in range(1, n)}
    return Model.from_dict({"segments": segments, "joints": joints})


@settings(max_examples=100, deadline=None)
@given(model=models(), seed=st.integers(0, 2**32 - 1), rom=st.floats(5.0, 120.0),
       n_axes=st.sampled_from([None, 1, 2, 3]), root_motion=st.booleans())
def test_random_models_satisfy_constraints(model, seed, rom, n_axes, root_motion):
    sim = simulate(model, n_frames=40, rom_deg=rom, n_axes=n_axes, root_motion=root_motion, seed=seed)
    assert_truth_consistent(sim)
    assert_joint_constraints(sim)
    assert_plausible(sim)
    for name, j in sim.truth.joints.items():
        if j.type == "revolute":
            assert np.ptp(j.angles_deg) == pytest.approx(rom)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), noise=st.floats(0.0, 5.0), occlusion=st.floats(0.0, 1.0))
def test_random_noise_and_occlusion(seed, noise, occlusion):
    sim = simulate(KNEE, n_frames=60, noise_mm=noise, occlusion=occlusion, seed=seed)
    assert sim.gaps.any(axis=1).sum() == round(occlusion * 60)
    seen = ~sim.gaps
    err = np.abs(sim.trial.xyz - sim.clean.xyz)[seen]
    assert err.max(initial=0.0) <= 8 * noise + 1e-12
    assert_joint_constraints(sim)
