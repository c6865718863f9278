"""Segment poses by SVD and seed 001's eq. (5) refinement of body-fixed marker coordinates."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from identcheck.geometry.poses import Poses, reference_shape, refine_local, segment_poses


def cluster(rng, m, spread=80.0):
    """A random non-collinear marker cluster, shape (m, 3), mm."""
    while True:
        x = rng.normal(0.0, spread, (m, 3)) + rng.uniform(-300, 300, 3)
        if np.linalg.svd(x - x.mean(0), compute_uv=False)[1] > 0.2 * spread:
            return x


def motion(rng, n, rom_deg=60.0):
    """Random world-from-body rotations (n, 3, 3) and translations (n, 3)."""
    t = np.linspace(0, 1, n)[:, None]
    w = np.deg2rad(rom_deg) * np.sin(2 * np.pi * (rng.uniform(0.3, 2, 3) * t + rng.uniform(0, 1, 3)))
    R = Rotation.from_rotvec(w).as_matrix() @ Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    d = rng.uniform(-500, 500, 3) + 200 * np.sin(2 * np.pi * (rng.uniform(0.3, 2, 3) * t))
    return R, d


def observe(R, d, local):
    """World marker positions (n, m, 3) of a body with these poses."""
    return np.einsum("fij,mj->fmi", R, local) + d[:, None, :]


seeds = st.integers(0, 2**32 - 1)


# ---------------------------------------------------------------------- segment_poses
@given(seeds, st.integers(3, 6))
def test_segment_poses_recovers_exact_poses(seed, m):
    """Noise-free markers: the SVD pose maps the body-fixed coordinates exactly onto them."""
    rng = np.random.default_rng(seed)
    local = cluster(rng, m)
    R, d = motion(rng, 30)
    poses = segment_poses(observe(R, d, local), local)
    assert poses.valid.all()
    np.testing.assert_allclose(poses.R, R, atol=1e-9)
    np.testing.assert_allclose(poses.t, d, atol=1e-7)
    assert np.nanmax(poses.rms) < 1e-8
    assert np.allclose(np.linalg.det(poses.R), 1.0)


@given(seeds)
def test_segment_poses_gaps(seed):
    """Frames with three of four markers still get the exact pose; fewer than three get none."""
    rng = np.random.default_rng(seed)
    local = cluster(rng, 4)
    R, d = motion(rng, 12)
    pts = observe(R, d, local)
    pts[3, 1] = np.nan                   # three left: fine
    pts[5, :2] = np.nan                  # two left: no pose
    pts[7] = np.nan                      # none
    poses = segment_poses(pts, local)
    assert poses.valid.tolist() == [i not in (5, 7) for i in range(12)]
    np.testing.assert_allclose(poses.R[poses.valid], R[poses.valid], atol=1e-9)
    assert np.isnan(poses.R[5]).all() and np.isnan(poses.rms[7])


def test_segment_poses_collinear_and_bad_input():
    local = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]) * 50
    assert not segment_poses(local[None].repeat(3, 0), local).valid.any()
    with pytest.raises(ValueError, match="at least 3 markers"):
        segment_poses(np.zeros((5, 2, 3)))
    with pytest.raises(ValueError, match=r"shape \(F, m, 3\)"):
        segment_poses(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="no frame has every marker"):
        segment_poses(np.full((4, 3, 3), np.nan))


# ---------------------------------------------------------------------- refine_local (eq. 5)
@given(seeds, st.integers(3, 5), st.integers(0, 9))
def test_refine_local_noise_free_is_the_reference_frame(seed, m, ref):
    """Without noise the refined shape is the true shape placed by the reference frame's pose,
    and that pose becomes the identity (seed 001: f(t_ref) = I)."""
    rng = np.random.default_rng(seed)
    local_true = cluster(rng, m)
    R, d = motion(rng, 10)
    local, poses = refine_local(observe(R, d, local_true), ref_frame=ref)
    np.testing.assert_allclose(local, local_true @ R[ref].T + d[ref], atol=1e-8)
    np.testing.assert_allclose(poses.R[ref], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(poses.t[ref], 0.0, atol=1e-8)
    assert isinstance(poses, Poses) and poses.local is local


@settings(max_examples=25)
@given(seeds, st.integers(3, 5), st.floats(0.2, 2.0), st.integers(20, 200))
def test_refine_local_fixed_point_of_eq5(seed, m, noise, n):
    """With noise: (i) the result is a fixed point of eq. (5), (ii) f(t_ref) = I there,
    (iii) it fits the markers no worse than the first-frame shape, and (iv) it converges
    to 1e-9 mm within five iterations (seed 001: "15 decimals in less than 5 iterations")."""
    rng = np.random.default_rng(seed)
    local_true = cluster(rng, m)
    R, d = motion(rng, n)
    pts = observe(R, d, local_true) + rng.normal(0, noise, (n, m, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        local, poses = refine_local(pts, n_iter=5, tol=1e-9)
    back = np.einsum("fji,fmj->fmi", poses.R, pts - poses.t[:, None])      # f(t)^-1 y(t)
    np.testing.assert_allclose(back.mean(axis=0), local, atol=1e-8)         # eq. (5), f(0) = I
    np.testing.assert_allclose(poses.R[0], np.eye(3), atol=1e-10)
    first = segment_poses(pts, reference_shape(pts))
    sse = lambda p: np.nansum((observe(p.R, p.t, p.local) - pts) ** 2)     # noqa: E731
    assert sse(poses) <= sse(first) * (1 + 1e-12)


@given(seeds)
def test_refine_local_gaps(seed):
    """A marker missing from some frames is averaged over the frames that see it; the result is
    still exact on noise-free data."""
    rng = np.random.default_rng(seed)
    local_true = cluster(rng, 4)
    R, d = motion(rng, 20)
    pts = observe(R, d, local_true)
    pts[:6, 0] = np.nan                       # not in the first frames: gauge moves to frame 0 anyway
    pts[10:12, 2:] = np.nan                   # two frames without a pose
    local, poses = refine_local(pts)
    np.testing.assert_allclose(local, local_true @ R[0].T + d[0], atol=1e-8)
    assert not poses.valid[10:12].any()


def test_refine_local_bad_input():
    rng = np.random.default_rng(1)
    local = cluster(rng, 3)
    R, d = motion(rng, 8)
    pts = observe(R, d, local)
    with pytest.raises(ValueError, match="at least 3 markers"):
        refine_local(pts[:, :2])
    with pytest.raises(ValueError, match="positive integer"):
        refine_local(pts, n_iter=0)
    bad = pts.copy()
    bad[:, :, :] = np.nan
    with pytest.raises(ValueError, match="no frame has every marker"):
        refine_local(bad)
    gap = pts.copy()
    gap[2, 0] = np.nan
    with pytest.raises(ValueError, match="ref_frame 2 has no valid pose"):
        refine_local(gap, ref_frame=2)
    with pytest.raises(ValueError, match="outside the 8 frames"):
        refine_local(pts, ref_frame=8)
    with pytest.warns(RuntimeWarning, match="still moved"):
        refine_local(pts + rng.normal(0, 1, pts.shape), n_iter=1, tol=0.0)


# ---------------------------------------------------------------------- Poses.body_fixed
@given(seed=seeds, n=st.integers(5, 60), robust=st.booleans(), hidden=st.floats(0.0, 0.8))
@settings(max_examples=40, deadline=None)
def test_a_point_carried_by_the_poses_is_found_fixed_in_the_body(seed, n, robust, hidden):
    """A body-fixed point seen through the poses (some frames unposed, some points unseen) is recovered, and carried
    back by to_world it is the trajectory again; a trajectory seen in no posed frame gives NaN."""
    rng = np.random.default_rng(seed)
    R, d = motion(rng, n)
    point = rng.uniform(-400, 400, 3)
    track = observe(R, d, point[None])[:, 0]
    unposed = rng.uniform(size=n) < hidden
    poses = Poses(np.where(unposed[:, None, None], np.nan, R), np.where(unposed[:, None], np.nan, d), ~unposed,
                  cluster(rng, 3), np.zeros(n))
    unseen = rng.uniform(size=n) < hidden
    seen_track = np.where(unseen[:, None], np.nan, track)
    found = poses.body_fixed(seen_track, robust=robust)
    if np.any(~unposed & ~unseen):
        assert np.allclose(found, point, atol=1e-6)
        assert np.allclose(poses.to_world(found[None])[~unposed, 0], track[~unposed], atol=1e-6)
    else:
        assert np.isnan(found).all()
