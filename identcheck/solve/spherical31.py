"""Spherical joint from three parent markers and one child marker (Pham et al., section IV-A).

The child marker B, expressed in the parent's frame, lies on a sphere about the fixed centre
J: four non-coplanar samples determine it through the derivation's linear system
(:mod:`identcheck.derive.spherical31`). Coplanar samples leave a whole line of centres (the
paper's Fig. 3, proved in the derivation); for real, noisy data the solver measures how close
to that the motion is, predicts the centre uncertainty it causes and says which motion to add.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import mpmath
import numpy as np

from identcheck.errors import DegenerateError, IdentifiabilityWarning
from identcheck.solve import generated as generated_code
from identcheck.solve.sampling import check_samples, column_scaled_lstsq, mp_solve

N_UNKNOWNS = 4


def generated(backend: str = "numpy") -> dict:
    """The numeric functions of this case (:mod:`identcheck.solve.generated`; the same dict every call)."""
    return generated_code.functions("spherical31", backend)


__getattr__ = generated_code.lazy_case(__name__, "spherical31")  # ``CASE``: the symbolic case, loads SymPy


@dataclass
class Conditioning:
    """How well a set of samples pins the sphere down, and what motion would help.

    ``spread_mm`` are the RMS extents of the samples along their principal directions
    (largest first); ``normal`` is the direction of least spread — for coplanar samples the
    plane's normal, along which the centre is free. ``uncertainty_mm`` is the predicted
    1-σ error of the centre along its worst direction for marker noise ``noise_mm``.
    """

    ok: bool
    reason: str
    spread_mm: tuple
    normal: tuple
    planarity: float
    uncertainty_mm: float | None
    noise_mm: float | None


EXACTLY_COPLANAR = 1e-9
"""Planarity (smallest principal spread over the largest) below which (3,1) samples are coplanar to rounding: no
sphere is determined, and :func:`identify` raises."""


def conditioning(xyz, noise_mm: float | None = None, *, min_planarity: float = 0.05) -> Conditioning:
    """Near-coplanarity check of (3,1) samples, with the uncertainty it predicts.

    ``planarity`` is the smallest principal spread over the largest; below ``min_planarity``
    the samples are nearly coplanar. The centre's covariance is the linearised Gauss–Markov
    covariance of the sphere equations: each equation |B|² − 2J·B − c = 0 moves by 2(B − J)·ε
    for marker noise ε, so Cov(J, c) = 4ρ²σ² (MᵀM)⁻¹ with M the derivation's rows (±[2B, 1]).
    """
    xyz = check_samples(xyz, N_UNKNOWNS, "B", "spherical (3,1)")
    centred = xyz - xyz.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    spread = sv / np.sqrt(len(xyz))
    planarity = float(spread[2] / spread[0]) if spread[0] > 0 else 0.0
    normal = vt[2]
    unc = None
    if noise_mm is not None and planarity > 0:
        rows = generated("numpy")["m_row"](xyz)          # the derivation's rows: M = −[2B, 1]
        M, K = rows[:, :-1], rows[:, -1]
        try:
            rho2 = generated("numpy")["back"](column_scaled_lstsq(M, K))[3]
            cov = 4 * max(rho2, 0.0) * noise_mm**2 * np.linalg.inv(M.T @ M)
            unc = float(np.sqrt(np.linalg.eigvalsh(cov[:3, :3]).max()))
        except np.linalg.LinAlgError:
            unc = float("inf")
    ok = planarity >= min_planarity
    n = ", ".join(f"{v:+.2f}" for v in normal)
    reason = ("the samples spread in all three directions" if ok else
              f"the samples are nearly coplanar (spread {spread[2]:.3g} along the normal ({n}) against "
              f"{spread[0]:.3g} in-plane): the centre is poorly determined along that normal. Add motion "
              "that moves the child marker out of this plane — rotate the child segment about an axis lying "
              "in the plane (e.g. add abduction/adduction to a flexion-only movement).")
    return Conditioning(ok, reason, tuple(map(float, spread)), tuple(map(float, normal)), planarity, unc, noise_mm)


@dataclass
class Joint31:
    """The sphere through the samples: the centre in the parent's frame and the radius."""

    centre: np.ndarray
    rho: float
    residual: float

    def as_tuple(self) -> tuple:
        return (*self.centre, self.rho)


@dataclass
class Identification31:
    joints: list
    conditioning: Conditioning
    precision: int | None

    @property
    def unique(self) -> bool:
        return len(self.joints) == 1


def _coplanar_error(cond: Conditioning) -> DegenerateError:
    n = ", ".join(f"{v:+.3f}" for v in cond.normal)
    return DegenerateError(
        f"the samples are coplanar (normal ({n})): every point of the line through the sphere's centre "
        "along that normal is equidistant from them (Pham et al. Fig. 3), so the centre is not identifiable "
        "from this motion. Rotate the child segment out of that plane.")


def identify(xyz, precision: int | None = None, *, rel_tol: float = 1e-6, noise_mm: float | None = None) -> Identification31:
    """The sphere through ≥ 4 samples of the child marker in the parent's frame.

    Exact data (``rel_tol`` finite): the sphere must pass through every sample. Noisy data:
    pass ``rel_tol=numpy.inf`` (least squares) and ``noise_mm`` for the predicted uncertainty;
    nearly coplanar samples then warn with the motion to add, exactly coplanar ones raise.
    """
    cond = conditioning(xyz if precision is None else np.array(xyz, dtype=float), noise_mm)
    if cond.planarity < EXACTLY_COPLANAR:
        raise _coplanar_error(cond)
    if not cond.ok:
        warnings.warn(cond.reason, IdentifiabilityWarning, stacklevel=2)
    if precision is not None:
        return _identify_mp(xyz, int(precision), cond)
    xyz = np.asarray(xyz, dtype=float)
    scale = float(np.sqrt(np.mean(xyz**2)))
    rows = generated("numpy")["m_row"](xyz / scale)
    Z = column_scaled_lstsq(rows[:, :-1], rows[:, -1])
    xj, yj, zj, rho2 = generated("numpy")["back"](Z)
    if not rho2 > 0:
        raise DegenerateError(f"no real sphere: ρ² = {rho2 * scale**2:.6g}")
    centre = np.array([xj, yj, zj]) * scale
    rho = float(np.sqrt(rho2) * scale)
    residual = float(np.max(np.abs(np.linalg.norm(xyz - centre, axis=1) - rho)))
    if not residual <= rel_tol * scale:
        raise DegenerateError(f"no sphere passes through the samples (misses by up to {residual:.3g}): they are "
                              "not exact samples of a (3,1) spherical joint; pass rel_tol=inf for a "
                              "least-squares sphere on noisy data")
    return Identification31([Joint31(centre, rho, residual)], cond, None)


def _identify_mp(xyz, precision: int, cond: Conditioning) -> Identification31:
    g = generated("mpmath")
    with mpmath.workdps(precision + 15):
        pts = [[mpmath.mpf(v) for v in p] for p in xyz]
        rows = [g["m_row"](p) for p in pts]
        Z = mp_solve([row[:-1] for row in rows], [row[-1] for row in rows])
        xj, yj, zj, rho2 = g["back"](Z)
        if rho2 <= 0:
            raise DegenerateError(f"no real sphere at {precision} digits")
        rho = mpmath.sqrt(rho2)
        res = max(abs(mpmath.sqrt((p[0] - xj) ** 2 + (p[1] - yj) ** 2 + (p[2] - zj) ** 2) - rho) for p in pts)
        return Identification31([Joint31(np.array([xj, yj, zj], dtype=object), rho, res)], cond, precision)
