"""The one forward kinematics: joint centres coincide in both segments for any parameters, in float64 and
at 50 digits, and it agrees with a plain frame-by-frame composition of rigid transforms."""
from __future__ import annotations

import mpmath
import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.geometry.kinematics import apply, chain_poses


def _random_chain(rng, n_joints, F):
    joints = [(f"j{k}", f"s{rng.integers(0, k + 1)}", f"s{k + 1}") for k in range(n_joints)]
    rel = {j: Rotation.from_rotvec(rng.normal(size=(F, 3))).as_matrix() for j, _, _ in joints}
    cp = {j: rng.normal(scale=200, size=3) for j, _, _ in joints}
    cc = {j: rng.normal(scale=200, size=3) for j, _, _ in joints}
    return joints, Rotation.from_rotvec(rng.normal(size=(F, 3))).as_matrix(), rng.normal(scale=500, size=(F, 3)), \
        rel, cp, cc


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10 ** 6), n_joints=st.integers(1, 6))
def test_centres_coincide_and_match_plain_composition(seed, n_joints):
    rng = np.random.default_rng(seed)
    F = 5
    joints, R0, t0, rel, cp, cc = _random_chain(rng, n_joints, F)
    R, t, centre = chain_poses(joints, "s0", R0, t0, rel, cp, cc)
    for j, par, chi in joints:
        from_parent = apply(R[par], cp[j]) + t[par]
        from_child = apply(R[chi], cc[j]) + t[chi]
        assert np.allclose(from_parent, from_child, atol=1e-9) and np.allclose(centre[j], from_parent)
        assert np.allclose(R[chi], R[par] @ rel[j])
    for f in range(F):                      # 4x4 homogeneous composition, frame by frame
        T = {"s0": np.block([[R0[f], t0[f][:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])}
        for j, par, chi in joints:
            def hom(Rm, v):
                return np.block([[Rm, v[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
            T[chi] = T[par] @ hom(np.eye(3), cp[j]) @ hom(rel[j][f], np.zeros(3)) @ hom(np.eye(3), -cc[j])
            assert np.allclose(T[chi][:3, :3], R[chi][f]) and np.allclose(T[chi][:3, 3], t[chi][f], atol=1e-8)


def test_runs_at_50_digits_on_object_arrays():
    rng = np.random.default_rng(1)
    joints, R0, t0, rel, cp, cc = _random_chain(rng, 3, 2)
    with mpmath.workdps(50):
        mp = lambda a: np.vectorize(mpmath.mpf, otypes=[object])(a)  # noqa: E731
        R, t, centre = chain_poses(joints, "s0", mp(R0), mp(t0), {k: mp(v) for k, v in rel.items()},
                                   {k: mp(v) for k, v in cp.items()}, {k: mp(v) for k, v in cc.items()})
        for j, par, chi in joints:
            gap = apply(R[chi], mp(cc[j])) + t[chi] - centre[j]
            assert max(abs(x) for x in gap.ravel()) < mpmath.mpf("1e-40")
