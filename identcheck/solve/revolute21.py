"""Revolute joint from two parent markers and one child marker (Pham et al., section III-A).

Input: samples of the child marker B in the frame F of the parent's markers (A1 at the
origin, A2 on +z; see :func:`identcheck.geometry.frames.pair_frame`). Output: *every* joint the
samples admit. The linear system M·Z = K (eq. 10) is solved, the cubic (13) gives three roots,
each root and each sign of cos α (the mirror image) is back-substituted, and each candidate is
kept only if it reproduces every sample (per-sample θ, β constructed and the sample rebuilt).
cos α and l come from the derivation's w = cos α·u and v = u², u = l + d cos α, by whichever
square root is well-conditioned (:func:`cos_and_l`), so the truth survives cos α → 0.
The derivation proves that generic data leave two joint-parameter sets (four joints with
mirror images); see derivations/ERRATA.md, E1 and E2.

Every formula comes from :mod:`identcheck.derive.revolute` through :mod:`identcheck.codegen`, printed once
into :mod:`identcheck.solve.generated` (:func:`identcheck.solve.formulas.revolute21` names them).
"""
from __future__ import annotations

import warnings
from functools import lru_cache
from dataclasses import dataclass, field
from types import SimpleNamespace

import mpmath
import numpy as np

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.solve import generated as generated_code
from identcheck.solve.linalg import cubic_roots, lstsq_stacked, solve_stacked

PARAMS = ("d", "r", "alpha", "l", "rho")
N_UNKNOWNS = 5
SLOTS = 6  # 3 roots of (13) × 2 signs of cos α
CHUNK = 16384        # problems per block, constants only
CHUNK_ANGLES = 4096  # problems per block with per-sample angles (arrays × samples × slots)
REAL_TOL = 1e-9      # scaled units: r², sin²α, ρ² must exceed it (ρ²: −it) for a real joint
COMPILED_MIN_PROBLEMS = 200_000  # solve_batch's default: the compiled kernel from this many problems on
IMAG_TOL = 1e-5      # a root of (13) with |Im| <= IMAG_TOL·(1 + |Re|) counts as real
ROUND = 1e4 * np.finfo(float).eps  # rounding slack per unit of conditioning (_cos2_slack)
ROUNDING_RESIDUAL = 1e-9  # float64 reproduction residuals below this × scale are rounding (_relabel)
_MP = SimpleNamespace(sqrt=mpmath.sqrt, maximum=max, where=lambda cond, a, b: a if cond else b)


def generated(backend: str = "numpy") -> dict:
    """The numeric functions of this case (:mod:`identcheck.solve.generated`; the same dict every call)."""
    return generated_code.functions("revolute21", backend)


__getattr__ = generated_code.lazy_case(__name__, "revolute21")  # ``CASE``: the symbolic case, loads SymPy


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
    ``theta``/``beta`` shape (..., 6, N) and ``residual`` shape (..., 6), NaN for slots whose
    constants are not real; ``pivot_ratio`` shape (...): min/max |pivot| of the elimination
    (for five samples, of the 4 × 4 system left after the constant column, see ``_solve_five``).
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


@lru_cache(maxsize=1)
def compiled_available() -> bool:
    """Whether the compiled kernel (:mod:`identcheck.solve.revolute21_compiled`, numba) can be used here."""
    try:
        from identcheck.solve import revolute21_compiled  # noqa: F401
    except ImportError:             # numba not installed, or the generated code stale
        return False
    return True


def solve_batch(xyz, *, angles=True, rel_tol=1e-6, compiled: bool | None = None) -> BatchResult:
    """Identify many problems at once (float64).

    Parameters
    ----------
    xyz : array, shape (..., n_samples, 3)
        Child-marker samples in the parent's marker frame F; n_samples >= 5 (least squares
        beyond 5).
    angles : bool
        Also construct per-sample θ, β and check that each candidate rebuilds every sample.
        Without it, ``valid`` only says that the constants are real.
    rel_tol : float
        Tolerance relative to the sample scale for the reproduction check.
    compiled : bool, optional
        Run the constants (``angles=False``, five samples) through the compiled kernel
        (:mod:`identcheck.solve.revolute21_compiled`, needs numba: ``pip install identcheck[fast]``): the same
        verdicts, several times the rate. True requires it (an error when numba is missing); False never uses
        it; None (default) uses it when it is installed and the batch has at least :data:`COMPILED_MIN_PROBLEMS`
        problems, where the rate repays loading the compiled code (about half a second once per process).
    """
    xyz = _check_samples(xyz)
    lead, N = xyz.shape[:-2], xyz.shape[-2]
    flat = xyz.reshape(-1, N, 3)
    n = len(flat)
    if compiled and not compiled_available():
        raise InputError("solve_batch(compiled=True) needs numba (pip install identcheck[fast])")
    if compiled is None:
        compiled = n >= COMPILED_MIN_PROBLEMS and compiled_available()
    if compiled and not angles and N == N_UNKNOWNS:
        return _solve_compiled(flat, lead)
    out = {"params": np.empty((n, SLOTS, 5)), "valid": np.empty((n, SLOTS), dtype=bool),
           "residual": np.full((n, SLOTS), np.nan), "Z": np.empty((n, N_UNKNOWNS)), "pivot_ratio": np.empty(n),
           "theta": np.full((n, SLOTS, N), np.nan) if angles else None,
           "beta": np.full((n, SLOTS, N), np.nan) if angles else None}
    step = CHUNK_ANGLES if angles else CHUNK
    for i in range(0, n, step):  # blocks that stay in cache; each writes its slice of ``out``
        block = {k: None if a is None else a[i:i + step] for k, a in out.items()}
        _solve_chunk(flat[i:i + step], angles, rel_tol, block)
    return BatchResult(**{k: None if a is None else a.reshape(lead + a.shape[1:]) for k, a in out.items()})


def _solve_compiled(flat, lead) -> BatchResult:
    """:func:`solve_batch` without angles through the compiled kernel; the problems it leaves (a cubic with one
    real root by its computed discriminant) go through the NumPy path."""
    from identcheck.solve.revolute21_compiled import solve_constants

    params, valid, Z, ratio, handled = solve_constants(flat, IMAG_TOL, REAL_TOL, ROUND)
    left = np.flatnonzero(~handled)
    if left.size:
        rest = solve_batch(flat[left], angles=False, compiled=False)
        params[left], valid[left], Z[left], ratio[left] = rest.params, rest.valid, rest.Z, rest.pivot_ratio
    residual = np.full(valid.shape, np.nan)
    return BatchResult(**{k: None if a is None else a.reshape(lead + a.shape[1:]) for k, a in
                          dict(params=params, valid=valid, residual=residual, theta=None, beta=None, Z=Z,
                               pivot_ratio=ratio).items()})


def _solve_chunk(xyz, angles, rel_tol, out):
    """:func:`solve_batch` on one block of problems, shape (n, N, 3), written into ``out``."""
    g = generated("numpy")
    n, N, _ = xyz.shape
    scale = np.sqrt(np.einsum("nij,nij->n", xyz, xyz) / N)  # RMS distance from A1: work in O(1) units
    scale = np.where(scale > 0, scale, 1.0)
    xs = xyz / scale[:, None, None]
    MK = g["m_row"](xs)
    Zs, ratio = _solve_five(MK) if N == N_UNKNOWNS else lstsq_stacked(MK[..., :N_UNKNOWNS], MK[..., N_UNKNOWNS])
    out["Z"][:], out["pivot_ratio"][:] = Zs, ratio
    coeffs = g["cubic"](Zs)
    q, im = fast_cubic_roots(coeffs)                                       # (n, 3)
    r2, S, w, v = np.moveaxis(g["back"](q[..., None], Zs[:, None, :]), -1, 0)
    d = Zs[:, :1]
    with np.errstate(all="ignore"):
        ca, l = cos_and_l(S, w, v, d)                                      # σ = +1; the mirror negates both
        rho2 = g["rho2"](q[..., None], Zs[:, None, :], l[..., None])[..., 0]
        # a double root (the twin joint meets the true one, e.g. l = 0 and r = rho) splits into a
        # complex pair of size ~sqrt(eps): accept near-real roots and let the reproduction check decide
        ok = (np.abs(im) <= IMAG_TOL * (1 + np.abs(q))) & np.isfinite(l)
        ok &= is_real(r2, S, v, rho2, REAL_TOL, _cos2_slack(coeffs, q, Zs, S, v, ratio))
        sa = np.sqrt(np.clip(S, 0, 1))
        r, rho = np.sqrt(np.maximum(r2, 0)), np.sqrt(np.maximum(rho2, 0))
    _slots(out["params"], scale, d, r, np.arctan2(sa, ca), l, rho)
    valid = out["valid"]
    valid[:] = np.repeat(ok, 2, axis=1)
    if angles:
        where = np.nonzero(valid)
        res = _angles(g, xs, where, (d, r, l, rho, ca, sa), out["theta"], out["beta"])
        valid[where] = res <= rel_tol  # NaN (a failed construction) compares False
        out["residual"][where] = res * scale[where[0]]


def _constant_column() -> int:
    """Index of the column of M that is the same number for every sample (M4 = 1, unknown Y4)."""
    return generated_code.facts("revolute21")["constant_column"]


def _solve_five(MK):
    """Z and the pivot ratio from five samples: rows ``MK`` (n, 5, 6) = [M | K].

    M has a constant column (:func:`_constant_column`). Subtracting the first sample's row
    from the others eliminates its unknown, which is the Gaussian step that pivots on that
    column (all of its entries have the same size), and leaves a 4 × 4 system for the other
    four: about 20 % less work than eliminating the 5 × 5 one. The pivot ratio is that of the
    4 × 4 elimination.
    """
    c = _constant_column()
    rest = [j for j in range(N_UNKNOWNS) if j != c]
    A = MK[:, :, rest + [N_UNKNOWNS]]                                      # (n, 5, 5) = [M without c | K]
    D = A[:, 1:] - A[:, :1]
    Zr, ratio = solve_stacked(D[..., :-1], D[..., -1])
    Zs = np.empty((len(MK), N_UNKNOWNS))
    Zs[:, rest] = Zr
    Zs[:, c] = (A[:, 0, -1] - np.einsum("nj,nj->n", A[:, 0, :-1], Zr)) / MK[:, 0, c]
    return Zs, ratio


def fast_cubic_roots(coeffs):
    """The roots of (13), stacked (n, 4) -> (re, im), each (n, 3); three real ones largest first.

    Erratum E1 proves all three roots real for exact data (the discriminant is a sum of
    squares), so the trigonometric form alone, followed by one Newton step, serves nearly every
    problem; :func:`~identcheck.solve.linalg.cubic_roots` evaluates both forms everywhere, with
    two Newton steps and numpy's slow ``** 3``, and takes 5-6 times as long. Problems whose
    computed discriminant says "one real root" (noise, or a near-double root pushed over by
    rounding) go through that general routine (Cardano). On 200 000 random problems the
    accuracy of the joints is the same either way.
    """
    a, b, c = (coeffs[:, i] / coeffs[:, 0] for i in (1, 2, 3))
    p3 = b / 3 - a * a / 9                                 # p/3 of the depressed cubic t³ + pt + h
    h = (2 * a * a / 27 - b / 3) * a + c
    three = h * h / 4 + p3 * p3 * p3 <= 0                  # x*x*x: numpy's ** 3 is ten times slower
    with np.errstate(all="ignore"):
        m = np.sqrt(np.maximum(-p3, 0))
        phi = np.arccos(np.clip(np.where(m > 0, h / (-2 * m * m * m), 0), -1, 1)) / 3
        cp, sp3 = m * np.cos(phi), np.sqrt(3) * m * np.sin(phi)  # 2m cos(phi - 2πk/3), k = 0, 1, 2
        re = np.stack([2 * cp, sp3 - cp, -cp - sp3], axis=-1) - (a / 3)[:, None]
        A, B, C = a[:, None], b[:, None], c[:, None]
        f = ((re + A) * re + B) * re + C
        step = f / ((3 * re + 2 * A) * re + B)
        re = np.where(np.isfinite(step), re - step, re)
    im = np.zeros_like(re)
    if not three.all():
        other = ~three
        re[other], im[other] = cubic_roots(coeffs[other])
    return re, im


def cos_and_l(S, w, v, d, xp=np):
    """cos α and l of the σ = +1 joint (cos α >= 0) of a root; the mirror image negates both.

    The derivation gives sin²α = S, w = cos α·u and v = u² with u = l + d cos α. Of the two
    factors of w, the larger in magnitude, m, is taken as a square root (of C = 1 − S or of v)
    and the smaller as w/m, so both are well-conditioned: the printed route
    cos α = sqrt(1 − sin²α), l = w/cos α − d cos α loses about half the digits of cos α as
    cos α -> 0 (hinge perpendicular to A1A2) and then drops the true joint. Then l = u − d cos α.
    u gets the sign of w; for w = 0 it is +sqrt(v), and the mirror gives −sqrt(v): at
    cos α = 0 the two mirror images are (π/2, l) and (π/2, −l), both kept.

    ``xp`` supplies sqrt, maximum and where: NumPy for arrays, ``_MP`` for mpmath numbers.
    """
    C = 1 - S
    from_c = C >= v
    m = xp.sqrt(xp.maximum(xp.maximum(C, v), 0))
    t = w / xp.where(m > 0, m, 1)
    c = xp.where(from_c, m, abs(t))
    u = xp.where(from_c, t, xp.where(w < 0, -m, m))
    return c, u - d * c


def is_real(r2, S, v, rho2, tol, slack, xp=np):
    """Whether a root's constants are those of a real joint.

    r² > 0, sin²α > 0, ρ² >= 0 up to ``tol``; cos²α = 1 − S >= 0 up to ``slack`` (rounding
    can push a hinge perpendicular to A1A2 slightly below 0; it is then taken as 0); and
    u² = v and cos²α not both <= 0. At a root of (13), w² = (1 − S)·v, so the two share a sign:
    both negative is the root that the derivation proves non-real (E1). That sign is read from the one larger
    in magnitude.
    """
    C = 1 - S
    # the smaller may be rounding alone: a root with cos²α exactly 0 and u² clearly negative came out at +1e-16
    larger = xp.where(abs(C) >= abs(v), C, v)
    return (r2 > tol) & (S > tol) & (C >= -slack) & (larger > 0) & (rho2 > -tol)


def _cos2_slack(coeffs, q, Zs, S, v, ratio):
    """How far below 0 rounding may push the computed cos²α = 1 + (Q − Z2)/(2(Z1² − Z5)), (n, 3).

    Only slots with cos²α < 0 < u² = v need it (a hinge nearly perpendicular to A1A2); the
    others get 0. First-order error with relative input errors ``ROUND``/pivot ratio (the
    pivot ratio stands in for the conditioning of M): the root Q moves by that times
    Σ|c_i Q^i| / |p'(Q)|, its own condition number, and Z2, Z1², Z5 add theirs. On 200 000
    random problems the true error stayed within 700·eps/pivot ratio times this bracket;
    ROUND = 1e4·eps leaves a margin.
    """
    slack = np.zeros_like(q)
    k, j = np.nonzero((S > 1) & (v > 0))
    if k.size:
        c0, c1, c2, c3 = coeffs[k].T
        Q, Z1s, Z2, Z5 = q[k, j], Zs[k, 0] ** 2, Zs[k, 1], Zs[k, 4]
        aq = np.abs(Q)
        size = ((abs(c0) * aq + abs(c1)) * aq + abs(c2)) * aq + abs(c3)
        slope = (3 * c0 * Q + 2 * c1) * Q + c2
        bracket = size / np.abs(slope) + aq + abs(Z2) + 2 * abs(S[k, j]) * (Z1s + abs(Z5))
        slack[k, j] = ROUND / ratio[k] * bracket / np.abs(2 * (Z1s - Z5))
    return slack


def mirror(params) -> np.ndarray:
    """The mirror image (d, r, π − α, −l, ρ) of a joint's constants (the slot beside it in :func:`_slots`): it
    reproduces the same samples, its meridian about the A1A2 line being the same curve (ERRATA E2)."""
    d, r, a, l, rho = params
    return np.array([d, r, np.pi - a, -l, rho], dtype=float)


def _slots(params, scale, d, r, alpha, l, rho):
    """Write the (n, 3) constants of the σ = +1 joints into ``params`` (n, 6, 5), input units.

    Slots are root-major, sign-minor; the mirror image has π − α and −l.
    """
    sc = scale[:, None]
    p = params.reshape(len(params), 3, 2, 5)
    p[..., 0] = (d * sc)[:, :, None]
    p[..., 1] = (r * sc)[:, :, None]
    p[..., 4] = (rho * sc)[:, :, None]
    p[:, :, 0, 2], p[:, :, 1, 2] = alpha, np.pi - alpha
    p[:, :, 0, 3] = l * sc
    p[:, :, 1, 3] = -p[:, :, 0, 3]


def _angles(g, xs, where, consts, theta, beta):
    """Per-sample θ, β and reproduction residual (scaled) of the slots ``where`` = (problem, slot).

    Only these slots are evaluated and written into ``theta``, ``beta`` (n, 6, N): the
    non-real ones cost as much and tell nothing. ``consts`` = (d, r, l, ρ, cos α, sin α) of
    the σ = +1 joints, each (n, 3) or (n, 1). Returns the residuals in ``where`` order (that
    of ``np.nonzero``).
    """
    k, slot = where
    root, sgn = slot // 2, 1.0 - 2.0 * (slot % 2)
    d, r, l, rho, ca, sa = (c[k, root] for c in np.broadcast_arrays(*consts))
    P = _planar(np.stack([d, r, sgn * l, rho, sgn * ca, sa])[:, :, None])  # (m, 1, 6), codegen order
    X = _planar(np.moveaxis(xs[k], -1, 0).copy())                          # (m, N, 3)
    cs = g["theta"](X, P)                                                  # (m, N, 2)
    h = np.hypot(cs[..., 0], cs[..., 1])
    trig = np.empty((4,) + h.shape)                                        # cos θ, sin θ, cos β, sin β
    np.divide(cs[..., 0], h, out=trig[0])
    np.divide(cs[..., 1], h, out=trig[1])
    loc = g["local"](X, P, _planar(trig[:2]))                              # (m, N, 3)
    b = np.arctan2(loc[..., 1], loc[..., 0])
    np.cos(b, out=trig[2])
    np.sin(b, out=trig[3])
    gap = g["forward"](P, _planar(trig)) - X
    theta[k, slot], beta[k, slot] = np.arctan2(trig[1], trig[0]), b
    return np.sqrt(np.max(np.einsum("mij,mij->mi", gap, gap), axis=-1))


def _planar(a):
    """View a (k, ...) array as (..., k): one contiguous array per component of the last axis.

    The generated functions split their arguments' last axis into C-contiguous columns; in
    this layout that costs nothing, where an interleaved (..., k) array is copied column by
    column (the per-sample angles run about 40 % faster).
    """
    return np.moveaxis(a, 0, -1)


def _degeneracy(xyz: np.ndarray) -> None:
    """Raise a specific DegenerateError for samples that cannot identify the joint."""
    N = len(xyz)
    scale = float(np.sqrt(np.mean(np.sum(xyz**2, axis=-1))))
    if not np.all(np.isfinite(xyz)):
        bad = sorted(set(np.argwhere(~np.isfinite(xyz))[:, 0].tolist()))
        raise DegenerateError(f"samples {bad} are not finite (NaN or inf): drop occluded frames first")
    if scale == 0:
        raise DegenerateError("all samples are at the origin (B coincides with A1)")
    for i in range(N - 1):  # each sample against the later ones at once: the first coinciding pair is named
        close = np.flatnonzero(np.linalg.norm(xyz[i + 1:] - xyz[i], axis=1) <= 1e-9 * scale)
        if close.size:
            raise DegenerateError(f"samples {i} and {i + 1 + close[0]} coincide: they give the same equation "
                                  "(det M = 0)")
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
    return Identification(_relabel(joints, ROUNDING_RESIDUAL * scale), [float(v) for v in res.Z],
                          float(res.pivot_ratio), None)


def _relabel(joints, floor):
    """Number the surviving parameter sets 0, 1, ...: best residual first.

    Residuals below ``floor`` (rounding, i.e. exact data) count as equal, and such sets keep
    the order of their roots of (13), largest first. Ordering by rounding noise would be
    arbitrary, and could differ between the float64 and mpmath runs on the same samples.
    """
    best = {}
    for j in joints:
        best[j.root] = min(best.get(j.root, j.residual), j.residual)
    order = {root: i for i, root in enumerate(sorted(best, key=lambda k: (max(best[k], floor), k)))}
    for j in joints:
        j.root = order[j.root]
    return sorted(joints, key=lambda j: (j.root, j.mirror))


def _identify_mp(xyz, precision: int, rel_tol=None) -> Identification:
    """:func:`identify` at ``precision`` digits: the same steps on generated mpmath code, root by root."""
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
        roots = sorted(mpmath.polyroots(coeffs, maxsteps=400, extraprec=4 * mp.prec), key=lambda z: -mpmath.re(z))
        eps = mpmath.mpf(10) ** (-(precision - 8))
        tol = eps if rel_tol is None else max(eps, mpmath.mpf(rel_tol))
        joints = []
        for k, Qk in enumerate(roots):
            if abs(mpmath.im(Qk)) > eps * (1 + abs(Qk)):
                continue
            Qk = mpmath.re(Qk)
            try:
                r2, S, w, v = g["back"]([Qk], Zs)
                ca, l = cos_and_l(S, w, v, Zs[0], _MP)
                rho2 = g["rho2"]([Qk], Zs, [l])[0]
            except ZeroDivisionError:
                continue
            if not (is_real(r2, S, v, rho2, eps, eps, _MP) and mpmath.isfinite(l)):
                continue
            sa = mpmath.sqrt(min(S, 1))
            for sgn in (1, -1):
                par = [Zs[0], mpmath.sqrt(r2), sgn * l, mpmath.sqrt(max(rho2, 0)), sgn * ca, sa]
                th, be, worst = _rebuild_mp(g, pts, par)
                if worst <= tol * scale:
                    joints.append(Joint21(par[0], par[1], mpmath.atan2(sa, sgn * ca), par[2], par[3],
                                          theta=th, beta=be, residual=worst, root=k, mirror=sgn < 0))
        if not joints:
            raise DegenerateError("no real joint reproduces these samples at the requested precision")
        return Identification(_relabel(joints, eps * scale), Zs, float("nan"), precision)


def _rebuild_mp(g, pts, par):
    """Per-sample θ, β of the joint ``par`` (codegen order) and its worst reproduction error."""
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
    return np.array(th, dtype=object), np.array(be, dtype=object), worst
