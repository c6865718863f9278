"""Exact algebra shared by every derivation: reduction modulo cos² + sin² - 1, exact
zero tests and the split of a constraint into the linear form M·Y = K.

Everything here is polynomial arithmetic over the rationals: no ``simplify``, no floats.
"""
from __future__ import annotations

import sympy as sp


def reduce_circle(expr, trig_pairs) -> sp.Expr:
    """Reduce a polynomial modulo s² = 1 - c² for every (c, s) pair; canonical form.

    The polynomials {s_i² + c_i² - 1} have pairwise coprime leading monomials (s_i²) in
    any order with s_i > c_i, so they are a Gröbner basis and the remainder is unique:
    the result is 0 exactly when ``expr`` vanishes for all real angles.
    """
    expr = sp.expand(expr)
    for c, s in trig_pairs:
        if not expr.has(s):
            continue
        poly = sp.Poly(expr, s)
        out = 0
        for (k,), coeff in poly.terms():
            out += coeff * (1 - c**2) ** (k // 2) * s ** (k % 2)
        expr = sp.expand(out)
    return expr


def is_zero(expr, trig_pairs=()) -> bool:
    """Exact test that a rational expression vanishes identically (for real angles)."""
    num, _den = sp.fraction(sp.together(sp.expand(expr)))
    return reduce_circle(num, trig_pairs) == 0


def equal(a, b, trig_pairs=()) -> bool:
    """Exact test that two rational expressions agree identically (for real angles)."""
    return is_zero(sp.sympify(a) - sp.sympify(b), trig_pairs)


def linear_form(expr, monomial_vars, trig_pairs=()):
    """Split ``expr`` = Σ_k m_k(v)·c_k(params) into the paper's form M·Y = K.

    ``expr`` must be a polynomial in ``monomial_vars`` (the sample invariants) whose
    coefficients are rational functions of the parameters. Each monomial m_k with a
    non-numeric coefficient becomes a column: its coefficient is written c_k = g_k·Y_k with
    g_k the numeric content, giving M_k = g_k·m_k and unknown Y_k. Monomials with numeric
    coefficients form -K. The unknowns are returned in the order of decreasing monomial
    degree, the row ``M`` accordingly.

    Returns
    -------
    M : list of Expr
        The row, one entry per unknown.
    Y : list of Expr
        The unknowns as functions of the parameters.
    K : Expr
        The right-hand side.
    """
    poly = sp.Poly(sp.expand(expr), *monomial_vars)
    M, Y, K = [], [], sp.Integer(0)
    for monom, coeff in poly.terms():
        mono = sp.Mul(*[v**e for v, e in zip(monomial_vars, monom)])
        coeff = sp.factor_terms(sp.together(coeff))
        num, den = sp.fraction(coeff)
        reduced = reduce_circle(num, trig_pairs)
        if reduced.is_number:
            K -= (reduced / den) * mono
            continue
        content, prim = sp.Poly(num, *sorted(num.free_symbols, key=sp.default_sort_key)).primitive()
        lead = sp.Poly(prim, *sorted(prim.free_symbols, key=sp.default_sort_key)).LC()
        if lead < 0:  # make the unknown's leading coefficient positive
            content, prim = -content, -prim
        M.append(content * mono)
        Y.append(prim.as_expr() / den)
    return M, Y, sp.expand(K)
