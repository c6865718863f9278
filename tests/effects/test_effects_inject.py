"""Effect injection: each effect does exactly what its record says, and nothing else."""
from __future__ import annotations

import copy
import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from identcheck import cli
from identcheck.effects.registry import NAMES as EFFECTS, inject_effect, true_centre_world
from identcheck.errors import InputError
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SEEDS = st.integers(0, 2**32 - 1)
BODY = ("soft_tissue", "marker_slip", "joint_translation", "extra_dof", "time_offset", "spatial_distortion")


@lru_cache(maxsize=None)
def model(name: str = "diagnose_leg") -> Model:
    return Model.from_toml(EXAMPLES / f"{name}.toml")


@lru_cache(maxsize=None)
def rigid(name: str = "diagnose_leg", seed: int = 1, occlusion: float = 0.1, rate_hz: float = 100.0):
    """A noisy rigid simulation with gaps (cached: tests must not modify it, which one test checks)."""
    return simulate(model(name), n_frames=300, noise_mm=0.5, seed=seed, occlusion=occlusion, rate_hz=rate_hz)


def local(sim, segment: str, xyz: np.ndarray) -> np.ndarray:
    """World positions (F, k, 3) in the segment frame of the rigid truth: R^T (x - t)."""
    pose = sim.truth.segments[segment].poses
    return np.einsum("fji,fmj->fmi", pose[:, :3, :3], xyz - pose[:, None, :3, 3])


def cols(sim, markers) -> list[int]:
    return [sim.trial.index(m) for m in markers]


def changed_markers(old, new, atol=1e-9) -> set[str]:
    """Markers whose positions differ anywhere (NaN equal to NaN)."""
    diff = ~np.isclose(old.xyz, new.xyz, atol=atol, rtol=0, equal_nan=True)
    return {old.labels[c] for c in np.flatnonzero(diff.any(axis=(0, 2)))}


def angle(sim, joint: str) -> np.ndarray:
    """The joint angle the effects use: hinge angle, or a ball joint's flexion component."""
    j = sim.truth.joints[joint]
    return j.angles_deg if j.angles_deg.ndim == 1 else j.angles_deg @ j.motion_axes[:, 0]


# ---------------------------------------------------------------------- every effect
@pytest.mark.parametrize("name", EFFECTS)
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_every_effect_leaves_its_input_alone_and_records_real_places(name, seed):
    sim = rigid()
    before = (sim.trial.as_array(), sim.clean.as_array(), sim.gaps.copy(), copy.deepcopy(sim.settings))
    out = inject_effect(sim, name, seed)
    np.testing.assert_array_equal(sim.trial.xyz, before[0])
    np.testing.assert_array_equal(sim.clean.xyz, before[1])
    np.testing.assert_array_equal(sim.gaps, before[2])
    assert sim.settings == before[3] and "effect" not in sim.settings
    assert out.truth is sim.truth and out.model is sim.model

    effect = out.settings["effect"]
    assert effect["name"] == name and json.loads(json.dumps(effect)) == effect
    where, n = effect["where"], sim.trial.n_frames
    assert set(where.get("markers", [])) <= set(sim.model.markers)
    assert where.get("segment", sim.model.root) in sim.model.segments
    assert where.get("joint", sim.model.joint_order[0]) in sim.model.joints
    frames = where.get("frames", []) + ([where["frame"]] if "frame" in where else [])
    assert all(isinstance(f, int) and 0 <= f < n for f in frames)

    gaps = np.isnan(out.trial.xyz).any(axis=2)
    np.testing.assert_array_equal(gaps, out.gaps)
    expected = sim.gaps.copy()
    if name == "marker_swap":
        a, b = where["frames"]
        c = cols(sim, where["markers"])
        expected[a:b + 1, c] = expected[a:b + 1, c[::-1]]
    np.testing.assert_array_equal(gaps, expected)
    if name in BODY:  # the same noise on the new clean positions
        np.testing.assert_allclose(out.trial.xyz - out.clean.xyz, sim.trial.xyz - sim.clean.xyz, atol=1e-9)
    else:
        np.testing.assert_array_equal(out.clean.xyz, sim.clean.xyz)


@pytest.mark.parametrize("name", EFFECTS)
def test_same_seed_same_effect(name):
    a, b = inject_effect(rigid(), name, 7), inject_effect(rigid(), name, 7)
    np.testing.assert_array_equal(a.trial.xyz, b.trial.xyz)
    assert a.settings == b.settings


# ---------------------------------------------------------------------- one marker on its segment
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_soft_tissue_moves_one_marker_with_its_joint_angle(seed):
    sim = rigid()
    out = inject_effect(sim, "soft_tissue", seed)
    where, p = out.settings["effect"]["where"], out.settings["effect"]["params"]
    (marker,), seg, joint = where["markers"], where["segment"], where["joint"]
    assert changed_markers(sim.clean, out.clean) == {marker}
    assert sim.model.parent_joint(seg).name == joint and seg != sim.model.root
    d = local(sim, seg, out.clean.xyz[:, cols(sim, [marker])])[:, 0] - sim.truth.segments[seg].marker_local[marker]
    th = angle(sim, joint)
    a = 2 * (th - th.min()) / (th.max() - th.min()) - 1
    model_d = (np.outer(p["linear_mm"] * a, p["linear_direction"])
               + np.outer(p["quadratic_mm"] * (a ** 2 - np.mean(a ** 2)), p["quadratic_direction"]))
    np.testing.assert_allclose(d, model_d, atol=1e-9)
    np.testing.assert_allclose(d, p["displacement_local"], atol=1e-9)
    assert 5 <= p["linear_mm"] <= 10 and 2 <= p["quadratic_mm"] <= 5
    pairwise = np.linalg.norm(d[:, None] - d[None], axis=2).max()
    assert pairwise * (1 - 1e-4) <= p["amplitude_mm"] <= pairwise * (1 + 1e-9)


@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_marker_slip_is_one_step_on_the_segment(seed):
    sim = rigid()
    out = inject_effect(sim, "marker_slip", seed)
    where, p = out.settings["effect"]["where"], out.settings["effect"]["params"]
    (marker,), seg, k = where["markers"], where["segment"], where["frame"]
    n = sim.trial.n_frames
    assert changed_markers(sim.clean, out.clean) == {marker}
    assert sim.model.marker_segment(marker) == seg and 0.25 * n <= k <= 0.75 * n
    x = local(sim, seg, out.clean.xyz[:, cols(sim, [marker])])[:, 0]
    rest = sim.truth.segments[seg].marker_local[marker]
    np.testing.assert_allclose(x[:k], np.broadcast_to(rest, (k, 3)), atol=1e-9)
    np.testing.assert_allclose(x[k:], np.broadcast_to(rest + p["step_local"], (n - k, 3)), atol=1e-9)
    assert np.linalg.norm(p["step_local"]) == pytest.approx(p["step_mm"], rel=1e-12)
    assert 6 <= p["step_mm"] <= 15


# ---------------------------------------------------------------------- labelling and recording
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_marker_swap_exchanges_two_columns_over_the_span_only(seed):
    sim = rigid()
    out = inject_effect(sim, "marker_swap", seed)
    where, n = out.settings["effect"]["where"], sim.trial.n_frames
    (a, b), c = where["frames"], cols(sim, where["markers"])
    assert c[0] != c[1] and 0.05 * n <= a <= b <= 0.95 * n and 0.1 * n - 1 <= b - a + 1 <= 0.3 * n
    expected = sim.trial.as_array()
    expected[a:b + 1, c] = sim.trial.xyz[a:b + 1][:, c[::-1]]
    np.testing.assert_array_equal(out.trial.xyz, expected)
    apart = np.linalg.norm(sim.clean.xyz[:, c[0]] - sim.clean.xyz[:, c[1]], axis=1).mean()
    assert apart >= 40


@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_outliers_change_exactly_count_samples_by_15_to_60_mm(seed):
    sim = rigid()
    out = inject_effect(sim, "outliers", seed)
    where = out.settings["effect"]["where"]
    step = np.linalg.norm(out.trial.xyz - sim.trial.xyz, axis=2)
    hit = np.nan_to_num(step) > 0
    assert hit.sum() == where["count"] >= 3
    assert np.all((step[hit] >= 15 - 1e-9) & (step[hit] <= 60 + 1e-9))
    frames, markers = np.nonzero(hit)
    assert where["frames"] == sorted(set(frames.tolist()))
    assert where["markers"] == sorted({sim.trial.labels[m] for m in markers})
    visible = (~sim.gaps).sum()
    assert where["count"] == max(3, round(out.settings["effect"]["params"]["fraction"] * visible))


# ---------------------------------------------------------------------- joints
@pytest.mark.parametrize("name", ["diagnose_leg", "leg"])
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_joint_translation_keeps_the_subtree_rigid_about_the_moving_centre(name, seed):
    sim = rigid(name)
    out = inject_effect(sim, "joint_translation", seed)
    effect = out.settings["effect"]
    joint = sim.model.joints[effect["where"]["joint"]]
    moved = effect["params"]["moved_segments"]
    subtree = [m for s in moved for m in sim.model.segments[s].markers]
    assert changed_markers(sim.clean, out.clean) == set(subtree)
    assert not set(sim.model.segments[joint.parent].markers) & set(subtree)
    assert_markers_rigid_about_true_centres(out)
    shift = np.linalg.norm(true_centre_world(out, joint.name) - sim.truth.centre_world(joint.name), axis=1)
    assert shift.min() <= 0.05 * shift.max()          # at rest near mid-range
    assert shift.max() == pytest.approx(effect["params"]["amplitude_mm"], rel=1e-9)
    assert 8 <= effect["params"]["amplitude_mm"] <= 15


@pytest.mark.parametrize("name", ["diagnose_leg", "leg"])
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_extra_dof_keeps_the_centre_but_breaks_the_hinge(name, seed):
    sim = rigid(name)
    out = inject_effect(sim, "extra_dof", seed)
    effect = out.settings["effect"]
    joint = sim.truth.joints[effect["where"]["joint"]]
    assert joint.type == "revolute"
    assert abs(np.dot(effect["params"]["axis_parent"], joint.axis_parent)) < 1e-12
    assert 12 <= effect["params"]["extra_rom_deg"] <= 25
    child = out.clean.xyz[:, cols(sim, sim.model.segments[joint.child].markers)]
    centre = sim.truth.centre_world(joint.name)[:, None]
    np.testing.assert_allclose(true_centre_world(out, joint.name), centre[:, 0], atol=1e-12)
    to_centre = np.linalg.norm(child - centre, axis=2)
    assert np.ptp(to_centre, axis=0).max() < 1e-9
    axis = sim.truth.axis_world(joint.name)[:, None]
    d = child - centre
    to_axis = np.linalg.norm(d - (d * axis).sum(axis=2, keepdims=True) * axis, axis=2)
    assert np.ptp(to_axis, axis=0).max() > 1.0
    assert_markers_rigid_about_true_centres(out)


def assert_markers_rigid_about_true_centres(sim):
    """Every marker keeps its distance to the true centre of each joint of its segment, except
    the parent's markers to a translating joint's centre (which moves on the parent)."""
    effect = sim.settings["effect"]
    for name, j in sim.model.joints.items():
        centre = true_centre_world(sim, name)[:, None]
        sliding = effect["name"] == "joint_translation" and effect["where"]["joint"] == name
        for seg in (j.child,) if sliding else (j.parent, j.child):
            x = sim.clean.xyz[:, cols(sim, sim.model.segments[seg].markers)]
            assert np.ptp(np.linalg.norm(x - centre, axis=2), axis=0).max() < 1e-9, (name, seg)


# ---------------------------------------------------------------------- timing and volume
@settings(max_examples=10, deadline=None)
@given(seed=SEEDS, lag=st.integers(2, 4))
def test_time_offset_delays_one_segment_by_whole_frames(seed, lag):
    delay_ms = inject_effect(rigid(), "time_offset", seed).settings["effect"]["where"]["delay_ms"]
    assert 20 <= delay_ms <= 50
    sim = rigid(rate_hz=1000.0 * lag / delay_ms)  # the same draw is then `lag` whole frames
    out = inject_effect(sim, "time_offset", seed)
    seg = out.settings["effect"]["where"]["segment"]
    assert out.settings["effect"]["params"]["delay_frames"] == pytest.approx(lag, rel=1e-12)
    c = cols(sim, sim.model.segments[seg].markers)
    assert changed_markers(sim.clean, out.clean) == set(sim.model.segments[seg].markers)
    np.testing.assert_allclose(out.clean.xyz[lag:, c], sim.clean.xyz[:-lag, c], atol=1e-6)
    t = sim.clean.times
    np.testing.assert_allclose(out.clean.xyz[:, c], CubicSpline(t, sim.clean.xyz[:, c], axis=0)(t - delay_ms / 1000),
                               atol=1e-9)
    for joint in sim.model.joints:
        np.testing.assert_array_equal(true_centre_world(out, joint), sim.truth.centre_world(joint))


@settings(max_examples=10, deadline=None)
@given(seed=SEEDS)
def test_spatial_distortion_peaks_at_its_amplitude_and_bends_segments(seed):
    sim = rigid()
    out = inject_effect(sim, "spatial_distortion", seed)
    p = out.settings["effect"]["params"]
    assert 8 <= p["amplitude_mm"] <= 15 and np.shape(p["coefficients"]) == (6, 3)
    moved = np.linalg.norm(out.clean.xyz - sim.clean.xyz, axis=2)
    assert moved.max() == pytest.approx(p["amplitude_mm"], rel=1e-9)
    bent = 0.0
    for seg in sim.model.segments.values():
        x = out.clean.xyz[:, cols(sim, seg.markers)]
        dist = np.linalg.norm(x[:, :, None] - x[:, None], axis=3)
        bent = max(bent, np.ptp(dist, axis=0).max())
    assert bent > 0.1


def test_effects_without_a_moving_centre_leave_the_true_centres():
    for name in ("soft_tissue", "marker_slip", "marker_swap", "outliers", "spatial_distortion", "time_offset"):
        out = inject_effect(rigid(), name, 3)
        for joint in out.model.joints:
            np.testing.assert_array_equal(true_centre_world(out, joint), out.truth.centre_world(joint))


# ---------------------------------------------------------------------- errors and CLI
def test_unknown_effect_impossible_effect_and_double_injection_are_input_errors():
    with pytest.raises(InputError, match="wobble.*soft_tissue.*spatial_distortion"):
        inject_effect(rigid(), "wobble")
    ball_only = simulate(model("hip_31"), n_frames=50, seed=2)
    assert all(j.type == "spherical" for j in ball_only.model.joints.values())
    with pytest.raises(InputError, match="extra_dof.*revolute"):
        inject_effect(ball_only, "extra_dof")
    with pytest.raises(InputError, match="already carries"):
        inject_effect(inject_effect(rigid(), "outliers"), "marker_slip")
    with pytest.raises(InputError, match="unknown joint"):
        true_centre_world(rigid(), "elbow")


def test_cli_simulate_with_an_effect_is_reproducible(tmp_path, capsys):
    leg = str(EXAMPLES / "diagnose_leg.toml")
    files = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        trial, truth = tmp_path / run / "t.trc", tmp_path / run / "t.json"
        args = ["simulate", leg, "--out", str(trial), "--effect", "marker_slip", "--truth", str(truth), "--seed", "4"]
        assert cli.main(args) == 0
        files.append((trial.read_bytes(), truth.read_text()))
    assert files[0] == files[1]
    effect = json.loads(files[0][1])["settings"]["effect"]
    assert effect["name"] == "marker_slip" and effect["where"]["markers"][0] in model().markers
    capsys.readouterr()
    args = ["simulate", leg, "--out", str(tmp_path / "c.trc"), "--effect", "joint_translation", "--json"]
    assert cli.main(args) == 0
    shown = json.loads(capsys.readouterr().out)["effect"]
    assert shown["name"] == "joint_translation" and "translation_parent" not in shown["params"]
    assert "direction_parent" in shown["params"]
