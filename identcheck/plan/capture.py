"""The capture ``plan --noise-mm`` predicts: how many frames it has by default and may have.

One place for the numbers the command line, the batch and the library check a request against, so that
``plan --frames 5`` and ``batch plan --frames 5`` are refused alike, before any work.
"""
from __future__ import annotations

FRAMES = 1000
"""Frames of the predicted capture unless the user says."""
FRAMES_RANGE = (10, 20000)
"""Fewest and most frames of a predicted capture: fewer do not pose a joint's samples apart from the noise, more
than a long functional trial only make the prediction slower (it scales the standard errors by √frames)."""


def frames_problem(frames) -> str:
    """Why `frames` is not a number of frames of a predicted capture ('' when it is)."""
    lo, hi = FRAMES_RANGE
    if isinstance(frames, bool) or not isinstance(frames, int) or not lo <= frames <= hi:
        return f"{frames!r}: the predicted capture's number of frames, {lo} to {hi}"
    return ""
