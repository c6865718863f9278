"""Joint location from two segments' poses by stacked SVD least squares (O'Brien et al. 2000).

For a joint between a parent (inboard) segment P and a child (outboard) segment C, with
world-from-segment poses ``x_world = R[f] @ x + t[f]`` in every frame f, the joint is the pair
of points ``c`` (child frame) and ``l`` (parent frame) that stay together (eq. 10)::

    R_C[f] c + t_C[f] = R_P[f] l + t_P[f]          for every frame f.

Stacked over the n usable frames this is ``Q̂ u = d`` (eqs. 11-15) with ``u = [c; l]``,
``Q_f = [R_C[f], -R_P[f]]`` (3 x 6) and ``d_f = -(t_C[f] - t_P[f])``; it is solved by the SVD
pseudo-inverse (eqs. 16-17), which picks the minimum-norm solution ``|c|² + |l|²`` when the
motion leaves directions undetermined (section 3.1). The residual vectors ``e_f = Q_f u - d_f``
(eq. 18) are the world-frame gaps between the joint as carried by the child and by the parent.

Why the singular values say what they say
-----------------------------------------
``Q_fᵀ Q_f = [[I, -R_Cᵀ R_P], [-R_Pᵀ R_C, I]]``, so ``Q̂ᵀQ̂ = n [[I, -Mᵀ], [-M, I]]`` with
``M = mean_f R_P[f]ᵀ R_C[f]`` the mean relative rotation. Its eigenvalues are ``n (1 ± s_j)``
for the singular values ``1 ≥ s_1 ≥ s_2 ≥ s_3 ≥ 0`` of M: the three largest singular values of
Q̂ are at least √n whatever the motion, and only the three smallest,
``σ = √(n (1 - s_j))``, carry information. ``s_j = 1`` exactly when every relative rotation
leaves one direction fixed, i.e. the motion is about a single axis (section 3.2). We turn each
of the three small singular values into a scale-free *rotation spread* angle
``φ = 2 arcsin(σ / √(2n))``: for rotations about one axis by ±α/2 it is exactly α/2, and in
general it is about the RMS rotation angle about that direction. Directions with ``φ`` below
``hinge_tol_deg`` are treated as undetermined (their ``W⁻¹`` entry set to zero, as section 3.1
prescribes for "near zero" singular values, for which the paper gives no scale):

- no spread below the tolerance: ``motion="general"``, a unique joint centre;
- one: ``motion="single_axis"``; the centre is any point on the hinge axis (the minimum-norm one
  is returned), and the axis is the right singular vector of the smallest singular value, its
  first three components in the *child* (outboard) frame and the last three in the *parent*
  (inboard) frame (the paper prints them the other way round: erratum O1 in
  ``derivations/ERRATA.md, seed 002``);
- two or three: ``motion="none"``; the segments hardly rotate relative to each other, and any
  point fits.

This is the same estimator as SCoRE/SARA (Ehrig et al. 2006, 2007): see
:mod:`identcheck.estimate.score_sara`, which reaches the same numbers through the 3 x 3 matrix M.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from identcheck.errors import InputError
from identcheck.geometry.poses import MIN_MARKERS, Poses, segment_poses

HINGE_TOL_DEG = 2.0
"""Rotation spread (degrees) below which a direction counts as not exercised (section 3.2)."""
MIN_FRAMES = 3
"""Fewest frames with both poses: two relative orientations always share an axis (Euler), so
two frames never determine a joint centre."""
MOTIONS = ("general", "single_axis", "none")


# ---------------------------------------------------------------------- input handling
def as_poses(segment, name: str = "segment") -> Poses:
    """A segment's poses, from :class:`Poses` (returned as is) or marker points.

    Parameters
    ----------
    segment : Poses or array, shape (n_frames, n_markers, 3)
        Poses, or measured marker positions in mm with NaN where occluded (n_markers ≥ 3).
    name : str
        Used in error messages.

    Returns
    -------
    Poses

    Raises
    ------
    InputError
        Wrong shape, fewer than 3 markers, all NaN, or no frame with every marker visible.
    """
    if isinstance(segment, Poses):
        return segment
    pts = np.asarray(segment, dtype=float)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise InputError([f"segment {name!r}: marker points must have shape (n_frames, n_markers, 3), "
                          f"got {pts.shape}"])
    if pts.shape[1] < MIN_MARKERS:
        raise InputError([f"segment {name!r} has {pts.shape[1]} marker(s); a segment pose needs at "
                          f"least {MIN_MARKERS}"])
    if not np.isfinite(pts).any():
        raise InputError([f"segment {name!r}: every marker coordinate is NaN (no visible marker in "
                          "any frame)"])
    try:
        return segment_poses(pts)
    except ValueError as exc:
        raise InputError([f"segment {name!r}: {exc}"]) from None


def paired_frames(parent, child, names=("parent", "child"), min_frames: int = MIN_FRAMES):
    """Both segments' poses and the frames in which both have one.

    Parameters
    ----------
    parent, child : Poses or array, shape (n_frames, n_markers, 3)
        See :func:`as_poses`.
    names : (str, str)
        Segment names for error messages.
    min_frames : int
        Fewest frames with both poses accepted.

    Returns
    -------
    parent, child : Poses
    frames : numpy.ndarray of int
        Indices of the frames with both poses, shape (n,).

    Raises
    ------
    InputError
        Bad segment input (:func:`as_poses`), different frame counts, or fewer than
        `min_frames` frames with both poses.
    """
    p = as_poses(parent, names[0])
    c = as_poses(child, names[1])
    if p.R.shape[0] != c.R.shape[0]:
        raise InputError([f"segments {names[0]!r} and {names[1]!r} have {p.R.shape[0]} and "
                          f"{c.R.shape[0]} frames; they must come from the same trial"])
    frames = np.flatnonzero(p.valid & c.valid)
    if len(frames) < min_frames:
        raise InputError([f"segments {names[0]!r} and {names[1]!r} both have a pose in only "
                          f"{len(frames)} frame(s) (of {p.R.shape[0]}); a joint fit needs at least "
                          f"{min_frames}"])
    return p, c, frames


def rotation_spread_deg(sigma_small, n_frames: int) -> np.ndarray:
    """Rotation spread angles (degrees) from the three smallest singular values of Q̂.

    ``φ = 2 arcsin(σ / √(2 n))``; σ² / n = 1 - s_j (module docstring), so φ = arccos(s_j):
    the spread of the relative rotations about the corresponding direction.
    """
    x = np.clip(np.asarray(sigma_small, dtype=float) / np.sqrt(2.0 * n_frames), 0.0, 1.0)
    return np.degrees(2.0 * np.arcsin(x))


def classify_motion(spread_deg, tol_deg: float) -> tuple[str, int, str]:
    """(motion, number of undetermined directions, reason) from the ascending spreads."""
    k = int(np.sum(np.asarray(spread_deg) < tol_deg))
    sp = ", ".join(f"{s:.3g}" for s in spread_deg)
    if k == 0:
        return "general", 0, f"rotation spreads ({sp}) deg all exceed {tol_deg:g} deg"
    if k == 1:
        return "single_axis", 1, (f"relative rotation is about a single axis (spreads {sp} deg; tolerance "
                                  f"{tol_deg:g} deg): the centre is any point on the axis; rotate about a "
                                  "second axis to locate it")
    return "none", k, (f"the segments hardly rotate relative to each other (spreads {sp} deg; tolerance "
                       f"{tol_deg:g} deg): any point fits")


def canonical_sign(a_parent: np.ndarray, a_child: np.ndarray):
    """Flip an axis pair together so that the parent-frame axis's largest component is positive."""
    s = 1.0 if a_parent[np.argmax(np.abs(a_parent))] >= 0 else -1.0
    return s * a_parent, s * a_child


# ---------------------------------------------------------------------- result
@dataclass(frozen=True)
class JointFit:
    """O'Brien et al. joint fit between a parent (inboard) and a child (outboard) segment.

    Attributes
    ----------
    centre_parent : numpy.ndarray
        Joint location in the parent frame (the paper's l_i), shape (3,), mm.
    centre_child : numpy.ndarray
        Joint location in the child frame (the paper's c_i), shape (3,), mm. When the motion
        is single-axis (or absent) these are the minimum-norm solution, one of many.
    axis_parent, axis_child : numpy.ndarray or None
        Unit hinge axis in the parent / child frame, shape (3,), when ``motion`` is
        "single_axis" (same sign in both frames, largest parent component positive); else None.
    motion : str
        "general", "single_axis" or "none" (module docstring).
    unique : bool
        Whether the data determine the joint centre (``motion == "general"``).
    reason : str
        Why (the rotation spreads against the tolerance).
    rms_residual : float
        RMS over frames of |e_f|, the gap between the joint as carried by each segment, mm.
    epsilon_printed : float
        Eq. (19) as printed, ``sqrt(Σ|e_f|²) / n`` = rms_residual / √n, mm (erratum O2).
    frame_residual_mm : numpy.ndarray
        |e_f| per frame, NaN in frames without both poses, shape (n_frames,).
    singular_values : numpy.ndarray
        Singular values of Q̂, descending, shape (6,).
    spread_deg : numpy.ndarray
        Rotation spread about the three least-exercised directions, ascending, shape (3,).
    uncertainty_mm : float
        Standard error of the worst-determined identified direction of ``[c; l]``, mm:
        ``sqrt(RSS / (3n - 6)) / σ_min_kept``. Assumes independent residuals across frames,
        so it is a lower bound for smooth (autocorrelated) motion; NaN if 3n ≤ 6.
    n_frames : int
        Frames used (both poses present).
    hinge_tol_deg : float
    """

    centre_parent: np.ndarray
    centre_child: np.ndarray
    axis_parent: np.ndarray | None
    axis_child: np.ndarray | None
    motion: str
    unique: bool
    reason: str
    rms_residual: float
    epsilon_printed: float
    frame_residual_mm: np.ndarray
    singular_values: np.ndarray
    spread_deg: np.ndarray
    uncertainty_mm: float
    n_frames: int
    hinge_tol_deg: float

    def reversed(self) -> "JointFit":
        """The same fit with the parent and child roles exchanged.

        Swapping the roles maps ``u = [c; l]`` to ``[l; c]`` and ``Q̂, d`` to ``-Q̂`` with columns
        swapped, ``-d``: singular values and residuals are unchanged (section 3.3: "the joint fit
        error for the edge implied by P(i) = j and by P(j) = i are the same").
        """
        return replace(self, centre_parent=self.centre_child, centre_child=self.centre_parent,
                       axis_parent=self.axis_child, axis_child=self.axis_parent)

    def centre_world(self, parent: Poses, child: Poses) -> np.ndarray:
        """Joint centre in the world, mean of its images through both segments, shape (n_frames, 3)."""
        a = np.einsum("fij,j->fi", parent.R, self.centre_parent) + parent.t
        b = np.einsum("fij,j->fi", child.R, self.centre_child) + child.t
        return 0.5 * (a + b)


# ---------------------------------------------------------------------- the estimator
def stacked_system(parent, child, names=("parent", "child")):
    """The stacked linear system of eq. (15) over the frames in which both segments have a pose.

    Parameters
    ----------
    parent, child : Poses or array, shape (n_frames, n_markers, 3)
        The inboard (P(i)) and outboard (i) segment, see :func:`as_poses`.

    Returns
    -------
    Q : numpy.ndarray
        ``[R_C[f], -R_P[f]]`` stacked (eq. 14), shape (3n, 6).
    d : numpy.ndarray
        ``-(t_C[f] - t_P[f])`` stacked (eq. 12), shape (3n,), mm.
    frames : numpy.ndarray of int
        The n frames used, shape (n,).

    Raises
    ------
    InputError
        See :func:`paired_frames`.
    """
    p, c, frames = paired_frames(parent, child, names)
    Q = np.concatenate([c.R[frames], -p.R[frames]], axis=2).reshape(-1, 6)
    d = -(c.t[frames] - p.t[frames]).reshape(-1)
    return Q, d, frames


def joint_location(parent, child, hinge_tol_deg: float = HINGE_TOL_DEG,
                   names=("parent", "child"), hinge: bool = False) -> JointFit:
    """Fit the joint between two segments by stacked SVD least squares (O'Brien et al., eqs. 11-19).

    Parameters
    ----------
    parent : Poses or array, shape (n_frames, n_markers, 3)
        The inboard segment: its poses, or its marker positions (mm, NaN = occluded, ≥ 3
        markers), from which poses are computed with
        :func:`identcheck.geometry.poses.segment_poses`.
    child : Poses or array, shape (n_frames, n_markers, 3)
        The outboard segment, likewise.
    hinge_tol_deg : float
        Rotation spread below which a direction counts as not exercised (module docstring).
    names : (str, str)
        Segment names for error messages.
    hinge : bool
        The joint is declared a hinge: take the single-axis solution even when every spread
        exceeds the tolerance (real joints wobble off their axis); the smallest spread, the wobble,
        is left for the caller to judge.

    Returns
    -------
    JointFit

    Raises
    ------
    InputError
        Fewer than 3 markers, all-NaN markers, mismatched frame counts, or fewer than
        :data:`MIN_FRAMES` frames in which both segments have a pose.

    Examples
    --------
    >>> fit = joint_location(thigh_points, shank_points)          # doctest: +SKIP
    >>> fit.motion, fit.centre_parent, fit.rms_residual           # doctest: +SKIP
    """
    if not (np.isfinite(hinge_tol_deg) and 0 <= hinge_tol_deg < 90):
        raise InputError([f"hinge_tol_deg must be in [0, 90), got {hinge_tol_deg!r}"])
    p, c, _ = paired_frames(parent, child, names)
    Q, d, frames = stacked_system(p, c, names)
    n = len(frames)
    U, W, Vt = np.linalg.svd(Q, full_matrices=False)               # eq. (16)
    spread = rotation_spread_deg(W[3:][::-1], n)                   # ascending
    motion, k, reason = classify_motion(spread, hinge_tol_deg)
    if hinge and motion == "general":
        motion, k = "single_axis", 1
        reason = (f"declared hinge: single-axis solution; it wobbles {spread[0]:.3g} deg off the axis "
                  f"(rotation spreads {', '.join(f'{x:.3g}' for x in spread)} deg)")
    keep = np.ones(6, dtype=bool)
    keep[6 - k:] = False                                           # W⁻¹ := 0 for those (3.1)
    keep &= W > 6 * np.finfo(float).eps * W[0]                     # exact zeros (tol 0)
    winv = np.where(keep, 1.0 / np.where(keep, W, 1.0), 0.0)
    u = Vt.T @ (winv * (U.T @ d))                                  # eq. (17)
    e = (Q @ u - d).reshape(n, 3)                                  # eq. (18)
    en = np.linalg.norm(e, axis=1)
    rss = float(np.sum(en**2))
    frame_res = np.full(p.R.shape[0], np.nan)
    frame_res[frames] = en
    dof = 3 * n - int(keep.sum())
    unc = float(np.sqrt(rss / dof) / W[keep][-1]) if dof > 0 else float("nan")
    axis_p = axis_c = None
    if motion == "single_axis":
        v = Vt[5]
        axis_p, axis_c = canonical_sign(v[3:] / np.linalg.norm(v[3:]), v[:3] / np.linalg.norm(v[:3]))
    return JointFit(centre_parent=u[3:].copy(), centre_child=u[:3].copy(), axis_parent=axis_p,
                    axis_child=axis_c, motion=motion, unique=motion == "general", reason=reason,
                    rms_residual=float(np.sqrt(rss / n)), epsilon_printed=float(np.sqrt(rss) / n),
                    frame_residual_mm=frame_res, singular_values=W, spread_deg=spread,
                    uncertainty_mm=unc, n_frames=n, hinge_tol_deg=float(hinge_tol_deg))
