"""Forward selection on the score test's moments: the statistic of any subset follows from the moments of all the
fields, it is what least squares on those fields explains, and the subset chosen is never worse by the criterion than
the best single unit or all of them; a residual made of one unit's fields is told to be that unit alone."""
import math

import numpy as np
from hypothesis import example, given, settings, strategies as st

from identcheck.bundle.score_test import quadratic_form
from identcheck.bundle.score_selection import choice_params, forward_selection


def _problem(seed, n_units, width, n_obs=60):
    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, width + 1, n_units)
    X = rng.normal(size=(n_obs, int(sizes.sum())))
    edges = np.concatenate([[0], np.cumsum(sizes)])
    units = [list(range(edges[k], edges[k + 1])) for k in range(n_units)]
    return rng, X, units


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(1, 3))
def test_the_statistic_of_a_subset_is_what_least_squares_on_it_explains(seed, n_units, width):
    rng, X, units = _problem(seed, n_units, width)
    r = rng.normal(size=len(X))
    n, G = X.T @ r, X.T @ X
    cols = sorted(c for u in rng.choice(n_units, rng.integers(1, n_units + 1), replace=False) for c in units[u])
    fitted = X[:, cols] @ np.linalg.lstsq(X[:, cols], r, rcond=None)[0]
    assert np.isclose(quadratic_form(n[cols], G[np.ix_(cols, cols)]), fitted @ fitted, rtol=1e-8)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7), st.integers(1, 3), st.floats(0.0, 5.0),
       st.one_of(st.none(), st.floats(0.5, 12.0)))
def test_the_choice_beats_every_single_unit_and_the_whole_set(seed, n_units, width, penalty, per_param):
    rng, X, units = _problem(seed, n_units, width)
    r = rng.normal(size=len(X)) + X @ (rng.normal(size=X.shape[1]) * (rng.random(X.shape[1]) < 0.3))
    n, G = X.T @ r, X.T @ X

    def gain(stat, m):
        return stat - penalty * m

    sel = forward_selection(n, G, units, gain, per_param)
    cols = list(sel.columns)
    assert cols == sorted(c for u in sel.units for c in units[u])
    assert len(set(sel.units)) == len(sel.units) >= 1
    assert sel.choice_params == choice_params(n_units, len(sel.units), per_param)
    assert np.isclose(sel.gain, gain(quadratic_form(n[cols], G[np.ix_(cols, cols)]), len(cols) + sel.choice_params))
    every = list(range(X.shape[1]))
    assert sel.gain >= gain(quadratic_form(n, G), len(every)) - 1e-9          # the whole set: no choice to charge
    single = choice_params(n_units, 1, per_param)
    for u in units:
        assert sel.gain >= gain(quadratic_form(n[u], G[np.ix_(u, u)]), len(u) + single) - 1e-9


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 80), st.data(), st.floats(1.0, 20.0))
def test_the_charge_for_a_choice_is_twice_the_log_of_the_subsets_in_whole_parameters(n_units, data, per_param):
    k = data.draw(st.integers(0, n_units))
    charge = choice_params(n_units, k, per_param)
    subsets = 2.0 * math.log(math.comb(n_units, k))
    assert charge * per_param >= subsets - 1e-9 and (charge - 1) * per_param < subsets
    assert choice_params(n_units, k, None) == 0
    assert choice_params(n_units, n_units, per_param) == 0 == choice_params(n_units, 0, per_param)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 7), st.integers(1, 3))
def test_a_residual_of_one_units_fields_selects_that_unit_alone(seed, n_units, width):
    rng, X, units = _problem(seed, n_units, width)
    truth = int(rng.integers(n_units))
    r = X[:, units[truth]] @ (rng.uniform(1.0, 3.0, len(units[truth])) * rng.choice([-1, 1], len(units[truth])))
    n, G = X.T @ r, X.T @ X
    sel = forward_selection(n, G, units, lambda stat, m: stat - 1e-3 * float(r @ r) * m)
    assert sel.units == (truth,)


def test_no_units_select_nothing():
    sel = forward_selection(np.zeros(0), np.zeros((0, 0)), [], lambda stat, m: stat - m)
    assert sel.units == () and sel.columns == () and sel.gain == 0.0


def _exhaustive_greedy(n, G, units, gain, per_param):
    """Greedy forward selection written the plain way: every candidate's union statistic from its own block."""
    chosen, left = [], list(range(len(units)))
    best = (float(gain(0.0, 0)), ())
    while left:
        charge = choice_params(len(units), len(chosen) + 1, per_param)
        gains = []
        for u in left:
            cols = sorted(c for k in chosen + [u] for c in units[k])
            gains.append(gain(quadratic_form(n[cols], G[np.ix_(cols, cols)]), len(cols) + charge))
        k = int(np.argmax(gains))
        chosen.append(left.pop(k))
        if gains[k] > best[0] or not best[1]:
            best = (gains[k], tuple(chosen))
    return best


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 7), st.integers(1, 3), st.booleans())
@example(0, 3, 1, True)
def test_the_step_by_step_statistic_is_the_unions(seed, n_units, width, dependent):
    """Each step adds what a unit adds with the chosen fields regressed out: the same choices and gains as computing
    every candidate's union from its own block, also where some fields are combinations of others or zero."""
    rng, X, units = _problem(seed, n_units, width)
    if dependent and X.shape[1] > 2:
        X[:, -1] = X[:, 0] - 2 * X[:, 1]
        X[:, rng.integers(X.shape[1])] = 0.0
    r = rng.normal(size=len(X)) + X @ (rng.normal(size=X.shape[1]) * (rng.random(X.shape[1]) < 0.4)) * 3
    n, G = X.T @ r, X.T @ X

    def gain(stat, m):
        return stat - 2.0 * m

    sel = forward_selection(n, G, units, gain, per_param=4.0)
    plain_gain, plain_units = _exhaustive_greedy(n, G, units, gain, 4.0)
    assert np.isclose(sel.gain, plain_gain, rtol=1e-7, atol=1e-7)
    # the same units, or where to stop along the same order decided by a tie the rounding breaks (a zero field's
    # unit added last, its parameters charged where the choice among subsets no longer is: seed 0, 3 units)
    shorter, longer = sorted((sel.units, plain_units), key=len)
    assert sel.units == plain_units or longer[:len(shorter)] == shorter


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 8), st.integers(1, 4))
def test_matrix_moments_are_the_kronecker_fields(seed, k, w):
    """Moments as a matrix (k functions, each with a free w-vector sharing one Gram matrix) select what the k·w
    fields with the Gram matrix ``G ⊗ I_w`` written out select, with the same gain."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(80, k))
    Y = X @ (rng.normal(size=(k, w)) * (rng.random((k, 1)) < 0.5)) * 2 + rng.normal(size=(80, w))
    N, A = X.T @ Y, X.T @ X

    def gain(stat, m):
        return stat - 3.0 * m

    a = forward_selection(N, A, [[f] for f in range(k)], gain, per_param=3.0)
    b = forward_selection(N.reshape(-1), np.kron(A, np.eye(w)), [[w * f + i for i in range(w)] for f in range(k)],
                          gain, per_param=3.0)
    assert a.units == b.units and np.isclose(a.gain, b.gain, rtol=1e-9)
