"""Ball-joint centre from two rigid marker clusters, with a calibrated covariance (seed 001).

Two-stage estimator of seed 001 (``/work/shared/papers/001_9593b07cc1e5af33.txt``):

1. **Segment poses.** Each segment (three or more markers) gets a rigid pose per frame, with
   body-fixed marker coordinates refined over all frames (eq. 5,
   :func:`identcheck.geometry.poses.refine_local`).
2. **Centre.** The joint constraint ``f0(t)·c0 = f1(t)·c1`` (eq. 2/10) is linear in the centre:
   ``R0(t) c0 − R1(t) c1 = d1(t) − d0(t)``. Its least-squares solution is refined by the
   Gauss–Markov estimator (eqs. 11–23): each frame's equation is weighted by the inverse
   covariance of the two segments' predictions of the centre, which follows from the marker
   noise; the inverse of the normal matrix is the linearised covariance of the centre.
3. **Marker noise** (section 8) comes from the scatter of inter-marker distances within each
   rigid segment (here robustly, by the median absolute deviation), unless given.
4. **Validation index** (eq. 16): ``v = sqrt(e/3)``, ``e`` the Mahalanobis distance of the
   estimate from the truth under the predicted covariance.

Where this module departs from the print (see ``derivations/ERRATA.md, seed 001``):

* Unknowns. Seed 001 makes both body frames coincide with the world at t = 0 and then solves
  for one point ``c = c0 = c1`` (eq. 9, "reduce by half the number of variables"). That hard
  constraint treats the frame-0 relative pose, as noisy as any other frame's, as exact: the
  centre inherits the frame-0 pose error (millimetres with lever arms of a few hundred mm) and
  it does not shrink with more frames, while the predicted covariance does. The default
  ``method="pair"`` solves for ``c0`` and ``c1`` separately (6 unknowns, every frame weighted
  alike). ``method="paper"`` keeps eq. 9 and eqs. 12–15 as printed for comparison.
* Per-frame covariance. Instead of a 6×6 pose covariance pushed through eq. (14), the covariance
  of each segment's prediction of the centre is written in closed form: for isotropic noise
  σ² per coordinate on n visible markers with centroid x̄ and inertia ``J = Σ(|q|² I − q qᵀ)``
  (``q = x − x̄``), ``Cov = σ² (I/n + [r]× J⁻¹ [r]×ᵀ)`` with ``r = c − x̄``: the same thing, with
  the rotation–translation correlation of a pose expressed far from its markers built in.
* O(σ²) corrections (``bias_correction``). The rows of the constraint hold noisy rotations,
  so the Gauss–Markov estimate is biased at O(σ²) (errors in variables, and a noisy rotation
  places a far point slightly towards its markers) and the bias does not shrink with frames;
  the normal matrix also contains noise that poses as excitation. Both expected terms are
  removed (:func:`_bias_term`, :func:`_noise_information`); the second gives the
  ``information_fraction`` on which the excitation verdict rests (rotation about one axis:
  the fraction is about 0 and the uncertainty infinite).
* Serial correlation. Eq. (12) takes frames as independent. The lag-1 autocorrelation of the
  whitened residuals is reported, warned about, and optionally allowed for (``serial="ar1"``).
* Frame of the covariance. Eq. (12) also ignores that all poses share the estimated body-fixed
  coordinates. To first order their error only moves a body frame rigidly (a gauge change), so
  the covariance is that of the centre relative to the parent's markers;
  :meth:`CentreFit.in_frame` compares with a truth on that footing.

Conventions: positions in mm; ``noise_mm`` is the standard deviation of each coordinate of a
marker (``sqrt(tr Wy) = sqrt(3)·noise_mm`` in the paper's terms); covariances in mm².
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg
from scipy.spatial.transform import Rotation

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.geometry.poses import MIN_MARKERS, Poses, refine_local, segment_poses
from identcheck.geometry.rotations import skew

MIN_FRAMES = 3
"""Fewest frames with valid poses of both segments (two rotations about different axes, plus
the reference)."""
MAD_TO_SD = 1.482602218505602
"""Median absolute deviation → standard deviation for Gaussian data (1 / Φ⁻¹(3/4))."""
SINGULAR_RTOL = 1e-14
"""Smallest-to-largest eigenvalue ratio of the normal matrix below which the centre is not
determined at all (:class:`DegenerateError`): within ~50 rounding errors of singular. Short,
barely moving trials sit just above it and are judged by the excitation check instead."""
INFO_OK = 0.7
"""Information fraction (see :attr:`CentreFit.information_fraction`) below which the motion
counts as near-degenerate: ``excitation_ok`` False and :class:`IdentifiabilityWarning`. In
Monte-Carlo runs the covariance is calibrated above about 0.7 (RMS validation index ≤ 1.05),
about 15% optimistic in the standard deviation at 0.5 and far off below 0.4, where higher-order
errors-in-variables bias takes over (``benchmarks/bench_seed001.py``)."""
INFO_FAIL = 0.25
"""... and below which the centre counts as not determined along the weakest direction:
``uncertainty_mm`` is infinite."""
SERIAL_WARN = 0.2
"""Lag-1 residual autocorrelation above which ``serial="white"`` warns (if also > 3 s.e.)."""
GM_MAX_ITER = 20
GM_TOL_MM = 1e-9
METHODS = ("pair", "paper")
SERIAL = ("white", "ar1")


# ---------------------------------------------------------------------- noise (section 8)
@dataclass(frozen=True)
class NoiseEstimate:
    """Marker noise from the scatter of inter-marker distances within rigid segments.

    Attributes
    ----------
    noise_mm : float
        Standard deviation of one coordinate of one marker, mm (isotropic noise assumed).
    distance_sd_mm : float
        Robust standard deviation of an inter-marker distance about its median, mm
        (the paper's σ_d); ``noise_mm = distance_sd_mm / sqrt(2)``.
    n_pairs : int
        Marker pairs used (both markers on the same segment).
    n_samples : int
        Distance samples used (pairs × frames in which both are visible).
    """

    noise_mm: float
    distance_sd_mm: float
    n_pairs: int
    n_samples: int


def marker_noise(*segments) -> NoiseEstimate:
    """Estimate isotropic marker noise from how much distances within rigid segments vary.

    For two markers on one rigid segment the distance d(t) varies only by noise: to first
    order ``δd = u·(n_i − n_j)`` (u the unit direction between them), whose variance is
    ``2σ²`` for independent isotropic noise of σ per coordinate (seed 001, section 8:
    ``3σ_d² = 2 tr Wy``). Each pair's distances are centred on their own median and the pooled
    deviations of all pairs give ``σ_d = 1.4826 · median|d − median(d)|``; median-based so
    that occasional gross errors (swaps, ghost markers) and a minority of bad frames do not
    inflate it.

    Parameters
    ----------
    *segments : array_like, each shape (n_frames, n_markers, 3)
        Marker positions of one rigid segment each, mm, NaN where occluded. Segments with
        fewer than two markers contribute nothing.

    Returns
    -------
    NoiseEstimate

    Raises
    ------
    InputError
        Bad shapes, or no pair of markers seen together in at least two frames.
    """
    devs, n_pairs, problems = [], 0, []
    for k, seg in enumerate(segments):
        pts = np.asarray(seg, dtype=float)
        if pts.ndim != 3 or pts.shape[2] != 3:
            problems.append(f"segment {k}: expected shape (n_frames, n_markers, 3), got {pts.shape}")
            continue
        i, j = np.triu_indices(pts.shape[1], k=1)
        d = np.linalg.norm(pts[:, i] - pts[:, j], axis=2)              # (F, n_pairs), NaN if gap
        ok = np.isfinite(d).sum(axis=0) >= 2
        if ok.any():
            dev = d[:, ok] - np.nanmedian(d[:, ok], axis=0)
            devs.append(dev[np.isfinite(dev)])
            n_pairs += int(ok.sum())
    if problems:
        raise InputError(problems, source="marker_noise")
    if not devs:
        raise InputError(["no two markers of one segment are seen together in two or more frames: "
                          "the marker noise cannot be estimated (pass noise_mm)"], source="marker_noise")
    dev = np.concatenate(devs)
    sd = float(MAD_TO_SD * np.median(np.abs(dev)))
    return NoiseEstimate(noise_mm=sd / np.sqrt(2.0), distance_sd_mm=sd, n_pairs=n_pairs,
                         n_samples=int(dev.size))


# ---------------------------------------------------------------------- eq. (9)
def centre_eq9(parent: Poses, child: Poses) -> np.ndarray:
    """Seed 001's analytic centre, eq. (9): one point with the same coordinates in both frames.

    With ``f(t)·c = R(t)(c − p(t))``, ``p = −Rᵀd`` (eq. 7), minimising
    ``Σ_t |f0(t)·c − f1(t)·c|²`` (eq. 6) gives
    ``[2N I − Σ R0ᵀR1 − Σ R1ᵀR0] c = Σ [p0 + p1 − R0ᵀR1 p1 − R1ᵀR0 p0]``.
    Meaningful only when the two body frames coincide at some instant (then ``c0 = c1``), as
    :func:`~identcheck.geometry.poses.refine_local` with a common ``ref_frame`` arranges.

    Parameters
    ----------
    parent, child : Poses
        Poses of the two segments over the same frames; frames where either is invalid are
        skipped.

    Returns
    -------
    numpy.ndarray, shape (3,)
        The centre, mm, in the (shared) body frame.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_FRAMES` frames with both poses valid.
    DegenerateError
        The matrix of eq. (9) is singular (no motion, or rotation about a single axis).
    """
    R0, d0, R1, d1 = _both_valid(parent, child)
    p0 = -np.einsum("fji,fj->fi", R0, d0)
    p1 = -np.einsum("fji,fj->fi", R1, d1)
    Q = np.einsum("fji,fjk->fik", R0, R1)                               # R0ᵀR1
    A = 2 * len(Q) * np.eye(3) - Q.sum(axis=0) - Q.sum(axis=0).T
    b = (p0 + p1 - np.einsum("fij,fj->fi", Q, p1) - np.einsum("fji,fj->fi", Q, p0)).sum(axis=0)
    _check_normal_matrix(A, "eq. (9)")
    return np.linalg.solve(A, b)


# ---------------------------------------------------------------------- result
@dataclass(frozen=True)
class CentreFit:
    """A ball-joint centre with its linearised covariance (seed 001).

    Attributes
    ----------
    centre_parent, centre_child : numpy.ndarray, shape (3,)
        The centre in the parent's and the child's body frame (the frames of
        ``parent_local`` / ``child_local``), mm.
    covariance : numpy.ndarray, shape (3, 3)
        Covariance of ``centre_parent``, mm²; relative to the parent's markers (see
        :meth:`in_frame` for why that is the meaningful frame). ``σ² (A − N)⁻¹`` with the
        noise-corrected information (``bias_correction``), else ``σ² A⁻¹`` (eq. 23).
    covariance_child : numpy.ndarray, shape (3, 3)
        Covariance of ``centre_child``, mm².
    covariance_full : numpy.ndarray, shape (6, 6)
        Joint covariance of (centre_parent, centre_child), mm².
    uncertainty_mm : float
        1-σ error of ``centre_parent`` along its worst direction: ``sqrt(λ_max(covariance))``;
        ``inf`` when the motion does not determine the centre along some direction
        (``information_fraction < INFO_FAIL``; ``covariance`` is then the uncorrected
        linearised one, a lower bound).
    rms_uncertainty_mm : float
        ``sqrt(tr covariance)``, the RMS length of the error vector (seed 001's Table 1
        column); ``inf`` with ``uncertainty_mm``.
    weakest_direction : numpy.ndarray, shape (3,)
        Unit eigenvector of ``covariance`` for ``λ_max``, parent frame (when not determined:
        the direction along which it is not).
    noise_mm : float
        Marker noise used (per coordinate, mm); estimated unless given.
    noise_estimated : bool
    n_frames : int
        Frames with valid poses of both segments (those used).
    rms_residual : float
        RMS over those frames of the distance between the centre as placed by the parent and
        by the child, mm.
    residual_autocorr : float
        Lag-1 autocorrelation of the whitened per-frame residuals over consecutive frames used;
        about 0 for white noise (± 1/sqrt(3 n_frames)). Large values mean serially correlated
        noise or a misfit (soft tissue, joint play): the covariance is then optimistic.
    covariance_inflation : float
        Factor applied to the Gauss–Markov covariance (1 unless ``serial="ar1"``).
    chi2_dof : float
        ``Σ_t r_tᵀ W_t⁻¹ r_t / (3 n_frames − k)`` (k = 6, or 3 for ``method="paper"``). About 1
        when the noise model (white, isotropic, ``noise_mm``) explains the residuals; NaN when
        ``noise_mm`` is 0.
    information_fraction : float
        Smallest generalised eigenvalue of ``(A − N, A)``: A the Gauss–Markov normal matrix, N
        its expected part due to pose noise alone (noisy rotations in the rows,
        :func:`_noise_information`). 1: every direction's information comes from real motion;
        ≤ 0: along the weakest direction the apparent excitation is all noise (e.g. rotation
        about one axis). Below :data:`INFO_OK` ``excitation_ok`` is False; below
        :data:`INFO_FAIL` the uncertainty is infinite.
    excitation_ok : bool
    excitation_reason : str
    rotation_spread_deg : numpy.ndarray, shape (3,)
        RMS spread of the child's rotation relative to the parent about its principal axes,
        largest first, degrees.
    method : str
        ``"pair"`` (6 unknowns, default) or ``"paper"`` (eq. 9: one point, frames coincident at
        ``ref_frame``).
    n_iter : int
        Gauss–Markov iterations used.
    parent, child : Poses
        The refined segment poses (``parent.local``, ``child.local`` are the body frames).
    frames : numpy.ndarray of int
        Indices of the frames used.
    """

    centre_parent: np.ndarray
    centre_child: np.ndarray
    covariance: np.ndarray
    covariance_child: np.ndarray
    covariance_full: np.ndarray
    uncertainty_mm: float
    rms_uncertainty_mm: float
    weakest_direction: np.ndarray
    noise_mm: float
    noise_estimated: bool
    n_frames: int
    rms_residual: float
    chi2_dof: float
    residual_autocorr: float
    covariance_inflation: float
    information_fraction: float
    excitation_ok: bool
    excitation_reason: str
    rotation_spread_deg: np.ndarray
    method: str
    n_iter: int
    parent: Poses = field(repr=False)
    child: Poses = field(repr=False)
    frames: np.ndarray = field(repr=False)

    @property
    def parent_local(self) -> np.ndarray:
        """Refined body-fixed coordinates of the parent's markers, shape (m0, 3), mm."""
        return self.parent.local

    @property
    def child_local(self) -> np.ndarray:
        """Refined body-fixed coordinates of the child's markers, shape (m1, 3), mm."""
        return self.child.local

    def centre_world(self) -> np.ndarray:
        """The centre in the world at every frame, as placed by the parent, shape (F, 3), mm."""
        return self.parent.to_world(self.centre_parent[None])[:, 0]

    def marker_distances(self, labels_parent: Sequence[str] = (), labels_child: Sequence[str] = ()) -> dict:
        """Each marker's distance to the centre (mm), parent markers first; names default to
        ``p0, p1, ...`` / ``c0, c1, ...``."""
        out = {}
        for local, c, labels, tag in ((self.parent_local, self.centre_parent, labels_parent, "p"),
                                      (self.child_local, self.centre_child, labels_child, "c")):
            names = list(labels) or [f"{tag}{i}" for i in range(len(local))]
            out.update({n: float(v) for n, v in zip(names, np.linalg.norm(local - c, axis=1))})
        return out

    def in_frame(self, local_true) -> tuple[np.ndarray, np.ndarray]:
        """The centre and its covariance moved into another frame of the parent's markers.

        ``local_true`` (shape (m0, 3), same marker order) are the parent's markers in the
        target frame, e.g. a simulation's true segment frame. The rigid motion that best maps
        ``parent_local`` onto them (least squares) moves the centre; the covariance rotates.

        Why this frame: the body frame of a fit is defined by its own (noisy) marker
        coordinates. To first order a shape error only moves the body frame rigidly, and the
        fitted centre moves with it, so the centre *relative to the markers* is the quantity
        whose error the covariance predicts.

        Returns
        -------
        centre : numpy.ndarray, shape (3,)
        covariance : numpy.ndarray, shape (3, 3)
        """
        target = np.asarray(local_true, dtype=float)
        if target.shape != self.parent_local.shape:
            raise ValueError(f"local_true must have shape {self.parent_local.shape}, got {target.shape}")
        pose = segment_poses(target[None], local=self.parent_local)     # the one Kabsch fit, one frame
        R, t = pose.R[0], pose.t[0]
        return R @ self.centre_parent + t, R @ self.covariance @ R.T

    def validation_index(self, centre_true, local_true=None) -> float:
        """Seed 001's validation index, eq. (16): ``v = sqrt(e/3)``, ``e = δᵀ W⁻¹ δ``.

        Parameters
        ----------
        centre_true : array_like, shape (3,)
            The true centre in the parent frame, mm.
        local_true : array_like, shape (m0, 3), optional
            The parent's markers in the frame of `centre_true`; the estimate is first moved
            there (:meth:`in_frame`). Without it `centre_true` must be in this fit's parent frame.

        Returns
        -------
        float
            With a correct covariance ``E[v²] = 1`` and ``E[v] = 2√2/√(3π) ≈ 0.921``. NaN when
            the centre is not determined (``uncertainty_mm`` infinite).
        """
        if not np.isfinite(self.uncertainty_mm):
            return float("nan")
        if local_true is None:
            c, W = self.centre_parent, self.covariance
        else:
            c, W = self.in_frame(local_true)
        return validation_index(c, centre_true, W)


# ---------------------------------------------------------------------- public entry points
def validation_index(estimate, truth, covariance) -> float:
    """Eq. (16): ``v = sqrt(e/3)``, ``e = (c − c_true)ᵀ W_c⁻¹ (c − c_true)`` (3-D centres).

    For Gaussian errors with covariance ``W_c``, ``e ~ χ²₃``: ``E[v²] = 1`` and
    ``E[v] = 2√2/√(3π) ≈ 0.921`` (not 1, as seed 001 states). Infinite when ``W_c`` is singular
    and the error is not in its range.
    """
    delta = np.asarray(estimate, dtype=float) - np.asarray(truth, dtype=float)
    W = np.asarray(covariance, dtype=float)
    if delta.shape != (3,) or W.shape != (3, 3):
        raise ValueError(f"expected a 3-vector and a 3x3 covariance, got {delta.shape}, {W.shape}")
    try:
        e = float(delta @ np.linalg.solve(W, delta))
    except np.linalg.LinAlgError:
        return float("inf") if np.any(delta) else 0.0
    return float(np.sqrt(max(e, 0.0) / 3.0))


EXPECTED_MEAN_V = float(2 * np.sqrt(2) / np.sqrt(3 * np.pi))
"""E[v] for a correct covariance: E[sqrt(χ²₃/3)] = 2√2/√(3π) ≈ 0.9213."""


def fit_centre(parent_points, child_points, noise_mm: float | None = None, method: str = "pair",
               ref_frame: int | None = None, bias_correction: bool = True, serial: str = "white",
               n_iter: int = GM_MAX_ITER, tol: float = GM_TOL_MM, warn: bool = True) -> CentreFit:
    """Ball-joint centre between two rigid marker clusters, with its covariance (seed 001).

    Parameters
    ----------
    parent_points, child_points : array_like, shape (n_frames, m, 3)
        Marker positions of the parent and of the child segment, mm, NaN where occluded;
        m ≥ 3 each, the same frames.
    noise_mm : float, optional
        Marker noise, standard deviation per coordinate, mm. Default: estimated from both
        segments by :func:`marker_noise`.
    method : {"pair", "paper"}
        ``"pair"``: unknowns c0 (parent frame) and c1 (child frame), every frame weighted by
        its covariance. ``"paper"``: seed 001 as printed, one point c in body frames that
        coincide with the world at ``ref_frame`` (eq. 9 start, eqs. 12–15 Gauss–Markov).
    ref_frame : int, optional
        Gauge frame of :func:`refine_local` (``"paper"``: the frame where both body frames
        coincide). Default: the first frame in which both segments have a valid pose.
    bias_correction : bool
        Remove the O(σ²) effects of noisy rotations in the rows of the constraint: the bias of
        the Gauss–Markov estimating equation (:func:`_bias_term`), which does not shrink with
        more frames while the standard deviation does, and the noise part of the normal matrix
        (:func:`_noise_information`), which poses as excitation. Seed 001 has neither.
    serial : {"white", "ar1"}
        ``"white"`` (seed 001): marker noise independent from frame to frame. ``"ar1"``: allow
        for serially correlated noise by inflating the covariance by ``(1 + ρ)/(1 − ρ)``, ρ the
        lag-1 autocorrelation of the whitened residuals (``residual_autocorr``, if positive):
        the variance factor of a mean of an AR(1) series, apt because the weights vary slowly.
    n_iter : int
        Most Gauss–Markov iterations (the weights depend on the centre).
    tol : float
        Stop when the centre moves by less than this, mm.
    warn : bool
        Emit the warnings below (the result records the same verdicts either way).

    Returns
    -------
    CentreFit

    Raises
    ------
    InputError
        Bad shapes, fewer than three markers on a segment, differing frame counts, fewer than
        :data:`MIN_FRAMES` frames with valid poses of both segments, a bad `method` or
        `noise_mm` (all problems listed at once).
    DegenerateError
        The motion does not determine the centre at all (no rotation, or rotation about one
        fixed axis without noise): the normal matrix is singular.

    Warns
    -----
    IdentifiabilityWarning
        ``information_fraction`` below :data:`INFO_OK`: along some direction (for rotation about
        one axis, that axis) much of the apparent excitation is pose noise, so the centre is
        poorly determined there (infinite uncertainty below :data:`INFO_FAIL`).
    UserWarning
        ``serial="white"`` but the residuals of consecutive frames are clearly correlated
        (lag-1 autocorrelation above :data:`SERIAL_WARN` and 3 standard errors): the covariance
        is then too small.

    Examples
    --------
    >>> sim = simulate(Model.from_toml("examples/hip_s22.toml"), n_frames=600, noise_mm=0.5)  # doctest: +SKIP
    >>> fit = fit_centre(sim.trial.select(["L5", "LPELVIS", "RPELVIS"]).xyz,
    ...                  sim.trial.select(["RHIP", "RKNEE", "RTHI"]).xyz)                      # doctest: +SKIP
    >>> fit.uncertainty_mm                                                                     # doctest: +SKIP
    """
    P0, P1 = _check_inputs(parent_points, child_points, noise_mm, method, serial)
    valid0 = _valid_frames(P0)
    valid1 = _valid_frames(P1)
    both = valid0 & valid1
    if both.sum() < MIN_FRAMES:
        raise InputError([f"only {int(both.sum())} frame(s) have at least {MIN_MARKERS} visible "
                          f"markers on both segments; seed 001 needs at least {MIN_FRAMES}"],
                         source="fit_centre")
    ref = int(np.argmax(both)) if ref_frame is None else ref_frame
    try:
        _, pose0 = refine_local(P0, ref_frame=ref)
        _, pose1 = refine_local(P1, ref_frame=ref)
    except ValueError as exc:
        raise InputError([str(exc)], source="fit_centre") from None
    if noise_mm is None:
        noise = marker_noise(P0, P1).noise_mm
    else:
        noise = float(noise_mm)
    frames = np.flatnonzero(pose0.valid & pose1.valid)
    if len(frames) < MIN_FRAMES:
        raise InputError([f"only {len(frames)} frame(s) have valid poses of both segments; "
                          f"seed 001 needs at least {MIN_FRAMES}"], source="fit_centre")
    seen0 = np.isfinite(P0[frames]).all(axis=2)
    seen1 = np.isfinite(P1[frames]).all(axis=2)
    R0, d0 = pose0.R[frames], pose0.t[frames]
    R1, d1 = pose1.R[frames], pose1.t[frames]

    M, y = _design(R0, R1, d0, d1, method)
    Mt = np.swapaxes(M, 1, 2)
    # start: unweighted least squares (method "paper": exactly eq. 9)
    A = (Mt @ M).sum(axis=0)
    _check_normal_matrix(A, "the centre's least-squares system")
    a = np.linalg.solve(A, (Mt @ y[..., None]).sum(axis=0)[:, 0])
    geo0 = _cluster_geometry(pose0.local, seen0)
    geo1 = _cluster_geometry(pose1.local, seen1)
    noise2 = noise**2 if bias_correction else 0.0
    it = 0
    for it in range(1, int(n_iter) + 1):
        new, A, Wi = _gauss_markov_step(a, M, Mt, y, R0, R1, geo0, geo1, noise2, method)
        step = float(np.max(np.abs(new - a)))
        a = new
        if step <= tol:
            break
    c0, c1 = _split(a, method)
    _, A, Wi = _gauss_markov_step(a, M, Mt, y, R0, R1, geo0, geo1, 0.0, method)
    r = M @ a - y                                                       # per-frame centre mismatch
    rho = _lag1_autocorrelation(r, Wi, frames)
    inflation = (1 + rho) / (1 - rho) if serial == "ar1" and rho > 0 else 1.0

    # how much of the information A is real excitation rather than pose noise
    A_real = A - _noise_information(R0, R1, geo0, geo1, Wi, noise**2, method)
    lam, vec = scipy.linalg.eigh(A_real, A)                             # A_real v = λ A v
    fraction = float(lam[0])
    weak = vec[:3, 0] / max(np.linalg.norm(vec[:3, 0]), 1e-300)
    identified = fraction >= INFO_FAIL
    info = A_real if bias_correction and identified else A
    cov_a = np.linalg.inv(info) * noise**2 * inflation                  # eq. (23)
    cov_a = (cov_a + cov_a.T) / 2
    cov_full = cov_a if method == "pair" else np.block([[cov_a, cov_a], [cov_a, cov_a]])
    cov0, cov1 = cov_full[:3, :3], cov_full[3:, 3:]
    ev, evec = np.linalg.eigh(cov0)
    spread = _rotation_spread(R0, R1)
    motion = (f"the child's rotation relative to the parent spreads {spread[0]:.3g}°, {spread[1]:.3g}°, "
              f"{spread[2]:.3g}° (RMS) about its principal axes")
    ok = fraction >= INFO_OK
    if ok:
        reason = f"{motion}; {fraction:.0%} of the information along the weakest direction is real motion"
    else:
        reason = (f"{motion}: along {np.round(weak, 3).tolist()} (parent frame) only {max(fraction, 0):.0%} of "
                  "the apparent information is real motion, the rest is pose noise, so the centre is "
                  + ("not determined along it (uncertainty infinite)" if not identified else
                     "poorly determined along it and its covariance may be optimistic")
                  + "; add rotation about a second axis")
        if warn:
            warnings.warn(reason, IdentifiabilityWarning, stacklevel=2)
    unc = float(np.sqrt(max(ev[-1], 0.0))) if identified else float("inf")
    rms_unc = float(np.sqrt(max(np.trace(cov0), 0.0))) if identified else float("inf")
    k = 6 if method == "pair" else 3
    chi2 = float(np.sum(r * (Wi @ r[..., None])[..., 0])) / noise**2 / max(3 * len(frames) - k, 1) \
        if noise > 0 else float("nan")
    n_pairs = int(np.sum(np.diff(frames) == 1))
    if warn and serial == "white" and noise > 0 and rho > max(SERIAL_WARN, 3 / np.sqrt(max(3 * n_pairs, 1))):
        warnings.warn(f"consecutive residuals are correlated (lag-1 autocorrelation {rho:.2f}): the noise "
                      "is not white, so the covariance, which assumes it is, is too small by a factor of "
                      f"about {(1 + rho) / (1 - rho):.2g} in variance; pass serial='ar1' to allow for it",
                      UserWarning, stacklevel=2)
    return CentreFit(
        centre_parent=c0, centre_child=c1, covariance=cov0, covariance_child=cov1,
        covariance_full=cov_full, uncertainty_mm=unc, rms_uncertainty_mm=rms_unc,
        weakest_direction=evec[:, -1] if identified else weak, noise_mm=noise,
        noise_estimated=noise_mm is None, n_frames=len(frames),
        rms_residual=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))), chi2_dof=chi2,
        residual_autocorr=rho, covariance_inflation=float(inflation),
        information_fraction=fraction, excitation_ok=ok, excitation_reason=reason,
        rotation_spread_deg=spread, method=method, n_iter=it, parent=pose0, child=pose1,
        frames=frames)


def fit_joint(trial, model, joint: str, **kw) -> CentreFit:
    """:func:`fit_centre` for a spherical joint of a model, on a recorded trial.

    Parameters
    ----------
    trial : identcheck.trial.Trial
    model : identcheck.io.model.Model
    joint : str
        A spherical joint of `model`; its parent and child segments need three or more
        markers each.
    **kw
        Passed to :func:`fit_centre`.

    Raises
    ------
    InputError
        Unknown or non-spherical joint, a segment with fewer than three markers or markers
        missing from the trial (all listed).
    """
    if joint not in model.joints:
        raise InputError([f"no joint {joint!r} in the model (it has {', '.join(model.joints) or 'none'})"],
                         source=model.source)
    j = model.joints[joint]
    if j.type != "spherical":
        raise InputError([f"joint {joint!r} is {j.type}; seed 001 fits a ball (spherical) joint's centre, "
                          "which a hinge does not have (it is free along the axis)"], source=model.source)
    problems = [f"segment {seg!r} ({side} of joint {joint!r}) has {len(model.segments[seg].markers)} "
                f"marker(s); seed 001 needs at least {MIN_MARKERS} on each segment"
                for side, seg in (("parent", j.parent), ("child", j.child))
                if len(model.segments[seg].markers) < MIN_MARKERS]
    if problems:
        raise InputError(problems, source=model.source)
    mp, mc = model.joint_markers(joint)
    return fit_centre(trial.select(mp).xyz, trial.select(mc).xyz, **kw)


# ---------------------------------------------------------------------- pieces
def _check_inputs(parent_points, child_points, noise_mm, method, serial):
    problems, arrays = [], []
    for name, pts in (("parent", parent_points), ("child", child_points)):
        try:
            a = np.asarray(pts, dtype=float)
        except (TypeError, ValueError) as exc:
            problems.append(f"{name} points are not numeric ({exc})")
            arrays.append(None)
            continue
        if a.ndim != 3 or a.shape[2] != 3:
            problems.append(f"{name} points: expected shape (n_frames, n_markers, 3), got {a.shape}")
        elif a.shape[1] < MIN_MARKERS:
            problems.append(f"{name} segment has {a.shape[1]} marker(s); seed 001 needs at least "
                            f"{MIN_MARKERS} on each segment")
        elif np.isinf(a).any():
            problems.append(f"{name} points contain infinite coordinates (use NaN for gaps)")
        elif not np.isfinite(a).all(axis=2).any():
            problems.append(f"{name} points are NaN in every frame")
        arrays.append(a)
    if all(a is not None and a.ndim == 3 for a in arrays) and arrays[0].shape[0] != arrays[1].shape[0]:
        problems.append(f"parent has {arrays[0].shape[0]} frames, child {arrays[1].shape[0]}")
    if method not in METHODS:
        problems.append(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if serial not in SERIAL:
        problems.append(f"serial must be one of {', '.join(SERIAL)}, got {serial!r}")
    if noise_mm is not None and not (isinstance(noise_mm, (int, float, np.number)) and np.isfinite(noise_mm)
                                     and noise_mm >= 0):
        problems.append(f"noise_mm must be a finite number >= 0, got {noise_mm!r}")
    if problems:
        raise InputError(problems, source="fit_centre")
    return arrays


def _valid_frames(pts: np.ndarray) -> np.ndarray:
    """Frames with at least three visible markers, shape (F,) bool (collinearity checked later)."""
    return np.isfinite(pts).all(axis=2).sum(axis=1) >= MIN_MARKERS


def _both_valid(parent: Poses, child: Poses):
    if len(parent.valid) != len(child.valid):
        raise InputError([f"parent has {len(parent.valid)} poses, child {len(child.valid)}"],
                         source="centre_eq9")
    ok = parent.valid & child.valid
    if ok.sum() < MIN_FRAMES:
        raise InputError([f"only {int(ok.sum())} frame(s) have valid poses of both segments; "
                          f"seed 001 needs at least {MIN_FRAMES}"], source="centre_eq9")
    return parent.R[ok], parent.t[ok], child.R[ok], child.t[ok]


def _design(R0, R1, d0, d1, method):
    """Rows of the joint constraint ``M a = y`` per frame: M shape (F, 3, k), y shape (F, 3)."""
    y = d1 - d0                                                         # eq. (15)
    if method == "pair":
        M = np.concatenate([R0, -R1], axis=2)                           # a = (c0, c1)
    else:
        M = R0 - R1                                                     # eq. (13), a = c
    return M, y


def _split(a, method):
    return (a[:3], a[3:]) if method == "pair" else (a, a)


def _gauss_markov_step(a, M, Mt, y, R0, R1, geo0, geo1, noise2, method):
    """One Gauss–Markov update (eqs. 20, 22): weights at the current centre `a`, then solve.

    ``W_t`` is the covariance of ``M_t a − y_t`` per unit marker noise (sum of the two segments'
    :func:`_prediction_covariance`). With ``noise2 > 0`` the O(σ²) bias of the estimating
    equation (:func:`_bias_term`) is removed. Returns the new `a`, the normal matrix
    ``A = Σ M_tᵀ W_t⁻¹ M_t`` (``σ² A⁻¹`` is eq. 23) and the weights ``W_t⁻¹``.
    """
    c0, c1 = _split(a, method)
    W = _prediction_covariance(R0, c0, geo0) + _prediction_covariance(R1, c1, geo1)
    Wi = np.linalg.inv(W)
    MtW = Mt @ Wi                                                       # (F, k, 3)
    A = (MtW @ M).sum(axis=0)
    _check_normal_matrix(A, "the Gauss–Markov normal matrix")
    target = y
    extra = 0.0
    if noise2 > 0:
        extra, mean_r = _bias_term(R0, R1, c0, c1, geo0, geo1, Wi, noise2, method)
        target = y + mean_r
    rhs = (MtW @ target[..., None]).sum(axis=0)[:, 0] + extra
    return np.linalg.solve(A, rhs), A, Wi


def _check_normal_matrix(A: np.ndarray, what: str) -> None:
    """DegenerateError naming the free direction when `A` is (numerically) singular."""
    lam, vec = np.linalg.eigh((A + A.T) / 2)
    if not (lam[-1] > 0) or lam[0] <= SINGULAR_RTOL * lam[-1]:
        free = np.round(vec[:3, 0] / max(np.linalg.norm(vec[:3, 0]), 1e-300), 3).tolist()
        raise DegenerateError(
            f"{what} is singular (eigenvalue ratio {lam[0] / lam[-1] if lam[-1] > 0 else 0:.2e}): "
            "the motion does not determine the centre; it is free along "
            f"{free} in the parent frame (no rotation, or rotation about a single fixed axis); "
            "add rotation about a second axis")


@dataclass(frozen=True)
class _Geometry:
    """Per-frame centroid (F, 3), inverse inertia (F, 3, 3) and count (F,) of visible markers."""

    centroid: np.ndarray
    inertia_inv: np.ndarray
    count: np.ndarray


def _cluster_geometry(local: np.ndarray, seen: np.ndarray) -> _Geometry:
    w = seen.astype(float)                                              # (F, m)
    n = w.sum(axis=1)
    centroid = (w @ local) / n[:, None]
    q = (local[None] - centroid[:, None]) * w[..., None]                # (F, m, 3)
    J = np.sum(q * q, axis=(1, 2))[:, None, None] * np.eye(3) - np.einsum("fki,fkj->fij", q, q)
    return _Geometry(centroid, np.linalg.inv(J), n)


def _prediction_covariance(R: np.ndarray, c: np.ndarray, geo: _Geometry) -> np.ndarray:
    """Covariance (world, per unit noise σ = 1) of a segment's per-frame prediction of a body point.

    The least-squares pose of n markers with isotropic noise σ² per coordinate has centroid
    error ``n̄ ~ N(0, σ²/n I)`` and, independently, small-rotation error
    ``φ ~ N(0, σ² J⁻¹)``; the body point c is placed at ``R(c − x̄) + ȳ``, whose error
    ``φ × R(c − x̄) + n̄`` has covariance ``R (I/n + [r]× J⁻¹ [r]×ᵀ) Rᵀ σ²``, ``r = c − x̄``
    (body frame). Shape (F, 3, 3).
    """
    S = skew(c[None] - geo.centroid)                                   # (F, 3, 3)
    body = np.eye(3) / geo.count[:, None, None] + S @ geo.inertia_inv @ np.swapaxes(S, 1, 2)
    return R @ body @ np.swapaxes(R, 1, 2)


_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0


def _bias_term(R0, R1, c0, c1, geo0, geo1, Wi, noise2, method):
    """Expected value at the true centre of the Gauss–Markov estimating equation, to O(σ²).

    The estimate solves ``ψ(a) = Σ_t M_tᵀ G_t (M_t a − y_t) = 0`` (G_t = W_t⁻¹, per unit
    noise). At the true ``a`` the residual is the difference of the two segments' errors in
    placing the centre, ``r_t = ε0 − ε1`` with ``εα = Exp(φα) rα − rα + n̄α`` (``rα = Rα(cα − x̄α)``
    world, φα the pose's rotation error, n̄α its centroid error). ``E[ψ] ≠ 0`` at O(σ²):

    * ``E[δM_tᵀ G_t r_t]``: the rows ``M_t`` hold the same noisy rotations,
      ``δRα = [φα]× Rα``; per segment ``Rαᵀ E[[φα]× G [rα]× φα]``, whose i-th component is
      ``ε_ijk (G [rα]× Σφα)_kj`` (errors-in-variables);
    * ``M_tᵀ G_t E[r_t]``: the second-order mean of rotating a far point with a noisy rotation,
      ``E[Exp(φ) r − r] = ½ (Σφ − tr(Σφ) I) r``: each segment places the centre slightly
      towards its own markers;

    with ``Σφα = σ² Rα Jα⁻¹ Rαᵀ``. The bias of â is ``−A⁻¹ Σ_t E[ψ_t]``; it does not depend on the
    number of frames, unlike the standard deviation. (The noise of the weights G_t themselves
    adds a term about 50 times smaller on simulated hips; it is left out.)

    Returns
    -------
    eiv : numpy.ndarray, shape (k,)
        ``Σ_t E[δM_tᵀ G_t r_t]``; k = 6 (``pair``) or 3 (``paper``).
    mean_r : numpy.ndarray, shape (F, 3)
        ``E[r_t]``; so ``Σ_t E[ψ_t] = eiv + Σ_t M_tᵀ G_t mean_r_t``.
    """
    blocks, mean_r = [], 0.0
    for R, c, geo, sign in ((R0, c0, geo0, 1.0), (R1, c1, geo1, -1.0)):
        r = np.einsum("fij,fj->fi", R, c[None] - geo.centroid)
        Sphi = noise2 * R @ geo.inertia_inv @ np.swapaxes(R, 1, 2)
        B = Wi @ skew(r) @ Sphi
        eiv = np.einsum("ijk,fkj->fi", _LEVI_CIVITA, B)                 # E[[φ]× G [r]× φ]
        blocks.append(np.einsum("fji,fj->i", R, eiv))                   # Rᵀ ·
        shrink = 0.5 * (np.einsum("fij,fj->fi", Sphi, r) - np.trace(Sphi, axis1=1, axis2=2)[:, None] * r)
        mean_r = mean_r + sign * shrink                                 # E[r] = E[ε0] − E[ε1]
    eiv = np.concatenate(blocks) if method == "pair" else blocks[0] + blocks[1]
    return eiv, mean_r


_SKEW_BASIS = skew(np.eye(3))
"""``[φ]× = Σ_k φ_k K_k``: ``_SKEW_BASIS[k]`` is the cross-product matrix of the k-th unit vector."""


def _skew_sandwich(Sphi: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``E[[φ]×ᵀ G [φ]×] = Σ_kn Σφ_kn K_kᵀ G K_n`` per frame (F, 3, 3), for φ with covariance `Sphi` (F, 3, 3): nine
    batched 3×3 products (a four-operand einsum took twelve times as long on 1500 frames, the same numbers)."""
    out = np.zeros(G.shape)
    for k in range(3):
        left = _SKEW_BASIS[k].T @ G
        for n in range(3):
            out += Sphi[:, k, n, None, None] * (left @ _SKEW_BASIS[n])
    return out


def _noise_information(R0, R1, geo0, geo1, Wi, noise2, method) -> np.ndarray:
    """Expected part of the normal matrix ``A = Σ_t M_tᵀ G_t M_t`` due to pose noise alone.

    The rows ``M_t = [R0, −R1]`` hold estimated rotations ``Exp(φα) Rα``. To O(σ²),
    ``Exp(φ) R = R + [φ]× R + ½ [φ]×² R`` and ``E[½ [φ]×²] = ½ (Σφ − tr(Σφ) I)``, so with
    ``D_t = E[δM_t]`` (that second-order mean, per block) ``E[M_tᵀ G M_t] = M̄_tᵀ G M̄_t + N_t``,

    ``N_t = E[δM¹_tᵀ G δM¹_t] + M̄_tᵀ G D_t + D_tᵀ G M̄_t``,

    with the first term block-diagonal, ``Rαᵀ E[[φα]×ᵀ G [φα]×] Rα`` and
    ``E[[φ]×ᵀ G [φ]×] = Σ_kn Σφ_kn K_kᵀ G K_n`` (``Σφα = σ² Rα Jα⁻¹ Rαᵀ``). The first term adds
    apparent information (noise posing as motion), the second removes some (a noisy rotation
    is on average a slight contraction). The information that motion really supplies is
    ``A − N`` (M̄ ≈ M, an O(σ³) error). ``method="paper"`` (``M = R0 − R1``): the blocks summed.
    Same units as ``A``. Shape (6, 6) or (3, 3).
    """
    blocks, means = [], []
    for R, geo, sign in ((R0, geo0, 1.0), (R1, geo1, -1.0)):
        Sphi = noise2 * R @ geo.inertia_inv @ np.swapaxes(R, 1, 2)
        E = _skew_sandwich(Sphi, Wi)
        blocks.append(np.einsum("fji,fjk,fkl->il", R, E, R, optimize=True))
        shrink = 0.5 * (Sphi - np.trace(Sphi, axis1=1, axis2=2)[:, None, None] * np.eye(3))
        means.append(sign * shrink @ R)                                 # E[δM²] block
    if method == "pair":
        first = scipy.linalg.block_diag(*blocks)
        M = np.concatenate([R0, -R1], axis=2)
        D = np.concatenate(means, axis=2)
    else:
        first = blocks[0] + blocks[1]
        M = R0 - R1
        D = means[0] + means[1]
    cross = np.einsum("fki,fkl,flj->ij", M, Wi, D, optimize=True)
    return first + cross + cross.T


def _lag1_autocorrelation(r: np.ndarray, Wi: np.ndarray, frames: np.ndarray) -> float:
    """Lag-1 autocorrelation of whitened residuals ``z_t = Lᵀ r_t`` (``W_t⁻¹ = L Lᵀ``) over
    pairs of consecutive frames; 0 when there is no such pair or no residual."""
    z = (np.swapaxes(np.linalg.cholesky(Wi), 1, 2) @ r[..., None])[..., 0]
    pair = np.diff(frames) == 1
    den = float(np.sum(z * z))
    if not pair.any() or den == 0:
        return 0.0
    return float(np.sum(z[:-1][pair] * z[1:][pair]) / pair.sum() / (den / len(z)))


def _rotation_spread(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """RMS spread (degrees, largest first) of the child's rotation relative to the parent about
    its principal axes, shape (3,): a description of the motion for messages."""
    rel = Rotation.from_matrix(np.einsum("fji,fjk->fik", R0, R1))       # parent-from-child
    dev = (rel * rel.mean().inv()).as_rotvec()                          # left deviations, parent frame
    sv = np.linalg.svd(dev - dev.mean(axis=0), compute_uv=False)
    spread = np.zeros(3)
    spread[:len(sv)] = np.rad2deg(sv / np.sqrt(len(dev)))
    return spread
