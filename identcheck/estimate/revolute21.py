"""Revolute (2,1) on noisy samples: geometric least squares seeded by Pham's closed form.

With two parent markers a sample is seen up to the parent's roll about A1A2, so it is the point
(R, z) of the half-plane (R = distance to the A1A2 axis). The child marker's orbit about the
hinge, turned about A1A2, sweeps a surface of revolution whose meridian is
(R(β), z(β)) = (|(ρ cos β + r, cos α ρ sin β − sin α l)|, sin α ρ sin β + cos α l + d) (the DH
forward map of :mod:`identcheck.derive.revolute` at θ = 0). Each sample's residual is its
distance to that meridian; the five constants minimise the sum of squares. The closed form's six
slots (three roots × mirror), clamped to real values, seed the search: on noise-free data they
are the answers; with noise the algebraic system is biased and may have no real root at all, and
every slot may lie in the basin of a wrong minimum, so a start from random joints
(:func:`scattered_seed`) is refined beside them.
By ERRATA E1/E2 the optimum comes with a twin parameter set and mirror images of exactly the
same cost, and all of them are returned.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from identcheck.solve import revolute21
from identcheck.solve.revolute21 import mirror

GRID = 256
NEWTON = 6
BRANCHES = 4      # local minima of the grid distance refined per sample
MAX_NFEV = 400    # the valley of a hinge near the A1A2 line is long and flat: stop on tolerance, not budget
TOL = 1e-12
SCATTERED = 100           # random joints scored on a few spread samples (:func:`scattered_seed`)
SCATTERED_SAMPLES = 40
SCATTERED_REFINED = 16    # of which this many are refined there
SCATTERED_NFEV = 30
SCATTERED_GAIN = 0.01     # what it finds is kept when its RMS distance is this share below the closed form's best


def _meridian(params, beta):
    d, r, a, l, rho = params
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(beta), np.sin(beta)
    x, y, z = rho * cb + r, ca * rho * sb - sa * l, sa * rho * sb + ca * l + d
    return x, y, z


def _nearest_beta(params, R, z):
    """β of the meridian point nearest each sample: every local minimum of the distance on a grid is
    refined by Newton and the nearest kept. (The grid alone is ~2πρ/GRID coarse in arc length, so the
    best grid point can sit on another branch of the meridian that passes close by.)"""
    grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
    x, y, zz = _meridian(params, grid)
    Rg = np.hypot(x, y)
    d = (R[:, None] - Rg[None]) ** 2 + (z[:, None] - zz[None]) ** 2          # (N, GRID), periodic
    is_min = (d <= np.roll(d, 1, axis=1)) & (d <= np.roll(d, -1, axis=1))
    d_min = np.where(is_min, d, np.inf)
    starts = np.argsort(d_min, axis=1)[:, :BRANCHES]                        # the best few local minima
    b = grid[starts]                                                         # (N, BRANCHES)
    Rb, zb = np.repeat(R[:, None], b.shape[1], axis=1), np.repeat(z[:, None], b.shape[1], axis=1)
    h = 1e-4
    for _ in range(NEWTON):
        f = [_dist2(params, b + s * h, Rb, zb) for s in (-1, 0, 1)]
        g1 = (f[2] - f[0]) / (2 * h)
        g2 = (f[2] - 2 * f[1] + f[0]) / h**2
        step = np.where(g2 > 0, -g1 / np.where(g2 > 0, g2, 1), 0.0)
        b = b + np.clip(step, -0.1, 0.1)
    best = np.argmin(np.where(np.isfinite(np.take_along_axis(d_min, starts, 1)), _dist2(params, b, Rb, zb), np.inf),
                     axis=1)
    return b[np.arange(len(R)), best]


def _dist2(params, b, R, z):
    x, y, zz = _meridian(params, b)
    return (np.hypot(x, y) - R) ** 2 + (zz - z) ** 2


def residuals(params, R, z) -> np.ndarray:
    """Signed-free distances of the samples (R, z) to the meridian of ``params``."""
    b = _nearest_beta(params, R, z)
    return np.sqrt(_dist2(params, b, R, z))


def thetas(params, local) -> np.ndarray:
    """The parent roll θ per sample: B's azimuth minus that of its nearest meridian point."""
    R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    b = _nearest_beta(params, R, z)
    x, y, _ = _meridian(params, b)
    return np.arctan2(local[:, 1], local[:, 0]) - np.arctan2(y, x)


def _odr(x, R, z):
    """Orthogonal-distance residuals: constants x[:5] and one β per sample x[5:]."""
    xx, yy, zz = _meridian(x[:5], x[5:])
    return np.concatenate([np.hypot(xx, yy) - R, zz - z])


def _odr_jacobian(x, R, z):
    """Analytic Jacobian of :func:`_odr` (2N × (5 + N), sparse): the meridian's derivatives with respect to
    (d, r, α, l, ρ) fill the first five columns, each sample's β its own column."""
    from scipy.sparse import csr_matrix

    d, r, a, l, rho = x[:5]
    beta = x[5:]
    N = len(beta)
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(beta), np.sin(beta)
    xx, yy = rho * cb + r, ca * rho * sb - sa * l
    Rm = np.maximum(np.hypot(xx, yy), 1e-300)
    one, zero = np.ones(N), np.zeros(N)
    # columns d, r, α, l, ρ, β of the meridian point (x, y, z)
    dx = [zero, one, zero, zero, cb, -rho * sb]
    dy = [zero, zero, -sa * rho * sb - ca * l, -sa * one, ca * sb, ca * rho * cb]
    dz = [one, zero, ca * rho * sb - sa * l, ca * one, sa * sb, sa * rho * cb]
    dR = [(xx * gx + yy * gy) / Rm for gx, gy in zip(dx, dy)]
    rows = np.r_[np.repeat(np.arange(N), 6), np.repeat(N + np.arange(N), 6)]
    cols = np.tile(np.r_[np.arange(5), -1], 2 * N)
    cols[cols < 0] = np.tile(5 + np.arange(N), 2)
    vals = np.r_[np.stack(dR, axis=1).ravel(), np.stack(dz, axis=1).ravel()]
    return csr_matrix((vals, (rows, cols)), shape=(2 * N, 5 + N))


def _odr_bounds(N: int, scale: float) -> tuple:
    """Bounds of the ODR problem (5 constants, then one β per sample): r, ρ > 0 and α in (0, π)."""
    lo = np.r_[[-np.inf, 1e-6 * scale, 1e-6, -np.inf, 1e-6 * scale], np.full(N, -np.inf)]
    hi = np.r_[[np.inf, np.inf, np.pi - 1e-6, np.inf, np.inf], np.full(N, np.inf)]
    return lo, hi


def fit(local, max_nfev: int = MAX_NFEV) -> list:
    """Distinct least-squares joints (d, r, α, l, ρ) with their RMS residual and 1-σ uncertainty (mm), best first.

    ``local``: (N, 3) samples in the frame of the two parent markers (A1 origin, A2 on +z).
    Orthogonal distance regression: the constants and one β per sample are fitted together
    (a smooth problem with a sparse Jacobian), from each seed of the closed form, each run stopped after
    ``max_nfev`` evaluations (a start for a later fit needs fewer than an answer). The closed form's slots come
    in mirror pairs (:func:`identcheck.solve.revolute21.mirror`: the same meridian, ERRATA E2): one of each pair
    is refined and the result mirrored, which halves the work and returns the two as exact mirror images (refined
    separately, runs stopped by the budget in a flat valley ended up to several mm apart).
    """
    local = np.asarray(local, dtype=float)
    R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    N = len(local)
    scale = float(np.sqrt(np.mean(local**2)))
    seeds = [s for s in revolute21.solve_batch(local).params if np.all(np.isfinite(s))]
    lo, hi = _odr_bounds(N, scale)
    found = []

    units = np.array([scale, scale, 1.0, scale, scale])

    def refine(s, into):
        s = np.clip(np.array(s, dtype=float), lo[:5] + 1e-9 * scale, hi[:5] - 1e-9)
        x0 = np.r_[s, _nearest_beta(s, R, z)]
        sol = least_squares(_odr, x0, jac=_odr_jacobian, args=(R, z), bounds=(lo, hi), x_scale="jac",
                            tr_solver="lsmr", max_nfev=max_nfev, ftol=TOL, xtol=TOL, gtol=TOL)
        p = sol.x[:5]
        rms, unc = float(np.sqrt(np.mean(residuals(p, R, z) ** 2))), _uncertainty(sol, N)
        into.extend([(p, rms, unc), (mirror(p), rms, unc)])     # the same meridian: the same fit (ERRATA E2)

    def met(s, among) -> bool:
        return any(np.max(np.abs(s - q) / units) <= 1e-3 for q, _, _ in among)

    def with_twins(into):
        """The best of `into` with its own twins (ERRATA E1): noise can hide them from the seeds."""
        into.sort(key=lambda t: t[1])
        for s in twin_seeds(into[0][0], R, z):
            if not met(s, found) and not met(s, into):
                refine(s, into)
        into.sort(key=lambda t: t[1])

    refined = []
    for s in seeds:                 # the closed form's slots come in mirror pairs: each pair is refined once
        if not any(np.max(np.abs(mirror(s) - t) / units) <= 1e-9 for t in refined):
            refined.append(s)
            refine(s, found)
    if found:
        with_twins(found)
    # noise can leave every slot of the closed form outside the best basin: a start from random joints, kept (with
    # its twins) only where it finds a better one, and then without the points it reaches in the same flat valley
    s = scattered_seed(R, z, scale)
    if s is not None and not met(s, found):
        extra: list = []
        refine(s, extra)
        if not found or extra[0][1] < (1 - SCATTERED_GAIN) * found[0][1]:
            with_twins(extra)
            for p, rms, unc in extra:
                if not any(_same_in_valley(p, rms, unc, q, r, u) for q, r, u in found):
                    found.append((p, rms, unc))
            found.sort(key=lambda t: t[1])
    distinct = []
    for p, rms, unc in found:
        if all(np.max(np.abs(p - q) / units) > 1e-4 for q, _, _ in distinct):
            distinct.append((p, rms, unc))
    return distinct


def _same_in_valley(p, rms_p, unc_p, q, rms_q, unc_q) -> bool:
    """Two refined joints that are one answer: the same RMS (within 1 %), on the same side of α = π/2 (not
    mirror images), and lengths (d, r, l, ρ) within twice the larger 1-σ. In a long flat valley the runs stop
    wherever their budget ends, and each such point would otherwise start its own whole-tree fit."""
    lengths = [0, 1, 3, 4]
    return (abs(rms_p - rms_q) <= 0.01 * max(rms_p, rms_q) and (p[2] - np.pi / 2) * (q[2] - np.pi / 2) > 0
            and np.max(np.abs(p[lengths] - q[lengths])) <= 2 * max(unc_p, unc_q))


def scattered_seed(R, z, scale: float, seed: int = 0) -> np.ndarray | None:
    """A start for the least squares that does not come from the closed form: the best of :data:`SCATTERED`
    random joints, scored on :data:`SCATTERED_SAMPLES` spread samples, after the :data:`SCATTERED_REFINED` best
    of them are refined there for :data:`SCATTERED_NFEV` evaluations (None with fewer samples than that).

    With noise, the closed form's roots are biased, and on a minimal marker set (one thigh and one shank
    marker) every one of its slots can lie in the basin of a wrong minimum: on a generated trial with 0.38 mm of
    noise they all refined to an RMS distance of 2.0 mm, while a joint 0.66 mm from the samples existed. The
    random joints cover the constants' plausible range (the hinge within one sample scale of the samples, α in
    (0, π/2], the other half being the mirror images); the generator is seeded, so the answer depends on the
    data alone. The short refinements are unbounded Levenberg-Marquardt (several times cheaper than the bounded
    solver on these small problems), brought back to r, ρ ≥ 0 and α in [0, π] by :func:`canonical`."""
    n = len(R)
    if n < SCATTERED_SAMPLES:
        return None
    idx = np.linspace(0, n - 1, SCATTERED_SAMPLES).astype(int)
    Rs, zs = R[idx], z[idx]
    rng = np.random.default_rng(seed)
    k = SCATTERED
    joints = np.c_[rng.uniform(zs.min() - scale, zs.max() + scale, k), rng.uniform(0.0, Rs.max() + scale, k),
                   rng.uniform(0.02, np.pi / 2, k), rng.uniform(-2 * scale, 2 * scale, k),
                   rng.uniform(0.02 * scale, 2 * scale, k)]
    cost = np.array([np.mean(residuals(j, Rs, zs) ** 2) for j in joints])
    best, best_cost = None, np.inf
    for j in joints[np.argsort(cost)[:SCATTERED_REFINED]]:
        sol = least_squares(_odr, np.r_[j, _nearest_beta(j, Rs, zs)], jac=_odr_dense_jacobian, args=(Rs, zs),
                            method="lm", x_scale="jac", max_nfev=SCATTERED_NFEV)
        if np.all(np.isfinite(sol.x[:5])) and sol.cost < best_cost:
            best, best_cost = sol.x[:5], sol.cost
    return None if best is None else canonical(best)


def _odr_dense_jacobian(x, R, z):
    """:func:`_odr_jacobian` as a dense array, for the Levenberg-Marquardt of :func:`scattered_seed`."""
    return _odr_jacobian(x, R, z).toarray()


def canonical(params) -> np.ndarray:
    """The same meridian with r ≥ 0, ρ ≥ 0 and α in [0, π]: ρ → −ρ is β → β + π; r → −r is β → π − β with the
    meridian mirrored in x (the same distances R); α → α − π with (ρ, l) → (−ρ, −l) is the same curve."""
    d, r, a, l, rho = (float(v) for v in params)
    a = a % (2 * np.pi)
    if a > np.pi:
        a, l = a - np.pi, -l
    return np.array([d, abs(r), a, l, abs(rho)])


def twin_seeds(params, R, z) -> list:
    """The closed form's joints for noise-free samples of the joint ``params`` (its meridian points nearest
    the samples (R, z)): the joint itself and the other real joint that reproduces the same samples
    exactly (ERRATA E1). On noisy data the closed form of the samples themselves can miss the twin."""
    b = _nearest_beta(params, R, z)
    x, y, zz = _meridian(params, b)
    return [np.array(s, dtype=float) for s in revolute21.solve_batch(np.c_[x, y, zz]).params if np.all(np.isfinite(s))]


def _uncertainty(sol, N: int) -> float:
    """1-σ of the worst-determined length constant (d, r, l, ρ), mm, from the linearised covariance.

    The per-sample β are eliminated by the Schur complement of their diagonal block of JᵀJ, so
    the 5 × 5 covariance of the constants costs O(N).
    """
    J = sol.jac.tocsc()
    Jp = J[:, :5].toarray()
    jb1 = np.asarray(J[np.arange(N), 5 + np.arange(N)]).ravel()
    jb2 = np.asarray(J[N + np.arange(N), 5 + np.arange(N)]).ravel()
    D = jb1**2 + jb2**2
    B = Jp[:N] * jb1[:, None] + Jp[N:] * jb2[:, None]
    keep = D > 0
    S = Jp.T @ Jp - (B[keep] / D[keep, None]).T @ B[keep]
    dof = max(2 * N - N - 5, 1)
    sigma2 = float(np.sum(sol.fun**2)) / dof
    try:
        cov = sigma2 * np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return float("inf")
    lengths = cov[np.ix_([0, 1, 3, 4], [0, 1, 3, 4])]
    return float(np.sqrt(max(np.linalg.eigvalsh(lengths)[-1], 0.0)))
