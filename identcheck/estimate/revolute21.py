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

from identcheck.solve import revolute21
from identcheck.solve.revolute21 import mirror

GRID = 256
NEWTON = 6
BRANCHES = 4      # local minima of the grid distance refined per sample
MAX_NFEV = 400    # the valley of a hinge near the A1A2 line is long and flat: stop on tolerance, not budget
TOL = 1e-12
UNDETERMINED_RCOND = 1e-12  # constants undetermined below this singular-value ratio (:func:`_uncertainty`)
BETA_FLOOR = 1e-6         # the least damping scale of a sample's β, as a share of the largest (:func:`_refine`)
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


def _odr_parts(x, R, z) -> tuple:
    """The orthogonal-distance residuals r (2N) of the constants x[:5] and one β per sample x[5:] (each sample's
    meridian point's R less the sample's, then its z less the sample's), with their Jacobian in pieces: the
    constants' columns ``Jp`` (2N × 5) and, for each sample i, the derivatives ``jb1[i]``, ``jb2[i]`` of its two rows
    (i and N + i) in its own β (the one other nonzero of those rows)."""
    d, r, a, l, rho = x[:5]
    beta = x[5:]
    N = len(beta)
    ca, sa = np.cos(a), np.sin(a)
    cb, sb = np.cos(beta), np.sin(beta)
    xx, yy = rho * cb + r, ca * rho * sb - sa * l
    zz = sa * rho * sb + ca * l + d
    Rm = np.maximum(np.hypot(xx, yy), 1e-300)
    one, zero = np.ones(N), np.zeros(N)
    # columns d, r, α, l, ρ, β of the meridian point (x, y, z)
    dx = [zero, one, zero, zero, cb, -rho * sb]
    dy = [zero, zero, -sa * rho * sb - ca * l, -sa * one, ca * sb, ca * rho * cb]
    dz = [one, zero, ca * rho * sb - sa * l, ca * one, sa * sb, sa * rho * cb]
    dR = [(xx * gx + yy * gy) / Rm for gx, gy in zip(dx, dy)]
    Jp = np.concatenate([np.stack(dR[:5], axis=1), np.stack(dz[:5], axis=1)])
    return np.concatenate([np.hypot(xx, yy) - R, zz - z]), Jp, dR[5], dz[5]


def _normal_pieces(Jp, jb1, jb2, r) -> tuple:
    """The normal equations of :func:`_odr_parts` in the arrow form its Jacobian gives them: the constants' block
    ``A = JpᵀJp`` (5 × 5), each sample's coupling ``B[i]`` (5) to its β and its β's own ``D[i]``, and the gradient's
    parts ``gp`` (5) and ``gb`` (N)."""
    N = len(jb1)
    B = Jp[:N] * jb1[:, None] + Jp[N:] * jb2[:, None]
    return Jp.T @ Jp, B, jb1**2 + jb2**2, Jp.T @ r, jb1 * r[:N] + jb2 * r[N:]


def _reduced(A, B, D) -> np.ndarray:
    """The constants' block of the normal equations with every β eliminated (its Schur complement, O(N)):
    ``A − Σ B[i] B[i]ᵀ / D[i]`` over the samples whose β moves their point (D > 0)."""
    keep = D > 0
    return A - (B[keep] / D[keep, None]).T @ B[keep]


def _damped_step(pieces, damp_p, damp_b) -> tuple:
    """The step (δp, δβ) solving ``(JᵀJ + diag(damp_p, damp_b)) δ = −Jᵀr`` from the normal equations' arrow-form
    `pieces` (:func:`_normal_pieces`): the constants' 5 × 5 system with every β eliminated, then each β's own
    division. `damp_b` must be positive where a sample's ``D`` is 0."""
    A, B, D, gp, gb = pieces
    Dl = D + damp_b
    S = _reduced(A + np.diag(damp_p), B, Dl)
    rhs = -gp + (B / Dl[:, None]).T @ gb
    try:
        dp = np.linalg.solve(S, rhs)
    except np.linalg.LinAlgError:
        dp = np.linalg.lstsq(S, rhs, rcond=None)[0]
    return dp, (-gb - B @ dp) / Dl


def _refine(x0, R, z, max_nfev: int, tol: float = TOL) -> tuple:
    """Levenberg–Marquardt on :func:`_odr_parts` (the constants and one β per sample together), each step solved
    through the arrow form of its normal equations (:func:`_damped_step`): a 5 × 5 system and N divisions, where a
    general sparse solver iterates (scipy's bounded trust region with LSMR, which this replaced, took 0.15 s for
    100 evaluations on 400 samples). The damping is scaled by each variable's diagonal term, its largest so far
    (MINPACK's rule: a scale that falls with the diagonal left the damping too weak where the valley is flat, and
    the run crawled), which makes the steps independent of the constants' units; a β whose point does not move with
    it (where ρ = 0, or r = 0 with α at 0 or π) is scaled as if it moved :data:`BETA_FLOOR` of the most, or its step
    would be unbounded. The damping follows Nielsen's rule. Stops after `max_nfev` evaluations of the residuals,
    when the scaled gradient is below `tol` of the residual's norm, when no variable's step times the square root of
    its damping scale exceeds `tol` of that norm, or when a step the linear model predicted well (gain above 1/4)
    lowered the cost by less than `tol` of itself (as MINPACK's tests). Unbounded: a run may leave r, ρ ≥ 0 and α in
    [0, π] for the same meridian, which :func:`canonical` brings back. Returns (x, residuals, Jp, jb1, jb2) at the
    end point."""
    x = np.array(x0, dtype=float)
    r, Jp, jb1, jb2 = _odr_parts(x, R, z)
    cost, nfev = float(r @ r) / 2, 1
    lam, nu = 1e-3, 2.0
    dA, dD = np.zeros(5), np.zeros(len(jb1))
    while nfev < max_nfev:
        A, B, D, gp, gb = _normal_pieces(Jp, jb1, jb2, r)
        dA = np.maximum(dA, np.maximum(np.diag(A), 1e-300))                      # MINPACK's running maximum
        dD = np.maximum(dD, np.maximum(D, BETA_FLOOR * D.max() if D.max() > 0 else 1.0))
        if max(np.max(np.abs(gp) / np.sqrt(dA)), np.max(np.abs(gb) / np.sqrt(dD))) <= tol * np.sqrt(2 * cost):
            break
        dp, db = _damped_step((A, B, D, gp, gb), lam * dA, lam * dD)
        step = np.r_[dp, db]
        predicted = 0.5 * (lam * (dA @ dp**2 + dD @ db**2) - gp @ dp - gb @ db)
        trial = x + step
        r_new, Jp_new, jb1_new, jb2_new = _odr_parts(trial, R, z)
        nfev += 1
        cost_new = float(r_new @ r_new) / 2
        gain = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if np.isfinite(cost_new) and gain > 0:
            small_step = np.all(np.abs(step) * np.sqrt(np.r_[dA, dD]) <= tol * (tol + np.sqrt(2 * cost)))
            small_change = cost - cost_new <= tol * cost and gain > 0.25     # (a poor model's small change: go on)
            x, r, Jp, jb1, jb2, cost = trial, r_new, Jp_new, jb1_new, jb2_new, cost_new
            lam *= max(1 / 3, 1 - (2 * gain - 1) ** 3)
            nu = 2.0
            if small_step or small_change:
                break
        else:
            lam *= nu
            nu *= 2
            if lam > 1e16:
                break
    return x, r, Jp, jb1, jb2


def fit(local, max_nfev: int = MAX_NFEV) -> list:
    """Distinct least-squares joints (d, r, α, l, ρ) with their RMS residual and 1-σ uncertainty (mm), best first.

    ``local``: (N, 3) samples in the frame of the two parent markers (A1 origin, A2 on +z).
    Orthogonal distance regression: the constants and one β per sample are fitted together
    (a smooth problem whose normal equations have an arrow form: :func:`_refine`), from each seed of the closed
    form (off the boundaries r, ρ, α = 0 and α = π, where a derivative vanishes), each run stopped after
    ``max_nfev`` evaluations (a start for a later fit needs fewer than an answer). The closed form's slots come
    in mirror pairs (:func:`identcheck.solve.revolute21.mirror`: the same meridian, ERRATA E2): one of each pair
    is refined and the result mirrored, which halves the work and returns the two as exact mirror images (refined
    separately, runs stopped by the budget in a flat valley ended up to several mm apart).
    """
    local = np.asarray(local, dtype=float)
    R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    scale = float(np.sqrt(np.mean(local**2)))
    seeds = [s for s in revolute21.solve_batch(local).params if np.all(np.isfinite(s))]
    found = []
    floor = np.array([-np.inf, 1e-6 * scale, 1e-6, -np.inf, 1e-6 * scale])     # the starts' r, α, ρ off 0 and π
    ceiling = np.array([np.inf, np.inf, np.pi - 1e-6, np.inf, np.inf])
    units = np.array([scale, scale, 1.0, scale, scale])

    def refine(s, into):
        s = np.clip(canonical(s), floor, ceiling)
        x, r, Jp, jb1, jb2 = _refine(np.r_[s, _nearest_beta(s, R, z)], R, z, max_nfev)
        p = canonical(x[:5])
        rms, unc = float(np.sqrt(np.mean(residuals(p, R, z) ** 2))), _uncertainty(Jp, jb1, jb2, r, scale)
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
    data alone. The short refinements are :func:`_refine`'s (unbounded), brought back to r, ρ ≥ 0 and α in [0, π]
    by :func:`canonical`."""
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
        x, r, _, _, _ = _refine(np.r_[j, _nearest_beta(j, Rs, zs)], Rs, zs, SCATTERED_NFEV)
        cost = float(r @ r) / 2
        if np.all(np.isfinite(x[:5])) and cost < best_cost:
            best, best_cost = x[:5], cost
    return None if best is None else canonical(best)


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


def _uncertainty(Jp, jb1, jb2, r, scale: float) -> float:
    """1-σ of the worst-determined length constant (d, r, l, ρ), mm, from the linearised covariance at the
    point whose residuals `r` and Jacobian pieces (:func:`_odr_parts`) are given; infinite where the constants are
    not determined to :data:`UNDETERMINED_RCOND`, and with no more samples than the five constants (no residual
    left to estimate the noise from). `scale`: the samples' length scale (mm), which puts α's column (mm per
    radian) on the lengths' footing for the test of a column the samples do not move: at α = π/2 with l = 0 the α
    and l columns vanish but for roundoff, which scaling each column to unit norm would have made look whole.

    The per-sample β are eliminated by projecting each sample's two rows of the constants' columns off its β's
    column: the projected 2N × 5 matrix's Gram matrix is the Schur complement :func:`_reduced` gives, but its SVD
    (columns scaled to unit norm) is only as ill-conditioned as the Jacobian itself, where forming and inverting
    the Schur complement squares the condition. In a flat valley (condition 10¹⁵ and more) the inverse had given
    0.7 mm where the Jacobian's SVD gives 10⁶ mm, and moving the point by 10⁻¹⁰ changed it a millionfold.
    """
    N = len(jb1)
    if N <= 5:
        return float("inf")
    norm = np.hypot(jb1, jb2)
    moves = norm > 0
    u1 = np.where(moves, jb1 / np.where(moves, norm, 1.0), 0.0)
    u2 = np.where(moves, jb2 / np.where(moves, norm, 1.0), 0.0)
    along = Jp[:N] * u1[:, None] + Jp[N:] * u2[:, None]           # each sample's rows along its β's column
    projected = np.concatenate([Jp[:N] - u1[:, None] * along, Jp[N:] - u2[:, None] * along])
    if not np.all(np.isfinite(projected)):
        return float("inf")
    column = np.linalg.norm(projected, axis=0)
    unitless = column / np.array([1.0, 1.0, scale, 1.0, 1.0])
    if np.min(unitless) <= UNDETERMINED_RCOND * np.max(unitless):
        return float("inf")
    _, sv, Vt = np.linalg.svd(projected / column, full_matrices=False)
    if sv[-1] <= UNDETERMINED_RCOND * sv[0]:
        return float("inf")
    sigma2 = float(np.sum(r**2)) / (N - 5)     # 2N residuals less N angles and 5 constants (N > 5 above)
    if not np.isfinite(sigma2):
        return float("inf")
    cov = sigma2 * ((Vt.T / sv**2) @ Vt) / np.outer(column, column)
    lengths = cov[np.ix_([0, 1, 3, 4], [0, 1, 3, 4])]
    return float(np.sqrt(max(np.linalg.eigvalsh(lengths)[-1], 0.0)))
