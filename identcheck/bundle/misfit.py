"""Does the rigid-joint model fit, or do markers move on their segments with the joint angles?

Skin moves over bone as the joints turn (soft-tissue artefact), and a rigid fit absorbs much of that motion
into the joint's geometry: its intervals then describe the noise, not the bias, and a joint can be
reported to a fraction of a millimetre while several millimetres off. The residual alone cannot tell skin
motion from serially correlated noise (both are smooth; a low-pass filtered export has lag-1 correlations of
0.9), and a comparison with the frame-to-frame noise flags every filtered trial. What tells them apart is
whether the residual *follows the joint angles*.

For every marker, its residual in its segment's frame is regressed on smooth functions of the angles of the
joints its segment takes part in (:func:`identcheck.bundle.hypothesis.angle_basis`: the angles and their
products). Under noise alone, AR(1) with coefficient φ, the regression explains on average
``3 σ_u² K / N_eff`` (K regressors, ``N_eff = N (1 − φ)/(1 + φ)`` effectively independent frames), σ_u and
φ read from the regression's own remainder. The ratio of the explained mean square to that is about 1 for
noise of any correlation; skin motion of a millimetre or more makes it hundreds. A marker whose ratio exceeds
:data:`RATIO` moves with the angles.

The ratio has no power when the residual is so smooth that the trial holds only a handful of effectively
independent frames (lag-1 0.99 leaves ``N_eff`` below the number of angle functions): then AR(1) noise of any
size could explain any fit, and on the real hip trial with two markers on each segment the greater trochanter's
residual followed the hip angles by 12 mm at a ratio of 4 (RGT–RLFE, a "rigid" pair, changed length by 96 mm),
while the joint was reported to ±7.6 mm some 30 mm from every other estimator's. No capture system's noise
reaches that size, however smooth: a marker whose angle-following part exceeds :data:`NOISE_CEILING_MM` moves
with the angles whatever its ratio.

What follows for the joints (:func:`model_error_sd`): the bias a rigid fit takes from skin motion is not
estimable from one trial, but its size is: a marker that moves by ``e`` with the joint's angle is, to first
order, indistinguishable from a joint centre displaced by ``e / θ`` (θ the joint's RMS excursion in
radians: ``(R(θ) − I) Δc ≈ θ × Δc``), so a joint moved through ±15° takes four times the bias of one moved
through ±60° from the same skin motion. The model-error standard deviation is the larger of
``e / max(θ, θ_min)`` and :data:`MODEL_ERROR_PER_MM` · e, with e the largest angle-following motion among
the joint's markers; it is added in quadrature to each marker distance's standard error. That is an order of
magnitude, not a calibrated model of the bias: the report says so, and names ``identcheck diagnose``, which
models the motion, as the next step. A joint beside a segment with fewer than three markers takes the
largest motion seen anywhere in the trial: such a segment cannot show its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identcheck.bundle.hypothesis import angle_basis, joint_angles
from identcheck.bundle.uncertainty import lag1

RATIO = 10.0
"""Explained mean square over what correlated noise would explain, beyond which a marker moves with the
joint angles (noise alone gives about 1: 0.7-2.7 over 24 simulated trials of white and AR(1) noise)."""
NOISE_CEILING_MM = 8.0
"""Angle-following motion (3-D RMS, mm) that noise does not reach at any correlation: twice what AR(1) noise
explains on average in the most extreme simulated capture (1.5 mm, lag-1 0.95, 300 frames, a pelvis between two
ball joints: 18 angle functions, ``σ sqrt(3K / N_eff)`` = 4 mm); optical capture noise is 0.1-1.5 mm."""
MODEL_ERROR_PER_MM = 1.5
"""Smallest model-error standard deviation (mm) per mm of angle-following motion of a joint's markers."""
MIN_EXCURSION_RAD = 0.05
"""A joint's RMS excursion is taken as at least this (3°) in ``e / θ``."""


@dataclass(frozen=True)
class MarkerMisfit:
    """How much of one marker's residual follows the joint angles.

    Attributes
    ----------
    marker, segment : str
    explained_mm : float
        RMS (3-D) of the part of the residual the angle functions explain, mm.
    ratio : float
        Its mean square over what serially correlated noise alone would explain (about 1 under the null).
    lag1 : float
        Lag-1 autocorrelation of the rest of the residual.
    """

    marker: str
    segment: str
    explained_mm: float
    ratio: float
    lag1: float

    @property
    def moves(self) -> bool:
        """Whether the marker moves with the joint angles (ratio above :data:`RATIO`, or a motion larger than
        noise reaches, :data:`NOISE_CEILING_MM`)."""
        return self.ratio > RATIO or self.explained_mm > NOISE_CEILING_MM


def angle_dependence(fit, data) -> dict:
    """marker -> :class:`MarkerMisfit` for every marker of a whole-chain fit (see the module docstring)."""
    chain = fit.chain
    angles = joint_angles(fit)
    resid = np.asarray(data, dtype=float) - fit.pred
    out = {}
    for seg in chain.segments:
        joints = [j for j in chain.joints if seg in (chain.parent[j], chain.child[j])]
        if not joints:
            continue
        basis = np.concatenate([angle_basis(angles[j]) for j in joints], axis=1)
        for col in chain.seg_markers[seg]:
            local = np.einsum("fji,fj->fi", fit.seg_R[seg], resid[:, col])
            ok = np.all(np.isfinite(local), axis=1)
            K = basis.shape[1]
            if ok.sum() <= 3 * (K + 2):
                continue
            X = np.column_stack([np.ones(ok.sum()), basis[ok]])
            y = local[ok] - local[ok].mean(axis=0)
            beta = np.linalg.lstsq(X, y, rcond=None)[0]
            fitted = X @ beta                # y is centred, so is its fit: the intercept must not be left out
            rest = y - fitted
            rho = float(np.clip(np.median([lag1(rest[:, c]) for c in range(3)]), 0.0, 0.99))
            n_eff = max(len(rest) * (1 - rho) / (1 + rho), 1.0)
            spurious = 3 * float(np.mean(rest ** 2)) * K / n_eff
            explained = float(np.mean(np.sum(fitted ** 2, axis=1)))
            out[chain.labels[col]] = MarkerMisfit(chain.labels[col], seg, float(np.sqrt(explained)),
                                                  explained / max(spurious, 1e-300), rho)
    return out


def excursion_rad(fit, joint: str) -> float:
    """RMS angular excursion of a joint about its mean pose over the trial, radians."""
    a = joint_angles(fit)[joint]
    dev = a - a.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(dev ** 2, axis=1))))


@dataclass(frozen=True)
class ModelledMotion:
    """Motion with the joint angles that an effect term of ``diagnose`` fits: a marker (or a cluster) moving on its
    segment, or a joint's centre moving in its parent; or (``reading`` set) that motion as an effect the data cannot
    tell from the fitted one would take it. The term takes that motion out of the residual, so
    :func:`angle_dependence` no longer sees it; the segments are what it moves relative to the joints.

    Attributes
    ----------
    segments : tuple of str
        The segments whose markers it moves relative to the joints beside them.
    rms_mm : float
        RMS (3-D) over the frames of the fitted motion about its mean, mm.
    joint : str or None
        The one joint it moves (a centre moving in its parent), or None: every joint beside `segments` (skin).
    reading : str
        Empty for the motion an adopted effect fits; else the effect the data cannot tell from the adopted one
        whose reading of the same motion this is (:meth:`identcheck.effects.base.Effect.reading`), for the report.
    """

    segments: tuple
    rms_mm: float
    joint: str | None = None
    reading: str = ""

    def beside(self, chain, joint: str) -> bool:
        """Whether this motion moves `joint`'s markers relative to it."""
        if self.joint is not None:
            return self.joint == joint
        return bool(set(self.segments) & {chain.parent[joint], chain.child[joint]})


def model_error_sd(fit, joint: str, misfit: dict, modelled: tuple = ()) -> float:
    """The model-error standard deviation (mm) for `joint`'s marker distances (see the module docstring):
    the larger of e / θ and MODEL_ERROR_PER_MM · e, e the largest angle-following motion among the markers of
    its two segments (0 when none moves).

    `modelled`: the motions effect terms fit (:class:`ModelledMotion`), counted as if seen in the residual. Fitting
    the motion a marker shows does not fit the motion its cluster may share unseen: a segment's markers moving
    together with the angles keep their distances to one another and are, to first order, the joint moved by
    ``e / θ``. On held-out trials whose shank cluster moved as one with the knee angle (3.8 mm), ``diagnose``
    fitted skin on the ankle marker only and reported the knee 4-5 mm off at ±0.9 mm. A modelled motion counts at
    any size (its effect was adopted: it earned its parameters), a motion in the residual only once it
    :attr:`~MarkerMisfit.moves`. A joint's own moving centre (``joint`` set) counts for that joint only, and as
    ``MODEL_ERROR_PER_MM · e``, not ``e / θ``: the centre's motion is fitted, no cluster motion is implied by it, and
    its distances are those to the centre's mean place, which change over the trial by about e (on simulated knees
    translating 8-15 mm, e / θ had made every one undetermined at 9-13 mm of model error). Where the same motion is
    also read as a cluster moving as one (``diagnose``'s readings of the effects it cannot tell apart: a knee's centre
    moving in the thigh and the last segment's cluster moving on it), that reading is skin and counts as e / θ; such a
    joint's intervals are then those to its centre's place over the trial, the joint itself claiming none
    (:func:`identcheck.bundle.honest.with_moving_centre`)."""
    chain = fit.chain
    sides = (chain.parent[joint], chain.child[joint])
    moved = [m.explained_mm for m in misfit.values() if m.moves and m.segment in sides]
    anywhere = [m.explained_mm for m in misfit.values() if m.moves]
    skin = [m for m in modelled if m.joint is None]                  # not a joint's own moving centre
    moved += [m.rms_mm for m in skin if m.beside(chain, joint)]
    anywhere += [m.rms_mm for m in skin]
    centre = max((m.rms_mm for m in modelled if m.joint == joint), default=0.0)
    if any(len(chain.seg_markers[s]) < 3 for s in sides) and anywhere:
        # a segment with fewer than three markers cannot show its own skin motion (no distance within it
        # changes, and the joint absorbs what would show in the residual): skin motion seen anywhere in the
        # trial may be there unseen, as large
        moved = moved + [max(anywhere)]
    if not moved:
        return MODEL_ERROR_PER_MM * centre
    e = max(moved)
    return max(MODEL_ERROR_PER_MM * max(e, centre), e / max(excursion_rad(fit, joint), MIN_EXCURSION_RAD))
