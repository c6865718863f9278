"""A joint centre started far from both of its segments (O'Brien's least squares when the joint turns little) is
moved half-way between them; a hinge keeps its axis; a centre near its segments is left alone."""
import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.chain import FAR_CENTRE_MM, _between_if_far
from identcheck.bundle.model import State
from identcheck.geometry.poses import Poses


def _poses(rng, F, local):
    R = Rotation.from_rotvec(rng.normal(0, 0.3, (F, 3))).as_matrix()
    t = rng.normal(0, 200, 3) + np.cumsum(rng.normal(0, 5, (F, 3)), axis=0)
    return Poses(R=R, t=t, valid=np.ones(F, bool), local=local, rms=np.zeros(F))


def _state(cp, cc):
    return State(np.zeros((0, 3)), {"j": np.array(cp, float)}, {"j": np.array(cc, float)}, {}, {},
                 np.zeros((0, 3, 3)), np.zeros((0, 3)), {}, {})


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1.5, 10.0), st.booleans())
def test_a_far_start_moves_between_the_segments(seed, how_far, hinge):
    rng = np.random.default_rng(seed)
    F = 50
    P = _poses(rng, F, rng.normal(0, 60, (3, 3)))
    C = _poses(rng, F, rng.normal(0, 60, (3, 3)) + [0, -300, 0])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    far = P.local.mean(axis=0) + how_far * FAR_CENTRE_MM * np.cross(axis, rng.normal(size=3) + 5 * np.eye(3)[0])
    s = _state(far, rng.normal(size=3))
    _between_if_far(s, "j", P, C, axis if hinge else None)
    world = lambda X, c: np.einsum("fij,j->fi", X.R, c) + X.t  # noqa: E731
    mid = (world(P, P.local.mean(axis=0)) + world(C, C.local.mean(axis=0))) / 2
    moved = s.c_parent["j"]
    if hinge:
        np.testing.assert_allclose(np.cross(moved - far, axis), 0.0, atol=1e-6 * np.linalg.norm(far))
    else:
        assert np.median(np.linalg.norm(world(P, moved) - mid, axis=1)) < np.median(
            np.linalg.norm(world(P, far) - mid, axis=1))
        np.testing.assert_allclose(moved, np.median(np.einsum("fji,fj->fi", P.R, mid - P.t), axis=0), atol=1e-9)
    # the child side names the same world point, as its median in the child's frame
    expected = np.median(np.einsum("fji,fj->fi", C.R, world(P, moved) - C.t), axis=0)
    np.testing.assert_allclose(s.c_child["j"], expected, atol=1e-9 * np.abs(expected).max())


def test_a_near_start_is_left_alone():
    rng = np.random.default_rng(1)
    P = _poses(rng, 40, rng.normal(0, 60, (3, 3)))
    C = _poses(rng, 40, rng.normal(0, 60, (3, 3)))
    near = P.local.mean(axis=0) + [50.0, 0, 0]
    s = _state(near, [1.0, 2.0, 3.0])
    _between_if_far(s, "j", P, C, None)
    np.testing.assert_array_equal(s.c_parent["j"], near)
    np.testing.assert_array_equal(s.c_child["j"], [1.0, 2.0, 3.0])
