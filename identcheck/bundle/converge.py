"""A whole-tree fit taken to convergence, within a time budget: the fit every joint's answer is judged from.

A Levenberg-Marquardt run stopped by its iteration cap is no maximum of the likelihood. Its quadratic intervals
describe a point that is not the estimate, and a profile walked from it meets fits better than its "minimum"
(a knee with skin motion on both its segments, stopped 40 iterations into a valley, lay 220 χ² units above the
minimum 70 further iterations found). So ``fit`` and ``diagnose`` both judge their final fit only after
:func:`converged_fit` has restarted it while it has not converged, and a fit still not converged then claims no
interval (:func:`not_converged_reason`).
"""
from __future__ import annotations

import time

import numpy as np

from identcheck.bundle.chain import fit_chain
from identcheck.bundle.stuck_frames import restarted_stuck_frames
from identcheck.progress import Progress
from identcheck.skeleton import Skeleton

MAX_ITER = 200           # LM iterations per start (and per restart, see CONVERGE_BUDGET_S)
CONVERGE_BUDGET_S = 10.0
"""Seconds a start that has not converged after MAX_ITER iterations may go on (LM restarted from where it stopped,
its damping reset: a fit crawling along the valley of a segment posed by two markers needed ~1200 iterations).
A best fit still not converged answers nothing: its joints are undetermined and a warning says why."""
START_BUDGET_S = 120.0
"""Seconds a start's first MAX_ITER iterations may take: a 40-segment chain's 1000-frame fit had not ended after
180 s. A start stopped by it is not converged (its joints undetermined, a warning saying why)."""
FAST_CHI2_TOL = 1e-3
"""A whole-tree fit whose drops shrink fast stops when they promise to remove at most this much more of the cost in
chi² units (σ² each): the estimate is then within √(2·0.001) ≈ 0.045 standard errors of the minimum along any
direction, and a likelihood ratio (3.84 to reject) within 0.001 of its value. A fixed 1e-8 of the cost had asked for
one more iteration on every 1500-frame leg (its last one removing 1.5e-4 mm² of 13 816)."""
ITERATION_REPORT_S = 5.0
"""A whole-tree fit running longer than this says its iteration and cost this often (a 16-marker body's start
ran 60 s between two lines)."""


def converged_fit(chain: Skeleton, data, state, progress=None, weights=None, terms=None):
    """The whole-chain fit from `state` (with effect `terms`, if any), its frames left in a wrong pose restarted from
    their neighbours' (:func:`~identcheck.bundle.stuck_frames.restarted_stuck_frames`), restarted (damping reset)
    while it has not converged, for at most :data:`CONVERGE_BUDGET_S` seconds after its first :data:`MAX_ITER`
    iterations (which stop after :data:`START_BUDGET_S` seconds, with no restart then). Measured on a held-out 2+2 gait
    trial: stopped at 200 iterations the hip was 7 mm off at ±2.3 mm and the truth's distances fitted better by
    Δχ² 100; converged, that gap was gone."""
    line = Progress(progress, first_after_s=ITERATION_REPORT_S, every_s=ITERATION_REPORT_S)
    done = 0
    nu = max(int(np.isfinite(np.asarray(data)).all(axis=2).sum()) * 3
             - len(data) * (chain.frame_dof() - chain.frame_free()), 1)
    fast_tol = FAST_CHI2_TOL / nu           # the cost is about nu sigma²: this is FAST_CHI2_TOL in chi² units

    def said(it, cost):
        line(lambda: f"whole-tree fit: iteration {done + it}, {cost / max(len(data), 1):.4g} mm² a frame, "
                     f"{line.elapsed:.0f} s")

    first = time.monotonic() + START_BUDGET_S
    fit = fit_chain(chain, data, state, terms=terms, weights=weights, max_iter=MAX_ITER, on_iteration=said,
                    fast_tol=fast_tol, deadline=first)
    fit = restarted_stuck_frames(fit, data, weights, deadline=first)   # frames in a wrong pose, from neighbours
    out_of_time = time.monotonic() > first
    deadline = time.monotonic() + CONVERGE_BUDGET_S
    while not fit.converged and not out_of_time and time.monotonic() < deadline:
        done += fit.iterations
        if progress:
            progress(f"whole-tree fit not converged after {done} iterations: going on (at most "
                     f"{deadline - time.monotonic():.0f} s more)")
        fit = fit_chain(chain, data, fit.state, terms=terms, weights=weights, max_iter=MAX_ITER, on_iteration=said,
                        deadline=deadline, fast_tol=fast_tol)
    return fit


def not_converged_reason() -> str:
    """Why a joint of a fit that :func:`converged_fit` could not converge claims nothing."""
    return (f"the whole-tree fit did not converge within {CONVERGE_BUDGET_S:g} s of restarts after {MAX_ITER} "
            "iterations: it is no maximum of the likelihood, so no interval is claimed")
