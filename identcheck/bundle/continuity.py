"""Joint angles that jump: a fit the rigid model matches only by turning a joint faster than any body can.

Two markers of one segment that exchange labels in mid-trial change no distance on it, and when the two sit alike
about a hinge (the same distance from its axis, a heel and a toe marker), the exchange is exactly a turn of the
segment about the axis: the rigid model fits the relabelled frames as well as the others, with the joint's angle
jumping at the exchange and its geometry wrong. On a simulated leg whose two foot markers were exchanged for the
second half of the trial, ``fit`` called the ankle ``determined`` with both markers 112 mm from its axis (truth 69 and
53 mm) at ±0.3 mm, exit 0. No distance screen sees that; the fitted angle does.

A joint is said to jump when it turns between two consecutive frames, both with its markers seen, by more than
:func:`jump_limit_deg`: :data:`MAX_TURN_DEG_S` times the frame interval, but never less than :data:`MIN_JUMP_DEG`
(a fast camera does not make a small turn a jump) nor more than :data:`MAX_JUMP_DEG` (at 50 Hz the speed alone
would let a half turn pass: a quarter turn in 20 ms is 4500 deg/s, which only a thrower's shoulder reaches, and
throwing is not captured at 50 Hz). Only angles the markers
measure are judged: the joint's, between two segments each posed by its own markers and the points its parent
joint fixes on it (:func:`~identcheck.bundle.honest.posed_by_itself`); a segment posed otherwise has a roll in
every frame that the data barely see, which may turn by a half turn from one frame to the next (a minimal leg's
knee did, on 2 of 40 held-out trials, before this rule).
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.honest import points_fixed_from_above, posed_by_itself

MAX_TURN_DEG_S = 10000.0
"""Fastest turn of a joint (deg/s): beyond a pitcher's shoulder in internal rotation, 7000-9000 deg/s."""
MIN_JUMP_DEG = 45.0
"""Smallest turn between two frames called a jump, however high the frame rate."""
MAX_JUMP_DEG = 90.0
"""A turn between two frames larger than this is a jump, however low the frame rate."""


def jump_limit_deg(rate_hz: float) -> float:
    """Turn between two consecutive frames beyond which a joint jumps, degrees (see the module docstring)."""
    return float(np.clip(MAX_TURN_DEG_S / float(rate_hz), MIN_JUMP_DEG, MAX_JUMP_DEG))


def _turns_deg(fit, joint: str) -> np.ndarray | None:
    """Turn of `joint` between consecutive frames (F-1,), degrees; None when the markers do not measure its angle."""
    chain, s = fit.chain, fit.state
    if not all(posed_by_itself(chain, seg, fit) for seg in (chain.parent[joint], chain.child[joint])):
        return None
    if chain.types[joint] == "revolute":
        d = np.diff(s.theta[joint])
        return np.abs(np.rad2deg((d + np.pi) % (2 * np.pi) - np.pi))
    R = s.rel_R[joint]
    cos = (np.einsum("fij,fij->f", R[:-1], R[1:]) - 1.0) / 2.0      # trace(R_fᵀ R_f+1) = 1 + 2 cos(turn)
    return np.rad2deg(np.arccos(np.clip(cos, -1.0, 1.0)))


def posed_frames(chain, seen: np.ndarray, segment: str) -> np.ndarray:
    """Frames (F,) bool in which a segment is posed by the markers seen there: its own seen markers and the points
    its parent joint fixes on it (:func:`~identcheck.bundle.honest.points_fixed_from_above`, when the parent is
    posed in that frame) number three or more."""
    own = seen[:, chain.seg_markers[segment]].sum(axis=1)
    up = [j for j in chain.joints if chain.child[j] == segment]
    if up:
        own = own + np.where(posed_frames(chain, seen, chain.parent[up[0]]), points_fixed_from_above(chain, segment), 0)
    return own >= 3


def angle_jumps(fit, data: np.ndarray, rate_hz: float) -> dict:
    """joint -> (largest jump in degrees, the 0-based row before it) for every joint whose measured angle turns
    faster than a body can between two consecutive frames in which the markers seen pose both its segments
    (:func:`posed_frames`). Across a gap the fitted angle follows the joints' geometry, not the markers: the bundled
    walking2 trial's hip "jumped" 174 deg where its pelvis had no marker seen and the thigh one or two, and the
    jump moved with the code's version (frames 1172, then 1078), as no exchange of labels does."""
    chain = fit.chain
    seen = np.isfinite(np.asarray(data, dtype=float)).all(axis=2)
    limit = jump_limit_deg(rate_hz)
    out = {}
    for j in chain.joints:
        turns = _turns_deg(fit, j)
        if turns is None or not len(turns):
            continue
        both = posed_frames(chain, seen, chain.parent[j]) & posed_frames(chain, seen, chain.child[j])
        turns = np.where(both[:-1] & both[1:], turns, 0.0)
        k = int(np.argmax(turns))
        if turns[k] > limit:
            out[j] = (float(turns[k]), k)
    return out
