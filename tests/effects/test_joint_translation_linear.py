"""The part of a joint translation linear in the angles that no shifted centre absorbs: its fields span exactly the
symmetric maps of a ball joint's rotation vector (a hinge: its angle along the axis), and a centre shift's own
signature, δ × ω, stays outside them."""
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.effects.joint_translation import linear_fields
from identcheck.effects.soft_tissue import explained


def _hyp(kind, axis=None):
    return SimpleNamespace(chain=SimpleNamespace(types={"j": kind}),
                           fit=SimpleNamespace(state=SimpleNamespace(axis={"j": axis})))


def _fit(fields, target):
    X = np.stack([f.reshape(-1) for f in fields], axis=1)
    coef = np.linalg.lstsq(X, target.reshape(-1), rcond=None)[0]
    return np.linalg.norm(X @ coef - target.reshape(-1)) / np.linalg.norm(target)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_ball_joint_fields_span_the_symmetric_maps_and_not_a_centre_shift(seed):
    rng = np.random.default_rng(seed)
    omega = rng.normal(0, 0.3, (300, 3))
    fields = linear_fields(_hyp("spherical"), "j", omega)
    assert len(fields) == 6
    A = rng.normal(size=(3, 3))
    sym = (A + A.T) / 2
    centred = omega - omega.mean(axis=0)
    assert _fit(fields, centred @ sym.T) < 1e-10                       # any symmetric map: reproduced exactly
    delta = rng.normal(size=3)
    assert _fit(fields, np.cross(delta, centred)) > 0.3                # a centre shift's δ × ω: not in their span


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_hinge_field_runs_along_its_axis(seed):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = rng.uniform(-1, 1, (200, 1))
    (field,) = linear_fields(_hyp("revolute", axis), "j", theta)
    np.testing.assert_allclose(np.cross(field, axis), 0.0, atol=1e-12)
    np.testing.assert_allclose(field @ axis, theta[:, 0] - theta.mean(), atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_fields_add_to_what_is_explained_what_they_carry(seed, k):
    rng = np.random.default_rng(seed)
    basis = rng.normal(size=(150, k))
    fields = [rng.normal(size=(150, 3)) for _ in range(2)]
    resid = rng.normal(size=(150, 3))
    kron_path = explained(resid, basis, [np.zeros((150, 3))])          # a null field: the general design
    assert np.isclose(kron_path, explained(resid, basis))
    signal = resid + 5.0 * fields[0]
    assert explained(signal, basis, fields) > explained(signal, basis) + 0.5 * 25 * np.sum(fields[0] ** 2) / 2


def _shift_fields(omega):
    from scipy.spatial.transform import Rotation

    lever = np.eye(3)[None] - Rotation.from_rotvec(omega).as_matrix()
    return [lever[:, :, k] - lever[:, :, k].mean(axis=0) for k in range(3)]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.005, 0.05))
def test_a_ball_joint_turned_mostly_about_one_axis_keeps_only_what_no_centre_shift_absorbs(seed, wobble):
    """Gait-like motion (one large rotation, small others): fewer than six fields are kept; each keeps at least
    ABSORBED_SHARE of its size once the best centre shift is subtracted; a translation along the main axis,
    linear in the angle (a hip pistoning with flexion), is still carried by them with a centre shift."""
    from identcheck.effects.joint_translation import ABSORBED_SHARE

    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    t = np.linspace(0, 6 * np.pi, 600)
    omega = np.outer(0.5 * np.sin(t + rng.uniform(0, 6)), axis) + rng.normal(0, wobble, (600, 3))
    fields = linear_fields(_hyp("spherical"), "j", omega)
    assert 1 <= len(fields) < 6
    shifts = _shift_fields(omega)
    for f in fields:
        assert 1.0 - _fit(shifts, f) ** 2 <= 1.0 - ABSORBED_SHARE + 1e-9
    centred = omega - omega.mean(axis=0)
    piston = np.outer(centred @ axis, axis)
    assert _fit(fields + shifts, piston) < 0.1
