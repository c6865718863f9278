"""The compiled revolute (2,1) kernel gives the NumPy path's verdicts and constants (numba optional)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.solve import revolute21
from identcheck.solve.revolute21 import solve_batch
from strategies import near_perpendicular, revolute21_problem


def _same(xyz):
    """Both paths on the problems `xyz` (n, 5, 3): identical verdicts, constants equal to rounding."""
    ref = solve_batch(xyz, angles=False, compiled=False)
    got = solve_batch(xyz, angles=False, compiled=True)
    np.testing.assert_array_equal(got.valid, ref.valid)
    both = ref.valid
    scale = np.sqrt(np.mean(np.sum(xyz ** 2, axis=-1), axis=-1))[:, None]
    gap = np.abs(got.params - ref.params)[both]
    assert np.all(gap[:, [0, 1, 3, 4]] <= 1e-6 * np.broadcast_to(scale, both.shape)[both][:, None])
    assert np.all(gap[:, 2] <= 1e-6)
    np.testing.assert_allclose(got.pivot_ratio, ref.pivot_ratio, rtol=1e-6)
    return ref


@pytest.fixture(autouse=True)
def _needs_numba():
    pytest.importorskip("numba")


@settings(max_examples=25, deadline=None)
@given(st.lists(st.one_of(revolute21_problem(), revolute21_problem(alpha=near_perpendicular())), min_size=1,
                max_size=40),
       st.floats(0, 2.0), st.integers(0, 2**32 - 1))
def test_compiled_verdicts_are_numpys(problems, noise, seed):
    """Random true joints (generic and with the hinge nearly perpendicular to the marker axis), with and without
    noise on the samples (noise gives cubics with one real root, which the kernel hands back to NumPy)."""
    xyz = np.stack([p[1] for p in problems])
    xyz = xyz + np.random.default_rng(seed).normal(0, noise, xyz.shape)
    _same(xyz)


def test_compiled_on_many_random_problems_with_bad_rows():
    """Ten thousand random problems, among them coincident samples, NaN and zeros: the same verdicts."""
    rng = np.random.default_rng(5)
    xyz = rng.normal(0, 100, (10_000, 5, 3))
    xyz[0] = np.nan
    xyz[1] = 0.0
    xyz[2, 1] = xyz[2, 0]
    ref = _same(xyz)
    assert 0.02 < ref.valid.any(axis=1).mean() < 0.98   # both verdicts occur among the random draws


def test_compiled_keeps_leading_shape_and_defaults():
    xyz = np.random.default_rng(1).normal(0, 100, (3, 4, 5, 3))
    got = solve_batch(xyz, angles=False, compiled=True)
    assert got.params.shape == (3, 4, 6, 5) and got.valid.shape == (3, 4, 6) and got.theta is None
    assert revolute21.COMPILED_MIN_PROBLEMS > 12            # a small batch stays on NumPy by default


def test_compiled_required_without_numba_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(revolute21, "compiled_available", lambda: False)
    with pytest.raises(InputError, match="numba"):
        solve_batch(np.ones((2, 5, 3)), angles=False, compiled=True)
    assert solve_batch(np.random.default_rng(0).normal(0, 1, (2, 5, 3)), angles=False).params.shape == (2, 6, 5)
