"""Gamage-Lasenby sphere fit and its two-moving-link extension: exact data give the exact centre,
noise moves it proportionally, degeneracies are named. ``make_hip`` is shared with test_s22."""
import warnings

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.geometry.frames import pair_frame
from identcheck.geometry.frames import parent_frame, to_local, to_world
from identcheck.solve.gamage_lasenby import distance_variance_cost, gamage_lasenby, sphere_centre


def make_hip(seed, n_frames=20, rom=0.6, n_children=2, noise=0.0, pelvis_rom=0.4):
    """A random rigid ball joint and its world trajectories.

    Parent markers (3) within ±150 mm, not collinear; centre within ±120 mm of the parent origin;
    child markers 40-450 mm from the centre, ≥ 30 mm apart. Per frame: random parent pose
    (rotation vector sd `pelvis_rom` rad, translation ±300 mm) and random joint rotation
    (rotation vector sd `rom` rad on every axis). Optional Gaussian noise (sd `noise` mm) on every
    coordinate, from the same stream so a given seed and `noise` scale the same draw.

    Returns a dict: ``a`` (3, 3) and ``b`` (q, 3) local positions, ``c`` (3,) centre in the parent,
    ``aw`` (n, 3, 3), ``bw`` (n, q, 3), ``cw`` (n, 3) world trajectories and ``truth`` the S22
    constants (d, r, ρ1, ρ2).
    """
    rng = np.random.default_rng(seed)
    while True:
        a = rng.uniform(-150, 150, (3, 3))
        e1, e2 = a[1] - a[0], a[2] - a[0]
        area = np.linalg.norm(np.cross(e1, e2))
        if area > 0.2 * np.linalg.norm(e1) * np.linalg.norm(e2) and min(np.linalg.norm(e1), np.linalg.norm(e2)) > 40:
            break
    c = rng.uniform(-120, 120, 3)
    while True:
        dirs = rng.normal(size=(n_children, 3))
        b = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * rng.uniform(40, 450, (n_children, 1))
        if (np.linalg.norm(b[:, None] - b[None], axis=-1) + 1e9 * np.eye(n_children)).min() > 30:
            break
    rp = Rotation.from_rotvec(rng.normal(0, pelvis_rom, (n_frames, 3))).as_matrix()
    tp = rng.uniform(-300, 300, (n_frames, 3))
    rc = rp @ Rotation.from_rotvec(rng.normal(0, rom, (n_frames, 3))).as_matrix()
    aw = np.einsum("fij,kj->fki", rp, a) + tp[:, None]
    cw = np.einsum("fij,j->fi", rp, c) + tp
    bw = np.einsum("fij,kj->fki", rc, b) + cw[:, None]
    unit = rng.normal(size=(n_frames, 3 + n_children, 3))
    aw, bw = aw + noise * unit[:, :3], bw + noise * unit[:, 3:]
    ez = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
    dz = (c - a[0]) @ ez
    truth = np.array([dz, np.linalg.norm(c - a[0] - dz * ez), *np.linalg.norm(b[:2], axis=1)])
    return dict(a=a, b=b, c=c, aw=aw, bw=bw, cw=cw, truth=truth)


@st.composite
def hip_trials(draw, n_children=2, min_frames=12, max_frames=30):
    """Arguments of :func:`make_hip` for a random, well-excited joint."""
    return dict(seed=draw(st.integers(0, 2**31)), n_frames=draw(st.integers(min_frames, max_frames)),
                rom=draw(st.floats(0.3, 0.8)), n_children=n_children)


def _gl(p, **kw):
    aw, bw = p["aw"], p["bw"]
    return gamage_lasenby(aw[:, 0], aw[:, 1], aw[:, 2], bw, **kw)


def _local_truth(p):
    """True centre in F_GL (the frame is rigid with the parent, so compute it in the parent frame)."""
    a = p["a"]
    rot, _ = parent_frame(a[None, 0], a[None, 1], (a[2] - a[0])[None])
    return to_local(rot, a[None, 0], p["c"][None])[0]


# ---------------------------------------------------------------------- exact data
@given(hip_trials(n_children=2))
def test_gl_two_moving_links_recovers_the_centre_exactly(kw):
    p = make_hip(**kw)
    res = _gl(p)
    assert np.abs(res.centres_world - p["cw"]).max() < 1e-8
    assert np.allclose(res.centre_local, _local_truth(p), atol=1e-8, rtol=0)
    assert np.allclose(res.radii, np.linalg.norm(p["b"], axis=1), atol=1e-8, rtol=0)
    assert res.sqrt_cost_mm < 1e-6 and res.rms_residual_mm < 1e-8


@given(hip_trials(n_children=3))
def test_gl_classic_three_plus_three(kw):
    p = make_hip(**kw)
    res = _gl(p, bias_correction=True)
    assert np.abs(res.centres_world - p["cw"]).max() < 1e-8
    assert res.fit.sigma2_mm2 < 1e-12                  # no noise to correct for


@given(hip_trials(n_children=1, min_frames=8))
def test_single_child_marker_is_a_plain_sphere_fit(kw):
    p = make_hip(**kw)
    res = _gl(p)
    assert np.abs(res.centres_world - p["cw"]).max() < 1e-7


def test_sphere_fit_matches_eq5_written_plainly():
    """Centred moments (the implementation) vs Gamage & Lasenby's eq. (5) in raw moments."""
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(40, 2, 3)) * 80 + [[10, 20, 30], [-40, 0, 5]]
    A, B = np.zeros((3, 3)), np.zeros(3)
    for k in range(2):
        v = pts[:, k]
        vbar, v2 = v.mean(0), np.sum(v * v, 1)
        A += 2 * (v.T @ v / len(v) - np.outer(vbar, vbar))
        B += (v2[:, None] * v).mean(0) - v2.mean() * vbar
    assert np.allclose(sphere_centre(pts).centre, np.linalg.solve(A, B), rtol=1e-10, atol=1e-9)


# ---------------------------------------------------------------------- noise
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_gl_error_scales_with_noise(seed):
    """First order: the same noise draw scaled by 10 moves the centre 10 times as far."""
    errs = []
    for noise in (1e-3, 1e-2):
        p = make_hip(seed, n_frames=30, noise=noise)
        errs.append(np.abs(_gl(p).centre_local - _local_truth(p)).max())
    assert 0 < errs[0] < 0.1 and 8 < errs[1] / errs[0] < 12


def test_halvorsen_correction_removes_the_noise_bias():
    """Small arc, much noise: the plain fit is pulled toward the markers, the corrected one is not."""
    rng = np.random.default_rng(0)
    centre, radius, n = np.array([5.0, -3.0, 2.0]), 100.0, 400
    plain, corrected = [], []
    for _ in range(20):
        az, el = rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n)
        pts = centre + radius * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
        pts += rng.normal(0, 3.0, pts.shape)
        plain.append(sphere_centre(pts).centre - centre)
        fit = sphere_centre(pts, bias_correction=True)
        corrected.append(fit.centre - centre)
    bias_plain, bias_corr = np.mean(plain, 0), np.mean(corrected, 0)
    assert bias_plain[0] > 3                          # toward the cap (+x), several mm
    assert np.linalg.norm(bias_corr) < 0.3 * np.linalg.norm(bias_plain)
    assert 6 < fit.sigma2_mm2 < 12                    # noise variance 9 mm² recovered


# ---------------------------------------------------------------------- frames and cost
@given(hip_trials())
def test_parent_frame_is_orthonormal_and_agrees_with_pair_frame(kw):
    p = make_hip(**kw)
    a1, a2, a3 = p["aw"][:, 0], p["aw"][:, 1], p["aw"][:, 2]
    rot, h = parent_frame(a1, a2, a3 - a1)
    assert np.allclose(rot @ np.swapaxes(rot, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(rot), 1.0)
    l2, l3 = to_local(rot, a1, a2), to_local(rot, a1, a3)
    assert np.allclose(l2[:, :2], 0, atol=1e-9) and np.allclose(l2[:, 2], h)      # A2 on +z
    assert np.allclose(l3[:, 1], 0, atol=1e-9) and np.all(l3[:, 0] > 0)           # A3 in x > 0, y = 0
    pf, _ = pair_frame(a1, a2, p["bw"][:, 0])
    lb = to_local(rot, a1, p["bw"][:, 0])
    assert np.allclose(lb[:, 2], pf[:, 2]) and np.allclose(np.hypot(*lb[:, :2].T), np.hypot(*pf[:, :2].T))
    assert np.allclose(to_world(rot, a1, lb), p["bw"][:, 0])


def test_distance_variance_cost_is_zero_for_a_rigid_joint_only():
    p = make_hip(5)
    parents, children = list(p["aw"].swapaxes(0, 1)), list(p["bw"].swapaxes(0, 1))
    assert distance_variance_cost(p["cw"], parents, children) < 1e-20
    assert distance_variance_cost(p["cw"] + [5.0, 0, 0], parents, children) > 1.0


# ---------------------------------------------------------------------- gaps and errors
def test_frames_with_gaps_are_dropped_and_reported():
    p = make_hip(7, n_frames=25)
    aw, bw = p["aw"].copy(), p["bw"].copy()
    aw[[2, 3], 2] = np.nan
    bw[10, 1] = np.nan
    res = gamage_lasenby(aw[:, 0], aw[:, 1], aw[:, 2], bw)
    assert np.isnan(res.centres_world[[2, 3, 10]]).all()
    assert list(res.frames) == [f for f in range(25) if f not in (2, 3, 10)]
    assert np.abs(res.centres_world[res.frames] - p["cw"][res.frames]).max() < 1e-8


def test_too_few_frames():
    p = make_hip(1, n_frames=3)
    with pytest.raises(DegenerateError, match="at least 4 frames.*only 3 of 3"):
        _gl(p)


def test_nan_only_marker_is_named():
    p = make_hip(1)
    bw = p["bw"].copy()
    bw[:, 1] = np.nan
    with pytest.raises(InputError, match="RKNE has no valid sample"):
        gamage_lasenby(p["aw"][:, 0], p["aw"][:, 1], p["aw"][:, 2], bw, labels=["SACR", "LASI", "RASI", "RGT", "RKNE"])


def test_coincident_a1_a2():
    p = make_hip(1)
    with pytest.raises(DegenerateError, match="A1 and A2 coincide"):
        gamage_lasenby(p["aw"][:, 0], p["aw"][:, 0], p["aw"][:, 2], p["bw"])


def test_collinear_parent_markers():
    p = make_hip(1)
    a1, a2 = p["aw"][:, 0], p["aw"][:, 1]
    with pytest.raises(DegenerateError, match="A3 - A1 is parallel to A1A2 in frames"):
        gamage_lasenby(a1, a2, a1 + 2.5 * (a2 - a1), p["bw"])


def test_hinge_motion_does_not_determine_the_centre():
    """Rotation about one axis only: every marker moves in a plane normal to it, A is singular."""
    rng = np.random.default_rng(0)
    ang = rng.uniform(-1, 1, 30)
    rot = Rotation.from_rotvec(ang[:, None] * [0, 1.0, 0]).as_matrix()
    b = np.array([[0, -80, -20.0], [10, -45, -420]])
    bw = np.einsum("fij,kj->fki", rot, b)
    with pytest.raises(DegenerateError, match="does not determine a sphere centre"):
        sphere_centre(bw)


def test_near_hinge_motion_warns():
    rng = np.random.default_rng(0)
    ang = rng.uniform(-1, 1, 30)
    rot = Rotation.from_rotvec(np.stack([1e-5 * rng.normal(size=30), ang, np.zeros(30)], -1)).as_matrix()
    bw = np.einsum("fij,kj->fki", rot, np.array([[0, -80, -20.0], [10, -45, -420]]))
    with pytest.warns(IdentifiabilityWarning, match="barely determines"):
        sphere_centre(bw)


def test_bad_shapes_are_listed_together():
    with pytest.raises(InputError, match="2 problems"):
        gamage_lasenby(np.zeros((5, 2)), np.zeros((5, 3)), np.zeros((6, 3)), [np.zeros((5, 3))])


def test_no_warning_on_good_data():
    p = make_hip(2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _gl(p)
