"""The noise floor: what measurement noise alone would leave of the gap, estimated without the joint model.

Two markers on one rigid segment keep their distance apart, so its scatter over frames is noise
(seed 001, section 8: ``σ_d² = 2σ²`` for isotropic noise σ per coordinate). But the effects being
looked for bend segments too (soft tissue, a distorted volume), and over a whole trial they add
their own scatter. They are slow, noise is not: so each pair's scatter is taken frame to frame, from
the second differences ``d(t+1) − 2d(t) + d(t−1)`` (variance ``6σ_d²`` for white noise, while a
movement at 2 Hz and 100 Hz keeps 1.6 % of its amplitude), robustly (median absolute deviation, so
the few frames at a slip, a swap's ends or a gross error do not count), and the median over pairs is
kept, so that one misbehaving marker cannot raise the estimate through the pairs it belongs to.

Exported trajectories are often low-pass filtered or smoothed, which makes the noise serially correlated
and hides most of it from frame-to-frame differences. The noise is therefore modelled as AR(1) with
coefficient φ: the lag-1 correlation of a distance's first differences is ``−(1 − φ)/2`` (−½ for white
noise), which gives φ per pair (median over pairs); the second differences then have variance
``σ_d² (1 − φ)(6 − 2φ)``, which gives the marginal σ. For white noise this is the estimate above. The seed
001 whole-trial scatter is reported alongside (``sigma_scatter_mm``): much larger than ``sigma_mm`` means the
segments deform slowly. A least-squares fit with P free parameters to 3N coordinates leaves, in
expectation, ``σ²(3N − P)``; the floor in the contract's gap measure (RMS 3-D distance over the N
marker samples) is therefore ``σ·sqrt((3N − P)/N)``.

Near φ = 1 the marginal σ hangs on φ's last digits (at φ 0.94 a change of 0.01 moves it by 9 %), and φ read from one
distance's 1 000 frames scatters by ±0.05: a one-pair ankle under noise of 1.09 mm and φ 0.94 read φ 0.98 and σ 1.97
mm. A distance's whole-trial spread bounds it: noise cannot scatter a distance more than the distance scatters, so
each pair's φ is at most the one that puts its marginal σ at its whole-trial spread (bias-corrected for the serial
correlation and raised by about one standard error; slow deformation only raises the spread, and with it the bound),
and σ's relative standard error counts φ's sampling error (``2/√n`` for n first differences) even with one pair, or
the spread's own where most pairs' φ is set by it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.seed001 import MAD_TO_SD, marker_noise

MIN_SAMPLES_PER_PAIR = 10
MAX_PHI = 0.98
"""Largest lag-1 coefficient estimated: beyond it, noise and slow motion cannot be told apart."""
WINSOR = 5.0
"""First differences beyond this many robust standard deviations (a slip, a swap's ends, a gross error)
are clipped before their correlation is taken."""


def frame_to_frame_sd(d: np.ndarray) -> tuple[float, int]:
    """Robust standard deviation of a distance series d (F,)'s second differences over consecutive visible
    frames, divided by √6 (the noise's own standard deviation if it is white); and how many were used."""
    dd = d[2:] - 2 * d[1:-1] + d[:-2]
    dd = dd[np.isfinite(dd)]
    if len(dd) < MIN_SAMPLES_PER_PAIR:
        return float("nan"), len(dd)
    return float(MAD_TO_SD * np.median(np.abs(dd - np.median(dd))) / np.sqrt(6.0)), len(dd)


def ar1_coefficient(d: np.ndarray) -> float:
    """φ of AR(1) noise on a distance series d (F,), from the lag-1 correlation ρ of its first differences
    (ρ = −(1 − φ)/2), the differences winsorised at :data:`WINSOR` robust standard deviations; in
    [0, :data:`MAX_PHI`], NaN when too few consecutive frames are visible."""
    dx = np.diff(d)
    ok = np.isfinite(dx[1:]) & np.isfinite(dx[:-1])
    if ok.sum() < MIN_SAMPLES_PER_PAIR:
        return float("nan")
    fin = dx[np.isfinite(dx)]
    med = np.median(fin)
    half = WINSOR * MAD_TO_SD * np.median(np.abs(fin - med))
    if not half > 0:
        return float("nan")
    dx = np.clip(dx - med, -half, half)
    a, b = dx[1:][ok], dx[:-1][ok]
    den = np.sqrt(float(a @ a) * float(b @ b))
    rho = float(a @ b) / den if den > 0 else -0.5
    return float(np.clip(1 + 2 * rho, 0.0, MAX_PHI))


def second_difference_factor(phi: float) -> float:
    """Variance of an AR(1) series' second differences over its marginal variance, over 6 (1 for white
    noise): what turns :func:`frame_to_frame_sd` into the marginal standard deviation."""
    return (1 - phi) * (6 - 2 * phi) / 6.0


def phi_of_factor(factor: float) -> float:
    """The φ whose :func:`second_difference_factor` is `factor` (its inverse on [0, 1]: ``2 − √(1 + 3 factor)``),
    clipped to [0, :data:`MAX_PHI`]."""
    return float(np.clip(2.0 - np.sqrt(1.0 + 3.0 * max(factor, 0.0)), 0.0, MAX_PHI))


def effective_samples(n: float, phi: float) -> float:
    """How many independent samples `n` consecutive samples of AR(1) noise of coefficient `phi` are worth for their
    mean, ``n (1 − φ)/(1 + φ)``, at least 2."""
    return max(n * (1 - phi) / (1 + phi), 2.0)


def spread_bound(d: np.ndarray, sd: float, phi: float) -> float:
    """The largest lag-1 coefficient a distance series d (F,) allows, given its frame-to-frame standard deviation
    `sd` (:func:`frame_to_frame_sd`) and its own coefficient `phi` (:func:`ar1_coefficient`): the one whose
    marginal σ (``sd / √factor``) equals the series' whole-trial standard deviation, that bias-corrected for the
    serial correlation (``1 − 1/n_eff``, ``n_eff = n (1 − φ)/(1 + φ)``, the mean's) and raised by ``1/√(2 n_eff)``
    (about one standard error of a standard deviation; the variance's own n_eff, ``n (1 − φ²)/(1 + φ²)``, is larger
    near φ = 1, so the bound is looser than one). Slow deformation and gross errors only raise the spread, and with it
    the bound."""
    x = d[np.isfinite(d)]
    var = float(np.var(x)) if len(x) > 1 else 0.0
    if not (var > 0 and sd > 0):
        return MAX_PHI
    var /= 1 - 1 / effective_samples(len(x), phi)
    first = phi_of_factor(sd ** 2 / var)
    upper = var * (1 + 1 / np.sqrt(2 * effective_samples(len(x), first))) ** 2
    return phi_of_factor(sd ** 2 / upper)


@dataclass(frozen=True)
class NoiseFloor:
    """Marker noise from within-segment distances.

    Attributes
    ----------
    sigma_mm : float
        Noise standard deviation of one coordinate, mm (median over pairs, frame to frame, corrected for
        the serial correlation ``lag1``).
    sigma_scatter_mm : float
        The same from the whole-trial scatter of the distances (seed 001, section 8), mm.
    pair_sigma_mm : dict
        "A-B" → that pair's own robust estimate, mm.
    rel_se : float
        Relative standard error of ``sigma_mm`` (from the spread of the pairs' estimates, φ's included: at least its
        sampling error over the frames, or the spread's where that bounds φ; near φ = 1 a linear reading of a
        σ known only within a factor, so large).
    n_pairs, n_samples : int
    lag1 : float
        φ, the AR(1) coefficient of the noise from frame to frame (0: white).
    """

    sigma_mm: float
    sigma_scatter_mm: float
    pair_sigma_mm: dict
    rel_se: float
    n_pairs: int
    n_samples: int
    lag1: float = 0.0

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
    pair_sd, scatter, counts, phis, capped = {}, [], [], [], []
    independent = 0          # distances whose noise is independent of the others': a segment's markers paired, less 1
    for seg, markers in segments.items():
        idx = [col[m] for m in markers if m in col]
        paired = set()
        for a in range(len(idx)):
            for b in range(a + 1, len(idx)):
                pts = data[:, [idx[a], idx[b]]]
                dist = np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1)
                sd, n = frame_to_frame_sd(dist)
                if not np.isfinite(sd):
                    # too few runs of three consecutive frames (every other frame blank): the seen frames in
                    # order, as a trial at a lower rate (the estimate had been lost, and with it every check
                    # that needs the noise: skeleton called such a trial settled)
                    dist = dist[np.isfinite(dist)]
                    sd, n = frame_to_frame_sd(dist)
                if not np.isfinite(sd):
                    continue
                pair_sd[f"{labels[idx[a]]}-{labels[idx[b]]}"] = sd / np.sqrt(2.0)
                phi = ar1_coefficient(dist)
                bound = spread_bound(dist, sd, phi) if np.isfinite(phi) else phi
                phis.append(min(phi, bound))
                capped.append(bool(np.isfinite(phi) and bound < phi))
                scatter.append(pts)
                counts.append(n)
                paired |= {a, b}
        independent += max(len(paired) - 1, 0)
    if not pair_sd:
        raise InputError(["no two markers of one segment are seen together in "
                          f"{MIN_SAMPLES_PER_PAIR} or more frames: the noise floor cannot be estimated"])
    phis = np.array([p for p in phis if np.isfinite(p)])
    phi = float(np.median(phis)) if len(phis) else 0.0
    scale = 1 / np.sqrt(second_difference_factor(phi))
    pair_sd = {k: v * scale for k, v in pair_sd.items()}
    vals = np.array(list(pair_sd.values()))
    sigma = float(np.median(vals))
    n = len(vals)
    # standard error of a median of n estimates, each with MAD's own sampling error
    mad_se = 1.167 / np.sqrt(max(np.median(counts), 1))
    spread = 1.2533 * 1.4826 * np.median(np.abs(vals - sigma)) / max(sigma, 1e-300) / np.sqrt(n) if n > 1 else 0.0
    # and φ's: d ln σ / dφ = ½ (1/(1 − φ) + 2/(6 − 2φ)), φ's standard error that of a median of the pairs', at least
    # its sampling error from the frames (2/√n for n first differences: one pair's φ is no better known than that),
    # over the distances whose noise is independent (six pairs of four markers: three). Where most pairs' φ is set
    # by their spread (spread_bound), σ is that spread's, known to 1/√(2 n_eff) a distance
    m_pairs = max(min(len(phis), independent), 1)
    spread_phi = 1.2533 * 1.4826 * np.median(np.abs(phis - phi)) / np.sqrt(len(phis)) if len(phis) > 1 else 0.0
    phi_se = max(spread_phi, 2.0 / np.sqrt(max(np.median(counts), 1) * m_pairs))
    phi_part = 0.5 * (1 / (1 - phi) + 2 / (6 - 2 * phi)) * phi_se if phi > 0 else 0.0
    if capped and np.mean(capped) >= 0.5:
        phi_part = min(phi_part, 1 / np.sqrt(2 * effective_samples(np.median(counts), phi) * m_pairs))
    whole = marker_noise(*scatter).noise_mm
    rel_se = float(np.hypot(max(mad_se / np.sqrt(n), spread), phi_part))
    return NoiseFloor(sigma, whole, pair_sd, rel_se, n, int(np.sum(counts)), phi)
