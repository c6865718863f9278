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
with the spring too), so the spring's stiffness changes which point is found, never its value. A stiff spring
(10⁴ per noise variance, as first written) made the refits ill-conditioned: Levenberg–Marquardt's damping on the
constants scales with the spring's curvature, and on a knee turning about three axes (held-out draw 55, trial 0)
the first refit of each side stopped at its 40-iteration cap still falling by 2–9 χ² an iteration, 237 χ² above
the minimum where the converged profile is near 4: the interval came out 2.4 mm wide where the quadratic one is
24 mm, and missed the truth. The next point is aimed with the parabola through the estimate and the last point
(1.1 times where it puts the bound), the spring's curvature set from the same parabola. A side whose refit does
not converge gives no bound: a refit stopped early overstates Δχ² (the profile is a minimum over everything
else), so it would close the interval too soon (a refit that has not converged after :data:`MAX_ITER` iterations
goes on once from where it stopped).

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
"""The spring's curvature in χ² per mm² as a multiple of the profile's (as the parabola through the estimate and
the last point measures it): the refit then comes to rest about 4/5 of the way to where the spring pulls."""
AIM = 1.1
"""Each point is aimed this far beyond where the parabola through the estimate and the last point puts the bound, so
that one refit usually crosses it and the bound is interpolated, not extrapolated."""
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
    bounds = []
    for side in (-1.0, 1.0):
        state, prev_d, prev_q = fit.state, d0, 0.0
        curvature = (root / first) ** 2                # χ² per mm² of the parabola the standard error gives
        reach = AIM * first                            # how far from the estimate the next point should rest
        bound = None
        for _ in range(MAX_POINTS):
            if side < 0:
                reach = min(reach, d0)                 # a distance is not negative: aim at zero at most
            # rest at `reach` under a spring SPRING times the profile's curvature: pull (1 + 1/SPRING) as far
            target = d0 + side * reach * (1.0 + 1.0 / SPRING)
            if deadline is not None and time.monotonic() > deadline:
                raise OutOfTime(f"{marker}'s distance to {joint}")
            weight = np.sqrt(SPRING * curvature * scale)
            f = fit_chain(chain, data, state, terms=fit.terms, weights=weights, max_iter=MAX_ITER, tol=tol,
                          penalty=distance_penalty(chain, joint, marker, target, weight, n_params),
                          deadline=deadline)
            if not f.converged and (deadline is None or time.monotonic() < deadline):
                f = fit_chain(chain, data, f.state, terms=fit.terms, weights=weights, max_iter=MAX_ITER, tol=tol,
                              penalty=distance_penalty(chain, joint, marker, target, weight, n_params),
                              deadline=deadline)      # once more from where it stopped
            if deadline is not None and time.monotonic() > deadline:
                raise OutOfTime(f"{marker}'s distance to {joint}")
            refits += 1
            lowest = min(lowest, f.rss)
            if lowest < fit.rss - scale:        # no minimum to profile about: the bounds would be withdrawn
                return ProfileInterval(None, None, refits, float(lowest), better_fit=True)
            if not f.converged:                 # its Δχ² is too large by an unknown amount: no bound from it
                break
            d = distance_gradients(chain, f.state, n_params)[joint][marker][0]
            q = np.sqrt(max(f.rss - fit.rss, 0.0) / scale)
            if q >= root and side * (d - prev_d) > 0:
                frac = (root - prev_q) / (q - prev_q) if q > prev_q else 1.0
                bound = prev_d + frac * (d - prev_d)
                break
            if side < 0 and reach >= d0:
                bound = 0.0                     # aimed at zero and still within the bound: 0 (the widest) it is
                break
            moved = abs(d - d0)
            if side * (d - prev_d) > 0:
                state, prev_d, prev_q = f.state, d, q
            if moved >= MAX_SPAN_MM:
                break
            # the parabola through the estimate and this point: its curvature, and where it puts the bound
            if moved > 0 and q > 0:
                curvature = max((q / moved) ** 2, (root / MAX_SPAN_MM) ** 2)
                aim = AIM * root / np.sqrt(curvature)
            else:
                aim = 2.0 * max(moved, reach)
            reach = float(np.clip(aim, moved + MIN_STEP_MM, moved + MAX_STEP_MM))
        if bound is None and side < 0:      # not closed above 0: 0 is the honest lower bound
            bound = 0.0
        bounds.append(None if bound is None else float(bound))
    return ProfileInterval(bounds[0], bounds[1], refits, float(lowest))
