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


def linear_form_in_parameters(expr, parameter_vars):
    """Split a polynomial in ``parameter_vars`` as Σ_k M_k(sample)·Y_k + (−K), Y_k its monomials.

    The counterpart of :func:`linear_form` when the unknowns are products of parameters (Pham
    eq. 16): every parameter monomial that occurs becomes an unknown, its coefficient (a
    polynomial in the sample coordinates) the entry of M, and the parameter-free part −K.
    Unknowns come in decreasing degree.
    """
    poly = sp.Poly(sp.expand(expr), *parameter_vars)
    M, Y, K = [], [], sp.Integer(0)
    for monom, coeff in poly.terms():
        mono = sp.Mul(*[v**e for v, e in zip(parameter_vars, monom)])
        if mono == 1:
            K = -coeff.as_expr()
            continue
        M.append(sp.factor(coeff.as_expr()))
        Y.append(mono)
    return M, Y, sp.expand(K)


def polynomial_relations(columns, multipliers, variables):
    """All relations Σ_k (Σ_j a_jk·m_j)·M_k ≡ 0 with rational a_jk: a basis of the solutions.

    ``columns`` are polynomials M_k in ``variables``. ``multipliers`` are pairs (m_j, name_j):
    a polynomial (1, or e.g. a squared distance that is constant on the output set) and the
    symbol that stands for its constant value. Each relation is returned as the list over k of
    Σ_j a_jk·name_j: a linear dependency among the columns wherever m_j takes the value name_j.
    """
    terms = [(j, k, sp.Poly(sp.expand(m * c), *variables)) for j, (m, _) in enumerate(multipliers)
             for k, c in enumerate(columns)]
    monomials = sorted({mon for _, _, p in terms for mon in p.monoms()})
    index = {mon: i for i, mon in enumerate(monomials)}
    A = sp.zeros(len(monomials), len(terms))
    for col, (_, _, p) in enumerate(terms):
        for mon, coef in p.terms():
            A[index[mon], col] = coef
    out = []
    for vec in A.nullspace():
        rel = [sp.Integer(0)] * len(columns)
        for val, (j, k, _) in zip(vec, terms):
            rel[k] += val * multipliers[j][1]
        out.append([sp.expand(v) for v in rel])
    return out
