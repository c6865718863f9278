"""The one exact linear algebra: rank, null spaces and maximal minors agree with SymPy's rational row
reduction on random rational matrices (two routes must agree), and the null spaces annihilate."""
from __future__ import annotations

from fractions import Fraction

import sympy as sp
from hypothesis import given, settings, strategies as st

from identcheck.exact import linalg

entries = st.fractions(min_value=-5, max_value=5, max_denominator=6)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 6), st.data())
def test_against_sympy(n, m, data):
    rows = [[data.draw(entries) for _ in range(m)] for _ in range(n)]
    if data.draw(st.booleans()) and n > 1:          # a dependent row now and then
        rows[-1] = [a + 2 * b for a, b in zip(rows[0], rows[1 % n])]
    M = sp.Matrix([[sp.Rational(v.numerator, v.denominator) for v in r] for r in rows])
    assert linalg.rank(rows, m) == M.rank()
    red, piv = linalg.rref(rows, m)
    R, spiv = M.rref()
    assert piv == list(spiv)
    assert [[sp.Rational(v.numerator, v.denominator) for v in r] for r in red] == R.tolist()[:len(piv)]
    null = linalg.nullspace(rows, m)
    assert len(null) == m - M.rank()
    assert all(sum(r[j] * v[j] for j in range(m)) == 0 for v in null for r in rows)
    assert [[sp.Rational(x.numerator, x.denominator) for x in v] for v in null] == [list(v) for v in M.nullspace()]
    left = linalg.left_nullspace(rows, m)
    assert all(sum(lam[i] * rows[i][j] for i in range(n)) == 0 for lam in left for j in range(m))
    r, prow, pcol, det = linalg.maximal_minor(rows)
    assert r == M.rank() and (r == 0 or det != 0)
    if r:
        assert Fraction(det) == Fraction(str(M.extract(prow, pcol).det()))
