"""The noise floor: what measurement noise alone would leave of the gap, estimated without the joint model.

Two markers on one rigid segment keep their distance apart, so its scatter over frames is noise
(seed 001, section 8: ``σ_d² = 2σ²`` for isotropic noise σ per coordinate). But the effects being
looked for bend segments too (soft tissue, a distorted volume), and over a whole trial they add
their own scatter. They are slow, noise is not: so each pair's scatter is taken frame to frame, from
the second differences ``d(t+1) − 2d(t) + d(t−1)`` (variance ``6σ_d²`` for white noise, while a
movement at 2 Hz and 100 Hz keeps 1.6 % of its amplitude), robustly (median absolute deviation, so
the few frames at a slip, a swap's ends or a gross error do not count), and the median over pairs is
kept, so that one misbehaving marker cannot raise the estimate through the pairs it belongs to. The
seed 001 whole-trial scatter is reported alongside (``sigma_scatter_mm``): much larger than
``sigma_mm`` means the segments deform slowly, or the recording was low-pass filtered (which hides
noise from the frame-to-frame estimate and makes the floor optimistic). A least-squares fit with P free parameters to 3N coordinates leaves, in
expectation, ``σ²(3N − P)``; the floor in the contract's gap measure (RMS 3-D distance over the N
marker samples) is therefore ``σ·sqrt((3N − P)/N)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.seed001 import MAD_TO_SD, marker_noise

MIN_SAMPLES_PER_PAIR = 10


def frame_to_frame_sd(d: np.ndarray) -> tuple[float, int]:
    """Robust standard deviation of the noise on a distance series d (F,), from its second differences
    over consecutive visible frames; and how many were used."""
    dd = d[2:] - 2 * d[1:-1] + d[:-2]
    dd = dd[np.isfinite(dd)]
    if len(dd) < MIN_SAMPLES_PER_PAIR:
        return float("nan"), len(dd)
    return float(MAD_TO_SD * np.median(np.abs(dd - np.median(dd))) / np.sqrt(6.0)), len(dd)


@dataclass(frozen=True)
class NoiseFloor:
    """Marker noise from within-segment distances.

    Attributes
    ----------
    sigma_mm : float
        Noise standard deviation of one coordinate, mm (median over pairs, frame to frame).
    sigma_scatter_mm : float
        The same from the whole-trial scatter of the distances (seed 001, section 8), mm.
    pair_sigma_mm : dict
        "A-B" → that pair's own robust estimate, mm.
    rel_se : float
        Relative standard error of ``sigma_mm`` (from the spread of the pairs' estimates).
    n_pairs, n_samples : int
    """

    sigma_mm: float
    sigma_scatter_mm: float
    pair_sigma_mm: dict
    rel_se: float
    n_pairs: int
    n_samples: int

    def floor(self, n_samples: int, n_params: int) -> float:
        """Expected RMS 3-D gap of a least-squares fit with `n_params` free parameters to
        `n_samples` marker samples, under this noise alone, mm."""
        return float(self.sigma_mm * np.sqrt(max(3 * n_samples - n_params, 0) / max(n_samples, 1)))


def noise_floor(data, labels, segments: dict) -> NoiseFloor:
    """Estimate the marker noise from every pair of markers sharing a segment.

    Parameters
    ----------
    data : array (F, M, 3)
        Markers in `labels` order, mm, NaN where occluded.
    labels : sequence of str
    segments : dict
        Segment name → its marker names.

    Raises
    ------
    InputError
        No pair of markers on one segment is seen together in enough frames.
    """
    col = {m: i for i, m in enumerate(labels)}
    pair_sd, scatter, counts = {}, [], []
    for seg, markers in segments.items():
        idx = [col[m] for m in markers if m in col]
        for a in range(len(idx)):
            for b in range(a + 1, len(idx)):
                pts = data[:, [idx[a], idx[b]]]
                sd, n = frame_to_frame_sd(np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1))
                if not np.isfinite(sd):
                    continue
                pair_sd[f"{labels[idx[a]]}-{labels[idx[b]]}"] = sd / np.sqrt(2.0)
                scatter.append(pts)
                counts.append(n)
    if not pair_sd:
        raise InputError(["no two markers of one segment are seen together in "
                          f"{MIN_SAMPLES_PER_PAIR} or more frames: the noise floor cannot be estimated"])
    vals = np.array(list(pair_sd.values()))
    sigma = float(np.median(vals))
    n = len(vals)
    # standard error of a median of n estimates, each with MAD's own sampling error
    mad_se = 1.167 / np.sqrt(max(np.median(counts), 1))
    spread = 1.2533 * 1.4826 * np.median(np.abs(vals - sigma)) / max(sigma, 1e-300) / np.sqrt(n) if n > 1 else 0.0
    whole = marker_noise(*scatter).noise_mm
    return NoiseFloor(sigma, whole, pair_sd, float(max(mad_se / np.sqrt(n), spread)), n, int(np.sum(counts)))
