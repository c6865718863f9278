"""The fitted skeleton as plain data a figure can draw: measured markers, fitted joint centres and hinge-axis
points over a sample of frames, and each marker's residual.

Why a separate step: the HTML report (:mod:`identcheck.report.html`) sits above the fit and must not reach
into its state; it gets numbers only. Frames are sampled evenly (at most :data:`MAX_FRAMES`) so that a long
trial stays a small page; coordinates are in the trial's millimetres and world frame, frames in the file's own
numbering.
"""
from __future__ import annotations

import numpy as np

from identcheck.fit.export import joint_trajectories
from identcheck.io.model import virtual_names
from identcheck.trial import Trial

MAX_FRAMES = 300


def trial_scene(trial: Trial, fit, offset=(0.0, 0.0, 0.0)) -> dict:
    """:func:`fit_scene` of a fit of `trial` itself (its markers in the fit's order, its own frame numbers)."""
    return fit_scene(fit, trial.select(fit.chain.labels).as_array(), trial.frame_number(np.arange(trial.n_frames)),
                     offset)


def fit_scene(fit, data: np.ndarray, frame_numbers, offset=(0.0, 0.0, 0.0), max_frames: int = MAX_FRAMES) -> dict:
    """Drawable data of a whole-chain fit of `data` ((F, M, 3), the fit's chain's marker order, moved by `offset`
    from the file's coordinates, which is added back); `frame_numbers` (F,): each row's number in the file.

    Returns a dict: ``frames`` (file frame numbers of the sampled rows), ``markers`` (labels),
    ``marker_segment`` (label -> segment), ``joints`` (list of ``{name, type, parent, child, points}``, the
    points being the names of its virtual markers: a centre, or a hinge's two axis points), ``xyz`` (per sampled
    frame, per marker, [x, y, z] mm or None where occluded), ``joint_xyz`` (per sampled frame, per joint point;
    None in a frame where no marker was seen, since the fit there only bridges the gap),
    ``residual_rms_mm`` (label -> RMS of measured minus fitted over the frames it is seen) and ``units``."""
    chain = fit.chain
    data = np.asarray(data, dtype=float)
    rows = np.unique(np.linspace(0, len(data) - 1, min(max_frames, len(data))).round().astype(int))
    shift = np.asarray(offset, dtype=float)
    points = joint_trajectories(fit)
    seen = np.all(np.isfinite(data), axis=2)
    residual = np.where(seen[..., None], data - fit.pred, np.nan)
    rms = np.sqrt(np.nanmean(np.sum(residual ** 2, axis=2), axis=0))

    def coords(xyz):
        return [None if not np.all(np.isfinite(p)) else [round(float(v), 1) for v in p] for p in xyz]

    names = list(points)
    return {
        "frames": [int(frame_numbers[r]) for r in rows],
        "markers": list(chain.labels),
        "marker_segment": {m: chain.marker_seg[i] for i, m in enumerate(chain.labels)},
        "joints": [{"name": j, "type": chain.types[j], "parent": chain.parent[j], "child": chain.child[j],
                    "points": list(virtual_names(j, chain.types[j]))} for j in chain.joints],
        "xyz": [coords(data[r] + shift) for r in rows],
        "joint_xyz": [coords(np.array([points[n][r] for n in names]) + (shift if seen[r].any() else np.nan))
                      for r in rows],
        "joint_points": names,
        "residual_rms_mm": {m: (None if not np.isfinite(v) else round(float(v), 3)) for m, v in zip(chain.labels, rms)},
        "units": "mm",
    }
