"""Products with term columns (a basis times base directions) taken from the base directions alone, against the
same products with the columns written out: random frames, rows, plain columns, terms and vectors."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.bundle.coupling import symmetric_from_upper, term_columns, term_products, term_sums


def _written_out(base: np.ndarray, parts: list) -> np.ndarray:
    """The terms' columns (F, n, T) of base directions `base` (F, n, D): column (kk, a) of a term is its direction a
    times its basis function kk, basis function first."""
    cols = []
    for off, d, basis in parts:
        for kk in range(basis.shape[1]):
            for a in range(d):
                cols.append(base[:, :, off + a] * basis[:, kk, None])
    return np.stack(cols, axis=2) if cols else np.zeros(base.shape[:2] + (0,))


@st.composite
def _problem(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    F, n, p = draw(st.integers(1, 6)), draw(st.integers(1, 7)), draw(st.integers(0, 4))
    shapes = draw(st.lists(st.tuples(st.sampled_from([1, 3]), st.integers(1, 3)), min_size=0, max_size=5))
    D = sum(d for d, _ in shapes)
    parts, at = [], 0
    for d, K in shapes:
        parts.append((at, d, rng.normal(size=(F, K))))
        at += d
    return rng, rng.normal(size=(F, n, p)), rng.normal(size=(F, n, D)), parts


@settings(max_examples=60, deadline=None)
@given(_problem())
def test_term_products_are_the_written_out_columns_products(problem):
    rng, plain, base, parts = problem
    T = _written_out(base, parts)
    pt, tt = term_products(base.transpose(0, 2, 1) @ plain, base.transpose(0, 2, 1) @ base, parts)
    want_pt = np.einsum("fnp,fnt->pt", plain, T)
    want_tt = np.einsum("fns,fnt->st", T, T)
    np.testing.assert_allclose(pt, want_pt, atol=1e-10 * (1 + np.abs(want_pt).max(initial=0)))
    np.testing.assert_allclose(symmetric_from_upper(tt), want_tt, atol=1e-10 * (1 + np.abs(want_tt).max(initial=0)))
    spans = np.cumsum([0] + [d * b.shape[1] for _, d, b in parts])
    for i in range(len(parts)):                      # below the block diagonal nothing is summed
        assert not tt[spans[i + 1]:, spans[i]:spans[i + 1]].any()


@settings(max_examples=60, deadline=None)
@given(_problem(), st.integers(0, 3), st.booleans())
def test_term_sums_are_the_written_out_columns_times_the_vectors(problem, Q, per_frame):
    rng, _, base, parts = problem
    T = _written_out(base, parts)
    F, n = base.shape[:2]
    v = rng.normal(size=(F, n) + ((Q,) if Q else ()))
    y = np.einsum("fnd,fn...->fd...", base, v)
    got = term_sums(y, parts, per_frame)
    want = np.einsum("fnt,fn...->ft...", T, v) if per_frame else np.einsum("fnt,fn...->t...", T, v)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, atol=1e-10 * (1 + np.abs(want).max(initial=0)))


@settings(max_examples=40, deadline=None)
@given(_problem())
def test_term_columns_are_each_direction_times_each_basis_function(problem):
    _, _, base, parts = problem
    for off, d, basis in parts:
        want = _written_out(base, [(off, d, basis)])
        np.testing.assert_array_equal(term_columns(base[:, :, off:off + d], basis), want)
