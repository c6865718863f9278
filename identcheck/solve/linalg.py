"""Small dense problems solved for many instances at once (stacked along the first axis).

LAPACK's stacked ``numpy.linalg.solve`` pays a per-matrix call overhead that dominates for
5×5 systems; eliminating all instances together, column by column, is several times faster.
"""
from __future__ import annotations

import numpy as np


def solve_stacked(M, K):
    """Solve M X = K for every instance by Gaussian elimination with partial pivoting.

    The instances are laid out structure-of-arrays (one contiguous array per matrix entry),
    so every step is a handful of contiguous vector operations across all instances.

    Parameters
    ----------
    M : array, shape (n, m, m)
    K : array, shape (n, m)

    Returns
    -------
    X : array, shape (n, m)
    pivot_ratio : array, shape (n,)
        min |pivot| / max |pivot|: a cheap condition indicator (0 for a singular M).
    """
    n, m, _ = M.shape
    A = [[np.ascontiguousarray(M[:, i, j]) for j in range(m)] + [np.ascontiguousarray(K[:, i])] for i in range(m)]
    pmax = np.zeros(n)
    pmin = np.full(n, np.inf)
    with np.errstate(all="ignore"):
        for k in range(m):
            col = np.abs(np.stack([A[i][k] for i in range(k, m)]))
            p = np.argmax(col, axis=0) + k
            for i in range(k + 1, m):
                sel = p == i
                if sel.any():
                    for j in range(k, m + 1):
                        a, b = A[k][j], A[i][j]
                        A[k][j], A[i][j] = np.where(sel, b, a), np.where(sel, a, b)
            piv = A[k][k]
            apiv = np.abs(piv)
            np.maximum(pmax, apiv, out=pmax)
            np.minimum(pmin, apiv, out=pmin)
            inv = 1.0 / piv
            for i in range(k + 1, m):
                f = A[i][k] * inv
                for j in range(k + 1, m + 1):
                    A[i][j] -= f * A[k][j]
        X = [None] * m
        for k in range(m - 1, -1, -1):
            acc = A[k][m].copy()
            for j in range(k + 1, m):
                acc -= A[k][j] * X[j]
            X[k] = acc / A[k][k]
        ratio = np.where(pmax > 0, pmin / pmax, 0.0)
    return np.stack(X, axis=-1), ratio


def lstsq_stacked(M, K):
    """Least squares for stacked tall systems (n, N, m), N >= m, through a stacked QR."""
    q, r = np.linalg.qr(M)
    return solve_stacked(r, np.einsum("nij,ni->nj", q, K))


def cubic_roots(coeffs):
    """The three roots of c0 t³ + c1 t² + c2 t + c3 for stacked real coefficients.

    Real arithmetic: the trigonometric form when all roots are real, Cardano's otherwise, then
    two Newton steps on the original cubic for the real roots.

    Parameters
    ----------
    coeffs : array, shape (..., 4)

    Returns
    -------
    re, im : arrays, shape (..., 3)
        Real and imaginary parts of the roots.
    """
    c = np.asarray(coeffs, dtype=float)
    a, b, d = (c[..., i] / c[..., 0] for i in (1, 2, 3))
    p = b - a * a / 3
    q = 2 * a**3 / 27 - a * b / 3 + d
    disc = (q / 2) ** 2 + (p / 3) ** 3
    three = disc <= 0
    with np.errstate(all="ignore"):
        # three real roots
        m = 2 * np.sqrt(np.maximum(-p / 3, 0))
        arg = np.clip(np.where(m > 0, 3 * q / np.where(m == 0, 1, p * m), 0), -1, 1)
        phi = np.arccos(arg) / 3
        trig = m[..., None] * np.cos(phi[..., None] - 2 * np.pi * np.arange(3) / 3)
        # one real root and a complex pair
        sq = np.sqrt(np.maximum(disc, 0))
        u = np.cbrt(-q / 2 + sq)
        v = np.cbrt(-q / 2 - sq)
        re1 = u + v
        re_c = -re1 / 2
        im_c = np.sqrt(3) / 2 * (u - v)
    re = np.where(three[..., None], trig, np.stack([re1, re_c, re_c], axis=-1)) - (a / 3)[..., None]
    im = np.where(three[..., None], 0.0, np.stack([np.zeros_like(re1), im_c, -im_c], axis=-1))
    A, B, D = a[..., None], b[..., None], d[..., None]
    real = im == 0
    with np.errstate(all="ignore"):
        for _ in range(2):
            f = ((re + A) * re + B) * re + D
            df = (3 * re + 2 * A) * re + B
            step = f / df
            re = np.where(real & np.isfinite(step), re - step, re)
    return re, im
