"""best_rotations (Horn's quaternion, solved as QCP with array operations) gives the Kabsch rotation: for any
cross-covariance, the same maximum of tr(Rᵀ H) as the SVD with the reflection guard, and a proper rotation;
for well-posed point sets (three or more non-collinear points) the same rotation."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.geometry.rotations import best_rotations


def kabsch(H):
    U, _, Vt = np.linalg.svd(H)
    D = np.ones((len(H), 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    return np.einsum("fij,fj,fjk->fik", U, D, Vt)


def objective(R, H):
    return np.einsum("fij,fij->f", R, H)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(3, 7), noise=st.sampled_from([0.0, 0.01, 0.5, 5.0]),
       size=st.floats(1.0, 500.0))
def test_the_kabsch_rotation_of_noisy_rigid_points(seed, m, noise, size):
    """Random shapes of 3-7 markers, random poses, noise from none to ten times a marker spacing's 1 %:
    the rotation equals the SVD's within 1e-9 (relative to the conditioning) and is proper."""
    rng = np.random.default_rng(seed)
    F = 50
    local = rng.standard_normal((m, 3)) * size
    local -= local.mean(axis=0)
    R0 = Rotation.random(F, random_state=rng).as_matrix()
    pts = np.einsum("fij,kj->fki", R0, local) + noise * rng.standard_normal((F, m, 3))
    pts -= pts.mean(axis=1, keepdims=True)
    H = np.einsum("fki,kj->fij", pts, local)
    bound = 0.5 * (np.einsum("fki,fki->f", pts, pts) + np.sum(local ** 2))
    R = best_rotations(H, bound)
    Rk = kabsch(H)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("fij,fkj->fik", R, R), np.broadcast_to(np.eye(3), (F, 3, 3)), atol=1e-12)
    sv = np.linalg.svd(local, compute_uv=False)
    if sv[1] > 1e-3 * sv[0]:                     # the rotation is well defined: the same one
        tol = 1e-9 * sv[0] / sv[1] * (1 + noise)
        assert np.abs(R - Rk).max() < tol
    top = objective(Rk, H)
    assert np.all(objective(R, H) >= top - 1e-12 * np.abs(top).max())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rank=st.sampled_from([0, 1, 2, 3]))
def test_any_cross_covariance_reaches_the_svd_maximum(seed, rank):
    """Arbitrary matrices, including reflections (det < 0), rank 2 (three points), rank 1 (collinear) and zero:
    a proper rotation whose objective is the SVD's maximum."""
    rng = np.random.default_rng(seed)
    F = 40
    A = rng.standard_normal((F, 3, rank)) @ rng.standard_normal((F, rank, 3)) if rank else np.zeros((F, 3, 3))
    R = best_rotations(A)
    Rk = kabsch(A)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    scale = max(float(np.abs(A).max()), 1.0)
    assert np.all(np.abs(objective(R, A) - objective(Rk, A)) <= 1e-9 * scale)


def test_a_wrong_bound_above_the_root_still_converges():
    """The Newton iteration starts from any upper bound of the largest eigenvalue."""
    rng = np.random.default_rng(3)
    H = rng.standard_normal((30, 3, 3))
    for bound in (None, np.full(30, 1e6)):
        np.testing.assert_allclose(objective(best_rotations(H, bound), H), objective(kabsch(H), H), atol=1e-12)
