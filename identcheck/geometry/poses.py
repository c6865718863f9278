"""Segment poses from three or more markers (Kabsch/Horn/Challis least squares), vectorised over frames.

A segment's markers have body-fixed coordinates ``local`` (m, 3); in frame f they are measured
at ``points[f]`` (m, 3, NaN where occluded). The least-squares rotation and translation with
``points[f] ≈ R[f] @ local + t[f]`` come from the weighted cross-covariance (Challis 1995), its rotation
with the reflection guard by Horn's quaternion method (:func:`identcheck.geometry.rotations.best_rotations`,
the SVD's answer without a LAPACK call per frame). Frames with fewer than three visible markers, or
with visible markers (nearly) collinear, get no pose (``valid`` False, NaN R and t).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from identcheck.geometry.rotations import best_rotations

MIN_MARKERS = 3
COLLINEAR_RATIO = 1e-6   # second singular value of the centred local points / first
REFINE_MAX_ITER = 20
"""Default iteration cap of :func:`refine_local` (it needs 2-4 on simulated data)."""
REFINE_TOL_MM = 1e-9
"""Default convergence threshold of :func:`refine_local`: largest change of a body-fixed
coordinate between iterations, mm."""


OFF_LINE_MM = 5.0
"""Markers closer than this to one line (RMS distance, :func:`off_line_mm`) do not pose their segment: its roll about
that line is the noise over their distance from it (at 1 mm of noise and 5 mm, a tenth of a radian in every
frame), and a fit started from such poses flips the roll by half turns from frame to frame. Three anatomical thigh
markers (greater trochanter, lateral thigh, lateral epicondyle) lay within 0.8 mm of one line on a held-out trial
(draw 54, trial 46): its clean rigid fit stopped at 4.5 times the noise floor with the hip's angle jumping by 118°
between frames, and ``diagnose`` named an extra rotation of the knee."""


def off_line_mm(points) -> float:
    """How far points (F, m, 3) lie from one line: the RMS distance of the m points from their best-fitting line,
    median over the frames that see every one of them; 0 for fewer than three points (two always lie on one), and
    infinite when no frame sees all of them (nothing to judge: they are taken to pose their segment, as before)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 3 or pts.shape[1] < 3:
        return 0.0
    full = pts[np.all(np.isfinite(pts), axis=(1, 2))]
    if not len(full):
        return float("inf")
    centred = full - full.mean(axis=1, keepdims=True)
    s = np.linalg.svd(centred, compute_uv=False)                      # (F', 3), largest first
    return float(np.median(np.sqrt((s[:, 1] ** 2 + s[:, 2] ** 2) / pts.shape[1])))


def poses_segment(points) -> bool:
    """Whether points (F, m, 3) fixed in one segment pose it: three or more, not all within :data:`OFF_LINE_MM` of one
    line."""
    pts = np.asarray(points, dtype=float)
    return pts.ndim == 3 and pts.shape[1] >= MIN_MARKERS and off_line_mm(pts) >= OFF_LINE_MM


def farthest_pair(points) -> tuple[int, int]:
    """The two of the points (F, m, 3) farthest apart, by their average places over the frames that see each (the
    line two points fix on a segment is the best fixed when they are far apart)."""
    mean = np.nanmean(np.asarray(points, dtype=float), axis=0)
    far = np.nan_to_num(np.linalg.norm(mean[:, None] - mean[None, :], axis=2))
    a, b = np.unravel_index(int(np.argmax(far)), far.shape)
    return int(a), int(b)


@dataclass(frozen=True)
class Poses:
    """Per-frame rigid poses of one segment: ``points[f] ≈ R[f] @ local.T + t[f]``."""

    R: np.ndarray        # (F, 3, 3)
    t: np.ndarray        # (F, 3)
    valid: np.ndarray    # (F,) bool
    local: np.ndarray    # (m, 3) body-fixed marker coordinates used
    rms: np.ndarray      # (F,) RMS marker residual (mm) of the fit, NaN where not valid

    def to_world(self, local_points) -> np.ndarray:
        """Body-fixed points (k, 3) → world (F, k, 3); NaN in frames without a pose."""
        p = np.asarray(local_points, dtype=float)
        return p @ np.swapaxes(self.R, 1, 2) + self.t[:, None, :]

    def to_local(self, world_points) -> np.ndarray:
        """World points (F, k, 3) → body-fixed (F, k, 3)."""
        w = np.asarray(world_points, dtype=float) - self.t[:, None, :]
        return w @ self.R

    def body_fixed(self, world_track, robust: bool = False) -> np.ndarray:
        """The body-fixed point (3,) that a world trajectory (F, 3) follows: its segment coordinates averaged over
        the frames that pose the segment and see the point (the median with `robust`, else the mean); NaN when
        no frame does. Carried back by :meth:`to_world`, it is the trajectory made rigid in this segment (a joint
        centre estimated in some frames, known in all)."""
        local = self.to_local(np.asarray(world_track, dtype=float)[:, None])[:, 0]
        seen = np.all(np.isfinite(local), axis=1)
        if not seen.any():
            return np.full(3, np.nan)
        return (np.median if robust else np.mean)(local[seen], axis=0)


def reference_shape(points) -> np.ndarray:
    """Body-fixed coordinates from the first frame in which every marker is visible.

    Any rigid placement works as the reference (poses are relative to it); seed 001's eq. (5)
    refinement (``identcheck.geometry.poses.refine_local``, where provided) averages it over frames.
    """
    pts = np.asarray(points, dtype=float)
    full = np.all(np.isfinite(pts), axis=(1, 2))
    if not full.any():
        raise ValueError("no frame has every marker of the segment visible")
    ref = pts[np.argmax(full)]
    return ref - ref.mean(axis=0)


def segment_poses(points, local=None) -> Poses:
    """Least-squares poses of one segment in every frame.

    Parameters
    ----------
    points : array (F, m, 3)
        Measured marker positions, NaN where occluded; m ≥ 3.
    local : array (m, 3), optional
        Body-fixed marker coordinates; by default :func:`reference_shape` of ``points``.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"points must have shape (F, m, 3), got {pts.shape}")
    if pts.shape[1] < MIN_MARKERS:
        raise ValueError(f"a segment pose needs at least {MIN_MARKERS} markers, got {pts.shape[1]}")
    loc = reference_shape(pts) if local is None else np.asarray(local, dtype=float)
    w = np.all(np.isfinite(pts), axis=2).astype(float)            # (F, m) visibility
    n = w.sum(axis=1)
    P = np.where(w[..., None] > 0, pts, 0.0)
    safe = np.maximum(n, 1)[:, None]
    cp = (w[..., None] * P).sum(axis=1) / safe                     # (F, 3) measured centroid
    cl = (w[..., None] * loc[None]).sum(axis=1) / safe             # (F, 3) local centroid
    Pc = (P - cp[:, None]) * w[..., None]
    Lc = (loc[None] - cl[:, None]) * w[..., None]
    H = np.swapaxes(Pc, 1, 2) @ Lc                                 # Σ p lᵀ
    R = best_rotations(H, bound=0.5 * (np.einsum("fki,fki->f", Pc, Pc) + np.einsum("fki,fki->f", Lc, Lc)))
    t = cp - np.einsum("fij,fj->fi", R, cl)
    valid = (n >= MIN_MARKERS) & _spread(w, loc)
    R[~valid] = np.nan
    t[~valid] = np.nan
    pred = loc @ np.swapaxes(R, 1, 2) + t[:, None, :]
    res = np.where(w > 0, np.sum((pred - P) ** 2, axis=2), 0.0)
    rms = np.where(valid, np.sqrt(res.sum(axis=1) / np.maximum(n, 1)), np.nan)
    return Poses(R=R, t=t, valid=valid, local=loc, rms=rms)


def _spread(w: np.ndarray, loc: np.ndarray) -> np.ndarray:
    """Per frame (F,): whether the visible body-fixed points are not (nearly) collinear. It depends on the
    frame only through which markers are seen, so it is decided once per visibility pattern (a trial has a
    handful), not once per frame."""
    seen_all = w > 0
    if seen_all.shape[1] <= 62:             # each pattern as one integer: a 1-D unique, not a sort of rows
        codes = seen_all @ (1 << np.arange(seen_all.shape[1], dtype=np.int64))
        _, first, which = np.unique(codes, return_index=True, return_inverse=True)
        patterns = seen_all[first]
    else:
        patterns, which = np.unique(seen_all, axis=0, return_inverse=True)
    ok = np.zeros(len(patterns), dtype=bool)
    for i, seen in enumerate(patterns):
        if seen.sum() >= 2:
            pts = loc[seen] - loc[seen].mean(axis=0)
            sv = np.linalg.svd(pts, compute_uv=False)
            ok[i] = len(sv) > 1 and sv[1] > COLLINEAR_RATIO * max(sv[0], 1e-300)
    return ok[np.asarray(which).reshape(-1)]


def refine_local(points, n_iter: int = REFINE_MAX_ITER, tol: float = REFINE_TOL_MM,
                 ref_frame: int | None = None) -> tuple[np.ndarray, Poses]:
    """Body-fixed marker coordinates refined by averaging over every frame (seed 001, eq. 5).

    Alternates the two steps of seed 001 (section 5) until the body-fixed coordinates stop
    moving: (1) given ``local``, the least-squares pose ``f(t)`` of every frame (eq. 4,
    :func:`segment_poses`); (2) ``local_i = f(t_ref) · mean_t f(t)⁻¹ y_i(t)`` (eq. 5), the
    average over the frames in which marker i is seen of its position mapped back into the
    body frame, re-expressed in the body frame that coincides with the world at ``t_ref``.
    Step (2) with the poses fixed is the exact minimiser of ``Σ_t Σ_i |y_i(t) − f(t) x_i|²``
    over the ``x_i``, so the loop is block-coordinate descent on that joint least-squares
    problem (generalised Procrustes analysis); its fixed point has ``f(t_ref) = I``.

    Why: the first-frame shape carries that frame's noise into every pose; the refined shape
    carries noise of order ``noise/sqrt(n_frames)`` only, and to first order even that only
    moves the body frame rigidly (a gauge change), never the relative poses.

    Parameters
    ----------
    points : array_like, shape (n_frames, n_markers, 3)
        Marker positions of one rigid segment, mm, NaN where occluded; n_markers ≥ 3.
    n_iter : int
        Most iterations; a ``RuntimeWarning`` says so if they do not reach `tol`.
    tol : float
        Stop when no body-fixed coordinate moves by more than this (mm).
    ref_frame : int, optional
        The frame ``t_ref`` whose pose becomes the identity (seed 001 uses t = 0). Default: the
        first frame with a valid pose. It must have a valid pose.

    Returns
    -------
    local : numpy.ndarray, shape (n_markers, 3)
        Refined body-fixed coordinates, mm, in the world frame of ``t_ref``.
    poses : Poses
        The poses of every frame for that ``local`` (``poses.R[t_ref] ≈ I``).

    Raises
    ------
    ValueError
        Bad shape, fewer than three markers, no frame with a valid pose, a `ref_frame` without
        one, or a marker never seen in a frame with a valid pose.

    Examples
    --------
    >>> local, poses = refine_local(points)                         # doctest: +SKIP
    >>> np.allclose(poses.R[0], np.eye(3)), np.allclose(poses.t[0], 0)   # doctest: +SKIP
    (True, True)
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"points must have shape (F, m, 3), got {pts.shape}")
    if pts.shape[1] < MIN_MARKERS:
        raise ValueError(f"a segment pose needs at least {MIN_MARKERS} markers, got {pts.shape[1]}")
    if not (isinstance(n_iter, (int, np.integer)) and n_iter >= 1):
        raise ValueError(f"n_iter must be a positive integer, got {n_iter!r}")
    local = reference_shape(pts)
    seen = np.isfinite(pts).all(axis=2)                                   # (F, m)
    step = np.inf
    for _ in range(int(n_iter)):
        poses = segment_poses(pts, local)
        if not poses.valid.any():
            raise ValueError("no frame has a valid pose (three non-collinear visible markers)")
        ref = _reference_frame(poses.valid, ref_frame)
        use = seen & poses.valid[:, None]
        count = use.sum(axis=0)
        if (count == 0).any():
            never = ", ".join(str(i) for i in np.flatnonzero(count == 0))
            raise ValueError(f"marker(s) {never} never seen in a frame with a valid pose")
        body = np.where(use[..., None], poses.to_local(np.where(use[..., None], pts, 0.0)), 0.0)
        mean = body.sum(axis=0) / count[:, None]                           # mean_t f(t)^-1 y(t)
        new = mean @ poses.R[ref].T + poses.t[ref]                         # eq. (5): f(t_ref) · mean
        step = float(np.max(np.abs(new - local)))
        local = new
        if step <= tol:
            break
    else:
        warnings.warn(f"refine_local: body-fixed coordinates still moved by {step:.3g} mm after "
                      f"{n_iter} iterations (tol {tol:g} mm)", RuntimeWarning, stacklevel=2)
    return local, segment_poses(pts, local)


def _reference_frame(valid: np.ndarray, ref_frame: int | None) -> int:
    """Index of the gauge frame: `ref_frame` if given (checked), else the first valid frame."""
    if ref_frame is None:
        return int(np.argmax(valid))
    ref = int(ref_frame)
    if not -len(valid) <= ref < len(valid):
        raise ValueError(f"ref_frame {ref_frame} is outside the {len(valid)} frames")
    if not valid[ref]:
        raise ValueError(f"ref_frame {ref_frame} has no valid pose (fewer than three visible, "
                         "non-collinear markers)")
    return ref % len(valid)


def pose_noise_factor(local: np.ndarray, points: np.ndarray) -> np.ndarray:
    """How much a least-squares (Kabsch) pose's own noise moves body-fixed points, per coordinate, in units of the
    markers' noise σ: ``sqrt(1/n + tr([r]x J^-1 [r]x^T) / 3)`` at ``r`` from the centroid of the n markers at
    `local`, with J their inertia tensor (the pose's translation error has covariance σ²/n, its rotation error
    σ² J⁻¹).

    Parameters
    ----------
    local : array, shape (n, 3)
        The body's marker coordinates, mm.
    points : array, shape (k, 3)
        Body-fixed points, mm.

    Returns
    -------
    numpy.ndarray, shape (k,)
    """
    local = np.asarray(local, dtype=float)
    L = local - local.mean(axis=0)
    Jinv = np.linalg.pinv(np.sum(L * L) * np.eye(3) - L.T @ L)
    r = np.atleast_2d(np.asarray(points, dtype=float)) - local.mean(axis=0)
    X = np.zeros((len(r), 3, 3))                                          # [r]x
    X[:, 0, 1], X[:, 0, 2], X[:, 1, 2] = -r[:, 2], r[:, 1], -r[:, 0]
    X -= np.transpose(X, (0, 2, 1))
    return np.sqrt(1.0 / len(L) + np.einsum("kij,jl,kil->k", X, Jinv, X) / 3.0)
