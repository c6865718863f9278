"""How well a whole-chain fit determines the joints: a covariance that holds when the noise is
serially correlated and when the rigid model does not fit exactly.

The per-frame unknowns (root pose, joint angles) are profiled out, so every frame f contributes a
score ``g_f = G_fᵀ r_f − B_fᵀ A_f⁻¹ J_fᵀ r_f`` to the constants (markers on their segments, joint
centres, hinge axes) and an information ``S = Σ_f (G_fᵀG_f − B_fᵀ A_f⁻¹ B_f)`` (the Schur complement of
the Gauss–Newton normal matrix). With white noise of variance σ² per coordinate, ``cov = σ² S⁺``. With
noise correlated from frame to frame (low-pass filtered exports), or with residuals that are not noise at
all (skin motion, a joint that is not quite rigid), ``σ² S⁺`` is too small by the factor the trial's
correlation time gives. The sandwich ``S⁺ H S⁺``, with H the long-run covariance of the scores, is right
in all three cases, to first order. H is estimated with a Bartlett kernel over frames (Newey and West,
1987) after prewhitening the scores by one AR(1) coefficient and recolouring (Andrews and Monahan, 1992),
the bandwidth chosen from the prewhitened scores' lag-1 autocorrelation (Andrews, 1991): without the
prewhitening the kernel's bias under strongly correlated noise (filtered exports, lag-1 up to 0.9) makes
the long-run variance some 15 % too small. Both covariances are returned, so that the report can say how much the
correlation and the misfit widened the intervals.

The scores are uncorrelated with the per-frame unknowns by construction (they are the residuals projected
off those unknowns' columns), so the variance the residuals lose to the per-frame unknowns is not lost by
the scores: only the constants' share is, ``3N / (3N − P_constants)``. Scaling by the whole fit's degrees of
freedom instead had inflated the variances by 3M per frame over 3M minus the frame's unknowns (×1.4 on a
14-marker leg, whose white-noise intervals then covered 98.6 %).

S itself is taken at the estimated per-frame unknowns, and those carry the noise: a segment posed by three close
markers turns by a degree or two from frame to frame in the estimate when it did not in the truth, and that jitter
shows as excitation the motion never had. Along a direction the motion barely excites (a gait hip's ab/adduction
seen through one thigh marker) it overstates the information: measured on the minimal gait leg whose hip a held-out
calibration draw had found confidently wrong, the hip's standard error at the estimate was 2.1 mm where the same
computation at the true poses gives 2.75 mm. The overstatement is removed by simulation and extrapolation (SIMEX;
Cook and Stefanski, 1994): the per-frame unknowns are moved again by draws of their own estimation error (σ² A_f⁻¹,
the determined directions only), the information averaged over :data:`SIMEX_DRAWS` draws is S̄, and
``S_c = 2S − S̄`` is S extrapolated back to error-free poses (2.88 mm on that leg). The covariances gain
``(σ² S_c⁺ − σ² S⁺)``, clipped to widen only (the sandwich's times the correlation inflation); on a leg posed by
three markers a segment the change is well under one per cent, on walking2's gait hips up to 11 %. It does not
remove everything: on that leg the estimates still scattered 1.4 times the standard error at the true poses (the
estimator is not efficient when every frame brings incidental unknowns): :mod:`identcheck.bundle.bootstrap`
measures that spread where this correction is large.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from identcheck.bundle.chain import _prepare, information_at
from identcheck.bundle.gauge import gauge_basis, turning_blocks
from identcheck.bundle.jacobian import jacobian_blocks
from identcheck.bundle.model import apply_step, forward, joint_offsets, n_const, null_count, tangents
from identcheck.bundle.normal import frames_eliminated

RANK_TOL = 1e-9        # relative eigenvalue of the scaled information below which a direction is undetermined
SIMEX_LEFT = 0.01       # least share of a direction's information taken as real (module docstring)
SIMEX_DRAWS = 2        # draws of the per-frame error: one antithetic pair (simex_information)
GAUGE_TOL = 1e-4       # largest entry of the scaled information times a written-out gauge direction: the
#                        Schur complement's roundoff reaches 1e-6 on a 600-frame leg, a wrong direction gives O(1)


@dataclass(frozen=True)
class Covariance:
    """The constants' covariance from a fit, three ways, and the noise model behind them.

    Attributes
    ----------
    information : ndarray, shape (P, P)
        Schur complement S (per unit noise variance), mm⁻² in the markers' coordinates.
    inverse : ndarray, shape (P, P)
        ``S⁺``, the gauge and the undetermined directions left out (:func:`chain_inverse`): the covariance per unit
        noise variance.
    naive : ndarray, shape (P, P)
        ``σ̂² S⁺``: white noise, model exact.
    sandwich : ndarray, shape (P, P)
        ``S⁺ H S⁺``: correlated noise and misfit allowed.
    sigma_mm : float
        Residual standard deviation per coordinate, ``sqrt(RSS / (3N − P))``.
    lag1 : float
        Median lag-1 autocorrelation of the residual coordinates over frames.
    bandwidth : int
        Bartlett kernel bandwidth (frames) of the long-run score covariance.
    undetermined : int
        Directions of S beyond the gauge with (scaled) eigenvalue below :data:`RANK_TOL`.
    """

    information: np.ndarray
    inverse: np.ndarray
    naive: np.ndarray
    sandwich: np.ndarray
    sigma_mm: float
    lag1: float
    bandwidth: int
    undetermined: int
    null: np.ndarray               # (P, k) unit directions the data leave free (gauge and beyond)
    frame_noise: np.ndarray | None = None
    """``S_c⁺ − S⁺`` (P, P) per unit noise variance: the variance the noise in the per-frame unknowns hid (module
    docstring), already inside ``naive`` and ``sandwich``."""

    def frame_noise_ratio(self, grad: np.ndarray) -> float:
        """Variance ratio with and without the per-frame noise correction along a functional's gradient (1: the
        estimated poses showed the joint no motion it did not have)."""
        base = float(grad @ self.inverse @ grad)
        if self.frame_noise is None or base <= 0:
            return 1.0
        return 1.0 + float(grad @ self.frame_noise @ grad) / base

    def scaled(self, factor: float) -> "Covariance":
        """The covariance with both estimates' variances multiplied by ``factor`` (a spread found otherwise)."""
        return replace(self, naive=self.naive * factor, sandwich=self.sandwich * factor)

    def free(self, grad: np.ndarray, tol: float = 1e-3) -> bool:
        """Whether a functional with this gradient moves along a direction the data leave free (then its
        standard error, which the pseudo-inverse computes without those directions, means nothing)."""
        return moves_along_free(grad, self.null, self.undetermined, tol)

    def inflation(self, grad: np.ndarray) -> float:
        """Variance ratio sandwich / naive along a functional's gradient (≥ 0; 1 for white noise)."""
        n = float(grad @ self.naive @ grad)
        return float(grad @ self.sandwich @ grad) / n if n > 0 else 1.0

    def se(self, grad: np.ndarray) -> float:
        """Standard error of a functional with this gradient: the larger of the two variances (the
        sandwich estimates its long-run covariance from the trial itself and can fall below the
        white-noise one by chance; a smaller one would not be honest)."""
        v = max(float(grad @ self.sandwich @ grad), float(grad @ self.naive @ grad), 0.0)
        return float(np.sqrt(v))


def moves_along_free(grad: np.ndarray, null: np.ndarray, undetermined: int, tol: float = 1e-3) -> bool:
    """Whether a functional with this gradient moves along one of the directions ``null`` the information leaves
    free (:func:`gauge_free_inverse`); never when only the gauge is free (``undetermined`` 0: distances do not
    move along it)."""
    if null.size == 0 or undetermined == 0:
        return False
    n = np.linalg.norm(grad)
    return bool(n > 0 and np.max(np.abs(grad @ null)) > tol * n)


def gauge_free_inverse(S: np.ndarray, gauge: int | None = None, basis: np.ndarray | None = None,
                       blocks: list | None = None) -> tuple[np.ndarray, int, np.ndarray]:
    """Pseudo-inverse of the information, scaled first so that millimetres and radians compare (by
    :func:`block_scaled` over ``blocks``, column by column without them); the number of directions left out
    beyond ``gauge`` (the data leave those undetermined); and those directions, (P, k) unit columns. Directions the
    data barely determine stay in, with the large variances they deserve.

    With ``basis`` (P, g), the gauge written out (:func:`identcheck.bundle.gauge.gauge_basis`), those directions
    are left out exactly and the eigenvalue cutoff judges only the rest (see that module for why); a basis the
    information does not annihilate (to :data:`GAUGE_TOL` of its scaled diagonal) is not a gauge, and the cutoff
    alone decides as without one. With ``blocks``, the groups of columns a change of body frames turns together
    (:func:`identcheck.bundle.gauge.turning_blocks`), the cutoff reads the same in every choice of frames."""
    scaled, d = block_scaled(S, blocks) if blocks is not None else jacobi_scaled(S)
    N = np.zeros((len(S), 0))
    if basis is not None and basis.shape[1]:
        written = np.linalg.qr(basis * d[:, None])[0]
        N = written if np.max(np.abs(scaled @ written)) <= GAUGE_TOL else N
    if N.shape[1]:
        rest = np.linalg.svd(N, full_matrices=True)[0][:, N.shape[1]:]      # orthonormal complement of the gauge
        w, V = np.linalg.eigh(rest.T @ scaled @ rest)
        U = rest @ V
    else:
        w, U = np.linalg.eigh(scaled)
    keep = determined_directions(w)
    inv = (U[:, keep] / w[keep]) @ U[:, keep].T
    dropped = int((~keep).sum())
    null = np.column_stack([N, U[:, ~keep]]) / d[:, None]
    null = null / np.maximum(np.linalg.norm(null, axis=0), 1e-300)
    if N.shape[1] or gauge is None:
        return inv / np.outer(d, d), dropped, null
    return inv / np.outer(d, d), max(dropped - gauge, 0), null


def chain_inverse(chain, state, S: np.ndarray, terms=None) -> tuple[np.ndarray, int, np.ndarray]:
    """:func:`gauge_free_inverse` of a chain's information ``S`` at ``state``, its gauge written out
    (:func:`identcheck.bundle.gauge.gauge_basis`; ``terms``: the fit's effect terms) and scaled by the blocks its
    frames turn (:func:`identcheck.bundle.gauge.turning_blocks`)."""
    return gauge_free_inverse(S, null_count(chain, terms), gauge_basis(chain, state, len(S), terms),
                              turning_blocks(chain, terms))


def block_scaled(S: np.ndarray, blocks: list) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric matrix S (P, P) scaled as :func:`jacobi_scaled` scales it, but with one scale per block of
    columns (`blocks`, index arrays covering every column once): the square root of the mean of the block's diagonal.
    With one column a block this is Jacobi scaling. Turning a block's coordinates (a segment's frame,
    :func:`identcheck.bundle.gauge.turning_blocks`) turns the scaled matrix by the same rotation, so its eigenvalues
    do not change; Jacobi scaling's do.

    Why one scale a block, not the inverse square root of the whole 3 × 3 block (also the same in every frame): a
    block can hold a direction with no information of its own (a one-marker shank's spin about its knee-marker
    line; a hinge's rest offset about its axis), whose only information is the per-frame ridge's (1e-12). Whitening
    the block lifts it (to 1e-5 of the largest eigenvalue with a floor at 1e-6 of the block), and the written-out
    gauge then failed its check (:data:`GAUGE_TOL`) in some frames, the knee of the one-marker leg reading free in
    one and determined in another; one scale leaves it where the information puts it."""
    d = np.empty(len(S))
    times = np.zeros(len(S), dtype=int)
    diag = np.maximum(np.einsum("ii->i", S), 0.0)
    for cols in blocks:
        d[cols] = np.sqrt(max(float(diag[cols].mean()), 1e-300))
        times[cols] += 1
    if not np.all(times == 1):
        raise ValueError(f"the blocks cover {int(np.sum(times == 1))} of the information's {len(S)} columns once "
                         f"(columns {np.flatnonzero(times != 1)[:5].tolist()} are not)")
    return S / (d[:, None] * d[None, :]), d


def jacobi_scaled(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric matrices M (..., k, k) scaled to unit diagonal, so that millimetres and radians compare, and the
    scale d (..., k): ``M / (d dᵀ)`` (a zero diagonal entry leaves its row and column 0)."""
    d = np.sqrt(np.maximum(np.einsum("...ii->...i", M), 1e-300))
    return M / (d[..., :, None] * d[..., None, :]), d


def determined_directions(w: np.ndarray) -> np.ndarray:
    """Which eigenvalues w (..., k) of a Jacobi-scaled information count as determined: above :data:`RANK_TOL`
    of the largest (of each matrix)."""
    return w > RANK_TOL * np.maximum(w.max(axis=-1, keepdims=True), 1e-300)


def frame_scores(fit, data, weights=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, np.ndarray, np.ndarray]:
    """Per-frame scores g (F, P), the information S (P, P), the residuals (F, M, 3) (0 where unseen), how many
    per-frame unknowns the samples determine (:func:`frame_rank`), the per-frame blocks A (F, k, k) and the weights
    (F, M) the samples got."""
    y, w = _prepare(data, weights)
    s = fit.state
    R, t, centre, pred = forward(fit.chain, fit.terms, s)
    lay, blocks = jacobian_blocks(fit.chain, fit.terms, s, R, centre, pred)
    r = np.where(w[..., None] > 0, pred - y, 0.0)
    S, g, A = frames_eliminated(lay, blocks, w, r, per_frame=True)
    return g, S, r, frame_rank(A), A, w


def simex_information(fit, A: np.ndarray, w: np.ndarray, sigma: float, draws: int = SIMEX_DRAWS,
                      seed: int = 0) -> np.ndarray:
    """S̄: the information averaged over `draws` copies of the fit's state whose per-frame unknowns are moved by
    draws of their estimation error, ``σ² A_f⁻¹`` over the directions the frame's samples determine (see the
    module docstring). The draws come in antithetic pairs (δ and −δ): the part of S that is linear in the move,
    zero on average but the largest part of any one draw, cancels exactly, and what is left is the second-order
    part SIMEX wants (an odd count ends with one unpaired draw). Seeded: the same fit always gets the same S̄."""
    chain, terms, s = fit.chain, fit.terms, fit.state
    scaled, d = jacobi_scaled(A)
    wv, V = np.linalg.eigh(scaled)
    keep = determined_directions(wv)
    R = forward(chain, terms, s)[0]
    rng = np.random.default_rng(seed)
    P = n_const(chain, terms)
    total, dq = None, None
    for k in range(draws):
        if k % 2 == 0:
            z = np.where(keep, rng.standard_normal(wv.shape) / np.sqrt(np.maximum(wv, 1e-300)), 0.0)
            dq = sigma * np.einsum("fij,fj->fi", V, z) / d
        else:
            dq = -dq
        S = information_at(chain, terms, apply_step(chain, terms, s, R, dq, np.zeros(P)), w)
        total = S if total is None else total + S
    return total / draws


def widening(S: np.ndarray, S_bar: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    """``S_c⁺ − S⁺`` (per unit noise variance) with ``S_c = 2S − S̄`` (module docstring), within the directions S
    determines and widening only: with ``S⁺ = LᵀL`` and ``T = L (S̄ − S) Lᵀ`` (the share of the information that the
    noise in the per-frame unknowns made up, direction by direction), ``Lᵀ [(I − T)⁻¹ − I] L``, T's eigenvalues
    clipped to [0, 1 − :data:`SIMEX_LEFT`]: a direction whose information was nearly all made up by noise keeps at
    least that share of it (its standard error grows at most tenfold, which the practical verdict reads as
    undetermined), and a direction S̄ happens to see less of is not narrowed."""
    scaled, e = jacobi_scaled(inverse)
    vals, V = np.linalg.eigh(scaled)
    L = ((V * np.sqrt(np.maximum(vals, 0.0))) @ V.T) * e[None, :]         # LᵀL = S⁺
    T = L @ (S_bar - S) @ L.T
    t, U = np.linalg.eigh((T + T.T) / 2)
    t = np.clip(t, 0.0, 1.0 - SIMEX_LEFT)
    M = (U * (t / (1.0 - t))) @ U.T
    return L.T @ M @ L


def frame_rank(A: np.ndarray) -> int:
    """The per-frame unknowns the samples determine: the summed numerical ranks of the frames' blocks A (F, k, k),
    each Jacobi-scaled (a column without samples counts as undetermined), to :data:`RANK_TOL`.

    Every unknown of a frame with any sample had counted, also those no sample sees: a segment's roll when the
    markers that see it are weighted out (the hip refitted without the markers below a one-marker thigh, in
    :mod:`identcheck.fit.whole_tree`), or the pose of a segment hidden in that frame. Each such unknown took a
    degree of freedom from the residual that it never used, and σ̂² came out too large by up to the ratio of
    the two counts: twice, for that hip (σ̂ 0.47 mm against 0.33 simulated, intervals 1.4 times too wide)."""
    return int(np.sum(determined_directions(np.linalg.eigvalsh(jacobi_scaled(A)[0]))))


def lag1(x: np.ndarray) -> float:
    """Lag-1 autocorrelation of a series (F,) (0 when it does not vary)."""
    x = x - x.mean()
    den = float(x @ x)
    return float(x[1:] @ x[:-1]) / den if den > 0 else 0.0


def bartlett_bandwidth(scores: np.ndarray) -> int:
    """Andrews' (1991) AR(1) plug-in bandwidth for the Bartlett kernel, from the scores' lag-1
    autocorrelations weighted by their variances; at most a third of the frames."""
    F = scores.shape[0]
    var = scores.var(axis=0)
    use = var > 1e-12 * max(var.max(), 1e-300)
    if not use.any() or F < 4:
        return 0
    rho = np.clip([lag1(scores[:, p]) for p in np.flatnonzero(use)], -0.97, 0.97)
    v = var[use]
    num = np.sum(v ** 2 * 4 * rho ** 2 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    den = np.sum(v ** 2 / (1 - rho) ** 4)
    alpha = num / den if den > 0 else 0.0
    return int(min(np.ceil(1.1447 * (alpha * F) ** (1 / 3)), F // 3))


PREWHITEN_CAP = 0.97   # largest |AR(1) coefficient| used to prewhiten the scores (Andrews-Monahan)


def prewhitened_long_run(scores: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Long-run covariance Σ_l Σ_f g_f g_{f+l}ᵀ of the scores (F, P): prewhitened by one AR(1) coefficient ρ
    common to every component (the median of their lag-1 autocorrelations, corrected for the estimator's
O(1/F) bias, which the recolouring would multiply by 2/(1 − ρ), and capped at ±:data:`PREWHITEN_CAP`),
    the Bartlett estimate taken of what is left, and recoloured by ``1 / (1 − ρ)²``. Returns (H, bandwidth, ρ).

    One coefficient, not one per component: a scalar filter commutes with every linear combination of the
    scores, so the directions the data barely determine (where S⁺ amplifies any error in H) keep their
    cancellations; per-component filters had tripled the white-noise variance of a 300-frame ankle."""
    F, P = scores.shape
    if F < 4:
        return scores.T @ scores, 0, 0.0
    var = scores.var(axis=0)
    use = var > 1e-12 * max(float(var.max()), 1e-300)
    if not use.any():
        return scores.T @ scores, 0, 0.0
    rho = float(np.median([lag1(scores[:, p]) for p in np.flatnonzero(use)]))
    rho = float(np.clip(rho + (1 + 3 * rho) / F, -PREWHITEN_CAP, PREWHITEN_CAP))   # Kendall's (1954) bias
    e = scores[1:] - rho * scores[:-1]
    L = bartlett_bandwidth(e)
    return long_run_covariance(e, L) * (F / (F - 1)) / (1.0 - rho) ** 2, L, rho


def long_run_covariance(scores: np.ndarray, bandwidth: int) -> np.ndarray:
    """Σ over lags |l| ≤ L of (1 − |l|/(L+1)) Σ_f g_f g_{f+l}ᵀ (Bartlett weights: positive semi-definite)."""
    H = scores.T @ scores
    for lag in range(1, bandwidth + 1):
        c = scores[lag:].T @ scores[:-lag]
        H += (1 - lag / (bandwidth + 1)) * (c + c.T)
    return H


def covariance(fit, data, weights=None) -> Covariance:
    """The constants' covariance of `fit` (see the module docstring), with the noise model behind it."""
    g, S, r, determined, A, w = frame_scores(fit, data, weights)
    Sinv, undetermined, null = chain_inverse(fit.chain, fit.state, S, fit.terms)
    # residual degrees of freedom: samples less the unknowns they determine, per frame and constant (rank of S)
    nu = max(3 * fit.n_samples - determined - (len(S) - null.shape[1]), 1)
    sigma = float(np.sqrt(fit.rss / nu))
    seen = np.any(r != 0, axis=2)
    lags = [lag1(r[seen[:, m], m, c]) for m in range(r.shape[1]) for c in range(3) if seen[:, m].sum() > 10]
    # the frames with no sample left out, not read as zero scores: zeros between the seen frames had made the
    # scores look white (their lag-1 products vanish), so the prewhitening's recolouring fell from 1/(1 - ρ)² to
    # about 1 and the intervals of a real walking knee shrank 6-12-fold as frames were blanked (24.4 mm with every
    # frame, 2.0 with every other one); the seen frames taken in their order keep the noise's correlation
    H, L, _ = prewhitened_long_run(g[(w > 0).any(axis=1)])
    # at the optimum the scores have lost the constants' share of their variance (not the per-frame
    # unknowns': the scores are projected off those already, see the module docstring)
    constants = max(len(S) - null.shape[1], 1) if null.size else len(S)
    H *= (3 * fit.n_samples) / max(3 * fit.n_samples - constants, 1)
    naive, sandwich = sigma ** 2 * Sinv, Sinv @ H @ Sinv
    hidden = widening(S, simex_information(fit, A, w, sigma), Sinv)
    # the sandwich's share: the correlation inflation overall (traces, which the markers' millimetres dominate),
    # never below the white-noise share
    tau = float(np.trace(sandwich) / np.trace(naive)) if np.trace(naive) > 0 else 1.0
    return Covariance(S, Sinv, naive + sigma ** 2 * hidden, sandwich + max(tau, 1.0) * sigma ** 2 * hidden, sigma,
                      float(np.median(lags)) if lags else 0.0, L, undetermined, null, hidden)


def distance_gradients(chain, state, n_params: int) -> dict:
    """Each joint's adjacent markers' distances to its centre (ball) or hinge axis, mm, with the gradient of
    each distance with respect to the constants: {joint: {marker: (distance, gradient (P,))}}."""
    offsets = joint_offsets(chain)
    out = {}
    for j in chain.joints:
        out[j] = {}
        for side, seg in ((0, chain.parent[j]), (1, chain.child[j])):
            centre = state.c_parent[j] if side == 0 else state.c_child[j]
            axis = None
            if chain.types[j] == "revolute":
                axis = state.axis[j] if side == 0 else state.rest[j].T @ state.axis[j]
            for col in chain.seg_markers[seg]:
                v = state.local[col] - centre
                if axis is not None:
                    v = v - (v @ axis) * axis
                d = float(np.linalg.norm(v))
                u = v / max(d, 1e-12)
                grad = np.zeros(n_params)
                grad[3 * col:3 * col + 3] = u
                grad[offsets[j] + 3 * side: offsets[j] + 3 * side + 3] = -u
                if axis is not None:            # the axis direction moves the distance too: ∂d = −(v·a) u·∂a
                    along = float((state.local[col] - centre) @ axis)
                    a, o = state.axis[j], offsets[j] + 6
                    turn = np.eye(3) if side == 0 else state.rest[j].T
                    for k, b in enumerate(tangents(a)):
                        grad[o + 3 + k] = -along * float(u @ (turn @ b))
                    if side == 1:               # the rest rotation turns the child's view of the axis
                        for k in range(3):
                            grad[o + k] = -along * float(u @ (turn @ np.cross(a, np.eye(3)[k])))
                out[j][chain.labels[col]] = (d, grad)
    return out
