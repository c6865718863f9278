"""SCoRE and SARA (Ehrig et al. 2006, 2007): recovery, and identity with O'Brien et al."""
import numpy as np
import pytest
from hypothesis import assume, given, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.estimate.obrien import joint_location
from identcheck.geometry.poses import Poses, segment_poses
from identcheck.estimate.score_sara import sara, score
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

SEEDS = st.integers(0, 2**32 - 1)


def poses(R, t, valid=None):
    valid = np.ones(len(R), bool) if valid is None else valid
    return Poses(R=np.asarray(R, float), t=np.asarray(t, float), valid=valid, local=np.eye(3),
                 rms=np.zeros(len(R)))


def apply(R, t, x):
    return np.einsum("fij,j->fi", R, x) + t


def joint_pair(rng, n, hinge_rom_deg=None):
    """Random parent poses and child poses keeping (c_P, c_C) together; a hinge about a_P
    (returned with a_C) when ``hinge_rom_deg`` is given, else random relative rotations."""
    Rp = Rotation.random(n, random_state=rng).as_matrix()
    tp = rng.normal(0, 500, (n, 3))
    a_p = a_c = None
    if hinge_rom_deg is None:
        Rc = Rotation.random(n, random_state=rng).as_matrix()
    else:
        a_p = rng.normal(size=3)
        a_p /= np.linalg.norm(a_p)
        rest = Rotation.random(random_state=rng).as_matrix()
        theta = np.deg2rad(hinge_rom_deg) * rng.uniform(-0.5, 0.5, n)
        theta[:2] = np.deg2rad(hinge_rom_deg) * np.array([-0.5, 0.5])   # the full swing
        Rc = Rp @ Rotation.from_rotvec(theta[:, None] * a_p).as_matrix() @ rest
        a_c = rest.T @ a_p
    c_p, c_c = rng.uniform(-300, 300, 3), rng.uniform(-300, 300, 3)
    tc = apply(Rp, tp, c_p) - apply(Rc, 0 * tp, c_c)
    return poses(Rp, tp), poses(Rc, tc), c_p, c_c, a_p, a_c


def jitter(rng, X, deg, mm):
    """Poses perturbed by random small rotations (about deg) and translations (about mm)."""
    dR = Rotation.from_rotvec(np.deg2rad(deg) * rng.normal(size=(len(X.R), 3))).as_matrix()
    return poses(X.R @ dR, X.t + rng.normal(0, mm, X.t.shape), X.valid)


# ---------------------------------------------------------------------- SCoRE
@given(SEEDS, st.integers(3, 60))
def test_score_recovers_centre_exactly(seed, n):
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, _, _ = joint_pair(rng, n)
    fit = score(P, C)
    assume(fit.spread_deg[0] > 10)
    assert fit.motion == "general" and fit.unique
    np.testing.assert_allclose(fit.centre_parent, c_p, atol=1e-7)
    np.testing.assert_allclose(fit.centre_child, c_c, atol=1e-7)
    np.testing.assert_allclose(fit.centre_world, apply(P.R, P.t, c_p), atol=1e-7)
    assert fit.rms_residual < 1e-8


@given(SEEDS, st.integers(3, 60), st.floats(0, 5), st.floats(0, 5))
def test_score_is_the_obrien_estimator(seed, n, deg, mm):
    """Same objective, same minimiser: the 3 x 3 route (SCoRE here) and the 3n x 6 SVD
    (O'Brien eq. 17) agree on noisy data, singular values and residuals included."""
    rng = np.random.default_rng(seed)
    P, C, *_ = joint_pair(rng, n)
    C = jitter(rng, C, deg, mm)
    a, b = score(P, C), joint_location(P, C)
    assume(abs(a.spread_deg - a.hinge_tol_deg).min() > 1e-6)   # not on the classification edge
    assert a.motion == b.motion
    scale = 1 + np.abs(b.centre_parent).max() + np.abs(b.centre_child).max()
    tol = 1e-8 * scale / max(b.spread_deg[0], 1e-3)     # conditioning: 1 / smallest spread
    np.testing.assert_allclose(a.centre_parent, b.centre_parent, atol=tol)
    np.testing.assert_allclose(a.centre_child, b.centre_child, atol=tol)
    np.testing.assert_allclose(a.singular_values, b.singular_values, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(a.spread_deg, b.spread_deg, atol=1e-5)
    assert a.rms_residual == pytest.approx(b.rms_residual, rel=1e-7, abs=1e-8)
    assert a.uncertainty_mm == pytest.approx(b.uncertainty_mm, rel=1e-6, abs=1e-9)


@given(SEEDS, st.integers(3, 40), st.floats(0, 5))
def test_score_matches_a_plain_lstsq_of_the_stacked_system(seed, n, mm):
    """Ehrig's formulation written out frame by frame and handed to numpy's least squares."""
    rng = np.random.default_rng(seed)
    P, C, *_ = joint_pair(rng, n)
    C = jitter(rng, C, 1.0, mm)
    A = np.vstack([np.hstack([P.R[f], -C.R[f]]) for f in range(n)])
    b = np.concatenate([C.t[f] - P.t[f] for f in range(n)])
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    fit = score(P, C)
    assume(fit.unique)
    np.testing.assert_allclose(np.concatenate([fit.centre_parent, fit.centre_child]), x, atol=1e-6)


@given(SEEDS, st.integers(4, 40), st.floats(20, 300))
def test_score_on_a_hinge_agrees_with_obrien_minimum_norm(seed, n, rom):
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, a_p, a_c = joint_pair(rng, n, hinge_rom_deg=rom)
    a, b = score(P, C), joint_location(P, C)
    assert a.motion == b.motion == "single_axis" and not a.unique
    np.testing.assert_allclose(a.centre_parent, b.centre_parent, atol=1e-6)
    np.testing.assert_allclose(a.centre_child, b.centre_child, atol=1e-6)
    np.testing.assert_allclose(np.cross(a.centre_parent - c_p, a_p), 0, atol=1e-6)


@given(SEEDS, st.integers(3, 30), st.floats(0, 3))
def test_score_moves_with_the_segment_frames(seed, n, mm):
    """Re-expressing the child in another body frame (x = G x' + g) maps its centre by the
    inverse map; the parent-frame centre, residual and singular values do not change."""
    rng = np.random.default_rng(seed)
    P, C, *_ = joint_pair(rng, n)
    C = jitter(rng, C, 2.0, mm)
    G, g = Rotation.random(random_state=rng).as_matrix(), rng.normal(0, 200, 3)
    C2 = poses(C.R @ G, apply(C.R, C.t, g))
    a, b = score(P, C), score(P, C2)
    assume(a.unique)
    np.testing.assert_allclose(b.centre_child, G.T @ (a.centre_child - g), atol=1e-6)
    np.testing.assert_allclose(b.centre_parent, a.centre_parent, atol=1e-6)
    np.testing.assert_allclose(b.singular_values, a.singular_values, rtol=1e-9)
    assert b.rms_residual == pytest.approx(a.rms_residual, abs=1e-7)


# ---------------------------------------------------------------------- SARA
@given(SEEDS, st.integers(4, 60), st.floats(10, 300))
def test_sara_recovers_hinge_axis_up_to_sign(seed, n, rom):
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, a_p, a_c = joint_pair(rng, n, hinge_rom_deg=rom)
    fit = sara(P, C)
    assert fit.hinge and fit.motion == "single_axis"
    assert abs(fit.axis_parent @ a_p) == pytest.approx(1, abs=1e-9)
    assert abs(fit.axis_child @ a_c) == pytest.approx(1, abs=1e-9)
    np.testing.assert_allclose(fit.axis_world(P), apply(C.R, 0 * C.t, fit.axis_child), atol=1e-9)
    np.testing.assert_allclose(np.cross(fit.point_parent - c_p, a_p), 0, atol=1e-6)
    np.testing.assert_allclose(np.cross(fit.point_child - c_c, a_c), 0, atol=1e-6)
    assert fit.off_axis_deg < 1e-5 and fit.rms_residual < 1e-8
    assert fit.singular_values[-1] < 1e-6 * fit.singular_values[0]
    ob = joint_location(P, C)
    np.testing.assert_allclose(fit.axis_parent, ob.axis_parent, atol=1e-9)
    np.testing.assert_allclose(fit.axis_child, ob.axis_child, atol=1e-9)


@given(SEEDS, st.integers(3, 60))
def test_sara_does_not_call_3d_motion_a_hinge(seed, n):
    rng = np.random.default_rng(seed)
    P, C, *_ = joint_pair(rng, n)
    fit = sara(P, C)
    assume(fit.spread_deg[0] > 10)
    assert not fit.hinge and fit.motion == "general" and fit.off_axis_deg > 10


@given(SEEDS, st.integers(6, 60), st.floats(30, 120), st.floats(0.05, 1.0))
def test_sara_axis_error_is_of_the_order_of_the_wobble(seed, n, rom, wobble_deg):
    """Small random off-axis rotations (RMS about wobble_deg) tilt the axis by about that much
    at most and are reported as the off-axis spread."""
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, a_p, a_c = joint_pair(rng, n, hinge_rom_deg=rom)
    C = jitter(rng, C, wobble_deg / np.sqrt(3), 0.0)
    fit = sara(P, C)
    tilt = np.degrees(np.arccos(min(1.0, abs(fit.axis_parent @ a_p))))
    assert tilt < 10 * wobble_deg * (1 + 60 / rom)
    assert fit.hinge and 0 < fit.off_axis_deg < 3 * wobble_deg


# ---------------------------------------------------------------------- simulated trials
KNEE_HIP = {"units": "mm",
            "segments": {"pelvis": {"markers": ["A", "B", "C"]}, "thigh": {"markers": ["D", "E", "F", "G"]},
                         "shank": {"markers": ["H", "I", "J"]}},
            "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
                       "knee": {"type": "revolute", "parent": "thigh", "child": "shank"}}}


def _seg(sim, name):
    xyz = sim.trial.as_array()
    return xyz[:, [sim.model.markers.index(m) for m in sim.model.segments[name].markers]]


@pytest.mark.parametrize("noise_mm, occlusion, centre_tol, axis_tol_deg",
                         [(0.0, 0.0, 1e-6, 1e-5), (0.0, 0.3, 1e-6, 1e-5), (0.3, 0.1, 6.0, 3.0)])
def test_simulated_trial(noise_mm, occlusion, centre_tol, axis_tol_deg):
    sim = simulate(Model.from_dict(KNEE_HIP), n_frames=300, noise_mm=noise_mm, occlusion=occlusion, seed=11)
    pelvis, thigh, shank = (_seg(sim, s) for s in ("pelvis", "thigh", "shank"))
    hip = score(pelvis, thigh, names=("pelvis", "thigh"))
    assert hip.unique
    err = np.linalg.norm(hip.centre_world - sim.truth.centre_world("hip"), axis=1)
    assert np.nanmax(err) < centre_tol
    assert np.isnan(hip.centre_world).any() == (occlusion > 0)
    knee = sara(thigh, shank)
    assert knee.hinge
    truth_axis = sim.truth.axis_world("knee")
    cosang = np.abs(np.sum(knee.axis_world(segment_poses(thigh)) * truth_axis, axis=1))
    assert np.degrees(np.arccos(np.clip(np.nanmin(cosang), -1, 1))) < axis_tol_deg


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize("estimator", [score, sara])
def test_degenerate_input_raises(estimator):
    rng = np.random.default_rng(1)
    pts = rng.normal(0, 100, (12, 3, 3))
    with pytest.raises(InputError, match="'thigh' has 2 marker"):
        estimator(pts, pts[:, :2], names=("pelvis", "thigh"))
    with pytest.raises(InputError, match="every marker coordinate is NaN"):
        estimator(np.full_like(pts, np.nan), pts)
    P, C, *_ = joint_pair(rng, 12)
    with pytest.raises(InputError, match="only 0 frame"):
        estimator(poses(P.R, P.t, np.zeros(12, bool)), C)
    with pytest.raises(InputError, match="only 2 frame"):
        estimator(poses(P.R[:2], P.t[:2]), poses(C.R[:2], C.t[:2]))
    with pytest.raises(InputError, match="hinge_tol_deg"):
        estimator(P, C, hinge_tol_deg=float("nan"))
