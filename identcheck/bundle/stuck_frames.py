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


def frame_residuals(fit: Fit, data: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's weighted sum of squared residuals (F,) and its seen weight (F,): `w` (F, M) is 0 where `data`
    is not seen."""
    r2 = np.sum(w * np.sum(np.nan_to_num(data - fit.pred) ** 2, axis=2), axis=1)
    return r2, w.sum(axis=1)


def stuck_frames(fit: Fit, data: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The frames (indices) whose mean squared residual per seen sample is beyond :data:`STUCK_FACTOR` times the
    median frame's (`w` (F, M) as :func:`frame_residuals` takes it)."""
    r2, seen = frame_residuals(fit, data, w)
    per = np.where(seen > 0, r2 / np.maximum(seen, 1e-12), np.nan)
    typical = float(np.nanmedian(per)) if np.isfinite(per).any() else 0.0
    if typical <= 0.0:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(np.nan_to_num(per) > STUCK_FACTOR * typical)


def posed_from_neighbours(state: State, bad: np.ndarray, n_frames: int, seen: np.ndarray | None = None) -> State:
    """`state` with each of the `bad` frames' per-frame unknowns (root pose, joint angles) copied from the nearest
    frame not among them (and, with `seen` (F,), among the frames that see a marker: an unseen frame's pose is no
    fitted pose)."""
    usable = np.ones(n_frames, dtype=bool) if seen is None else np.asarray(seen, dtype=bool).copy()
    usable[bad] = False
    good = np.flatnonzero(usable)
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


def restarted_stuck_frames(fit: Fit, data: np.ndarray, weights=None, deadline: float | None = None) -> Fit:
    """`fit`, or, where :func:`stuck_frames` finds frames, its refit from their neighbours' poses
    (:func:`posed_from_neighbours`, :data:`RESTART_ITER` iterations, none begun after `deadline`, a
    ``time.monotonic()`` value) when that lowers the cost and at least halves what those frames leave: a fit that
    had not converged lowers its cost by iterating on alone, which says nothing of the frames."""
    data = np.asarray(data)
    finite = np.isfinite(data).all(axis=2)
    w = finite.astype(float) if weights is None else np.where(finite, np.asarray(weights, float), 0.0)
    bad = stuck_frames(fit, data, w)
    if not len(bad) or len(bad) > len(data) // 2:
        return fit
    start = posed_from_neighbours(fit.state, bad, len(data), seen=w.sum(axis=1) > 0)
    again = fit_chain(fit.chain, data, start, terms=fit.terms, weights=w, max_iter=RESTART_ITER, deadline=deadline)
    left_before, left_after = (frame_residuals(f, data, w)[0][bad].sum() for f in (fit, again))
    return again if again.rss < fit.rss and left_after < 0.5 * left_before else fit
