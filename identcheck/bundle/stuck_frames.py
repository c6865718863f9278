"""Frames a whole-tree fit left in a wrong pose: found by their residual, restarted from a neighbour's pose.

Each frame's pose is solved by its own few unknowns inside the whole fit, and a frame can settle in a second,
wrong minimum of them: a pelvis seen by two markers (the third in a gap) turns about the line through them, and its
hip centre, carried round a circle, meets the thigh's at a second place. Levenberg-Marquardt never leaves such a
minimum, and the fit then carries frames 15-20 mm off on every marker of the leg among good ones on either side
(held-out draw 45, trial 39: a clean gait trial whose rigid fit failed the noise test, ratio 1.81, and was named an
effect). The poses of neighbouring frames differ by little: started from the nearest good frame's pose, such a frame
falls into the right minimum. The restart is kept only where the whole fit's cost falls.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import fit_chain
from identcheck.bundle.model import Fit, State

STUCK_FACTOR = 25.0
"""A frame is suspect when its mean squared residual per seen sample exceeds this many times the trial's median
frame's (5 times the RMS)."""
RESTART_ITER = 20
"""Iterations of the fit restarted from the repaired poses (the constants start where they were)."""


def stuck_frames(fit: Fit, data: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The frames (indices) whose mean squared residual per seen sample is beyond :data:`STUCK_FACTOR` times the
    median frame's."""
    w = np.where(np.isfinite(np.asarray(data)).all(axis=2), np.asarray(weights, dtype=float), 0.0)
    seen = w.sum(axis=1)
    r2 = np.sum(w * np.sum(np.nan_to_num(np.asarray(data) - fit.pred) ** 2, axis=2), axis=1)
    per = np.where(seen > 0, r2 / np.maximum(seen, 1e-12), np.nan)
    typical = float(np.nanmedian(per)) if np.isfinite(per).any() else 0.0
    if typical <= 0.0:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(np.nan_to_num(per) > STUCK_FACTOR * typical)


def posed_from_neighbours(state: State, bad: np.ndarray, n_frames: int) -> State:
    """`state` with each of the `bad` frames' per-frame unknowns (root pose, joint angles) copied from the nearest
    frame not among them."""
    good = np.setdiff1d(np.arange(n_frames), bad)
    s = state.copy()
    if not len(good):
        return s
    src = good[np.clip(np.searchsorted(good, bad), 0, len(good) - 1)]
    left = good[np.clip(np.searchsorted(good, bad) - 1, 0, len(good) - 1)]
    src = np.where(np.abs(left - bad) <= np.abs(src - bad), left, src)              # the earlier on a tie
    s.root_R[bad], s.root_t[bad] = state.root_R[src], state.root_t[src]
    for j in s.rel_R:
        s.rel_R[j][bad] = state.rel_R[j][src]
    for j in s.theta:
        s.theta[j][bad] = state.theta[j][src]
    return s


def restarted_stuck_frames(fit: Fit, data: np.ndarray, weights=None) -> Fit:
    """`fit`, or, where :func:`stuck_frames` finds frames, its refit from their neighbours' poses
    (:func:`posed_from_neighbours`, :data:`RESTART_ITER` iterations) when that lowers the cost."""
    w = np.isfinite(np.asarray(data)).all(axis=2).astype(float) if weights is None else np.asarray(weights, float)
    bad = stuck_frames(fit, data, w)
    if not len(bad) or len(bad) > len(data) // 2:
        return fit
    start = posed_from_neighbours(fit.state, bad, len(data))
    again = fit_chain(fit.chain, data, start, terms=fit.terms, weights=w, max_iter=RESTART_ITER)
    return again if again.rss < fit.rss else fit
