"""The generated solvers: truth in, truth among the candidates out; every candidate verified."""
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.errors import DegenerateError, InputError
from identcheck.solve import identify, solve_batch
from identcheck.solve.revolute21 import generated
from strategies import revolute21_problem


def _err(joint, truth):
    L = max(abs(truth[0]), truth[1], abs(truth[3]), truth[4])
    return np.max(np.abs(np.array([float(v) for v in joint.as_tuple()]) - truth) / np.array([L, L, 1, L, L]))


@given(revolute21_problem())
def test_truth_is_among_candidates_float64(problem):
    truth, xyz = problem
    res = identify(xyz)
    assert min(_err(j, truth) for j in res.joints) < 1e-8
    scale = np.sqrt(np.mean(np.sum(xyz**2, -1)))
    assert all(j.residual < 1e-6 * scale for j in res.joints)  # every candidate rebuilds every sample


@given(revolute21_problem())
def test_generic_data_admit_two_parameter_sets_and_their_mirrors(problem):
    """Erratum E1/E2: four joints, two distinct (r, |alpha|, l, rho) up to the mirror."""
    truth, xyz = problem
    res = identify(xyz)
    assert len(res.joints) == 4 and res.n_parameter_sets == 2 and not res.unique
    for s in (0, 1):
        a, b = [j for j in res.joints if j.root == s]
        assert np.isclose(a.alpha + b.alpha, np.pi) and np.isclose(a.l, -b.l) and np.isclose(a.r, b.r)


@settings(max_examples=8)
@given(revolute21_problem())
def test_truth_is_among_candidates_at_50_digits(problem):
    truth, _ = problem
    d, r, a, l, rho = truth
    with mpmath.workdps(70):
        f = generated("mpmath")["forward"]
        par = [mpmath.mpf(v) for v in (d, r, l, rho)] + [mpmath.cos(mpmath.mpf(a)), mpmath.sin(mpmath.mpf(a))]
        rng = np.random.default_rng(int(abs(d) * 1000) % 2**32)
        th = rng.uniform(-np.pi, np.pi) + 2 * np.pi * np.arange(5) / 5
        be = rng.uniform(-np.pi, np.pi) + 4 * np.pi * np.arange(5) / 5
        xyz = [f(par, [mpmath.cos(t), mpmath.sin(t), mpmath.cos(b), mpmath.sin(b)]) for t, b in zip(th, be)]
        res = identify(xyz, precision=50)
        truth_mp = [par[0], par[1], mpmath.mpf(a), par[2], par[3]]
        best = min(max(abs(u - v) for u, v in zip(j.as_tuple(), truth_mp)) for j in res.joints)
        assert best < mpmath.mpf(10) ** -40 * max(abs(v) for v in truth_mp)
        assert len(res.joints) == 4
        assert all(j.residual < mpmath.mpf(10) ** -40 for j in res.joints)


@given(st.lists(revolute21_problem(), min_size=2, max_size=6))
def test_batch_agrees_with_single(problems):
    xyz = np.stack([p[1] for p in problems])
    b = solve_batch(xyz)
    for i, (truth, x) in enumerate(problems):
        single = identify(x)
        got = sorted(tuple(np.round(b.params[i, k], 6)) for k in range(6) if b.valid[i, k])
        want = sorted(tuple(np.round(j.as_tuple(), 6)) for j in single.joints)
        assert np.allclose(got, want, atol=1e-5)


def test_hinge_parallel_to_marker_axis_is_degenerate():
    """alpha = 0: B stays in a plane, det M = 0 -> a clear error, never a number."""
    f = generated()["forward"]
    th = np.linspace(0, 5, 5)
    be = np.linspace(1, 4, 5)
    xyz = f(np.array([10, 80, 30, 60, 1.0, 0.0]), np.stack([np.cos(th), np.sin(th), np.cos(be), np.sin(be)], -1))
    with pytest.raises(DegenerateError, match="det M"):
        identify(xyz)


@given(revolute21_problem(), st.integers(0, 4), st.integers(0, 4))
def test_coincident_samples_are_degenerate(problem, i, j):
    _, xyz = problem
    if i == j:
        j = (i + 1) % 5
    xyz = xyz.copy()
    xyz[j] = xyz[i]
    with pytest.raises(DegenerateError, match="coincide"):
        identify(xyz)


def test_bad_shapes_and_nan_are_clear_errors():
    with pytest.raises(InputError, match="at least 5"):
        identify(np.ones((4, 3)))
    with pytest.raises(InputError, match="shape"):
        identify(np.ones((5, 2)))
    x = np.random.default_rng(0).normal(size=(5, 3))
    x[2, 1] = np.nan
    with pytest.raises(DegenerateError, match="not finite"):
        identify(x)


def test_double_root_locus_still_contains_the_truth():
    """l = 0 and r = rho: the twin joint coincides with the truth (double root of (13))."""
    f = generated()["forward"]
    th = np.array([0.1, 1.4, 2.6, 3.9, 5.1])
    be = np.array([0.3, 2.9, 5.3, 1.6, 4.2])
    a = 0.9
    xyz = f(np.array([20.0, 70.0, 0.0, 70.0, np.cos(a), np.sin(a)]),
            np.stack([np.cos(th), np.sin(th), np.cos(be), np.sin(be)], -1))
    res = identify(xyz)
    best = min(np.max(np.abs(np.array(j.as_tuple()) - [20, 70, a, 0, 70]) / [70, 70, 1, 70, 70]) for j in res.joints)
    assert best < 1e-6
