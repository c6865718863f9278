"""Samples no marker can take, set aside before a fit: one frame far from where both its neighbours put the marker.

A ghost marker labelled for one frame, or a coordinate an export multiplied or cut short, puts a marker metres
away for a single frame. A least-squares fit cannot absorb that: on a simulated leg one such sample of the knee
marker (its coordinates times ten) stopped the whole-tree fit from converging and left every joint 500-1100 mm off,
and ``diagnose`` called the hip ``determined`` 3.7 m from the knee marker, exit 0.

The test is the median of three: per coordinate, the median of a sample and its two neighbours is the sample itself
whenever that coordinate moves one way through the three frames, however fast; it differs only where the
coordinate turns back within a frame, and there real motion is slow (the turn is where its velocity passes zero).
A sample more than :data:`GROSS_JUMP_MM` from that median is a gross error: out by that much and back within
one frame each is 20 m/s each way at 100 Hz (below 49 Hz the limit grows with the frame interval squared,
:func:`jump_limit`: at 15 Hz and below it passes 3.5 m, and a coordinate multiplied by ten is no longer caught
here). Smaller gross errors (15-60 mm ghosts) are ``diagnose``'s ``outliers`` effect, which models them; this only
keeps the impossible ones from wrecking the fits that effect starts from. A spike beside a gap, or two in a row, is
not seen here (the median needs both neighbours, and two equal spikes are each other's median); beside a jump the
median is the other neighbour, so in the fastest motions (some 10 m/s at 50 Hz) a good sample next to a jump can go
too: one sample lost, never a jump kept.
"""
from __future__ import annotations

import numpy as np

from identcheck.trial import Trial

GROSS_JUMP_MM = 200.0
"""Distance (mm) from the median of a sample and its two neighbours beyond which the sample is a gross error (at 50 Hz
and faster; slower captures get :func:`jump_limit`)."""
FASTEST_TURN_MM_S2 = 25_000.0 * np.pi * 3.0
"""The fastest motion a turn is allowed (mm/s², speed times π times turns a second): 25 m/s, faster than a kicking
foot, turning back 3 times a second. At such a turn a sample departs from its neighbours' median by about this times
the frame interval squared (23.6 mm at 100 Hz)."""


def jump_limit(rate_hz: float | None) -> float:
    """The distance (mm) from the median of three beyond which a sample is a gross error at `rate_hz`:
    :data:`GROSS_JUMP_MM`, or twice what the fastest turn (:data:`FASTEST_TURN_MM_S2`) departs by in a frame when that
    is more (below 49 Hz: 524 mm at 30 Hz, 18.8 m at 5 Hz). A fixed 200 mm had set aside 19 % of the samples of a leg
    captured at 1 Hz as jumps no body makes."""
    if not rate_hz or not np.isfinite(rate_hz) or rate_hz <= 0:
        return GROSS_JUMP_MM
    return max(GROSS_JUMP_MM, 2.0 * FASTEST_TURN_MM_S2 / rate_hz ** 2)


def gross_spikes(xyz: np.ndarray, rate_hz: float | None = None) -> np.ndarray:
    """(F, M) True where a sample of `xyz` (F, M, 3), mm, NaN where occluded, lies more than :func:`jump_limit` (at
    `rate_hz`; :data:`GROSS_JUMP_MM` when not given) from the per-coordinate median of itself and its two neighbours
    (never at the first or last frame, nor beside a gap)."""
    limit = jump_limit(rate_hz)
    xyz = np.asarray(xyz, dtype=float)
    out = np.zeros(xyz.shape[:2], dtype=bool)
    if xyz.shape[0] < 3:
        return out
    three = np.stack([xyz[:-2], xyz[1:-1], xyz[2:]])
    with np.errstate(invalid="ignore"):
        dev = np.linalg.norm(xyz[1:-1] - np.median(three, axis=0), axis=2)
        out[1:-1] = dev > limit                      # NaN (a neighbour unseen) compares False
    return out


def without_spikes(trial: Trial) -> tuple[Trial, dict | None]:
    """The trial with its gross spikes (:func:`gross_spikes`) made occluded, and a warning naming them (``kind``
    ``gross_error``, ``markers``, ``frames`` as 0-based rows, ``file_frames`` and ``count``, the samples), or None
    when there are none.
    The input file is not touched."""
    mask = gross_spikes(trial.xyz, trial.rate_hz)
    if not mask.any():
        return trial, None
    xyz = trial.as_array()
    xyz[mask] = np.nan
    rows, cols = np.nonzero(mask)
    markers = sorted({trial.labels[c] for c in cols})
    shown = ", ".join(f"{trial.labels[c]} at frame {trial.frame_number(int(r))}" for r, c in zip(rows[:8], cols[:8]))
    more = f" and {len(rows) - 8} more" if len(rows) > 8 else ""
    message = (f"{trial.source}: {len(rows)} sample(s) lie more than {jump_limit(trial.rate_hz):g} mm from where the "
               f"frames before and after put their marker, a jump out and back that no body makes in one frame at "
               f"{trial.rate_hz:g} Hz (a ghost marker or a corrupt coordinate); left out: {shown}{more}")
    frames = sorted({int(r) for r in rows})
    return (trial.replace(xyz=xyz),
            {"kind": "gross_error", "message": message, "markers": markers, "frames": frames,
             "count": int(len(rows)),
             "file_frames": [trial.frame_number(f) for f in frames]})
