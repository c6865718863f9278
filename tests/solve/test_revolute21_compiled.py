"""The compiled revolute (2,1) kernel gives the NumPy path's verdicts and constants (numba optional)."""
import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from identcheck.errors import InputError
from identcheck.solve import revolute21
from identcheck.solve.revolute21 import solve_batch
from strategies import near_perpendicular, revolute21_problem


def _same(xyz):
    """Both paths on the problems `xyz` (n, 5, 3): identical verdicts, constants equal to rounding."""
    ref = solve_batch(xyz, angles=False, compiled=False)
    got = solve_batch(xyz, angles=False, compiled=True)
    np.testing.assert_array_equal(got.valid, ref.valid)
    scale = np.sqrt(np.mean(np.sum(xyz ** 2, axis=-1), axis=-1))
    # a root's two mirror images may come in either order when cos α is 0 to rounding (w's sign decides which is
    # first): compare each root's pair as it is and exchanged, and keep the closer
    a, b = got.params.reshape(-1, 3, 2, 5), ref.params.reshape(-1, 3, 2, 5)
    tol = np.array([1e-6, 1e-6, 0.0, 1e-6, 1e-6]) * scale[:, None, None, None] + np.array([0, 0, 1e-6, 0, 0])
    same = np.all(np.abs(a - b) <= tol, axis=(2, 3))
    swapped = np.all(np.abs(a[:, :, ::-1] - b) <= tol, axis=(2, 3))
    real = ref.valid.reshape(-1, 3, 2).any(axis=2)
    assert np.all((same | swapped)[real])
    np.testing.assert_allclose(got.pivot_ratio, ref.pivot_ratio, rtol=1e-6)
    return ref


@pytest.fixture(autouse=True)
def _needs_numba():
    pytest.importorskip("numba")


@settings(max_examples=25, deadline=None)
@given(st.lists(st.one_of(revolute21_problem(), revolute21_problem(alpha=near_perpendicular())), min_size=1,
                max_size=40),
       st.floats(0, 2.0), st.integers(0, 2**32 - 1))
@example(problems=[(np.array([0.0, 30.0, np.pi / 2, 1.0, 30.0]),       # cos α = 0 exactly: the mirror pair's order
                    np.array([[60.0, -1.0, 6.123234e-17], [2.72156635, 5.14005197, 17.6335576],
                              [-31.1827246, 23.8916435, -28.5316955], [-32.3582951, -22.2736095, 28.5316955],
                              [0.819453315, -5.75808595, -17.6335576]]))], noise=0.0, seed=0)
@example(problems=[(np.array([0.0, 40.0, 1.0, 0.0, 30.0]),              # l = 0: a root with cos²α 0 exactly, u² < 0
                    np.array([[10.3002251, 2.28742397, 3.56245176], [29.74710831, 55.04069625, -17.57171847],
                              [-37.57909988, 7.5648844, 24.86918595], [-30.2333036, -3.97528742, -22.66746968],
                              [27.76507007, -60.91771721, 11.80755043]]))], noise=0.0, seed=0)
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
