"""Spherical joint from two markers per link on noisy data: the S22 algorithm (Pham et al., V-A).

Parent markers A1, A2, child markers B1, B2. Per frame, the frame F_S22 has origin A1, u1 along
A1A2, u2 from a fixed vector v (drawn from a seed, checked non-collinear with A1A2 in every
frame) and u3 = u1 × u2; coordinates are taken along (u2, u3, u1), so A2 is on +z as in
section II-A. For joint constants x = (d, r, ρ1, ρ2):

* Γ(d, r) is the circle z = d, radius r, about the z axis: where the centre must be in the
  parent's frame;
* Γ'(B1, B2, ρ1, ρ2) is the circle of points at distance ρ1 from B1 and ρ2 from B2 (the
  intersection of two spheres), where the centre must be for the child. When the spheres do not
  meet, (ρ1, ρ2) is replaced by the nearest pair (a, b) of realisable distances
  (|a - b| <= |B1B2| <= a + b, Euclidean projection): Γ' is then the single point of the B1B2
  axis minimising (|JB1| - ρ1)² + (|JB2| - ρ2)², the natural (continuous) extension;
* J_opt minimises d(J, Γ) + d(J, Γ'). That minimum is the distance between the circles and is
  attained on the whole segment joining a closest pair (P ∈ Γ, Q ∈ Γ'), so J_opt is *defined*
  as the midpoint (P + Q) / 2. The closest pair is found for all frames at once: the distance
  from P(φ) ∈ Γ to Γ' in closed form, a grid over φ plus the angles where Γ crosses the plane
  and the sphere of Γ', then safeguarded Newton steps (:func:`closest_points`). When the circles
  nearly meet at two places, noise can make the other one the closer: J_opt then jumps there in
  that frame (a property of the definition, visible as outlying frames in the benchmark).

The cost is ``C(x) = Σ_{p=1,2} var|J_opt A_p| + Σ_{q=1,2} var|J_opt B_q|`` across frames
(population variance). It is minimised by multi-start local least squares
(``scipy.optimize.least_squares``, Levenberg-Marquardt), seeded by the linear (2, 2) solution of
section IV-C when :mod:`identcheck.solve.spherical22` provides it, by a Gamage-Lasenby sphere fit
in F_S22, and by random starts; there is no penalty term.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from identcheck.errors import DegenerateError, InputError
from identcheck.geometry.frames import parent_frame, to_local, to_world
from identcheck.solve.gamage_lasenby import complete_frames, distance_variance_cost, sphere_centre

S22_MIN_FRAMES = 9
"""The (2, 2) case is 9-identifiable (section IV-C): fewer complete frames are refused."""
PARAMS = ("d", "r", "rho1", "rho2")
N_GRID = 64
"""Grid over the angle of Γ before the Newton refinement of the closest pair."""
N_BASINS = 3
"""Lowest grid minima refined per frame: the closest pair's basin is not always the one with the
lowest grid value (a steep basin next to a shallow one)."""
SHARED_STEPS = 2
"""Newton steps taken from every start before the best start per frame is kept."""
NEWTON_STEPS = 12
"""Cap on Newton steps from the best start (quadratic convergence needs far fewer)."""
SMALL_STEP = 1e-6
"""Newton steps below this (rad) are taken without the descent check (round-off near g = 0)."""
CONVERGED_STEP = 1e-10
"""A frame stops iterating once its Newton steps are below this (rad): quadratic convergence."""
V_CANDIDATES = 16
"""Random vectors drawn from the seed; the one farthest from A1A2 over all frames is kept."""
FD_STEP = 1e-7
"""Relative step of the forward differences (J_opt is exact to round-off, so ~sqrt(eps))."""
ALT_REL = 0.05
"""Another local minimum within this relative cost of the best is reported as an alternative."""
ALT_MM = 1.0
"""... if its parameters differ from the best by more than this (max abs, mm)."""


# ---------------------------------------------------------------------- geometry
def choose_v(direction, seed: int = 0) -> np.ndarray:
    """A fixed unit vector v, drawn from `seed`, non-collinear with A1A2 in every frame.

    ``V_CANDIDATES`` Gaussian directions are drawn (``np.random.default_rng(seed)``); the one
    whose smallest sine with A1A2 over the frames is largest is kept, so the frame F_S22 is well
    defined in every frame (the S22 cost itself does not depend on v: rolling F about A1A2
    rotates Γ onto itself).

    Parameters
    ----------
    direction : array, shape (n_frames, 3)
        A2 - A1 per frame.
    seed : int

    Returns
    -------
    numpy.ndarray, shape (3,)
    """
    e = np.asarray(direction, dtype=float)
    e = e / np.linalg.norm(e, axis=-1, keepdims=True)
    cand = np.random.default_rng(seed).normal(size=(V_CANDIDATES, 3))
    cand /= np.linalg.norm(cand, axis=-1, keepdims=True)
    sine = np.sqrt(np.clip(1.0 - (e @ cand.T) ** 2, 0.0, None)).min(axis=0)
    return cand[int(np.argmax(sine))]


def realisable_radii(rho1, rho2, length):
    """Project (ρ1, ρ2) on the distance pairs a point can have to two points `length` apart.

    The set ``{(a, b): |a - b| <= length <= a + b}``; with ρ >= 0 at most one inequality is
    violated, and its projection moves both radii by the same amount. Inside the set, (ρ1, ρ2)
    is returned unchanged.
    """
    a, b, length = np.broadcast_arrays(np.abs(rho1), np.abs(rho2), length)
    short = np.maximum(length - a - b, 0.0) / 2          # spheres apart: grow both
    over1 = np.maximum(a - b - length, 0.0) / 2          # sphere 2 inside sphere 1
    over2 = np.maximum(b - a - length, 0.0) / 2          # sphere 1 inside sphere 2
    return a + short - over1 + over2, b + short + over1 - over2


def spheres_circle(b1, b2, rho1, rho2):
    """Γ'(B1, B2, ρ1, ρ2): the circle at distance ρ1 from B1 and ρ2 from B2, per frame.

    Radii that no point realises are first made realisable (:func:`realisable_radii`); the
    circle is then a single point of the axis (radius 0).

    Parameters
    ----------
    b1, b2 : array, shape (n_frames, 3)
    rho1, rho2 : float

    Returns
    -------
    centre : numpy.ndarray, shape (n_frames, 3)
    normal : numpy.ndarray, shape (n_frames, 3)
        Unit B1 -> B2.
    radius : numpy.ndarray, shape (n_frames,)
    """
    e = b2 - b1
    length = np.linalg.norm(e, axis=-1)
    normal = e / length[:, None]
    a, b = realisable_radii(rho1, rho2, length)
    t = (length**2 + a**2 - b**2) / (2 * length)
    radius = np.sqrt(np.clip(a**2 - t**2, 0.0, None))
    return b1 + t[:, None] * normal, normal, radius


def _circle_gap(phi, d, r, centre, normal, radius, derivatives: bool = True):
    """Squared distance g(φ) from P(φ) = (r cos φ, r sin φ, d) on Γ to the circle Γ', with g', g''.

    With ``w = P - c'``, ``w_n = w·n`` and ``s = |w - w_n n|`` (distance to the axis of Γ'),
    ``g = w_n² + (s - ρ')²``, ρ' the radius of Γ' (written as a sum of squares, not expanded,
    so that g stays accurate near 0). Shapes broadcast: `phi` (n, m) against per-frame (n, 1)
    quantities. Without `derivatives`, g alone.
    """
    cph, sph = np.cos(phi), np.sin(phi)
    w0, w1, w2 = r * cph - centre[..., 0], r * sph - centre[..., 1], d - centre[..., 2]
    n0, n1, n2 = normal[..., 0], normal[..., 1], normal[..., 2]
    wn = w0 * n0 + w1 * n1 + w2 * n2
    p0, p1, p2 = w0 - wn * n0, w1 - wn * n1, w2 - wn * n2
    s = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    off = s - radius
    g = wn * wn + off * off
    if not derivatives:
        return g
    wdp = r * (w1 * cph - w0 * sph)                    # w · P', P' = r (-sin φ, cos φ, 0)
    ndp = r * (n1 * cph - n0 * sph)                    # w_n'
    wddp = -r * (w0 * cph + w1 * sph)                  # w · P'', P'' = -r (cos φ, sin φ, 0)
    nddp = -r * (n0 * cph + n1 * sph)                  # w_n''
    s_safe = np.maximum(s, 1e-300)
    s1 = (wdp - wn * ndp) / s_safe                     # from (s²)' = 2 (w·P' - w_n w_n')
    s2 = ((r * r + wddp) - (ndp * ndp + wn * nddp) - s1 * s1) / s_safe
    g1 = 2 * (wn * ndp + off * s1)
    g2 = 2 * (ndp * ndp + wn * nddp + s1 * s1 + off * s2)
    return g, g1, g2


def _grid_gap(grid, d, r, centre, normal, radius):
    """g(φ) of :func:`_circle_gap` on a grid, shape (n, len(grid)), from per-frame coefficients.

    On Γ, ``w·n = α cos φ + β sin φ + γ`` and ``|w|² = δ cos φ + ε sin φ + ζ``; the expanded
    ``s² = |w|² - (w·n)²`` loses a little accuracy, which only ranks grid points.
    """
    cg, sg = np.cos(grid)[None, :], np.sin(grid)[None, :]
    rr, dd = r[:, 0], d[:, 0]
    wn = (rr * normal[:, 0])[:, None] * cg + (rr * normal[:, 1])[:, None] * sg \
        + (normal[:, 2] * dd - np.sum(normal * centre, axis=-1))[:, None]
    ww = (-2 * rr * centre[:, 0])[:, None] * cg + (-2 * rr * centre[:, 1])[:, None] * sg \
        + (rr * rr + dd * dd - 2 * dd * centre[:, 2] + np.sum(centre * centre, axis=-1))[:, None]
    off = np.sqrt(np.maximum(ww - wn * wn, 0.0)) - radius[:, None]
    return wn * wn + off * off


def _newton(phi, g_now, args, n_steps: int, spacing: float):
    """Safeguarded Newton steps on g'(φ) for every start at once (see :func:`closest_points`).

    `phi`, `g_now` have shape (n, m); `args` are the per-frame arrays of :func:`_circle_gap`
    (leading dimension n). Frames whose steps have all fallen below ``CONVERGED_STEP`` drop out.
    """
    phi, g_now = phi.copy(), g_now.copy()
    active = np.arange(len(phi))
    for _ in range(n_steps):
        sub = tuple(a[active] for a in args)
        ph, g0 = phi[active], g_now[active]
        _, g1, g2 = _circle_gap(ph, *sub)
        step = np.where(g2 > 0, -g1 / np.where(g2 > 0, g2, 1.0), -np.sign(g1) * spacing / 4)
        step = np.clip(step, -spacing, spacing)
        g_new = _circle_gap(ph + step, *sub, derivatives=False)
        ok = (g_new <= g0) | (np.abs(step) < SMALL_STEP)      # tiny Newton steps are safe
        if not ok.all():                                       # one halving for the others
            half = _circle_gap(ph + step / 2, *sub, derivatives=False)
            use_half = ~ok & (half <= g0)
            step = np.where(use_half, step / 2, np.where(ok, step, 0.0))
            g_new = np.where(use_half, half, np.where(ok, g_new, g0))
        phi[active], g_now[active] = ph + step, g_new
        active = active[np.max(np.abs(step), axis=1) >= CONVERGED_STEP]
        if not len(active):
            break
    return phi, g_now


def _grid_minima(grid, g, k: int):
    """The `k` lowest discrete local minima of g over a periodic grid, per row.

    A row with fewer minima repeats its lowest one. Returns angles and values, shape (n, k).
    """
    masked = np.where((g <= np.roll(g, 1, axis=1)) & (g <= np.roll(g, -1, axis=1)), g, np.inf)
    ranked = np.argsort(masked, axis=1)[:, :k]
    found = np.isfinite(np.take_along_axis(masked, ranked, axis=1))
    ranked = np.where(found, ranked, ranked[:, :1])
    return grid[ranked], np.take_along_axis(g, ranked, axis=1)


def _crossing_angles(d, r, centre, normal, radius):
    """Angles of Γ where it crosses the plane of Γ' and the sphere about c' of radius ρ'.

    Both conditions read ``A cos φ + B sin φ = C``; where Γ and Γ' (nearly) meet they hold
    (nearly) together, so these four angles start the Newton search inside narrow basins that a
    grid can miss. Without a real solution the angle of closest approach is used. `d`, `r` have
    shape (n, 1); returns shape (n, 4).
    """
    rows = [(r[:, 0] * normal[:, 0], r[:, 0] * normal[:, 1],
             np.sum(normal * centre, axis=-1) - normal[:, 2] * d[:, 0]),
            (2 * r[:, 0] * centre[:, 0], 2 * r[:, 0] * centre[:, 1],
             r[:, 0] ** 2 + d[:, 0] ** 2 - 2 * d[:, 0] * centre[:, 2] + np.sum(centre**2, axis=-1) - radius**2)]
    out = []
    for a, b, c in rows:
        size = np.hypot(a, b)
        base = np.arctan2(b, a)
        spread = np.arccos(np.clip(c / np.where(size > 0, size, 1.0), -1.0, 1.0))
        out += [base + spread, base - spread]
    return np.stack(out, axis=1)


def closest_points(d, r, centre, normal, radius, n_grid: int = N_GRID):
    """Closest pair between Γ(d, r) and the circles Γ', all frames at once.

    g(φ), the squared distance from P(φ) ∈ Γ to Γ', is evaluated in closed form on a grid of
    `n_grid` angles. Starts: the ``N_BASINS`` lowest grid minima and the four angles where Γ
    crosses the plane and the sphere of Γ' (:func:`_crossing_angles`). Safeguarded Newton steps
    on g'(φ) (step capped at one grid spacing, kept only if g does not increase) run from every
    start for ``SHARED_STEPS``, then from the best start per frame to machine precision.

    Parameters
    ----------
    d, r : float or array, shape (n_frames,)
        One circle Γ for all frames, or one per frame (several parameter sets stacked).
    centre, normal : array, shape (n_frames, 3)
    radius : array, shape (n_frames,)

    Returns
    -------
    p, q : numpy.ndarray, shape (n_frames, 3)
        Closest points on Γ and on Γ'.
    """
    n = len(centre)
    d = np.broadcast_to(np.asarray(d, dtype=float), (n,))[:, None]
    r = np.abs(np.broadcast_to(np.asarray(r, dtype=float), (n,)))[:, None]
    args = (d, r, centre[:, None, :], normal[:, None, :], radius[:, None])
    grid = np.linspace(-np.pi, np.pi, n_grid, endpoint=False)
    phi, g_now = _grid_minima(grid, _grid_gap(grid, d, r, centre, normal, radius), N_BASINS)
    extra = _crossing_angles(d, r, centre, normal, radius)
    phi = np.concatenate([phi, extra], axis=1)
    g_now = np.concatenate([g_now, _circle_gap(extra, *args, derivatives=False)], axis=1)
    spacing = 2 * np.pi / n_grid
    phi, g_now = _newton(phi, g_now, args, SHARED_STEPS, spacing)      # every start a few steps,
    best = np.argmin(g_now, axis=1)[:, None]                            # then the best one only
    phi, _ = _newton(np.take_along_axis(phi, best, axis=1), np.take_along_axis(g_now, best, axis=1),
                     args, NEWTON_STEPS, spacing)
    p = np.concatenate([r * np.cos(phi), r * np.sin(phi), d], axis=-1)
    w = p - centre
    perp = w - np.sum(w * normal, axis=-1, keepdims=True) * normal
    size = np.linalg.norm(perp, axis=-1, keepdims=True)
    any_perp = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal), axis=-1)])   # P on Γ's axis
    perp = np.where(size > 1e-12, perp, any_perp)
    q = centre + radius[:, None] * perp / np.linalg.norm(perp, axis=-1, keepdims=True)
    return p, q


def joint_centres(x, b1, b2) -> tuple[np.ndarray, np.ndarray]:
    """J_opt per frame in F_S22: the midpoint of the closest pair of Γ(d, r) and Γ'.

    Parameters
    ----------
    x : array, shape (4,) or (m, 4)
        (d, r, ρ1, ρ2), mm; several parameter sets are evaluated together.
    b1, b2 : array, shape (n_frames, 3)
        Child markers in F_S22 (A1 at the origin, A2 on +z), mm.

    Returns
    -------
    centres : numpy.ndarray, shape (n_frames, 3) or (m, n_frames, 3)
    gap : numpy.ndarray, shape (n_frames,) or (m, n_frames)
        Distance between the two circles, mm (0 for exact data at the true constants).
    """
    x = np.asarray(x, dtype=float)
    xs = np.atleast_2d(x)
    m, n = len(xs), len(b1)
    rows = np.repeat(xs, n, axis=0)                                  # (m n, 4), set-major
    tile = lambda b: np.broadcast_to(b, (m, n, 3)).reshape(-1, 3)    # noqa: E731
    centre, normal, radius = spheres_circle(tile(b1), tile(b2), rows[:, 2], rows[:, 3])
    p, q = closest_points(rows[:, 0], rows[:, 1], centre, normal, radius)
    j, gap = ((p + q) / 2).reshape(m, n, 3), np.linalg.norm(p - q, axis=-1).reshape(m, n)
    return (j[0], gap[0]) if x.ndim == 1 else (j, gap)


def _residuals_batch(xs, b1, b2, h):
    """Centred distances, shape (m, 4 n_frames), whose sums of squares are C at each of the m
    parameter sets: (|J A_p| - mean, |J B_q| - mean) / sqrt(n_frames)."""
    j, _ = joint_centres(np.atleast_2d(xs), b1, b2)
    dist = np.stack([np.linalg.norm(j, axis=-1),
                     np.sqrt(j[..., 0] ** 2 + j[..., 1] ** 2 + (j[..., 2] - h) ** 2),
                     np.linalg.norm(j - b1, axis=-1),
                     np.linalg.norm(j - b2, axis=-1)], axis=1)       # (m, 4, n)
    res = (dist - dist.mean(axis=-1, keepdims=True)) / np.sqrt(len(h))
    return res.reshape(len(res), -1)


def _residuals(x, b1, b2, h):
    """Residual vector of one parameter set (the least-squares objective is C)."""
    return _residuals_batch(x, b1, b2, h)[0]


class _Objective:
    """Residuals of C and their forward-difference Jacobian for ``least_squares``.

    The Jacobian's four shifted parameter sets go through :func:`joint_centres` in one batch,
    and the residuals at the unshifted point are reused from the last evaluation (MINPACK asks
    for the Jacobian where it has just evaluated the function).
    """

    def __init__(self, b1, b2, h):
        self.b1, self.b2, self.h = b1, b2, h
        self._last = (None, None)

    def residuals(self, x):
        res = _residuals(x, self.b1, self.b2, self.h)
        self._last = (np.array(x, dtype=float), res)
        return res

    def jacobian(self, x):
        x0, base = self._last
        if x0 is None or not np.array_equal(x0, x):
            base = self.residuals(x)
        step = FD_STEP * np.maximum(1.0, np.abs(x))
        shifted = _residuals_batch(x + np.diag(step), self.b1, self.b2, self.h)
        return ((shifted - base) / step[:, None]).T


def s22_cost(x, b1, b2, h) -> float:
    """C(d, r, ρ1, ρ2) of Pham et al. (section V-A) in F_S22, mm².

    Parameters
    ----------
    x : array, shape (4,)
    b1, b2 : array, shape (n_frames, 3)
        Child markers in F_S22.
    h : array, shape (n_frames,)
        |A1A2| per frame (A2 = (0, 0, h)).
    """
    res = _residuals(np.asarray(x, dtype=float), b1, b2, np.asarray(h, dtype=float))
    return float(res @ res)


# ---------------------------------------------------------------------- seeds
def _linear_seed(b1, b2):
    """The linear (2, 2) solution of section IV-C, or None when it is unavailable or has no real
    solution for these data."""
    try:
        from identcheck.solve.spherical22 import solve_linear
    except ImportError:
        return None
    try:
        with warnings.catch_warnings():          # a poor seed is fine: the minimisation decides
            warnings.simplefilter("ignore")
            x = np.asarray(solve_linear(b1, b2), dtype=float)
    except (DegenerateError, np.linalg.LinAlgError, ValueError, ZeroDivisionError):
        return None
    return x if x.shape == (4,) and np.all(np.isfinite(x)) else None


def _sphere_seed(b1, b2):
    """(d, r, ρ1, ρ2) from a Gamage-Lasenby sphere fit of B1, B2 in F_S22, or None.

    Exact when the parent does not roll about A1A2 relative to v; otherwise a rough start.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = sphere_centre(np.stack([b1, b2], axis=1))
    except DegenerateError:
        return None
    c = fit.centre
    return np.array([c[2], np.hypot(c[0], c[1]), fit.radii[0], fit.radii[1]])


def _random_seeds(b1, b2, h, n: int, rng: np.random.Generator, around=None) -> list:
    """`n` random starts: half jittered around `around` (the best local minimum so far, ±10 % and
    ±10 mm per constant: neighbouring minima of the same valley), the rest from random candidate
    centres in the box spanned by A1, A2, B1, B2 in F_S22 (other valleys)."""
    n_near = n // 2 if around is not None else 0
    out = []
    for _ in range(n_near):
        x = around + rng.normal(size=4) * (0.1 * np.abs(around) + 10.0)
        out.append(np.concatenate([x[:1], np.abs(x[1:])]))
    pts = np.vstack([b1, b2, np.zeros((1, 3)), [[0.0, 0.0, float(np.mean(h))]]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.2 * (hi - lo)
    for c in rng.uniform(lo - pad, hi + pad, size=(n - n_near, 3)):
        out.append(np.array([c[2], np.hypot(c[0], c[1]),
                             np.linalg.norm(b1 - c, axis=-1).mean(), np.linalg.norm(b2 - c, axis=-1).mean()]))
    return out


# ---------------------------------------------------------------------- result and solver
@dataclass(frozen=True)
class S22Result:
    """Spherical joint from two markers per link (Pham et al., section V-A).

    Attributes
    ----------
    params : numpy.ndarray, shape (4,)
        (d, r, ρ1, ρ2), mm: height and radius of Γ in F_S22, distances of B1, B2 to the centre.
    centres_world : numpy.ndarray, shape (n_frames, 3)
        J_S22 per frame (world), mm; NaN in dropped frames.
    centres_local : numpy.ndarray, shape (n_used, 3)
        J_S22 in F_S22 (components along u2, u3, u1), used frames only.
    cost_mm2 : float
        The minimised C (p = 1, 2).
    paper_cost_mm2 : float
        C_S22 as the paper compares it: p = 1..3 when a third parent marker was given
        (otherwise equal to `cost_mm2`).
    gap_mm : numpy.ndarray, shape (n_used,)
        Distance between Γ and Γ' per frame (how far the data are from an exact joint).
    frames : numpy.ndarray of int
        Frames used (A1, A2, B1, B2 and A3 if given all present).
    v : numpy.ndarray, shape (3,)
        The fixed vector that set u2.
    starts : list of dict
        Per start: ``source`` ("linear", "sphere" or "random"), ``x0``, ``x``, ``cost_mm2``,
        ``nfev``.
    alternatives : list of numpy.ndarray
        Other local minima whose cost is within ``ALT_REL`` of the best (empty: unique).
    run_time_s : float
    """

    params: np.ndarray
    centres_world: np.ndarray
    centres_local: np.ndarray
    cost_mm2: float
    paper_cost_mm2: float
    gap_mm: np.ndarray
    frames: np.ndarray
    v: np.ndarray
    starts: list = field(repr=False)
    alternatives: list = field(default_factory=list)
    run_time_s: float = 0.0

    @property
    def sqrt_cost_mm(self) -> float:
        """sqrt(C_S22) (p = 1..3 if A3 was given), mm: 9.18 mm for the paper's jump."""
        return float(np.sqrt(self.paper_cost_mm2))

    @property
    def unique(self) -> bool:
        """True when no other local minimum came close to the best cost."""
        return not self.alternatives

    def as_dict(self) -> dict:
        """The constants by name (``d``, ``r``, ``rho1``, ``rho2``), mm."""
        return dict(zip(PARAMS, (float(v) for v in self.params)))


def s22_frames(a1, a2, b1, b2, seed: int = 0, names=("A1", "A2")):
    """Child markers in F_S22 for every frame, with the frame itself.

    Parameters
    ----------
    a1, a2, b1, b2 : array, shape (n_frames, 3)
        World positions, mm, no NaN.
    seed : int
        Seeds v (:func:`choose_v`).
    names : tuple of 2 str
        Names of a1, a2 for messages.

    Returns
    -------
    lb1, lb2 : numpy.ndarray, shape (n_frames, 3)
    h : numpy.ndarray, shape (n_frames,)
    rot : numpy.ndarray, shape (n_frames, 3, 3)
        As :func:`~identcheck.solve.gamage_lasenby.parent_frame` returns it.
    v : numpy.ndarray, shape (3,)
    """
    a1, a2 = np.asarray(a1, dtype=float), np.asarray(a2, dtype=float)
    if np.all(np.linalg.norm(a2 - a1, axis=-1) > 0):
        v = choose_v(a2 - a1, seed)
    else:                                   # parent_frame reports the coincident frames
        v = np.array([1.0, 0.0, 0.0])
    rot, h = parent_frame(a1, a2, v, names=(names[0], names[1], "v"))
    return to_local(rot, a1, b1), to_local(rot, a1, b2), h, rot, v


def solve_s22(a1, a2, b1, b2, a3=None, *, n_random: int = 6, seed: int = 0,
              labels: Sequence[str] | None = None, max_nfev: int = 400) -> S22Result:
    """Identify a spherical joint from two markers per link with the S22 algorithm.

    Parameters
    ----------
    a1, a2 : array, shape (n_frames, 3)
        Parent markers (world), mm, NaN = occluded.
    b1, b2 : array, shape (n_frames, 3)
        Child markers (world), mm.
    a3 : array, shape (n_frames, 3), optional
        A third parent marker: not used by the fit, only in ``paper_cost_mm2`` (p = 1..3) so
        that C_S22 compares with C_GL as in the paper. Frames where it is missing are dropped.
    n_random : int
        Random starts added to the linear and sphere-fit seeds.
    seed : int
        Seeds v and the random starts (``np.random.default_rng``).
    labels : sequence of str, optional
        Names of a1, a2, b1, b2 (and a3) for messages.
    max_nfev : int
        Cap on cost evaluations per start.

    Returns
    -------
    S22Result

    Raises
    ------
    InputError
        Bad shapes or a marker with no sample.
    DegenerateError
        Fewer than 9 complete frames, coincident A1/A2 or B1/B2, or no start converged.

    Examples
    --------
    >>> res = solve_s22(l5, lasi, rgt, rkne, a3=rasi)          # doctest: +SKIP
    >>> res.as_dict(), res.sqrt_cost_mm                        # doctest: +SKIP
    """
    t0 = time.perf_counter()
    names = list(labels) if labels is not None else ["A1", "A2", "B1", "B2"] + (["A3"] if a3 is not None else [])
    arrays = [a1, a2, b1, b2] + ([a3] if a3 is not None else [])
    if len(names) != len(arrays):
        raise InputError([f"{len(names)} labels for {len(arrays)} markers"], source="S22")
    kept, frames = complete_frames(dict(zip(names, arrays)), S22_MIN_FRAMES, "S22")
    pa1, pa2, pb1, pb2, *rest = kept.values()
    _check_pair(pb1, pb2, names[2], names[3])
    lb1, lb2, h, rot, v = s22_frames(pa1, pa2, pb1, pb2, seed, names[:2])
    starts = _run_starts(lb1, lb2, h, n_random, seed, max_nfev)
    best = min(starts, key=lambda s: s["cost_mm2"])
    x = best["x"]
    local, gap = joint_centres(x, lb1, lb2)
    world = np.full((np.asarray(a1).shape[0], 3), np.nan)
    world[frames] = to_world(rot, pa1, local)
    paper = distance_variance_cost(world[frames], [pa1, pa2] + rest, [pb1, pb2])
    alts = _alternatives(starts, best)
    return S22Result(x, world, local, best["cost_mm2"], paper, gap, frames, v, starts, alts,
                     time.perf_counter() - t0)


def _check_pair(b1, b2, n1, n2) -> None:
    """DegenerateError if the two child markers coincide in some frame (Γ' undefined)."""
    sep = np.linalg.norm(b2 - b1, axis=-1)
    bad = np.flatnonzero(sep <= 1e-9 * max(1.0, float(np.max(np.abs(b1)))))
    if len(bad):
        raise DegenerateError(f"{n1} and {n2} coincide in frames {bad[:10].tolist()}: the circle "
                              "of points at given distances from both is undefined")


def _run_starts(b1, b2, h, n_random, seed, max_nfev) -> list:
    """Local least squares from every seed; one dict per start (see :class:`S22Result`).

    The linear and sphere-fit seeds run first; the random starts are then drawn, half of them
    around the best minimum found so far.
    """
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    seeds = [("linear", _linear_seed(b1, b2)), ("sphere", _sphere_seed(b1, b2))]
    out = [_local_fit(k, x, b1, b2, h, max_nfev) for k, x in seeds if x is not None]
    out = [o for o in out if o is not None]
    around = min(out, key=lambda o: o["cost_mm2"])["x"] if out else None
    for x0 in _random_seeds(b1, b2, h, n_random, rng, around):
        fit = _local_fit("random", x0, b1, b2, h, max_nfev)
        if fit is not None:
            out.append(fit)
    if not out:
        raise DegenerateError("S22: no start of the local minimisation converged to a finite cost")
    return out


def _local_fit(source, x0, b1, b2, h, max_nfev):
    """One Levenberg-Marquardt run of C from `x0`; None if it fails or ends at a non-finite cost."""
    try:
        obj = _Objective(b1, b2, h)
        sol = least_squares(obj.residuals, x0, jac=obj.jacobian, method="lm", x_scale="jac",
                            ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=max_nfev)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None
    x = np.array([sol.x[0], abs(sol.x[1]), abs(sol.x[2]), abs(sol.x[3])])
    cost = s22_cost(x, b1, b2, h)
    if not np.isfinite(cost):
        return None
    return {"source": source, "x0": np.asarray(x0, dtype=float), "x": x, "cost_mm2": cost, "nfev": int(sol.nfev)}


def _alternatives(starts, best) -> list:
    """Distinct local minima nearly as good as the best: the data do not single out one joint."""
    alts = []
    limit = best["cost_mm2"] * (1 + ALT_REL) + 1e-12
    for s in sorted(starts, key=lambda s: s["cost_mm2"]):
        if s["cost_mm2"] > limit:
            break
        if all(np.max(np.abs(s["x"] - y)) > ALT_MM for y in [best["x"]] + alts):
            alts.append(s["x"])
    return alts
