"""Revolute joint from two parent markers and one child marker (Pham et al., section III-A).

Input: samples of the child marker B in the frame F of the parent's markers (A1 at the
origin, A2 on +z; see :func:`identcheck.solve.frames.pair_frame`). Output: *every* joint the
samples admit. The linear system M·Z = K (eq. 10) is solved, the cubic (13) gives three roots,
each root and each sign of cos α (the mirror image) is back-substituted, and each candidate is
kept only if it reproduces every sample (per-sample θ, β constructed and the sample rebuilt).
The derivation proves that generic data leave two joint-parameter sets (four joints with
mirror images); see derivations/ERRATA.md, E1 and E2.

Every formula comes from :mod:`identcheck.derive.revolute` through :mod:`identcheck.codegen`.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import mpmath
import numpy as np

from .. import codegen, derive
from ..errors import DegenerateError, IdentifiabilityWarning, InputError
from ..symbols import Q, Z, case, cos_sign
from .linalg import cubic_roots, lstsq_stacked, solve_stacked

CASE = case("revolute", 2, 1)
PARAMS = ("d", "r", "alpha", "l", "rho")
N_UNKNOWNS = 5
SLOTS = 6  # 3 roots of (13) × 2 signs of cos α
CHUNK = 16384


@lru_cache(maxsize=None)
def generated(backend: str = "numpy") -> dict:
    """The numeric functions of this case, generated from the derivation (cached)."""
    dv = derive.for_case(CASE)
    sample = CASE.sample
    inv = dv.result("invariants")
    par = CASE.parameter_symbols  # (d, r, l, rho, c_alpha, s_alpha)
    vars_ = [s for a in CASE.variables for s in (a.cos, a.sin)]  # (c_theta, s_theta, c_beta, s_beta)
    back = dv.result("back")
    h, dist2 = dv.result("axis_distance2")
    f = lambda exprs, groups, name: codegen.numeric(exprs, groups, backend, name)  # noqa: E731
    return {
        "m_row": f([e.subs(inv) for e in dv.result("M")] + [dv.result("K").subs(inv)], [sample], "m_row"),
        "cubic": f(dv.result("cubic").all_coeffs(), [Z], "cubic"),
        "back": f([back[k] for k in ("r2", "sin2_alpha", "l", "rho2", "l_if_cos0", "rho2_if_cos0")],
                  [(Q,), Z, (cos_sign,)], "back"),
        "theta": f(dv.result("theta_cs"), [sample, par], "theta"),
        "local": f(list(dv.result("local")), [sample, par, vars_[:2]], "local"),
        "forward": f(list(dv.result("forward")), [par, vars_], "forward"),
        "dist2": f([dist2], [(h,), par], "dist2"),
    }


@dataclass
class Joint21:
    """One joint that reproduces the samples: DH constants and per-sample angles.

    Lengths are in the units of the input (mm for trials). ``alpha`` lies in (0, π); a
    joint and its mirror image have supplementary ``alpha`` and opposite ``l``.
    """

    d: float
    r: float
    alpha: float
    l: float
    rho: float
    theta: np.ndarray
    beta: np.ndarray
    residual: float
    root: int
    mirror: bool

    def as_tuple(self) -> tuple:
        return (self.d, self.r, self.alpha, self.l, self.rho)

    def marker_distances(self, h: float) -> dict:
        """Distances of A1 (origin), A2 (at height ``h`` on z) and B to the hinge axis."""
        g = generated("numpy")["dist2"]
        a = float(self.alpha)
        par = np.array([float(self.d), float(self.r), float(self.l), float(self.rho), np.cos(a), np.sin(a)])
        a1, a2 = (float(np.sqrt(g(np.array([hh]), par)[0])) for hh in (0.0, h))
        return {"A1": a1, "A2": a2, "B": float(self.rho)}  # float64 view, also for mpmath joints


@dataclass
class Identification:
    """Every joint the samples admit, with how well the linear system was posed."""

    joints: list
    Z: list
    pivot_ratio: float
    precision: int | None
    n_parameter_sets: int = field(init=False)

    def __post_init__(self):
        self.n_parameter_sets = len({j.root for j in self.joints})

    @property
    def unique(self) -> bool:
        """True only if a single joint (mirror images counted) survives."""
        return len(self.joints) == 1


@dataclass
class BatchResult:
    """Stacked results: ``params`` shape (..., 6, 5) in slot order root-major, sign-minor.

    ``valid`` shape (..., 6) marks slots that are real joints reproducing every sample;
    ``theta``/``beta`` shape (..., 6, N); ``residual`` shape (..., 6); ``pivot_ratio`` shape (...).
    """

    params: np.ndarray
    valid: np.ndarray
    residual: np.ndarray
    theta: np.ndarray | None
    beta: np.ndarray | None
    Z: np.ndarray
    pivot_ratio: np.ndarray


def _check_samples(xyz, n_min=N_UNKNOWNS):
    xyz = np.asarray(xyz, dtype=float)
    if xyz.ndim < 2 or xyz.shape[-1] != 3:
        raise InputError(f"samples must have shape (..., n_samples, 3), got {xyz.shape}")
    if xyz.shape[-2] < n_min:
        raise InputError(f"revolute (2,1) needs at least {n_min} samples per problem, got {xyz.shape[-2]}")
    return xyz


def solve_batch(xyz, *, angles=True, rel_tol=1e-6) -> BatchResult:
    """Identify many problems at once (NumPy float64).

    Parameters
    ----------
    xyz : array, shape (..., n_samples, 3)
        Child-marker samples in the parent's marker frame F; n_samples >= 5 (least squares
        beyond 5).
    angles : bool
        Also construct per-sample θ, β and check that each candidate rebuilds every sample.
        Without it, ``valid`` only says that the constants are real.
    rel_tol : float
        Tolerance relative to the sample scale for reality and reproduction checks.
    """
    xyz = _check_samples(xyz)
    lead, N = xyz.shape[:-2], xyz.shape[-2]
    flat = xyz.reshape(-1, N, 3)
    outs = [_solve_chunk(flat[i:i + CHUNK], angles, rel_tol) for i in range(0, len(flat), CHUNK)]
    cat = {k: (np.concatenate([o[k] for o in outs]) if outs[0][k] is not None else None) for k in outs[0]}
    shape = lambda a, tail: None if a is None else a.reshape(lead + tail)  # noqa: E731
    return BatchResult(
        params=shape(cat["params"], (SLOTS, 5)), valid=shape(cat["valid"], (SLOTS,)),
        residual=shape(cat["residual"], (SLOTS,)), theta=shape(cat["theta"], (SLOTS, N)),
        beta=shape(cat["beta"], (SLOTS, N)), Z=shape(cat["Z"], (N_UNKNOWNS,)),
        pivot_ratio=cat["pivot_ratio"].reshape(lead))


def _solve_chunk(xyz, angles, rel_tol):
    g = generated("numpy")
    n, N, _ = xyz.shape
    scale = np.sqrt(np.mean(np.sum(xyz**2, axis=-1), axis=-1))  # per problem, to work in O(1) units
    scale = np.where(scale > 0, scale, 1.0)
    xs = xyz / scale[:, None, None]
    MK = g["m_row"](xs)
    M, K = MK[..., :N_UNKNOWNS], MK[..., N_UNKNOWNS]
    Zs, ratio = solve_stacked(M.copy(), K) if N == N_UNKNOWNS else lstsq_stacked(M, K)
    re, im = cubic_roots(g["cubic"](Zs))                                    # (n, 3)
    # a double root (the twin joint meets the true one, e.g. l = 0 and r = rho) splits into a
    # complex pair of size ~sqrt(eps): accept near-real roots and let the reproduction check decide
    real = np.abs(im) <= 1e-5 * (1 + np.abs(re))
    # back-substitute each root once with cos α > 0; the mirror (cos α < 0) has l -> -l
    bk = g["back"](re[..., None], Zs[:, None, :], np.ones((n, 3, 1)))       # (n, 3, 6)
    r2, S, l, rho2, l0, rho20 = (np.repeat(v, 2, axis=1) for v in np.moveaxis(bk, -1, 0))
    sig = np.tile([1.0, -1.0], 3)[None, :, None] * np.ones((n, 1, 1))
    cos0 = np.abs(1 - S) < 1e-9
    l = np.where(cos0, l0, l) * sig[..., 0]
    rho2 = np.where(cos0, rho20, rho2)
    tol = 1e-9
    ok = np.repeat(real, 2, axis=1) & (r2 > tol) & (S > tol) & (S <= 1 + 1e-9) & (rho2 > -1e-9)
    ok &= np.isfinite(l)
    with np.errstate(invalid="ignore"):
        S_ = np.clip(S, 0, 1)
        ca = sig[..., 0] * np.sqrt(1 - S_)
        sa = np.sqrt(S_)
        r, rho = np.sqrt(np.maximum(r2, 0)), np.sqrt(np.maximum(rho2, 0))
    d = np.broadcast_to(Zs[:, :1], r.shape)
    par = np.stack([d, r, l, rho, ca, sa], axis=-1)                        # (n, 6, 6), codegen order
    params = np.stack([d, r, np.arctan2(sa, ca), l, rho], axis=-1)
    params[..., [0, 1, 3, 4]] *= scale[:, None, None]
    theta = beta = None
    residual = np.full(ok.shape, np.nan)
    if angles:
        P = par[:, :, None, :]
        X = xs[:, None, :, :]
        cs = g["theta"](X, P)                                              # (n, 6, N, 2)
        norm = np.hypot(cs[..., 0], cs[..., 1])
        cs = cs / norm[..., None]
        loc = g["local"](X, P, cs)                                         # (n, 6, N, 3)
        b = np.arctan2(loc[..., 1], loc[..., 0])
        rebuilt = g["forward"](P, np.concatenate([cs, np.stack([np.cos(b), np.sin(b)], -1)], -1))
        residual = np.max(np.linalg.norm(rebuilt - X, axis=-1), axis=-1)  # (n, 6), scaled units
        ok &= np.nan_to_num(residual, nan=np.inf) <= rel_tol
        residual = residual * scale[:, None]
        theta, beta = np.arctan2(cs[..., 1], cs[..., 0]), b
    return {"params": params, "valid": ok, "residual": residual, "theta": theta, "beta": beta,
            "Z": Zs, "pivot_ratio": ratio}


def _degeneracy(xyz: np.ndarray) -> None:
    """Raise a specific DegenerateError for samples that cannot identify the joint."""
    N = len(xyz)
    scale = float(np.sqrt(np.mean(np.sum(xyz**2, axis=-1))))
    if not np.all(np.isfinite(xyz)):
        bad = sorted(set(np.argwhere(~np.isfinite(xyz))[:, 0].tolist()))
        raise DegenerateError(f"samples {bad} are not finite (NaN or inf): drop occluded frames first")
    if scale == 0:
        raise DegenerateError("all samples are at the origin (B coincides with A1)")
    for i in range(N):
        for j in range(i + 1, N):
            if np.linalg.norm(xyz[i] - xyz[j]) <= 1e-9 * scale:
                raise DegenerateError(f"samples {i} and {j} coincide: they give the same equation (det M = 0)")
    on_axis = np.hypot(xyz[:, 0], xyz[:, 1]) <= 1e-9 * scale
    if on_axis.any():
        raise DegenerateError(f"samples {np.flatnonzero(on_axis).tolist()} lie on the A1A2 line: "
                              "the roll θ is undefined there")


def identify(xyz, precision: int | None = None, *, cond_limit: float = 1e10, rel_tol: float = 1e-6) -> Identification:
    """Every joint that reproduces the samples, verified sample by sample.

    Parameters
    ----------
    xyz : array_like, shape (n_samples, 3)
        Child-marker samples in the parent's marker frame F (n_samples >= 5). With
        ``precision``, entries may be mpmath numbers or strings to keep every digit.
    precision : int, optional
        None: float64 (generated NumPy code). An integer: that many decimal digits (generated
        mpmath code); candidates must then rebuild every sample to about 10^-(precision-10).
    rel_tol : float
        float64 only: a candidate must rebuild every sample to ``rel_tol`` × the sample scale;
        ``numpy.inf`` keeps every real candidate (noisy data) and reports its residual.

    Raises
    ------
    DegenerateError
        Coincident samples, samples on the A1A2 line, det M ≈ 0 (e.g. α = 0: a hinge parallel
        to A1A2 keeps B in a plane), or no real joint at all.
    """
    if precision is not None:
        return _identify_mp(xyz, int(precision), None if rel_tol == 1e-6 else rel_tol)
    xyz = _check_samples(xyz)
    if xyz.ndim != 2:
        raise InputError("identify() takes one problem of shape (n_samples, 3); use solve_batch for many")
    _degeneracy(xyz)
    scale = float(np.sqrt(np.mean(np.sum(xyz**2, axis=-1))))
    M = generated("numpy")["m_row"](xyz / scale)[:, :N_UNKNOWNS]
    cond = float(np.linalg.cond(M / np.abs(M).max(axis=0)))
    if not np.isfinite(cond) or cond > cond_limit:
        raise DegenerateError(
            f"det M ≈ 0 (condition number {cond:.3g}): the samples do not determine the 5 unknowns; "
            "they lie on a special surface (e.g. the hinge is parallel to A1A2, α = 0, so B stays in a "
            "plane, or the joint axis meets the A1A2 line, r = 0). Add samples with more varied motion.")
    if cond > 1e6:
        warnings.warn(f"M is ill-conditioned (condition number {cond:.3g}): noise will be amplified",
                      IdentifiabilityWarning, stacklevel=2)
    res = solve_batch(xyz, angles=True, rel_tol=rel_tol)
    joints = [Joint21(*map(float, res.params[k]), theta=res.theta[k], beta=res.beta[k],
                      residual=float(res.residual[k]), root=k // 2, mirror=bool(k % 2))
              for k in range(SLOTS) if res.valid[k]]
    if not joints:
        raise DegenerateError("no real joint reproduces these samples: they are not exact samples of a revolute "
                              "joint with (2,1) markers. With measurement noise the closed-form solution is "
                              "unreliable (Pham et al. V-A); statistical fitting is `identcheck fit`. Otherwise "
                              "check the joint type and the marker assignment.")
    return Identification(_relabel(joints), [float(v) for v in res.Z], float(res.pivot_ratio), None)


def _relabel(joints):
    """Number the surviving parameter sets 0, 1, ... (best residual first)."""
    joints = sorted(joints, key=lambda j: (j.root, j.mirror))
    order = {root: i for i, root in enumerate(dict.fromkeys(j.root for j in sorted(joints, key=lambda j: j.residual)))}
    for j in joints:
        j.root = order[j.root]
    return sorted(joints, key=lambda j: (j.root, j.mirror))


def _identify_mp(xyz, precision: int, rel_tol=None) -> Identification:
    g = generated("mpmath")
    mp = mpmath.mp
    with mpmath.workdps(precision + 15):
        pts = [[mpmath.mpf(v) for v in row] for row in xyz]
        if len(pts) < N_UNKNOWNS:
            raise InputError(f"revolute (2,1) needs at least {N_UNKNOWNS} samples, got {len(pts)}")
        _degeneracy(np.array([[float(v) for v in p] for p in pts]))
        scale = mpmath.sqrt(mpmath.fsum(v * v for p in pts for v in p) / len(pts))
        rows = [g["m_row"](p) for p in pts]
        M = mpmath.matrix([row[:N_UNKNOWNS] for row in rows])
        K = mpmath.matrix([row[N_UNKNOWNS] for row in rows])
        try:
            Zs = mpmath.lu_solve(M, K) if len(pts) == N_UNKNOWNS else mpmath.qr_solve(M, K)[0]
        except ZeroDivisionError:
            raise DegenerateError("det M = 0: the samples do not determine the 5 unknowns") from None
        Zs = [Zs[i] for i in range(N_UNKNOWNS)]
        coeffs = g["cubic"](Zs)
        roots = mpmath.polyroots(coeffs, maxsteps=400, extraprec=4 * mp.prec)
        eps = mpmath.mpf(10) ** (-(precision - 8))
        joints = []
        for k, Qk in enumerate(roots):
            if abs(mpmath.im(Qk)) > eps * (1 + abs(Qk)):
                continue
            Qk = mpmath.re(Qk)
            for sgn in (1, -1):
                try:
                    vals = g["back"]([Qk], Zs, [mpmath.mpf(sgn)]) if abs(1 - g["back"]([Qk], Zs, [1])[1]) > eps else \
                        _cos0(g, Qk, Zs, sgn)
                except ZeroDivisionError:
                    continue
                if any(isinstance(v, mpmath.mpc) and abs(mpmath.im(v)) > eps * (1 + abs(v)) for v in vals):
                    continue  # a complex constant: no real joint for this root and sign
                r2, S, l, rho2, l0, rho20 = (mpmath.re(v) for v in vals)
                if not (r2 > eps and eps < S <= 1 + eps and rho2 > -eps) or not mpmath.isfinite(l):
                    continue
                S = min(S, mpmath.mpf(1))
                ca, sa = sgn * mpmath.sqrt(1 - S), mpmath.sqrt(S)
                par = [Zs[0], mpmath.sqrt(r2), l, mpmath.sqrt(max(rho2, 0)), ca, sa]
                th, be, worst = [], [], mpmath.mpf(0)
                for p in pts:
                    c, s = g["theta"](p, par)
                    nrm = mpmath.sqrt(c * c + s * s)
                    c, s = c / nrm, s / nrm
                    loc = g["local"](p, par, [c, s])
                    b = mpmath.atan2(loc[1], loc[0])
                    rebuilt = g["forward"](par, [c, s, mpmath.cos(b), mpmath.sin(b)])
                    worst = max(worst, mpmath.sqrt(mpmath.fsum((u - v) ** 2 for u, v in zip(rebuilt, p))))
                    th.append(mpmath.atan2(s, c))
                    be.append(b)
                if worst > (eps if rel_tol is None else max(eps, mpmath.mpf(rel_tol))) * scale:
                    continue
                joints.append(Joint21(par[0], par[1], mpmath.atan2(sa, ca), par[2], par[3],
                                      theta=np.array(th, dtype=object), beta=np.array(be, dtype=object),
                                      residual=worst, root=k, mirror=sgn < 0))
        if not joints:
            raise DegenerateError("no real joint reproduces these samples at the requested precision")
        return Identification(_relabel(joints), Zs, float("nan"), precision)


def _cos0(g, Qk, Zs, sgn):
    """Back-substitution when cos α = 0 (then l = ±sqrt(v))."""
    r2, S, _l, _rho2, l0, rho20 = g["back"]([Qk], Zs, [mpmath.mpf(sgn)])
    return r2, S, l0, rho20, l0, rho20
