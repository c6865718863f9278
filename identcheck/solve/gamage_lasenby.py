"""Spherical joint centre by the closed-form least squares of Gamage & Lasenby (2002).

Gamage & Lasenby (J Biomech 35:87-93, 2002, eq. 5) fit one sphere centre ``c`` shared by
several marker trajectories ``v_k^(i)`` (each marker ``k`` with its own radius ``r_k``) by
minimising ``Σ_k Σ_i (|v_k^(i) - c|² - r_k²)²``. Eliminating the radii leaves a linear system::

    A c = B,    A = 2 Σ_k (mean(v vᵀ) - v̄ v̄ᵀ),    B = Σ_k (mean(|v|² v) - mean(|v|²) v̄),

per-marker covariances and third moments, then ``r_k² = mean |v_k - c|²``. Halvorsen (J Biomech
36:999-1008, 2003) showed the estimate is biased by measurement noise of variance σ² per
coordinate and corrected it (``bias_correction=True``): the fixed point of
``A c = B - 2 σ² Σ_k (v̄_k - c)`` with ``σ² = mean_k var_i(|v_k - c|²) / (4 mean_i |v_k - c|²)``.

Pham et al. (section V-A) extend it to two moving links: three parent markers define per frame
the frame F_GL (origin A1, u1 along A1A2, u2 from A3 - A1 by Gram-Schmidt, u3 = u1 × u2), the
child markers are expressed in F_GL, and the sphere centre found there is constant in F_GL,
hence gives a per-frame world centre. With three child markers this is the classic "3 + 3" use.

Local coordinates in this module put A1A2 on +z, as :func:`identcheck.geometry.frames.pair_frame`
does (section II-A): a point's local (x, y, z) are its components along (u2, u3, u1).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.geometry.frames import parent_frame, to_local, to_world

GL_MIN_FRAMES = 4
"""Fewest complete frames the sphere fit accepts (4 points fix a sphere)."""
EIG_WARN = 1e-6
"""Smallest-to-largest eigenvalue ratio of A below which the centre is ill-determined (warning)."""
EIG_FAIL = 1e-12
"""... and below which it is not determined at all (DegenerateError)."""
BC_LIMIT = 0.5
"""Halvorsen's correction is refused when 2 q σ² exceeds this fraction of A's smallest eigenvalue."""


# ---------------------------------------------------------------------- shared helpers
def complete_frames(markers: dict, n_min: int, method: str) -> tuple[dict, np.ndarray]:
    """Check marker trajectories and keep the frames in which every one of them is present.

    Parameters
    ----------
    markers : dict of str to array, shape (n_frames, 3)
        Named trajectories (the names appear in messages), mm, NaN = occluded.
    n_min : int
        Fewest complete frames the caller's method needs.
    method : str
        Method name for messages.

    Returns
    -------
    kept : dict of str to numpy.ndarray, shape (n_kept, 3)
    frames : numpy.ndarray of int, shape (n_kept,)
        Indices of the kept frames in the input.

    Raises
    ------
    InputError
        Wrong shapes, differing frame counts or markers with no sample at all (all listed).
    DegenerateError
        Fewer than `n_min` complete frames.
    """
    problems, arrays = [], {}
    for name, xyz in markers.items():
        a = np.asarray(xyz, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3:
            problems.append(f"marker {name}: expected shape (n_frames, 3), got {a.shape}")
        elif np.isinf(a).any():
            problems.append(f"marker {name}: infinite coordinates (use NaN for gaps)")
        elif np.isnan(a).any(axis=1).all():
            problems.append(f"marker {name} has no valid sample (NaN in every frame)")
        arrays[name] = a
    counts = {a.shape[0] for a in arrays.values() if a.ndim == 2}
    if len(counts) > 1:
        problems.append("markers have different frame counts: "
                        + ", ".join(f"{n}: {a.shape[0]}" for n, a in arrays.items()))
    if problems:
        raise InputError(problems, source=method)
    ok = np.all([~np.isnan(a).any(axis=1) for a in arrays.values()], axis=0)
    frames = np.flatnonzero(ok)
    if len(frames) < n_min:
        n_total = len(ok)
        raise DegenerateError(f"{method} needs at least {n_min} frames in which all of "
                              f"{', '.join(arrays)} are present; only {len(frames)} of {n_total} are")
    return {n: a[frames] for n, a in arrays.items()}, frames


def distance_variance_cost(centres, parents: Sequence, children: Sequence) -> float:
    """Pham et al.'s quality measure C: summed across-frame variances of marker-centre distances.

    ``C = Σ_p var(|J A_p|) + Σ_q var(|J B_q|)`` (section V-A; population variance, ddof = 0).
    A rigid joint centre keeps every distance constant, so C = 0 for exact data at the truth.

    Parameters
    ----------
    centres : array, shape (n_frames, 3)
        Joint centre per frame (world), mm.
    parents, children : sequence of array, shape (n_frames, 3)
        Parent markers A_p and child markers B_q (world), mm; frames with NaN are skipped.

    Returns
    -------
    float
        C in mm².
    """
    centres = np.asarray(centres, dtype=float)
    total = 0.0
    for m in list(parents) + list(children):
        dist = np.linalg.norm(np.asarray(m, dtype=float) - centres, axis=-1)
        total += float(np.nanvar(dist))
    return total


# ---------------------------------------------------------------------- sphere fit
@dataclass(frozen=True)
class SphereFit:
    """Common sphere centre of several marker trajectories (Gamage & Lasenby, 2002).

    Attributes
    ----------
    centre : numpy.ndarray, shape (3,)
        In the coordinates of the input, mm.
    radii : numpy.ndarray, shape (n_markers,)
        ``sqrt(mean |v_k - c|²)`` per marker, mm.
    rms_residual_mm : float
        RMS of ``|v_k - c| - r_k`` over markers and frames.
    eig_ratio : float
        Smallest / largest eigenvalue of A: how well the motion determines the centre.
    sigma2_mm2 : float or None
        Halvorsen's estimate of the noise variance per coordinate (bias-corrected fit only).
    n_iter : int
        Bias-correction iterations (0 for the plain fit).
    """

    centre: np.ndarray
    radii: np.ndarray
    rms_residual_mm: float
    eig_ratio: float
    sigma2_mm2: float | None = None
    n_iter: int = 0


def _moments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-marker means, covariances and third moments of points, shape (n_frames, k, 3).

    Centred form of Gamage & Lasenby's eq. (5) (same solution, far less round-off): with
    ``u = v - v̄``, ``mean(|v|² v) - mean(|v|²) v̄ = mean(|u|² u) + 2 cov v̄``.
    """
    mean = points.mean(axis=0)                                   # (k, 3)
    u = points - mean
    cov = np.einsum("fki,fkj->kij", u, u) / len(points)          # (k, 3, 3)
    third = np.einsum("fk,fki->ki", np.sum(u * u, axis=-1), u) / len(points)
    return mean, cov, third


def sphere_centre(points, bias_correction: bool = False, max_iter: int = 100,
                  tol_mm: float = 1e-10) -> SphereFit:
    """Least-squares common centre of spheres traced by several markers (closed form).

    Parameters
    ----------
    points : array, shape (n_frames, n_markers, 3) or (n_frames, 3)
        Marker positions in a frame where the centre is fixed, mm, no NaN.
    bias_correction : bool
        Apply Halvorsen's (2003) iterative noise-bias compensation.
    max_iter : int
        Cap on bias-correction iterations.
    tol_mm : float
        Stop iterating when the centre moves less than this.

    Returns
    -------
    SphereFit

    Raises
    ------
    DegenerateError
        The motion does not determine the centre (A singular: every marker moves along a line,
        or all in parallel planes).

    Warns
    -----
    IdentifiabilityWarning
        A is near singular (eigenvalue ratio below ``EIG_WARN``): noise is amplified.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 2:
        pts = pts[:, None, :]
    origin = pts.reshape(-1, 3).mean(axis=0)       # translation invariant: solve near the data
    pts = pts - origin
    mean, cov, third = _moments(pts)
    a = 2.0 * cov.sum(axis=0)
    rhs = third.sum(axis=0) + 2.0 * np.einsum("kij,kj->i", cov, mean)
    eig = np.linalg.eigvalsh(a)
    ratio = float(eig[0] / eig[-1]) if eig[-1] > 0 else 0.0
    if ratio < EIG_FAIL:
        raise DegenerateError("the marker motion does not determine a sphere centre (every "
                              f"marker moves on a line or in parallel planes; eigenvalue ratio {ratio:.2g})")
    if ratio < EIG_WARN:
        warnings.warn(f"the motion barely determines the sphere centre (eigenvalue ratio {ratio:.2g}): "
                      "noise will be amplified", IdentifiabilityWarning, stacklevel=2)
    c = np.linalg.solve(a, rhs)
    sigma2, n_iter = None, 0
    if bias_correction:
        c, sigma2, n_iter = _halvorsen(pts, a, rhs, mean, c, max_iter, tol_mm)
    dist = np.linalg.norm(pts - c, axis=-1)
    radii = np.sqrt(np.mean(dist**2, axis=0))
    rms = float(np.sqrt(np.mean((dist - radii) ** 2)))
    return SphereFit(c + origin, radii, rms, ratio, sigma2, n_iter)


def _halvorsen(pts, a, rhs, mean, c, max_iter, tol_mm):
    """Halvorsen's bias-compensated estimate: the fixed point of ``A c = B - 2 σ² Σ_k (v̄_k - c)``.

    σ² is re-estimated from the current centre (``var(|u|²) ≈ 4 σ² mean(|u|²)`` for ``u = v - c``,
    averaged over the markers), and for each σ² the fixed point is solved for c directly,
    ``(A - 2 q σ² I) c = B - 2 σ² Σ_k v̄_k`` (q markers): the same answer as iterating on c, but
    stable when A is poorly conditioned. When ``2 q σ²`` reaches ``BC_LIMIT`` × the smallest
    eigenvalue of A, the noise is as large as the motion in that direction and no correction is
    meaningful: the plain estimate is kept, with an IdentifiabilityWarning.
    """
    q, lam_min = pts.shape[1], float(np.linalg.eigvalsh(a)[0])
    plain, n_iter, sigma2 = c, 0, 0.0
    for n_iter in range(1, max_iter + 1):
        d2 = np.sum((pts - c) ** 2, axis=-1)                      # (n_frames, q)
        sigma2 = float(np.mean(np.var(d2, axis=0) / (4.0 * np.mean(d2, axis=0))))
        if 2 * q * sigma2 >= BC_LIMIT * lam_min:
            warnings.warn(f"noise (σ² ≈ {sigma2:.3g} mm²) is as large as the motion along its weakest "
                          "direction: bias correction skipped", IdentifiabilityWarning, stacklevel=3)
            return plain, sigma2, 0
        new = np.linalg.solve(a - 2 * q * sigma2 * np.eye(3), rhs - 2.0 * sigma2 * mean.sum(axis=0))
        step = float(np.linalg.norm(new - c))
        c = new
        if step < tol_mm:
            break
    return c, sigma2, n_iter


# ---------------------------------------------------------------------- two moving links
@dataclass(frozen=True)
class GLResult:
    """Joint centre from the Gamage-Lasenby fit in the frame of three parent markers.

    Attributes
    ----------
    centre_local : numpy.ndarray, shape (3,)
        Centre in F_GL, mm: components along (u2, u3, u1), i.e. A1A2 is +z and A3 lies in the
        half-plane x > 0, y = 0 (see :func:`parent_frame`).
    centres_world : numpy.ndarray, shape (n_frames, 3)
        Per-frame world centre, mm; NaN in frames that were dropped (a marker missing).
    radii : numpy.ndarray, shape (n_children,)
        Child-marker distances to the centre, mm.
    cost_mm2 : float
        Pham et al.'s C_GL = Σ_p var|J A_p| + Σ_q var|J B_q| over the used frames, p = 1..3.
    rms_residual_mm : float
        RMS of ``|B_q - c| - r_q`` in F_GL.
    frames : numpy.ndarray of int
        Frames used (all markers present).
    fit : SphereFit
        The underlying sphere fit (in F_GL).
    """

    centre_local: np.ndarray
    centres_world: np.ndarray
    radii: np.ndarray
    cost_mm2: float
    rms_residual_mm: float
    frames: np.ndarray
    fit: SphereFit = field(repr=False)

    @property
    def sqrt_cost_mm(self) -> float:
        """sqrt(C_GL), mm: the figure Pham et al. report (9.65 mm for their jump)."""
        return float(np.sqrt(self.cost_mm2))


def gamage_lasenby(a1, a2, a3, children, *, bias_correction: bool = False,
                   labels: Sequence[str] | None = None) -> GLResult:
    """Joint centre between a three-marker parent and a child with two or more markers.

    Pham et al.'s extension of Gamage & Lasenby to two moving links (section V-A): per frame,
    the parent frame F_GL (origin A1, u1 along A1A2, u2 toward A3, u3 = u1 × u2); the child
    markers in F_GL; one common sphere centre there (:func:`sphere_centre`). With three child
    markers it is the classic 3 + 3 functional joint centre.

    Parameters
    ----------
    a1, a2, a3 : array, shape (n_frames, 3)
        Parent markers (world), mm, NaN = occluded.
    children : sequence of array, shape (n_frames, 3), or array, shape (n_frames, q, 3)
        Child markers B_1..B_q (world), q >= 1, mm.
    bias_correction : bool
        Use Halvorsen's (2003) bias-compensated estimate.
    labels : sequence of str, optional
        Names of a1, a2, a3 and the children for messages (default A1, A2, A3, B1, ...).

    Returns
    -------
    GLResult

    Raises
    ------
    InputError
        Bad shapes or a marker with no sample.
    DegenerateError
        Fewer than ``GL_MIN_FRAMES`` complete frames, coincident A1/A2, collinear parent
        markers, or a motion that does not determine the centre.

    Examples
    --------
    >>> res = gamage_lasenby(l5, lasi, rasi, [rgt, rkne])     # doctest: +SKIP
    >>> res.centre_local, res.sqrt_cost_mm                     # doctest: +SKIP
    """
    kids = _as_list(children)
    names = list(labels) if labels is not None else ["A1", "A2", "A3"] + [f"B{q + 1}" for q in range(len(kids))]
    if len(names) != 3 + len(kids):
        raise InputError([f"{len(names)} labels for {3 + len(kids)} markers"], source="gamage_lasenby")
    kept, frames = complete_frames(dict(zip(names, [a1, a2, a3] + kids)), GL_MIN_FRAMES, "Gamage-Lasenby")
    pa1, pa2, pa3, *pb = kept.values()
    rot, _ = parent_frame(pa1, pa2, pa3 - pa1, names=(names[0], names[1], f"{names[2]} - {names[0]}"))
    local = to_local(rot, pa1, np.stack(pb, axis=1))
    fit = sphere_centre(local, bias_correction=bias_correction)
    n_total = np.asarray(a1).shape[0]
    world = np.full((n_total, 3), np.nan)
    world[frames] = to_world(rot, pa1, fit.centre)
    cost = distance_variance_cost(world[frames], [pa1, pa2, pa3], pb)
    return GLResult(fit.centre, world, fit.radii, cost, fit.rms_residual_mm, frames, fit)


def _as_list(children) -> list:
    """Child trajectories as a list of arrays, shape (n_frames, 3) each."""
    if isinstance(children, np.ndarray) and children.ndim == 3:
        return [children[:, q] for q in range(children.shape[1])]
    return [np.asarray(c, dtype=float) for c in children]
