"""Profile-likelihood intervals for marker distances, where the quadratic (Wald) interval misleads.

``estimate ± 1.96 SE`` assumes the likelihood is a parabola in the distance. On sparse marker sets (a knee
seen through one thigh and one shank marker, ERRATA E1) and on nearly degenerate motion the whole-tree
likelihood is a long, curved, flat valley: the parabola at the minimum can be far too narrow on one side
and absurdly wide on the other. The profile likelihood follows the valley instead: the distance is held at
a value by a stiff spring on the constants (:func:`identcheck.bundle.chain.fit_chain`'s ``penalty``),
everything else is refitted, and the interval is the set of values whose refitted residual is within
``χ²₁(0.95) = 3.84`` noise units of the minimum (Venzon and Moolgavkar, 1988; Raue et al., 2009, who call a
parameter *practically non-identifiable* when such an interval does not close).

Each side is walked outwards from the estimate (warm-started refits), and the bound is interpolated in the
signed root of Δχ², which is linear in the distance where the profile is a parabola. The distance is pulled by a
soft spring, a few times the profile's own curvature (:data:`SPRING`), and each point of the profile is where the
refit comes to rest, not where the spring pulls: a minimum of the data's cost plus any spring on the distance is
the data's least cost at the distance it reaches (were any state with that distance cheaper, it would be cheaper
with the spring too), so the spring's stiffness changes which point is found, never its value. At rest the spring's
pull also gives the profile's slope there (:func:`slope_at_rest`). A stiff spring (10⁴ per noise variance, as
first written) made the refits ill-conditioned: Levenberg–Marquardt's damping on the constants scales with the
spring's curvature, and on a knee turning about three axes (held-out draw 55, trial 0) the first refit of each side
stopped at its 40-iteration cap still falling by 2–9 χ² an iteration, 237 χ² above the minimum where the converged
profile is near 4: the interval came out 2.4 mm wide where the quadratic one is 24 mm, and missed the truth.

The next point is aimed by Newton's step in √Δχ² from the last point inside the bound (its value and slope) at a
little beyond the bound (:data:`AIM_CHI2`), and the spring set to rest there by the same local model; a refit that
covers less than half the way asked stiffens the spring tenfold (a profile steeper than its local parabola had held
the walk at one place). Once a point lies beyond the bound, points are aimed inside the bracket until the points
either side place it (:func:`bracketed`: the outer one within :data:`REFINE_CHI2` of the bound, √Δχ² nearly
straight between them by its slopes at both), and the bound is where the line between them or the tangent at the
outer point reaches it, the farther (:func:`crossing`); a walk that runs out of points first takes its nearest point
beyond the bound as the bound. A refit that does not converge gives no new point: a refit stopped early overstates
Δχ² (the profile is a minimum over everything else), so it would close the interval too soon (one that has not
converged after :data:`MAX_ITER` iterations goes on once from where it stopped); without a point beyond the bound
the side claims none.

A refit that lands more than one χ² unit below the minimum ends the walk there: the fit had not found the best
joint, and the caller withdraws the interval whatever the rest of the walk would have given
(:attr:`ProfileInterval.better_fit`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from identcheck.bundle.chain import REL_TOL, fit_chain
from identcheck.bundle.uncertainty import distance_gradients

PROFILE_CHI2 = 3.841      # χ²₁ 95 % quantile
MAX_POINTS = 8            # refits per side at most
MAX_ITER = 40             # LM iterations per refit (warm-started from the previous point)
MIN_STEP_MM = 0.5
MAX_STEP_MM = 160.0
MAX_SPAN_MM = 1000.0      # beyond this a side is reported open
SPRING = 4.0
"""The spring's curvature in χ² per mm² as a multiple of the profile's (the larger of what the parabola through the
estimate and the last point, and the slope there, say): the refit then comes to rest about 4/5 of the way to where
the spring pulls."""
REFINE_CHI2 = 1.0
"""A point beyond the bound by more than this (Δχ² above χ²₁(0.95)) is not used to interpolate the bound: a point
aimed nearer is fitted first."""
AIM_CHI2 = PROFILE_CHI2 + 0.75 * REFINE_CHI2
"""Where each point is aimed (Δχ²): three quarters of the way from the bound to the farthest point beyond it that
ends the walk, so that a refit falling short or long still crosses the bound and ends it. Aimed at a fixed ratio
beyond Newton's step instead (1.1 times), the points near the bound crept up on it from inside (Δχ² 3.63, 3.80,
3.79, 3.87 on a knee of held-out draw 55, trial 8), a refit each; and a refit that stays inside the bound when
aimed beyond it doubles the spring's stiffness for the next."""
STALL = 0.5
"""A refit that covers less than this share of the way it was aimed stiffens the spring tenfold for the next."""
MAX_CURVATURE = (np.sqrt(PROFILE_CHI2) / MIN_STEP_MM) ** 2
"""χ² per mm²: a profile this steep puts the bound within :data:`MIN_STEP_MM`; a curvature read above it from a point
that hardly moved is capped here (it would make the spring stiff again)."""
STEP_CHI2 = 1e-3
"""A refit stops when an iteration lowers the cost by less than this many χ² units (the fit's own relative
1e-8 of the RSS is thousands of times finer than a 95 % bound needs on long trials). Measured on walking2's
right knee (three marker distances, 12 refits): 213 iterations at the fit's tolerance, 70 at this one, bounds
within 0.04 mm of the intervals' ±13 mm."""


class OutOfTime(Exception):
    """A profile's refits passed the caller's deadline before both sides were found."""


@dataclass(frozen=True)
class ProfileInterval:
    """A profile-likelihood 95 % interval for one marker distance (``None``: that side does not close)."""

    lo: float | None
    hi: float | None
    refits: int
    lowest_rss: float          # the smallest data RSS met on the way (below the minimum's: a better fit exists)
    better_fit: bool = False   # a refit beat the minimum by more than one χ² unit: the walk stopped there


def slope_at_rest(kappa: float, pull_mm: float) -> float:
    """The profile's slope (χ² per mm, outwards) where a refit under a spring of curvature `kappa` (χ² per mm²)
    came to rest `pull_mm` short of the spring's target: there the data's cost and the spring balance,
    ``P'(d) = 2 κ (target − d)``."""
    return 2.0 * kappa * pull_mm


def bracketed(inner: tuple, outer: tuple) -> bool:
    """Whether the line through the points (distance out, √Δχ², …, the slope of √Δχ² there) `inner` and `outer`
    either side of the bound places the bound: the outer point within :data:`REFINE_CHI2` of it, and the line's slope
    within a fifth of √Δχ²'s own at both points, so that √Δχ² is nearly straight between them, as a parabola's is.
    When the inner point is the estimate only the outer slope is asked: the estimate's is the standard error's guess
    (on walking2's knees the sandwich's standard error is not the profile's, and asking it refitted every bound), and
    :func:`crossing` still takes the farther of the line and the outer tangent. A flat profile running into a wall,
    its points at Δχ² 0.5 and 4.4, had been closed 7 mm inside its bound by the line; points both within 1 χ² of the
    bound but far apart on a plateau, 53 mm inside it."""
    if outer[1] ** 2 > PROFILE_CHI2 + REFINE_CHI2:
        return False
    line = (outer[1] - inner[1]) / max(outer[0] - inner[0], 1e-12)
    ends = (outer, inner) if inner[1] > 0 else (outer,)     # the estimate's own slope is the parabola's guess
    return all(np.isfinite(end[-1]) and abs(end[-1] - line) <= 0.2 * line for end in ends)


def crossing(inner: tuple, outer: tuple, root: float) -> float:
    """Where √Δχ² reaches `root` between the points (distance out from the estimate, √Δχ², …, its slope there)
    `inner` (below it) and `outer` (at or above it): the farther of where the line through them and where the
    tangent at the outer point reach it, never past the outer point. Whether √Δχ² curves up or down between them,
    the farther of the two is not inside the true crossing (the line crosses late on a curve bending down, the
    tangent at the far end on one bending up)."""
    (x0, q0), (x1, q1) = inner[:2], outer[:2]
    line = x0 + ((root - q0) / (q1 - q0) if q1 > q0 else 1.0) * (x1 - x0)
    tangent = x1 - (q1 - root) / outer[-1] if np.isfinite(outer[-1]) and outer[-1] > 0 else x1
    return float(min(max(line, tangent), x1))


def distance_penalty(chain, joint: str, marker: str, target: float, weight: float, n_params: int):
    """The spring ``weight · (d(state) − target)`` on one marker distance, in :func:`fit_chain`'s form."""

    def penalty(state):
        d, g = distance_gradients(chain, state, n_params)[joint][marker]
        return np.array([weight * (d - target)]), weight * g[None, :]

    return penalty


def profile_interval(fit, data, joint: str, marker: str, scale: float, se: float, n_params: int,
                     weights=None, deadline: float | None = None) -> ProfileInterval:
    """The 95 % profile interval of `marker`'s distance to `joint` around the minimum `fit`.

    Parameters
    ----------
    fit : identcheck.bundle.chain.Fit
        The unconstrained minimum.
    data : array (F, M, 3)
        The trial's markers in the chain's order.
    scale : float
        mm² per unit of χ²: the noise variance times the correlation inflation (as in the likelihood-ratio
        test between candidates).
    se : float
        The quadratic standard error, to size the first step.
    n_params : int
        Number of constants (the information's size).
    deadline : float, optional
        ``time.monotonic()`` after which no refit is started or continued: :class:`OutOfTime` is raised (a
        half-walked side would be a bound the data did not give).
    """
    chain = fit.chain
    d0 = distance_gradients(chain, fit.state, n_params)[joint][marker][0]
    root = np.sqrt(PROFILE_CHI2)
    refits, lowest = 0, fit.rss
    tol = max(REL_TOL, STEP_CHI2 * scale / max(fit.rss, 1e-300))
    first = float(np.clip(root * se if np.isfinite(se) and se > 0 else MAX_STEP_MM, MIN_STEP_MM, MAX_STEP_MM / 4))

    def refit(state, target: float, weight: float):
        pen = distance_penalty(chain, joint, marker, target, weight, n_params)
        f = fit_chain(chain, data, state, terms=fit.terms, weights=weights, max_iter=MAX_ITER, tol=tol, penalty=pen,
                      deadline=deadline)
        if not f.converged and (deadline is None or time.monotonic() < deadline):
            f = fit_chain(chain, data, f.state, terms=fit.terms, weights=weights, max_iter=MAX_ITER, tol=tol,
                          penalty=pen, deadline=deadline)      # once more from where it stopped
        if deadline is not None and time.monotonic() > deadline:
            raise OutOfTime(f"{marker}'s distance to {joint}")
        return f

    bounds = []
    for side in (-1.0, 1.0):
        a = (root / first) ** 2             # the profile's half second derivative (χ²/mm²), as the parabola says
        # the farthest point inside the bound (how far out, √Δχ², state, the slope of √Δχ² there: the parabola's at
        # the estimate), and the nearest point beyond it (how far out, √Δχ², the slope of √Δχ²)
        inner = (0.0, 0.0, fit.state, np.sqrt(a))
        outer = None
        slope, stiff, zero = 0.0, 1.0, False
        for _ in range(MAX_POINTS):
            if deadline is not None and time.monotonic() > deadline:
                raise OutOfTime(f"{marker}'s distance to {joint}")
            moved, q = inner[0], inner[1]
            aim_q = np.sqrt(AIM_CHI2)
            newton = (aim_q - q) * 2.0 * q / slope if q > 0 and slope > 0 else aim_q / np.sqrt(a) - moved
            if outer is None:
                reach = moved + float(np.clip(newton, MIN_STEP_MM, MAX_STEP_MM))
            else:
                # inside the bracket: Newton's step from the inner point where it falls short of the outer one, else
                # halfway from where the line between them crosses the bound to the outer point
                chord = crossing(inner, outer, root)
                reach = moved + newton if moved + newton < outer[0] else (chord + outer[0]) / 2.0
                span = max(outer[0] - moved, 1e-9)     # the curvature the two points and the slope imply
                a = float(np.clip(max(a, (outer[1] ** 2 - q ** 2 - slope * span) / span ** 2), a, MAX_CURVATURE))
            if side < 0:
                reach = min(reach, d0)                 # a distance is not negative: aim at zero at most
            kappa = min(SPRING * stiff * a, SPRING * stiff * MAX_CURVATURE)
            force = slope + 2.0 * a * (reach - moved)  # the profile's slope expected where the refit should rest
            target = d0 + side * (reach + force / (2.0 * kappa))
            f = refit(inner[2], target, np.sqrt(kappa * scale))
            refits += 1
            if not np.isfinite(f.rss):
                break
            lowest = min(lowest, f.rss)
            if lowest < fit.rss - scale:        # no minimum to profile about: the bounds would be withdrawn
                return ProfileInterval(None, None, refits, float(lowest), better_fit=True)
            if not f.converged:                 # its Δχ² is too large by an unknown amount: no point from it
                break
            out = side * (distance_gradients(chain, f.state, n_params)[joint][marker][0] - d0)
            q_new = np.sqrt(max(f.rss - fit.rss, 0.0) / scale)
            pull = side * (target - d0) - out            # how far short of the spring's target it rests
            if q_new >= root:
                if outer is None or out < outer[0]:
                    outer = (out, q_new, slope_at_rest(kappa, pull) / (2.0 * q_new))
            elif out > moved:
                if out - moved < STALL * (reach - moved):
                    stiff *= 10.0
                elif outer is None:
                    stiff *= 2.0                          # aimed beyond the bound and still inside it
                slope = max(slope_at_rest(kappa, pull), 0.0)
                a = float(np.clip(max(q_new ** 2 / out ** 2, slope / (2.0 * out)), (root / MAX_SPAN_MM) ** 2,
                                  MAX_CURVATURE))
                inner = (out, q_new, f.state, slope / (2.0 * q_new) if q_new > 0 else np.sqrt(a))
                zero = side < 0 and out >= d0 - MIN_STEP_MM     # at zero, still inside the bound
            else:
                stiff *= 10.0                            # no way made at all
            if zero or inner[0] >= MAX_SPAN_MM:
                break
            if outer is not None and bracketed(inner, outer):
                break
        if outer is not None:
            # between the nearest points either side when they place it (:func:`bracketed`); else the outer point
            # itself (the bound lies between them, and a line through far points may cross too soon)
            bounds.append(float(d0 + side * (crossing(inner, outer, root) if bracketed(inner, outer) else outer[0])))
        else:
            bounds.append(0.0 if side < 0 else None)    # not closed: 0 is the honest lower bound, no upper one
    return ProfileInterval(bounds[0], bounds[1], refits, float(lowest))
