"""SCoRE joint centre and SARA hinge axis (Ehrig et al. 2006, 2007), through the 3 x 3 mean rotation.

SCoRE (symmetrical centre of rotation estimation; Ehrig et al. 2006, J Biomech 39:2798) finds
the points ``c_P`` (parent frame) and ``c_C`` (child frame) that minimise::

    Σ_f |R_P[f] c_P + t_P[f] - R_C[f] c_C - t_C[f]|²

and reports the joint centre in the world as the mean of the two images. SARA (symmetrical
axis of rotation approach; Ehrig et al. 2007, J Biomech 40:2150) takes the same stacked matrix
``A = [R_P[f], -R_C[f]]`` and reads the hinge axis, in both frames, off the right singular
vector of its smallest singular value.

Same estimator as O'Brien et al.
--------------------------------
This objective is, term for term, O'Brien et al.'s eq. (10) summed over frames (with
``l = c_P``, ``c = c_C``), and SARA's axis is their section 3.2. SCoRE and O'Brien's stacked SVD
are therefore the *same* estimator (the same minimiser; the same minimum-norm point when the
motion leaves the centre undetermined, as here), and SARA's axis is O'Brien's single-axis
direction. ``tests/estimate/test_fit_score_sara.py`` checks the agreement to rounding on noisy data. What
differs is the route: here nothing of size n is decomposed. The normal equations divided by n
are::

    c_P - M c_C = g,    -Mᵀ c_P + c_C = -h,
    M = mean R_Pᵀ R_C,  g = mean R_Pᵀ (t_C - t_P),  h = mean R_Cᵀ (t_C - t_P),

and with the SVD ``M = U diag(s) Vᵀ`` they split into three 2 x 2 systems
``[[1, -s_j], [-s_j, 1]] [p_j; q_j] = [g'_j; -h'_j]`` for ``p = Uᵀ c_P``, ``q = Vᵀ c_C``,
``g' = Uᵀ g``, ``h' = Vᵀ h``. The singular values of A are ``√(n (1 ± s_j))``; the axis (the
null direction when ``s_1 = 1``) is ``u_1`` in the parent frame and ``v_1`` in the child
frame, the top singular vectors of the mean relative rotation. So everything costs one pass
over the frames (three ``einsum``) and one 3 x 3 SVD.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.obrien import (HINGE_TOL_DEG, canonical_sign, classify_motion, paired_frames,
                                   rotation_spread_deg)


@dataclass(frozen=True)
class ScoreFit:
    """SCoRE joint centre.

    Attributes
    ----------
    centre_parent, centre_child : numpy.ndarray
        Joint centre in the parent / child frame, shape (3,), mm (the minimum-norm solution
        when ``unique`` is False).
    centre_world : numpy.ndarray
        Mean of the centre's images through both segments, shape (n_frames, 3), mm; NaN in
        frames without both poses.
    motion, unique, reason
        As :class:`identcheck.estimate.obrien.JointFit`.
    rms_residual : float
        RMS over frames of the gap between the two images, mm.
    frame_residual_mm : numpy.ndarray
        That gap per frame, NaN without both poses, shape (n_frames,).
    singular_values : numpy.ndarray
        Singular values of the stacked matrix A, descending, shape (6,) (``√(n (1 ± s_j))``).
    spread_deg : numpy.ndarray
        Rotation spread about the three least-exercised directions, ascending, shape (3,).
    uncertainty_mm : float
        Standard error of the worst-determined identified direction, mm (as JointFit).
    n_frames : int
    hinge_tol_deg : float
    """

    centre_parent: np.ndarray
    centre_child: np.ndarray
    centre_world: np.ndarray
    motion: str
    unique: bool
    reason: str
    rms_residual: float
    frame_residual_mm: np.ndarray
    singular_values: np.ndarray
    spread_deg: np.ndarray
    uncertainty_mm: float
    n_frames: int
    hinge_tol_deg: float


@dataclass(frozen=True)
class SaraFit:
    """SARA hinge axis.

    Attributes
    ----------
    axis_parent, axis_child : numpy.ndarray
        Unit axis in the parent / child frame, shape (3,); the same line (``R_P a_P = R_C a_C``
        for a hinge), sign chosen so the parent-frame axis's largest component is positive.
        Always the least-exercised rotation direction; a hinge axis only when ``hinge``.
    point_parent, point_child : numpy.ndarray
        A point on the axis in each frame, shape (3,), mm: the minimum-norm solution with the
        axis direction left free (a hinge never fixes a position along its axis).
    hinge : bool
        The motion is single-axis: spread about every direction but the axis is at least
        ``hinge_tol_deg``, and about the axis (``off_axis_deg``) below it.
    motion, reason
        As :class:`identcheck.estimate.obrien.JointFit`.
    off_axis_deg : float
        Rotation spread about directions other than the axis (the smallest spread), degrees;
        0 for an ideal hinge.
    rms_residual : float
        RMS gap between the axis points' images, mm.
    frame_residual_mm : numpy.ndarray
        Shape (n_frames,), NaN without both poses.
    singular_values : numpy.ndarray
        Descending, shape (6,); ``singular_values[-1]`` is Ehrig's smallest singular value.
    spread_deg : numpy.ndarray
        Ascending, shape (3,).
    n_frames : int
    hinge_tol_deg : float
    """

    axis_parent: np.ndarray
    axis_child: np.ndarray
    point_parent: np.ndarray
    point_child: np.ndarray
    hinge: bool
    motion: str
    reason: str
    off_axis_deg: float
    rms_residual: float
    frame_residual_mm: np.ndarray
    singular_values: np.ndarray
    spread_deg: np.ndarray
    n_frames: int
    hinge_tol_deg: float

    def axis_world(self, parent) -> np.ndarray:
        """The axis in the world through the parent's rotations, shape (n_frames, 3)."""
        return np.einsum("fij,j->fi", parent.R, self.axis_parent)


# ---------------------------------------------------------------------- shared core
def _moments(parent, child, names):
    """Mean relative rotation M, g, h (module docstring) and its SVD, over the paired frames."""
    p, c, frames = paired_frames(parent, child, names)
    Rp, Rc = p.R[frames], c.R[frames]
    dt = c.t[frames] - p.t[frames]
    M = np.einsum("fji,fjk->ik", Rp, Rc) / len(frames)            # mean R_Pᵀ R_C
    g = np.einsum("fji,fj->i", Rp, dt) / len(frames)               # mean R_Pᵀ (t_C - t_P)
    h = np.einsum("fji,fj->i", Rc, dt) / len(frames)               # mean R_Cᵀ (t_C - t_P)
    U, s, Vt = np.linalg.svd(M)
    return p, c, frames, U, np.clip(s, 0.0, 1.0), Vt.T, g, h


def _solve(U, s, V, g, h, free):
    """Minimum-norm solution of the normal equations with the 2 x 2 blocks ``free`` left
    undetermined (their ``1 - s_j`` eigen-direction dropped)."""
    free = free | (s >= 1.0 - 6 * np.finfo(float).eps)             # exact zeros (tol 0)
    gp, hp = U.T @ g, V.T @ h
    den = np.where(free, 1.0, 1.0 - s**2)
    p = np.where(free, (gp + hp) / (2.0 * (1.0 + s)), (gp - s * hp) / den)
    q = np.where(free, -(gp + hp) / (2.0 * (1.0 + s)), (s * gp - hp) / den)
    return U @ p, V @ q


def _residuals(p, c, frames, c_parent, c_child):
    a = np.einsum("fij,j->fi", p.R, c_parent) + p.t
    b = np.einsum("fij,j->fi", c.R, c_child) + c.t
    gap = np.linalg.norm(a - b, axis=1)
    per = np.full(len(gap), np.nan)
    per[frames] = gap[frames]
    return a, b, per, float(np.sqrt(np.mean(gap[frames] ** 2)))


def _singular_values(s, n):
    return np.sqrt(n * np.concatenate([1.0 + s, (1.0 - s)[::-1]]))


def _check_tol(tol):
    if not (np.isfinite(tol) and 0 <= tol < 90):
        raise InputError([f"hinge_tol_deg must be in [0, 90), got {tol!r}"])


# ---------------------------------------------------------------------- estimators
def score(parent, child, hinge_tol_deg: float = HINGE_TOL_DEG, names=("parent", "child")) -> ScoreFit:
    """SCoRE joint centre in both segment frames (Ehrig et al. 2006), vectorised over frames.

    Parameters
    ----------
    parent, child : Poses or array, shape (n_frames, n_markers, 3)
        Segment poses, or marker positions (mm, NaN = occluded, ≥ 3 markers).
    hinge_tol_deg : float
        Rotation spread below which a direction counts as not exercised; those directions are
        left to the minimum-norm choice and ``unique`` is False.
    names : (str, str)
        Segment names for error messages.

    Returns
    -------
    ScoreFit

    Raises
    ------
    InputError
        Fewer than 3 markers, all-NaN markers, mismatched frame counts, or fewer than 3 frames
        with both poses.
    """
    _check_tol(hinge_tol_deg)
    p, c, frames, U, s, V, g, h = _moments(parent, child, names)
    n = len(frames)
    spread = rotation_spread_deg(np.sqrt(n * (1.0 - s)), n)       # ascending, as s descends
    motion, k, reason = classify_motion(spread, hinge_tol_deg)
    free = np.arange(3) < k
    c_parent, c_child = _solve(U, s, V, g, h, free)
    a, b, per, rms = _residuals(p, c, frames, c_parent, c_child)
    sv = _singular_values(s, n)
    kept = sv[: 6 - k]
    dof = 3 * n - len(kept)
    unc = float(np.sqrt(n * rms**2 / dof) / kept[-1]) if dof > 0 else float("nan")
    world = 0.5 * (a + b)
    world[~np.isin(np.arange(len(world)), frames)] = np.nan
    return ScoreFit(centre_parent=c_parent, centre_child=c_child, centre_world=world, motion=motion,
                    unique=motion == "general", reason=reason, rms_residual=rms,
                    frame_residual_mm=per, singular_values=sv, spread_deg=spread,
                    uncertainty_mm=unc, n_frames=n, hinge_tol_deg=float(hinge_tol_deg))


def sara(parent, child, hinge_tol_deg: float = HINGE_TOL_DEG, names=("parent", "child")) -> SaraFit:
    """SARA hinge axis in both segment frames (Ehrig et al. 2007), vectorised over frames.

    Parameters
    ----------
    parent, child : Poses or array, shape (n_frames, n_markers, 3)
        Segment poses, or marker positions (mm, NaN = occluded, ≥ 3 markers).
    hinge_tol_deg : float
        Spread (degrees) below which the motion about a direction counts as absent.
    names : (str, str)
        Segment names for error messages.

    Returns
    -------
    SaraFit
        ``hinge`` says whether the data are single-axis; the axis is returned either way.

    Raises
    ------
    InputError
        As :func:`score`.
    """
    _check_tol(hinge_tol_deg)
    p, c, frames, U, s, V, g, h = _moments(parent, child, names)
    n = len(frames)
    spread = rotation_spread_deg(np.sqrt(n * (1.0 - s)), n)
    motion, _, reason = classify_motion(spread, hinge_tol_deg)
    pt_parent, pt_child = _solve(U, s, V, g, h, np.array([True, False, False]))
    _, _, per, rms = _residuals(p, c, frames, pt_parent, pt_child)
    a_p, a_c = canonical_sign(U[:, 0], V[:, 0])
    return SaraFit(axis_parent=a_p, axis_child=a_c, point_parent=pt_parent, point_child=pt_child,
                   hinge=motion == "single_axis", motion=motion, reason=reason,
                   off_axis_deg=float(spread[0]), rms_residual=rms, frame_residual_mm=per,
                   singular_values=_singular_values(s, n), spread_deg=spread, n_frames=n,
                   hinge_tol_deg=float(hinge_tol_deg))
