"""How well a whole-chain fit determines the joints: a covariance that holds when the noise is
serially correlated and when the rigid model does not fit exactly.

The per-frame unknowns (root pose, joint angles) are profiled out, so every frame f contributes a
score ``g_f = G_fᵀ r_f − B_fᵀ A_f⁻¹ J_fᵀ r_f`` to the constants (markers on their segments, joint
centres, hinge axes) and an information ``S = Σ_f (G_fᵀG_f − B_fᵀ A_f⁻¹ B_f)`` (the Schur complement of
the Gauss–Newton normal matrix). With white noise of variance σ² per coordinate, ``cov = σ² S⁺``. With
noise correlated from frame to frame (low-pass filtered exports), or with residuals that are not noise at
all (skin motion, a joint that is not quite rigid), ``σ² S⁺`` is too small by the factor the trial's
correlation time gives. The sandwich ``S⁺ H S⁺``, with H the long-run covariance of the scores estimated
with a Bartlett kernel over frames (Newey and West, 1987) and the bandwidth chosen from the scores' own
lag-1 autocorrelation (Andrews, 1991), is right in all three cases, to first order. Both are returned,
so that the report can say how much the correlation and the misfit widened the intervals.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identcheck.bundle.chain import _jacobians, _prepare, tangents, forward

RANK_TOL = 1e-9        # relative eigenvalue of the scaled information below which a direction is undetermined


@dataclass(frozen=True)
class Covariance:
    """The constants' covariance from a fit, three ways, and the noise model behind them.

    Attributes
    ----------
    information : ndarray, shape (P, P)
        Schur complement S (per unit noise variance), mm⁻² in the markers' coordinates.
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
    naive: np.ndarray
    sandwich: np.ndarray
    sigma_mm: float
    lag1: float
    bandwidth: int
    undetermined: int
    null: np.ndarray               # (P, k) unit directions the data leave free (gauge and beyond)

    def free(self, grad: np.ndarray, tol: float = 1e-3) -> bool:
        """Whether a functional with this gradient moves along a direction the data leave free (then its
        standard error, which the pseudo-inverse computes without those directions, means nothing)."""
        if self.null.size == 0 or self.undetermined == 0:      # only the gauge is free: distances do not move
            return False
        n = np.linalg.norm(grad)
        return bool(n > 0 and np.max(np.abs(grad @ self.null)) > tol * n)

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


def gauge_free_inverse(S: np.ndarray, gauge: int | None = None) -> tuple[np.ndarray, int, np.ndarray]:
    """Pseudo-inverse of the information, Jacobi-scaled first so that millimetres and radians compare;
    the number of directions left out beyond ``gauge`` (the data leave those undetermined); and those
    directions, (P, k) unit columns. Directions the data barely determine stay in, with the large
    variances they deserve."""
    d = np.sqrt(np.maximum(np.diag(S), 1e-300))
    w, V = np.linalg.eigh(S / np.outer(d, d))
    keep = w > RANK_TOL * max(w.max(), 1e-300)
    inv = (V[:, keep] / w[keep]) @ V[:, keep].T
    dropped = int((~keep).sum())
    null = V[:, ~keep] / d[:, None]
    null = null / np.maximum(np.linalg.norm(null, axis=0), 1e-300)
    return inv / np.outer(d, d), (max(dropped - gauge, 0) if gauge is not None else dropped), null


def frame_scores(fit, data, weights=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame scores g (F, P), the information S (P, P), and the residuals (F, M, 3) (0 where unseen)."""
    y, w = _prepare(data, weights)
    s = fit.state
    R, t, centre, pred = forward(fit.chain, fit.terms, s)
    J, G = _jacobians(fit.chain, fit.terms, s, R, t, centre, pred)
    F = y.shape[0]
    sw = np.sqrt(w)[..., None, None]
    r = np.where(w[..., None] > 0, pred - y, 0.0)
    rw = (r * np.sqrt(w)[..., None]).reshape(F, -1)
    Jw = (J * sw).reshape(F, -1, J.shape[-1])
    Gw = (G * sw).reshape(F, -1, G.shape[-1])
    Jt = Jw.transpose(0, 2, 1)
    A = Jt @ Jw
    B = Jt @ Gw
    k = A.shape[1]
    scale = np.trace(A, axis1=1, axis2=2)[:, None, None] / k
    ridge = 1e-12 * np.maximum(scale, np.median(scale) + 1e-300)
    sol = np.linalg.solve(A + ridge * np.eye(k), np.concatenate([B, (Jt @ rw[..., None])], axis=2))
    Ainv_B, Ainv_Jr = sol[..., :-1], sol[..., -1]
    g = np.einsum("fmp,fm->fp", Gw, rw) - np.einsum("fkp,fk->fp", B, Ainv_Jr)
    B2 = B.reshape(-1, B.shape[-1])
    G2 = Gw.reshape(-1, Gw.shape[-1])
    S = G2.T @ G2 - B2.T @ Ainv_B.reshape(B2.shape)
    return g, 0.5 * (S + S.T), r


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


def long_run_covariance(scores: np.ndarray, bandwidth: int) -> np.ndarray:
    """Σ over lags |l| ≤ L of (1 − |l|/(L+1)) Σ_f g_f g_{f+l}ᵀ (Bartlett weights: positive semi-definite)."""
    H = scores.T @ scores
    for lag in range(1, bandwidth + 1):
        c = scores[lag:].T @ scores[:-lag]
        H += (1 - lag / (bandwidth + 1)) * (c + c.T)
    return H


def covariance(fit, data, weights=None) -> Covariance:
    """The constants' covariance of `fit` (see the module docstring), with the noise model behind it."""
    g, S, r = frame_scores(fit, data, weights)
    Sinv, undetermined, null = gauge_free_inverse(S, fit.chain.gauge())
    nu = max(3 * fit.n_samples - fit.n_params, 1)
    sigma = float(np.sqrt(fit.rss / nu))
    seen = np.any(r != 0, axis=2)
    lags = [lag1(r[seen[:, m], m, c]) for m in range(r.shape[1]) for c in range(3) if seen[:, m].sum() > 10]
    L = bartlett_bandwidth(g)
    H = long_run_covariance(g, L)
    # H estimates Σ g gᵀ; at a least-squares optimum each frame's own score uses a residual that has
    # lost a share of its variance to the fitted parameters: scale by 3N/(3N − P)
    H *= (3 * fit.n_samples) / nu
    return Covariance(S, sigma ** 2 * Sinv, Sinv @ H @ Sinv, sigma, float(np.median(lags)) if lags else 0.0, L,
                      undetermined, null)


def joint_offsets(chain) -> dict:
    """Column where each joint's constants start (centre in parent, centre in child, then for a hinge the
    rest rotation and the axis' two tangent directions), after the 3M marker coordinates."""
    offsets, c = {}, 3 * chain.n_markers
    for j in chain.joints:
        offsets[j] = c
        c += 6 + (5 if chain.types[j] == "revolute" else 0)
    return offsets


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
