"""A compiled kernel for the batched revolute (2,1) solver: the constants of every candidate, one problem at a time.

:func:`identcheck.solve.revolute21.solve_batch` with ``angles=False`` is a few dozen NumPy passes over all
problems; each pass reads and writes arrays far larger than the cache, so it runs at memory speed (about
1.5 M five-sample problems per second on one core). Here the same steps run problem by problem in registers,
compiled by numba and spread over the cores: the generated formulas of :mod:`identcheck.solve.generated`
(compiled as they are, no copy typed in by hand), the elimination of :func:`identcheck.solve.revolute21._solve_five`
with the partial pivoting of :func:`identcheck.solve.linalg.solve_stacked`, the trigonometric roots and
Newton step of :func:`identcheck.solve.revolute21.fast_cubic_roots`, :func:`identcheck.solve.revolute21.cos_and_l`,
:func:`identcheck.solve.revolute21.is_real` and the rounding slack, in the same order of operations but one: the
samples are scaled by multiplying with the reciprocal of their RMS distance rather than dividing by it (15 divisions
fewer per problem, about a sixth of the time; the constants move by rounding only).

A problem the kernel does not take is marked and left to the NumPy path: a cubic whose computed discriminant
says "one real root" (Cardano's form, rare: noise or a near-double root). The verdicts are the NumPy path's; a
test compares them on random problems, and ``benchmarks/bench_revolute21.py`` on a million.

numba is optional (``pip install identcheck[fast]``); importing this module without it raises ImportError, and
:func:`identcheck.solve.revolute21.solve_batch` then stays on NumPy. The kernel is compiled on first use (about ten
seconds) and cached on disk by numba (next to this file, or in numba's user cache when that is not writable), so
later processes load it in about half a second.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from identcheck.solve import generated as generated_code

N_UNKNOWNS = 5
BLOCK = 512          # problems per parallel task

if not generated_code.is_current("revolute21"):
    raise ImportError("the revolute (2,1) generated code is stale: run `identcheck derive --regenerate`")
_G = generated_code.module("revolute21")
_jit = numba.njit(cache=True, error_model="numpy", inline="always")
_m_row, _cubic, _back, _rho2 = (_jit(_G.FUNCTIONS["numpy"][k][0]) for k in ("m_row", "cubic", "back", "rho2"))
_C = int(_G.FACTS["constant_column"])   # the column of M that is 1 for every sample
_REST = np.array([j for j in range(N_UNKNOWNS) if j != _C], dtype=np.int64)


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _kernel(xyz, params, valid, Z, ratio, handled, imag_tol, real_tol, round_):
    n, N = xyz.shape[0], xyz.shape[1]
    n_blocks = (n + BLOCK - 1) // BLOCK
    for blk in numba.prange(n_blocks):          # scratch arrays allocated once per block, not per problem
        MK, D, Zr = np.empty((N, 6)), np.empty((4, 5)), np.empty(4)
        for i in range(blk * BLOCK, min((blk + 1) * BLOCK, n)):
            _one(xyz[i], params[i], valid[i], Z[i], ratio, handled, i, imag_tol, real_tol, round_, MK, D, Zr)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _one(x, params, valid, Zs, ratio, handled, i, imag_tol, real_tol, round_, MK, D, Zr):
    N = x.shape[0]
    ss = 0.0
    for s in range(N):
        for k in range(3):
            ss += x[s, k] * x[s, k]
    scale = math.sqrt(ss / N)
    if not scale > 0:
        scale = 1.0
    iscale = 1.0 / scale
    for s in range(N):
        MK[s, 0], MK[s, 1], MK[s, 2], MK[s, 3], MK[s, 4], MK[s, 5] = _m_row(x[s, 0] * iscale, x[s, 1] * iscale,
                                                                       x[s, 2] * iscale)
    # _solve_five: subtract the first row, eliminate the other four unknowns with partial pivoting
    for a in range(4):
        for b in range(4):
            D[a, b] = MK[a + 1, _REST[b]] - MK[0, _REST[b]]
        D[a, 4] = MK[a + 1, 5] - MK[0, 5]
    pmax, pmin = 0.0, np.inf
    for k in range(4):
        p, best = k, abs(D[k, k])
        for a in range(k + 1, 4):
            if abs(D[a, k]) > best:
                p, best = a, abs(D[a, k])
        if p != k:
            for b in range(k, 5):
                D[k, b], D[p, b] = D[p, b], D[k, b]
        piv = D[k, k]
        pmax, pmin = np.maximum(pmax, abs(piv)), np.minimum(pmin, abs(piv))
        inv = 1.0 / piv
        for a in range(k + 1, 4):
            f = D[a, k] * inv
            for b in range(k + 1, 5):
                D[a, b] -= f * D[k, b]
    for k in range(3, -1, -1):
        acc = D[k, 4]
        for b in range(k + 1, 4):
            acc -= D[k, b] * Zr[b]
        Zr[k] = acc / D[k, k]
    ratio[i] = pmin / pmax if pmax > 0 else 0.0
    dot = 0.0
    for b in range(4):
        Zs[_REST[b]] = Zr[b]
        dot += MK[0, _REST[b]] * Zr[b]
    Zs[_C] = (MK[0, 5] - dot) / MK[0, _C]
    Z1, Z2, Z3, Z4, Z5 = Zs[0], Zs[1], Zs[2], Zs[3], Zs[4]
    # fast_cubic_roots: the trigonometric form and one Newton step; Cardano's case is left to NumPy
    c0, c1, c2, c3 = _cubic(Z1, Z2, Z3, Z4, Z5)
    a, b, cc = c1 / c0, c2 / c0, c3 / c0
    p3 = b / 3 - a * a / 9
    h = (2 * a * a / 27 - b / 3) * a + cc
    if not (h * h / 4 + p3 * p3 * p3 <= 0):
        handled[i] = False
        return
    handled[i] = True
    m = math.sqrt(np.maximum(-p3, 0.0))
    arg = h / (-2 * m * m * m) if m > 0 else 0.0
    phi = math.acos(np.minimum(np.maximum(arg, -1.0), 1.0)) / 3
    cp, sp3 = m * math.cos(phi), math.sqrt(3) * m * math.sin(phi)
    roots = (2 * cp - a / 3, (sp3 - cp) - a / 3, (-cp - sp3) - a / 3)
    for j in range(3):
        q = roots[j]
        f = ((q + a) * q + b) * q + cc
        step = f / ((3 * q + 2 * a) * q + b)
        if math.isfinite(step):
            q = q - step
        r2, S, w, v = _back(q, Z1, Z2, Z3, Z4, Z5)
        # cos_and_l
        C = 1 - S
        from_c = C >= v
        mm = math.sqrt(np.maximum(np.maximum(C, v), 0.0))
        t = w / (mm if mm > 0 else 1.0)
        ca = mm if from_c else abs(t)
        u = t if from_c else (-mm if w < 0 else mm)
        l = u - Z1 * ca
        rho2 = _rho2(q, Z1, Z2, Z3, Z4, Z5, l)[0]
        # NumPy's |Im| <= IMAG_TOL (1 + |q|) with Im = 0 here: False only for a NaN root, as there
        ok = (0.0 <= imag_tol * (1 + abs(q))) and math.isfinite(l)
        slack = 0.0
        if S > 1 and v > 0:                       # _cos2_slack
            aq = abs(q)
            Z1s = Z1 ** 2
            size = ((abs(c0) * aq + abs(c1)) * aq + abs(c2)) * aq + abs(c3)
            slope = (3 * c0 * q + 2 * c1) * q + c2
            bracket = size / abs(slope) + aq + abs(Z2) + 2 * abs(S) * (Z1s + abs(Z5))
            slack = round_ / ratio[i] * bracket / abs(2 * (Z1s - Z5))
        ok = (ok and (r2 > real_tol) and (S > real_tol) and (C >= -slack) and ((C if abs(C) >= abs(v) else v) > 0)
              and (rho2 > -real_tol))
        sa = math.sqrt(np.minimum(np.maximum(S, 0.0), 1.0))
        r, rho = math.sqrt(np.maximum(r2, 0.0)), math.sqrt(np.maximum(rho2, 0.0))
        alpha = math.atan2(sa, ca)
        for sgn in range(2):
            slot = 2 * j + sgn
            params[slot, 0] = Z1 * scale
            params[slot, 1] = r * scale
            params[slot, 2] = alpha if sgn == 0 else math.pi - alpha
            params[slot, 3] = l * scale if sgn == 0 else -(l * scale)
            params[slot, 4] = rho * scale
            valid[slot] = ok




def solve_constants(xyz: np.ndarray, imag_tol: float, real_tol: float, round_: float):
    """The kernel over problems ``xyz`` (n, 5, 3): params (n, 6, 5), valid (n, 6), Z (n, 5), pivot ratio (n,) and
    ``handled`` (n,): False where the problem was left to the NumPy path (its other outputs undefined)."""
    xyz = np.ascontiguousarray(xyz, dtype=float)
    n = len(xyz)
    params, valid = np.empty((n, 6, 5)), np.zeros((n, 6), dtype=bool)
    Z, ratio, handled = np.empty((n, N_UNKNOWNS)), np.empty(n), np.zeros(n, dtype=bool)
    _kernel(xyz, params, valid, Z, ratio, handled, imag_tol, real_tol, round_)
    return params, valid, Z, ratio, handled
