"""Shapes the detectors were not built on: a marker that slips over a fraction of a second (a ramp, not a step), and
a shank marker whose skin moves with the hip's angle (a joint that is not its segment's)."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

import identcheck as ic
from identcheck.effects.injection import rotations
from identcheck.effects.marker_slip import best_ramp, best_step, explained_by, ramp
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
MODEL = Model.from_toml(EXAMPLES / "diagnose_leg.toml")


def unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(30, 150), st.floats(6.0, 15.0), st.floats(0.2, 1.0))
def test_a_slow_slip_is_read_as_a_ramp_of_about_its_length(seed, length, size, noise):
    """A marker's residual creeping `size` mm over 30-150 frames (0.3-1.5 s at 100 Hz), in white noise: the best
    ramp about the change in mean is longer than a step, within a factor 2 of the true length, and explains at
    least 95 % of what the true ramp does."""
    rng = np.random.default_rng(seed)
    n = 1200
    onset = int(rng.integers(200, n - 200 - length))
    truth = ramp(n, onset, length) * (size * unit(rng))
    resid = truth + rng.normal(0, noise, (n, 3))
    frame, _ = best_step(resid)
    got_onset, got_length, found = best_ramp(resid, frame, 100.0)
    assert got_length > 1
    assert length / 2 <= got_length <= 2 * length
    assert found >= 0.95 * explained_by(resid, ramp(n, onset, length))


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(6.0, 15.0), st.floats(0.2, 1.0))
def test_a_step_stays_a_step_or_a_ramp_of_a_few_frames(seed, size, noise):
    """A marker's residual stepping `size` mm at one frame: the ramp kept is the step itself or at most 3 frames
    long, starting within 2 frames of the step."""
    rng = np.random.default_rng(seed)
    n = 1200
    at = int(rng.integers(100, n - 100))
    resid = ramp(n, at, 1) * (size * unit(rng)) + rng.normal(0, noise, (n, 3))
    frame, _ = best_step(resid)
    got_onset, got_length, _ = best_ramp(resid, frame, 100.0)
    assert got_length <= 3 and abs(got_onset - at) <= 2


def test_diagnose_names_a_marker_slipping_over_half_a_second():
    """A thigh marker slips 10 mm on its segment over 0.5 s (0.5 mm noise): named a marker slip of that marker
    first, its span over the ramp, and the gap closed to the noise floor."""
    sim = simulate(MODEL, n_frames=1200, noise_mm=0.0, seed=5)
    xyz = sim.trial.as_array().copy()
    marker = MODEL.segments["thigh"].markers[1]
    k = sim.trial.labels.index(marker)
    onset, length = 500, 50
    step = np.array([6.0, -7.0, 3.6])
    xyz[:, k] += ramp(len(xyz), onset, length) * np.einsum("fij,j->fi", rotations(sim, "thigh"), step)
    xyz += np.random.default_rng(5).normal(0, 0.5, xyz.shape)
    d = ic.diagnose(MODEL, sim.trial.replace(xyz=xyz)).to_dict()
    first = d["effects"][0]
    assert first["name"] == "marker_slip" and first["where"]["markers"] == [marker]
    lo, hi = first["where"]["frames"]
    assert abs(lo - onset) <= 15 and abs(hi - (onset + length - 1)) <= 15
    assert d["gap_after"] <= 1.05 * d["noise_floor"]


def test_diagnose_names_a_shank_marker_moving_with_the_hip():
    """A shank marker moves on the shank with the hip's flexion (8 mm at the ends of its range), 0.5 mm noise: named
    soft tissue of that marker driven by the hip, where only the knee's angles had been tried for a shank."""
    sim = simulate(MODEL, n_frames=1200, noise_mm=0.0, seed=9)
    xyz = sim.trial.as_array().copy()
    marker = MODEL.segments["shank"].markers[0]
    k = sim.trial.labels.index(marker)
    hip = sim.truth.joints["hip"].angles_deg[:, 0]
    a = (hip - hip.mean()) / np.abs(hip - hip.mean()).max()
    local = np.outer(8.0 * a, [0.6, 0.0, 0.8]) + np.outer(3.0 * (a ** 2 - np.mean(a ** 2)), [0.0, 1.0, 0.0])
    xyz[:, k] += np.einsum("fij,fj->fi", rotations(sim, "shank"), local)
    xyz += np.random.default_rng(9).normal(0, 0.5, xyz.shape)
    first = ic.diagnose(MODEL, sim.trial.replace(xyz=xyz)).to_dict()["effects"][0]
    assert first["name"] == "soft_tissue" and marker in first["where"]["markers"]
    assert first["where"]["joint"] == "hip" or "hip" in first["where"].get("joints", [])
