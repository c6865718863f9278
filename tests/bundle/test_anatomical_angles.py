"""Joint angles in the joint's own frames: the Cardan decomposition returns the angles a rotation was built from;
a thigh turning about its knee's axis shows flexion only; below an ISB pelvis the angles are the anatomical ones
(zero in the neutral pose, flexion positive) whatever sign the fitted knee axis has."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.anatomical_angles import anatomical_angles, cardan_angles, joint_frames
from identcheck.bundle.hypothesis import main_angle

SEEDS = st.integers(0, 2**32 - 1)


def _frame(rng) -> np.ndarray:
    return Rotation.random(random_state=rng).as_matrix()


@settings(max_examples=200, deadline=None)
@given(SEEDS, st.floats(-170, 170), st.floats(-80, 80), st.floats(-170, 170))
def test_cardan_angles_return_the_angles_a_rotation_was_built_from(seed, a, b, c):
    rng = np.random.default_rng(seed)
    P, C = _frame(rng), _frame(rng)
    truth = np.deg2rad([a, b, c])
    Q = Rotation.from_euler("XYZ", truth).as_matrix()
    rel = (P.T @ Q @ C)[None]                      # Q = P rel Cᵀ
    assert np.allclose(cardan_angles(P, rel, C)[0], truth, atol=1e-9)


def _leg(local, c_child_hip, knee_point, knee_axis, rel, labels=("M1", "M2", "M3", "T1", "T2", "T3")):
    """A pelvis-thigh-shank fit: the hip a ball joint, the knee a hinge; markers M* on the pelvis, T* on the thigh."""
    chain = SimpleNamespace(joints=("hip", "knee"), types={"hip": "spherical", "knee": "revolute"},
                            parent={"hip": "pelvis", "knee": "thigh"}, child={"hip": "thigh", "knee": "shank"},
                            labels=tuple(labels), marker_seg=("pelvis",) * 3 + ("thigh",) * 3,
                            seg_markers={"pelvis": [0, 1, 2], "thigh": [3, 4, 5], "shank": []})
    state = SimpleNamespace(local=np.asarray(local, float), c_child={"hip": c_child_hip}, c_parent={"knee": knee_point},
                            axis={"knee": knee_axis}, rel_R={"hip": rel}, theta={})
    return SimpleNamespace(chain=chain, state=state)


def _unit(v):
    return v / np.linalg.norm(v)


@settings(max_examples=100, deadline=None)
@given(SEEDS, st.floats(10, 70))
def test_a_thigh_turning_about_its_knees_axis_shows_flexion_only(seed, amp):
    """rel(t) = ref · Rot(knee axis, θ(t)) in the thigh's coordinates: flexion follows θ one for one (up to the
    median pose's offset), ab-/adduction and axial rotation stay zero."""
    rng = np.random.default_rng(seed)
    ref = _frame(rng)
    axis = _unit(rng.standard_normal(3))
    hip = rng.normal(0, 100, 3)
    long = _unit(np.cross(axis, rng.standard_normal(3)))            # the knee 400 mm from the hip, off the axis
    knee = hip - 400 * long + rng.normal(0, 50) * axis
    theta = np.deg2rad(amp) * np.sin(np.linspace(0, 6, 300)) + rng.normal(0, 0.2)
    rel = ref @ Rotation.from_rotvec(np.outer(theta, axis)).as_matrix()
    fit = _leg(rng.normal(0, 100, (6, 3)), hip, knee, axis, rel)
    angles, frames = anatomical_angles(fit, "hip")
    assert np.allclose(angles[:, 1:], 0, atol=1e-9)
    assert np.allclose(np.abs(np.corrcoef(angles[:, 0], theta)[0, 1]), 1, atol=1e-9)
    assert np.isclose(np.ptp(angles[:, 0]), np.ptp(theta), atol=1e-9)
    assert "knee's hinge axis" in frames.medio_lateral and "median" in frames.zero
    x, label = main_angle(fit, "hip")
    assert np.allclose(x, np.rad2deg(angles[:, 0])) and "flexion" in label and "knee's hinge axis" in label


@settings(max_examples=100, deadline=None)
@given(SEEDS, st.floats(-40, 90), st.floats(-30, 30), st.floats(-40, 40), st.booleans())
def test_below_an_isb_pelvis_the_angles_are_the_anatomical_ones(seed, flex, abd, rot, flip_axis):
    """A pelvis with RASI/LASI/SACR in random technical coordinates, a thigh whose frame (knee axis pointing right,
    long axis up) sits at the pose built from known ISB hip angles: the angles come back, flexion positive, the
    neutral pose at zero, whichever way the fitted knee axis points."""
    rng = np.random.default_rng(seed)
    # the pelvis: anatomical (right, anterior, superior) rows, expressed in a random technical frame
    T = _frame(rng)
    origin = rng.normal(0, 50, 3)
    to_tech = lambda p: T @ p + origin                      # anatomical coordinates -> pelvis segment coordinates
    rasi, lasi, sacr = to_tech(np.array([120.0, 0, 0])), to_tech(np.array([-120.0, 0, 0])), \
        to_tech(np.array([0.0, -160, 0]))      # in the plane the ISB frame takes as transverse
    P_seg = T.T                                              # rows: anatomical axes in segment coordinates
    # the thigh: anatomical rows (knee axis right, anterior, long up) in a random thigh segment frame
    C_seg = _frame(rng).T
    hip = rng.normal(0, 50, 3)
    knee = hip - 420 * C_seg[2] + rng.normal(0, 20) * C_seg[0]
    axis = C_seg[0] * (-1 if flip_axis else 1)
    frames = [np.deg2rad([flex, abd, rot]) * s for s in np.linspace(0.2, 1.0, 50)]
    truth = np.array(frames)
    Q = Rotation.from_euler("XYZ", truth).as_matrix()
    rel = np.einsum("ji,fjk,kl->fil", P_seg, Q, C_seg)       # rel = P_segᵀ Q C_seg
    thigh_markers = rng.normal(0, 80, (3, 3))
    fit = _leg(np.vstack([rasi, lasi, sacr, thigh_markers]), hip, knee, axis, rel,
               labels=("RASI", "LASI", "SACR", "T1", "T2", "T3"))
    angles, fr = anatomical_angles(fit, "hip")
    assert np.allclose(angles, truth, atol=1e-8), (angles[-1], truth[-1])
    assert "ISB" in fr.zero


def test_a_ball_joint_with_nothing_below_uses_its_main_rotation():
    """No joint below, one thigh marker (the long axis through it): the medio-lateral axis is the direction the
    joint turned most, and flexion spans that rotation's range."""
    rng = np.random.default_rng(1)
    axis = _unit(rng.standard_normal(3))
    ref = _frame(rng)
    t = np.linspace(0, 4 * np.pi, 400)
    rel = (Rotation.from_rotvec(np.outer(np.deg2rad(40) * np.sin(t), axis)) * Rotation.from_matrix(ref)).as_matrix()
    chain = SimpleNamespace(joints=("hip",), types={"hip": "spherical"}, parent={"hip": "pelvis"},
                            child={"hip": "thigh"}, labels=("A", "B", "C", "D"), marker_seg=("pelvis",) * 3 + ("thigh",),
                            seg_markers={"pelvis": [0, 1, 2], "thigh": [3]})
    local = rng.normal(0, 100, (4, 3))
    local[3] = -300 * _unit(np.cross(ref.T @ axis, rng.standard_normal(3)))    # the thigh marker, off the axis
    state = SimpleNamespace(local=local, c_child={"hip": np.zeros(3)}, c_parent={}, axis={},
                            rel_R={"hip": rel}, theta={})
    fit = SimpleNamespace(chain=chain, state=state)
    angles, fr = anatomical_angles(fit, "hip")
    assert fr.medio_lateral == "its main rotation"
    assert abs(np.ptp(angles[:, 0]) - np.deg2rad(80)) < np.deg2rad(1)
    assert np.max(np.abs(angles[:, 1:])) < np.deg2rad(0.5)
    assert joint_frames(fit, "hip").child.shape == (3, 3)


@settings(max_examples=60, deadline=None)
@given(SEEDS, st.floats(10, 70), st.integers(0, 7))
def test_ranges_of_motion_are_the_anatomical_ones_and_ignore_a_few_flipped_frames(seed, amp, flipped):
    """The thigh turning about the knee's axis by ±amp: flexion's range is the central 95 % of 2·amp, the other two
    angles' ranges stay near zero; up to 7 of 300 frames turned a further half-turn about the long axis (a pose the
    data barely fix) do not change them. A hinge's range is its angle's central range."""
    from identcheck.bundle.anatomical_angles import ROM_SHARE, motion_ranges

    rng = np.random.default_rng(seed)
    ref = _frame(rng)
    axis = _unit(rng.standard_normal(3))
    hip = rng.normal(0, 100, 3)
    long = _unit(np.cross(axis, rng.standard_normal(3)))
    knee = hip - 400 * long + rng.normal(0, 50) * axis
    theta = np.deg2rad(amp) * np.sin(np.linspace(0, 6, 300))
    rel = ref @ Rotation.from_rotvec(np.outer(theta, axis)).as_matrix()
    bad = rng.choice(300, flipped, replace=False)
    rel[bad] = rel[bad] @ Rotation.from_rotvec(np.pi * long).as_matrix()
    local = np.vstack([rng.normal(0, 80, (3, 3)), hip + rng.normal(0, 60, (3, 3))])
    fit = _leg(local, hip, knee, axis, rel)
    fit.state.theta = {"knee": theta}
    central = np.rad2deg(np.ptp(np.percentile(theta, [2.5, 97.5])))
    (name, knee_rom), = motion_ranges(fit, "knee")
    assert name == "flexion–extension" and np.isclose(knee_rom, central)
    ranges = dict(motion_ranges(fit, "hip"))
    assert list(ranges) == ["flexion–extension", "ab-/adduction", "axial rotation"]
    assert abs(ranges["flexion–extension"] - central) < 0.05 * central + 1.0
    assert ranges["ab-/adduction"] < 1.0 and ranges["axial rotation"] < 1.0
    assert ROM_SHARE == 0.95
