"""Spherical joint from two parent markers and two child markers (Pham et al., section IV-C).

Input: per-sample coordinates of B1, B2 in the frame F of the parent's markers (A1 at the
origin, A2 on +z; :func:`identcheck.geometry.frames.pair_frame`). The derivation
(:mod:`identcheck.derive.spherical22`) gives a full-rank linear system in nine unknowns (not
the printed (17); errata E4, E5) from which d, r², ρ1², ρ2² follow linearly: exact data admit
exactly one joint. Each sample's centre J = (r cos θ, r sin θ, d) is constructed and the joint
is kept only if |J − B1| = ρ1 and |J − B2| = ρ2 in every sample.

Every formula comes from the derivation through :mod:`identcheck.codegen`, printed once into
:mod:`identcheck.solve.generated` (:func:`identcheck.solve.formulas.spherical22` names them).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import mpmath
import numpy as np

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.solve import generated as generated_code
from identcheck.solve.sampling import check_samples, column_scaled_lstsq, mp_solve

PARAMS = ("d", "r", "rho1", "rho2")


def generated(backend: str = "numpy") -> dict:
    """The numeric functions of this case (:mod:`identcheck.solve.generated`; the same dict every call)."""
    return generated_code.functions("spherical22", backend)


def n_unknowns() -> int:
    """Unknowns of the full-rank linear system: the minimum number of samples."""
    return generated_code.facts("spherical22")["n_unknowns"]


__getattr__ = generated_code.lazy_case(__name__, "spherical22")  # ``CASE``: the symbolic case, loads SymPy


@dataclass
class Joint22:
    """The joint that reproduces the samples: constants, per-sample roll θ and centre in F."""

    d: float
    r: float
    rho1: float
    rho2: float
    theta: np.ndarray
    centre: np.ndarray     # (N, 3), in each sample's frame F
    residual: float        # max | |J − B_k| − ρ_k | over samples, input units

    def as_tuple(self) -> tuple:
        return (self.d, self.r, self.rho1, self.rho2)

    def marker_distances(self, h: float) -> dict:
        """Distances of A1 (origin), A2 (at height ``h`` on z), B1 and B2 to the centre."""
        dd, rr = float(self.d), float(self.r)
        return {"A1": float(np.hypot(rr, dd)), "A2": float(np.hypot(rr, dd - h)),
                "B1": float(self.rho1), "B2": float(self.rho2)}


@dataclass
class Identification22:
    """Every joint the samples admit (one for exact generic data), with the system's conditioning."""

    joints: list
    Z: list
    condition: float
    precision: int | None

    @property
    def unique(self) -> bool:
        return len(self.joints) == 1


def _stack(b1, b2, n_min: int) -> np.ndarray:
    b1, b2 = check_samples(b1, n_min, "B1", "spherical (2,2)"), check_samples(b2, n_min, "B2", "spherical (2,2)")
    if b1.shape != b2.shape:
        raise InputError(f"B1 and B2 need the same number of samples, got {b1.shape} and {b2.shape}")
    return np.concatenate([b1, b2], axis=-1)


def _params_from_Z(Z, scale) -> tuple:
    dd, r2, q1, q2 = (float(v) for v in generated("numpy")["back"](np.asarray(Z, dtype=float)))
    if min(r2, q1, q2) <= 0 or not np.isfinite([dd, r2, q1, q2]).all():
        raise DegenerateError(
            f"no real joint: the solved unknowns give r² = {r2 * scale**2:.6g}, ρ1² = {q1 * scale**2:.6g}, "
            f"ρ2² = {q2 * scale**2:.6g}. The samples are not those of a spherical joint with (2,2) markers "
            "(check the joint type and marker assignment), or they are too noisy for the closed form: "
            "use the S22 algorithm (identcheck.solve.s22).")
    return float(dd * scale), float(np.sqrt(r2) * scale), float(np.sqrt(q1) * scale), float(np.sqrt(q2) * scale)


def _system(s: np.ndarray, cond_limit: float):
    """Normalised rows M, K and the condition number of the column-scaled M."""
    scale = float(np.sqrt(np.mean(s**2)))
    if scale == 0:
        raise DegenerateError("every marker coincides with A1")
    rows = generated("numpy")["m_row"](s / scale)
    M, K = rows[:, :-1], rows[:, -1]
    colnorm = np.linalg.norm(M, axis=0)
    cond = float(np.linalg.cond(M / np.where(colnorm == 0, 1, colnorm))) if np.all(colnorm > 0) else np.inf
    if not np.isfinite(cond) or cond > cond_limit:
        raise DegenerateError(
            f"the samples do not determine the {M.shape[1]} unknowns (condition number {cond:.3g}): the child "
            "segment's motion is too poor — e.g. rotation about a single axis, or B1, B2 on a line through "
            "the centre — or fewer distinct samples than unknowns. Record motion in several directions.")
    if cond > 1e7:
        warnings.warn(f"the (2,2) linear system is ill-conditioned (condition number {cond:.3g}): noise will be "
                      "amplified", IdentifiabilityWarning, stacklevel=3)
    return M, K, scale, cond


def solve_linear(b1, b2, *, cond_limit: float = 1e12) -> tuple:
    """(d, r, ρ1, ρ2) by least squares on the linear system — the closed form for noisy data.

    Parameters
    ----------
    b1, b2 : array, shape (N, 3)
        Child markers in the pair frame F, N ≥ 9.

    Raises
    ------
    DegenerateError
        Poor motion (rank-deficient system) or no real joint (noise too large for the closed form).
    """
    s = _stack(b1, b2, n_unknowns())
    M, K, scale, _ = _system(s, cond_limit)
    return _params_from_Z(column_scaled_lstsq(M, K), scale)


def identify(b1, b2, precision: int | None = None, *, cond_limit: float = 1e10,
             rel_tol: float = 1e-6) -> Identification22:
    """Every joint that reproduces the samples exactly (one for generic data), verified per sample.

    Parameters
    ----------
    b1, b2 : array_like, shape (N, 3)
        B1 and B2 in the parent's pair frame F, N ≥ 9. With ``precision`` entries may be
        mpmath numbers or strings.
    precision : int, optional
        None: float64. An integer: that many digits (generated mpmath code).
    rel_tol : float
        The joint must rebuild every sample to ``rel_tol`` × the sample scale (float64) or
        10^-(precision − 10) (mpmath); ``numpy.inf`` accepts any real joint (noisy data).
    """
    if precision is not None:
        return _identify_mp(b1, b2, int(precision))
    s = _stack(b1, b2, n_unknowns())
    M, K, scale, cond = _system(s, cond_limit)
    Z = column_scaled_lstsq(M, K)
    joint = _joint(s, _params_from_Z(Z, scale), generated("numpy"))
    if not joint.residual <= rel_tol * scale:
        raise DegenerateError(
            f"the solved joint misses the samples by up to {joint.residual:.3g} (tolerance {rel_tol * scale:.3g}): "
            "the data are not exact samples of a spherical joint with (2,2) markers; for measured data use "
            "the S22 algorithm (identcheck.solve.s22).")
    return Identification22([joint], [float(v) for v in Z], cond, None)


def _joint(s, params, g) -> Joint22:
    """Construct each sample's centre and measure how well the joint rebuilds the samples."""
    par = np.asarray(params, dtype=object if isinstance(params[0], mpmath.mpf) else float)
    if g is generated("numpy"):
        cs = g["theta"](s, par[None, :].astype(float))
        J = np.stack([par[1] * cs[:, 0], par[1] * cs[:, 1], np.full(len(s), par[0])], axis=-1)
        res = max(np.max(np.abs(np.linalg.norm(J - s[:, :3], axis=1) - par[2])),
                  np.max(np.abs(np.linalg.norm(J - s[:, 3:], axis=1) - par[3])))
        return Joint22(*map(float, par), theta=np.arctan2(cs[:, 1], cs[:, 0]), centre=J, residual=float(res))
    thetas, centres, res = [], [], mpmath.mpf(0)
    for row in s:
        c, sn = g["theta"](row, list(par))
        Jm = [par[1] * c, par[1] * sn, par[0]]
        for k in range(2):
            dist = mpmath.sqrt(mpmath.fsum((a - b) ** 2 for a, b in zip(Jm, row[3 * k:3 * k + 3])))
            res = max(res, abs(dist - par[2 + k]))
        thetas.append(mpmath.atan2(sn, c))
        centres.append(Jm)
    return Joint22(*par, theta=np.array(thetas, dtype=object), centre=np.array(centres, dtype=object), residual=res)


def _identify_mp(b1, b2, precision: int) -> Identification22:
    g = generated("mpmath")
    with mpmath.workdps(precision + 15):
        s = [[mpmath.mpf(v) for v in list(p1) + list(p2)] for p1, p2 in zip(b1, b2)]
        n = n_unknowns()
        if len(s) < n:
            raise InputError(f"spherical (2,2) needs at least {n} samples, got {len(s)}")
        _system(np.array([[float(v) for v in row] for row in s]), 1e12)  # degeneracy check in float64
        rows = [g["m_row"](row) for row in s]
        Z = mp_solve([row[:-1] for row in rows], [row[-1] for row in rows])
        dd, r2, q1, q2 = g["back"](Z)
        if min(r2, q1, q2) <= 0:
            raise DegenerateError(f"no real joint at {precision} digits (r² = {mpmath.nstr(r2, 8)}, "
                                  f"ρ1² = {mpmath.nstr(q1, 8)}, ρ2² = {mpmath.nstr(q2, 8)})")
        joint = _joint(s, [dd, mpmath.sqrt(r2), mpmath.sqrt(q1), mpmath.sqrt(q2)], g)
        scale = mpmath.sqrt(mpmath.fsum(v * v for row in s for v in row) / (6 * len(s)))
        if joint.residual > scale * mpmath.mpf(10) ** (-(precision - 10)):
            raise DegenerateError(f"the solved joint misses the samples by {mpmath.nstr(joint.residual, 3)} at "
                                  f"{precision} digits: not exact samples of a spherical (2,2) joint")
        return Identification22([joint], list(Z), float("nan"), precision)
