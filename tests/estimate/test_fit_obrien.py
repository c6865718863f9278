"""O'Brien et al. (2000) stacked SVD joint fit: exact recovery, single-axis detection, errata."""
import numpy as np
import pytest
from hypothesis import assume, given, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.estimate.obrien import as_poses, joint_location, rotation_spread_deg, stacked_system
from identcheck.geometry.poses import Poses, segment_poses
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

SEEDS = st.integers(0, 2**32 - 1)


def poses(R, t):
    """Poses with every frame valid (no markers needed by the estimator)."""
    return Poses(R=np.asarray(R, float), t=np.asarray(t, float), valid=np.ones(len(R), bool),
                 local=np.eye(3), rms=np.zeros(len(R)))


def apply(R, t, x):
    return np.einsum("fij,j->fi", R, x) + t


def general_pair(rng, n, noise_deg=0.0):
    """Random parent poses, random joint (c_P, c_C) and child poses that keep it together."""
    Rp = Rotation.random(n, random_state=rng).as_matrix()
    tp = rng.normal(0, 500, (n, 3))
    Rc = Rotation.random(n, random_state=rng).as_matrix()
    c_p, c_c = rng.uniform(-300, 300, 3), rng.uniform(-300, 300, 3)
    tc = apply(Rp, tp, c_p) - apply(Rc, np.zeros((n, 3)), c_c)
    return poses(Rp, tp), poses(Rc, tc), c_p, c_c


def hinge_pair(rng, n, rom_deg):
    """A hinge: child = parent · Exp(θ a_P) · rest; axis a_C = restᵀ a_P, centre on the axis."""
    Rp = Rotation.random(n, random_state=rng).as_matrix()
    tp = rng.normal(0, 500, (n, 3))
    a_p = rng.normal(size=3)
    a_p /= np.linalg.norm(a_p)
    rest = Rotation.random(random_state=rng).as_matrix()
    theta = np.deg2rad(rom_deg) * np.linspace(-0.5, 0.5, n) + rng.uniform(-1, 1)
    Rc = Rp @ Rotation.from_rotvec(theta[:, None] * a_p).as_matrix() @ rest
    c_p, c_c = rng.uniform(-300, 300, 3), rng.uniform(-300, 300, 3)
    tc = apply(Rp, tp, c_p) - apply(Rc, np.zeros((n, 3)), c_c)
    return poses(Rp, tp), poses(Rc, tc), c_p, c_c, a_p, rest.T @ a_p


# ---------------------------------------------------------------------- exact recovery
@given(SEEDS, st.integers(3, 60))
def test_general_motion_recovers_joint_exactly(seed, n):
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c = general_pair(rng, n)
    fit = joint_location(P, C)
    assume(fit.spread_deg[0] > 10)   # three random rotations can (rarely) share an axis
    assert fit.motion == "general" and fit.unique and fit.axis_parent is None
    np.testing.assert_allclose(fit.centre_parent, c_p, atol=1e-7)
    np.testing.assert_allclose(fit.centre_child, c_c, atol=1e-7)
    assert fit.rms_residual < 1e-8
    assert fit.n_frames == n and np.all(np.isfinite(fit.frame_residual_mm))


@given(SEEDS, st.integers(4, 60), st.floats(10, 300))
def test_single_axis_is_detected_and_axis_recovered(seed, n, rom):
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, a_p, a_c = hinge_pair(rng, n, rom)
    fit = joint_location(P, C)
    assert fit.motion == "single_axis" and not fit.unique
    assert abs(fit.axis_parent @ a_p) == pytest.approx(1, abs=1e-9)
    assert abs(fit.axis_child @ a_c) == pytest.approx(1, abs=1e-9)
    # same line in the world, same sign in both frames
    np.testing.assert_allclose(apply(P.R, 0 * P.t, fit.axis_parent), apply(C.R, 0 * C.t, fit.axis_child),
                               atol=1e-9)
    # the centre is a point of the true axis, the same point in both frames ...
    np.testing.assert_allclose(np.cross(fit.centre_parent - c_p, a_p), 0, atol=1e-6)
    np.testing.assert_allclose(np.cross(fit.centre_child - c_c, a_c), 0, atol=1e-6)
    assert fit.rms_residual < 1e-8
    # ... the one nearest both origins: d/dλ (|c_P + λ a_P|² + |c_C + λ a_C|²) = 0 (section 3.1)
    slope = fit.centre_parent @ fit.axis_parent + fit.centre_child @ fit.axis_child
    assert slope == pytest.approx(0, abs=1e-6)


@given(SEEDS, st.integers(3, 60))
def test_general_motion_is_not_flagged_single_axis(seed, n):
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, n)
    fit = joint_location(P, C)
    assume(fit.spread_deg[0] > 10)
    assert fit.motion == "general"
    assert np.all(fit.spread_deg >= fit.hinge_tol_deg)


@given(SEEDS, st.integers(3, 40))
def test_no_relative_rotation_is_reported(seed, n):
    rng = np.random.default_rng(seed)
    Rp = Rotation.random(n, random_state=rng).as_matrix()
    rest = Rotation.random(random_state=rng).as_matrix()
    tp = rng.normal(0, 500, (n, 3))
    c_p, c_c = rng.uniform(-300, 300, 3), rng.uniform(-300, 300, 3)
    Rc = Rp @ rest
    fit = joint_location(poses(Rp, tp), poses(Rc, apply(Rp, tp, c_p) - apply(Rc, 0 * tp, c_c)))
    assert fit.motion == "none" and not fit.unique and fit.axis_parent is None
    assert fit.rms_residual < 1e-8


# ---------------------------------------------------------------------- structure
@given(SEEDS, st.integers(3, 40), st.floats(0, 2))
def test_singular_values_are_sqrt_n_one_plus_minus_s(seed, n, noise):
    """σ² = n (1 ± s_j) with s_j the singular values of M = mean R_Pᵀ R_C (module docstring)."""
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, n)
    C = poses(C.R, C.t + rng.normal(0, noise, C.t.shape))
    fit = joint_location(P, C)
    s = np.linalg.svd(np.einsum("fji,fjk->ik", P.R, C.R) / n, compute_uv=False)
    expect = np.sort(np.sqrt(n * np.concatenate([1 + s, 1 - s])))[::-1]
    np.testing.assert_allclose(fit.singular_values, expect, atol=1e-7 * np.sqrt(n))
    assert np.all(fit.singular_values[:3] >= np.sqrt(n) * (1 - 1e-12))
    np.testing.assert_allclose(fit.spread_deg, np.degrees(np.arccos(np.clip(s, -1, 1))), atol=1e-5)


def test_spread_angle_is_half_the_swing_for_two_frames():
    """Two frames ±α/2 about one axis: the spread about a perpendicular direction is α/2."""
    for alpha in (10.0, 60.0, 170.0):
        Rp = np.stack([np.eye(3)] * 2)
        Rc = Rotation.from_rotvec(np.deg2rad([[0, 0, -alpha / 2], [0, 0, alpha / 2]])).as_matrix()
        s = np.linalg.svd(np.einsum("fji,fjk->ik", Rp, Rc) / 2, compute_uv=False)
        np.testing.assert_allclose(rotation_spread_deg(np.sqrt(2 * np.clip(1 - s, 0, None)), 2),
                                   [0, alpha / 2, alpha / 2], atol=1e-6)


@given(SEEDS, st.integers(3, 40), st.floats(0, 3))
def test_swapping_parent_and_child_gives_the_same_fit(seed, n, noise):
    """Section 3.3: the fit error of P(i) = j and of P(j) = i are the same."""
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, n)
    C = poses(C.R, C.t + rng.normal(0, noise, C.t.shape))
    a, b = joint_location(P, C), joint_location(C, P).reversed()
    assert a.rms_residual == pytest.approx(b.rms_residual, rel=1e-9, abs=1e-9)
    np.testing.assert_allclose(a.singular_values, b.singular_values, rtol=1e-10)
    np.testing.assert_allclose(a.centre_parent, b.centre_parent, atol=1e-7)
    np.testing.assert_allclose(a.centre_child, b.centre_child, atol=1e-7)


@given(SEEDS, st.integers(3, 40), st.floats(0, 3))
def test_fit_does_not_depend_on_the_world_frame(seed, n, noise):
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, n)
    C = poses(C.R, C.t + rng.normal(0, noise, C.t.shape))
    G, g = Rotation.random(random_state=rng).as_matrix(), rng.normal(0, 1000, 3)
    moved = [poses(G @ X.R, X.t @ G.T + g) for X in (P, C)]
    a, b = joint_location(P, C), joint_location(*moved)
    np.testing.assert_allclose(a.centre_parent, b.centre_parent, atol=1e-6)
    np.testing.assert_allclose(a.centre_child, b.centre_child, atol=1e-6)
    assert a.rms_residual == pytest.approx(b.rms_residual, abs=1e-7)


# ---------------------------------------------------------------------- errata evidence
@given(SEEDS, st.integers(4, 40), st.floats(10, 300))
def test_erratum_axis_halves_child_first(seed, n, rom):
    """Section 3.2 prints the first three components of V's null column as the inboard axis.
    With u = [c_i; l_i] (eq. 13) they are the outboard (child) axis."""
    rng = np.random.default_rng(seed)
    P, C, _, _, a_p, a_c = hinge_pair(rng, n, rom)
    assume(abs(a_p @ a_c) < 0.9)
    Q, _, _ = stacked_system(P, C)
    v = np.linalg.svd(Q)[2][5]
    assert abs(v[:3] @ a_c) / np.linalg.norm(v[:3]) == pytest.approx(1, abs=1e-9)
    assert abs(v[3:] @ a_p) / np.linalg.norm(v[3:]) == pytest.approx(1, abs=1e-9)
    assert abs(v[:3] @ a_p) / np.linalg.norm(v[:3]) < 0.95


@given(SEEDS)
def test_erratum_two_frames_never_determine_the_joint(seed):
    """Section 3.1 implies two frames give a square, determined system; they never do: the
    two relative orientations differ by one rotation, about one axis (Euler), so Q̂ (6 x 6)
    is singular."""
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, 2)
    Q = np.concatenate([C.R, -P.R], axis=2).reshape(-1, 6)     # eq. (14) stacked, n = 2
    w = np.linalg.svd(Q, compute_uv=False)
    assert w[-1] < 1e-7 * w[0]
    with pytest.raises(InputError, match="only 2 frame"):
        joint_location(P, C)


@given(SEEDS, st.integers(3, 40), st.floats(0.1, 3))
def test_erratum_eq19_is_not_an_average(seed, n, noise):
    """Eq. (19) sqrt(Σ|e|²)/n is RMS/√n: the same data twice over (same fit, same per-frame
    errors) lowers it by √2, while the RMS stays."""
    rng = np.random.default_rng(seed)
    P, C, *_ = general_pair(rng, n)
    C = poses(C.R, C.t + rng.normal(0, noise, C.t.shape))
    once = joint_location(P, C)
    twice = joint_location(*(poses(np.concatenate([X.R] * 2), np.concatenate([X.t] * 2)) for X in (P, C)))
    assert once.epsilon_printed == pytest.approx(once.rms_residual / np.sqrt(n), rel=1e-12)
    assert twice.rms_residual == pytest.approx(once.rms_residual, rel=1e-9)
    assert twice.epsilon_printed == pytest.approx(once.epsilon_printed / np.sqrt(2), rel=1e-9)


# ---------------------------------------------------------------------- from markers
HIP_KNEE = {"units": "mm",
            "segments": {"pelvis": {"markers": ["A", "B", "C"]}, "thigh": {"markers": ["D", "E", "F"]},
                         "shank": {"markers": ["G", "H", "I"]}},
            "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
                       "knee": {"type": "revolute", "parent": "thigh", "child": "shank"}}}


def _segments(sim, clean=True):
    xyz = (sim.clean if clean else sim.trial).as_array()
    return {s: xyz[:, [sim.model.markers.index(m) for m in sim.model.segments[s].markers]]
            for s in sim.model.segments}


def _truth_in_pose_frame(points, truth_seg, x_local):
    """A point given in the simulator's segment frame, in the frame of segment_poses(points)."""
    p = segment_poses(points)
    world = truth_seg.poses[:, :3, :3] @ x_local + truth_seg.poses[:, :3, 3]
    return p.to_local(world[:, None, :])[:, 0, :]


@pytest.mark.parametrize("n_axes", [3, 2])
def test_simulated_hip_and_knee_recovered_from_markers(n_axes):
    sim = simulate(Model.from_dict(HIP_KNEE), n_frames=150, n_axes=n_axes, seed=7)
    seg = _segments(sim)
    hip = joint_location(seg["pelvis"], seg["thigh"])
    assert hip.motion == "general"
    want = _truth_in_pose_frame(seg["pelvis"], sim.truth.segments["pelvis"],
                                sim.truth.joints["hip"].centre_parent)
    np.testing.assert_allclose(hip.centre_parent, want[0], atol=1e-6)
    np.testing.assert_allclose(want - want[0], 0, atol=1e-6)   # a fixed point of the pose frame
    knee = joint_location(seg["thigh"], seg["shank"])
    assert knee.motion == "single_axis"
    world_axis = np.einsum("fij,j->fi", sim.truth.segments["thigh"].poses[:, :3, :3],
                           sim.truth.joints["knee"].axis_parent)
    got = np.einsum("fij,j->fi", segment_poses(seg["thigh"]).R, knee.axis_parent)
    np.testing.assert_allclose(np.abs(np.sum(got * world_axis, axis=1)), 1, atol=1e-9)


def test_noise_and_gaps_give_close_answers_and_nan_residuals():
    sim = simulate(Model.from_dict(HIP_KNEE), n_frames=300, noise_mm=0.3, occlusion=0.2, seed=3)
    clean, noisy = _segments(sim), _segments(sim, clean=False)
    a, b = joint_location(clean["pelvis"], clean["thigh"]), joint_location(noisy["pelvis"], noisy["thigh"])
    world_a = a.centre_world(*(as_poses(clean[s]) for s in ("pelvis", "thigh")))
    world_b = b.centre_world(*(as_poses(noisy[s]) for s in ("pelvis", "thigh")))
    err = np.linalg.norm(world_a - world_b, axis=1)
    assert np.nanmedian(err) < 5.0
    assert 0 < b.rms_residual < 5.0 and b.uncertainty_mm > 0
    assert np.isnan(b.frame_residual_mm).sum() == 300 - b.n_frames > 0


# ---------------------------------------------------------------------- bad input
def test_degenerate_input_raises_specific_errors():
    rng = np.random.default_rng(0)
    P, C, *_ = general_pair(rng, 10)
    pts = rng.normal(0, 100, (10, 4, 3))
    with pytest.raises(InputError, match="has 2 marker"):
        joint_location(pts[:, :2], pts)
    with pytest.raises(InputError, match="every marker coordinate is NaN"):
        joint_location(np.full((10, 3, 3), np.nan), pts)
    with pytest.raises(InputError, match=r"shape \(n_frames, n_markers, 3\)"):
        joint_location(pts[..., :2], pts)
    with pytest.raises(InputError, match="only 2 frame"):
        joint_location(poses(P.R[:2], P.t[:2]), poses(C.R[:2], C.t[:2]))
    with pytest.raises(InputError, match="have 10 and 9 frames"):
        joint_location(P, poses(C.R[:9], C.t[:9]))
    with pytest.raises(InputError, match="hinge_tol_deg"):
        joint_location(P, C, hinge_tol_deg=-1)
    gappy = pts.copy()
    gappy[2:, :2] = np.nan    # poses only in frames 0 and 1
    with pytest.raises(InputError, match="'thigh'.*only 2 frame"):
        joint_location(pts[:, :3], gappy, names=("pelvis", "thigh"))


@given(SEEDS, st.integers(20, 60), st.floats(30, 120), st.floats(3, 6))
def test_declared_hinge_keeps_its_axis_through_a_wobble(seed, n, rom, wobble_deg):
    """A real hinge wobbles a few degrees off its axis: the free fit calls that general motion and gives
    no axis; declared a hinge, the fit keeps the single-axis solution, near the true axis, and reports
    the wobble as the smallest spread."""
    rng = np.random.default_rng(seed)
    P, C, c_p, c_c, a_p, a_c = hinge_pair(rng, n, rom)
    wob = Rotation.from_rotvec(np.deg2rad(wobble_deg) * rng.normal(size=(n, 3)) / np.sqrt(3)).as_matrix()
    C = poses(np.einsum("fij,fjk->fik", C.R, wob), C.t)
    free, declared = joint_location(P, C), joint_location(P, C, hinge=True)
    assume(free.motion == "general")
    assert free.axis_parent is None
    assert declared.motion == "single_axis" and "declared hinge" in declared.reason
    assert np.degrees(np.arccos(min(1.0, abs(declared.axis_parent @ a_p)))) < 3 * wobble_deg
    assert declared.spread_deg[0] == pytest.approx(free.spread_deg[0])
