"""The one exact linear algebra of the certificates: row reduction, rank, null spaces and maximal minors
over the rationals (FLINT ``fmpq_mat``) or over GF(p) (FLINT ``nmod_mat``, p a random prime).

The reduced row echelon form is unique, so every result here is canonical: the pivots, the echelon basis
of a row space, and the null-space basis with one vector per free column (1 there, minus the pivot rows'
entries at the pivot columns) are the same whichever library computes them, and certificates replay
byte for byte.
"""
from __future__ import annotations

import random
from fractions import Fraction

import flint

from identcheck.exact.algebra import random_prime

PRIME_BITS = 61


def qq(x) -> flint.fmpq:
    """An exact rational from an int, a ``Fraction`` or anything with ``p``/``q`` or ``numerator``/``denominator``."""
    kind = type(x)
    if kind is flint.fmpq:
        return x
    if kind is int:
        return flint.fmpq(x)
    if kind is Fraction:
        return flint.fmpq(x.numerator, x.denominator)
    num = getattr(x, "numerator", None)
    if num is None:
        num, den = x.p, x.q                     # SymPy Rational
    else:
        den = x.denominator
    return flint.fmpq(int(num), int(den))


def to_fraction(v: flint.fmpq) -> Fraction:
    return Fraction(int(v.p), int(v.q))


def qq_matrix(rows, ncols: int) -> flint.fmpq_mat:
    """The rational matrix with these rows (a list of lists of exact numbers)."""
    return flint.fmpq_mat(len(rows), ncols, [qq(v) for r in rows for v in r])


def rowspace(rows, ncols: int) -> list:
    """The non-zero rows of the reduced row echelon form over QQ, as ``flint.fmpq`` (for callers that go on
    computing with them; :func:`rref` gives them as ``Fraction`` with their pivots)."""
    if not rows or ncols == 0:
        return []
    R, rank = qq_matrix(rows, ncols).rref()
    flat = R.entries()
    return [flat[i * ncols:(i + 1) * ncols] for i in range(rank)]


def _pivots(echelon: list) -> list:
    """The pivot column of each non-zero row of a reduced row echelon form."""
    return [next(j for j, v in enumerate(row) if v != 0) for row in echelon]


def rref(rows, ncols: int) -> tuple[list, list]:
    """(the non-zero rows of the reduced row echelon form as Fractions, the pivot columns) over QQ."""
    echelon = rowspace(rows, ncols)
    return [[to_fraction(v) for v in row] for row in echelon], _pivots(echelon)


def rank(rows, ncols: int) -> int:
    return qq_matrix(rows, ncols).rank() if rows and ncols else 0


def nullspace(rows, ncols: int) -> list:
    """Basis of {x : A x = 0}, one Fraction vector per free column of the RREF (1 at that column)."""
    if not rows:
        return [[Fraction(int(i == j)) for j in range(ncols)] for i in range(ncols)]
    red, piv = rref(rows, ncols)
    free = [j for j in range(ncols) if j not in piv]
    out = []
    for f in free:
        v = [Fraction(0)] * ncols
        v[f] = Fraction(1)
        for r, p in enumerate(piv):
            v[p] = -red[r][f]
        out.append(v)
    return out


def left_nullspace(rows, ncols: int) -> list:
    """Basis of {λ : λ A = 0} for the matrix with these rows (len(rows) × ncols)."""
    n = len(rows)
    if n == 0:
        return []
    if ncols == 0:
        return [[Fraction(int(i == j)) for j in range(n)] for i in range(n)]
    transposed = [[rows[i][j] for i in range(n)] for j in range(ncols)]
    return nullspace(transposed, n)


def maximal_minor(rows) -> tuple[int, list, list, Fraction]:
    """Rank over QQ, the pivot rows and columns of a non-zero maximal minor, and that minor's value."""
    ncols = len(rows[0])
    M = qq_matrix(rows, ncols)
    col_piv = _pivots(rowspace(rows, ncols))
    row_piv = _pivots(rowspace([[rows[i][j] for i in range(len(rows))] for j in range(ncols)], len(rows)))
    r = len(col_piv)
    if not r:
        return 0, [], [], Fraction(1)
    minor = flint.fmpq_mat(r, r, [M[i, j] for i in row_piv for j in col_piv])
    return r, row_piv, col_piv, to_fraction(minor.det())


class Field:
    """Scalars and matrices of QQ (exact) or GF(p) (a random prime of :data:`PRIME_BITS` bits, for fast search)."""

    def __init__(self, kind: str, rng: random.Random):
        self.kind = kind
        if kind == "QQ":
            self.p = None
        elif kind == "GFp":
            self.p = random_prime(rng, PRIME_BITS)
        else:
            raise ValueError(f"unknown field {kind!r}")

    def __call__(self, x):
        if self.p is None:
            if isinstance(x, Fraction):
                return flint.fmpq(x.numerator, x.denominator)
            return flint.fmpq(x)
        if isinstance(x, Fraction):
            return flint.nmod(x.numerator, self.p) / flint.nmod(x.denominator, self.p)
        return flint.nmod(x, self.p)

    def zeros(self, nrows: int, ncols: int):
        """The zero matrix of this field (entries set one by one, which FLINT does without conversions)."""
        if self.p is None:
            return flint.fmpq_mat(nrows, ncols)
        return flint.nmod_mat(nrows, ncols, self.p)
