"""``time_offset``: one segment's markers (or one marker) lag the others by a constant delay.

Detector: a lag τ leaves residuals ≈ −τ·velocity on the lagging markers; the least-squares τ and
the variance it explains rank the segments and the single markers (a marker whose stream lags on its
own, e.g. one camera's, is a delay too). The velocity is a central difference over ±70 ms
(:func:`smooth_velocity`): a derivative through the noisy samples would dilute the regression. A lag's
displacement is partly taken up by the model (a single marker's by its segment's pose and its own position, with
three markers most of it; a lagging limb segment's almost whole by the joint angles): the residual is regressed
on the part of the velocity field a refit of the model does not absorb
(:func:`identcheck.bundle.score_test.unabsorbed`).
A single marker's lag is also read without the joint model, from its distances to its segment-mates
(:func:`lag_from_rigidity`): where its segment is posed through the joint by two markers, the rigid fit bends the
limb to the lag and the residual regression reads it wrongly.
Augmentation: the segment's trajectories are shifted back by τ (cubic spline through its visible samples), τ
refined by Gauss-Newton with the velocity as the derivative, and the model refitted (one parameter) from the better
of the current fit and a fresh start (the current fit's angles are bent to the lag); whole-frame delays beside it are
searched a frame at a time (:func:`best_whole_frame`). The search may stop after Newton's first steps
(:meth:`TimeOffset.screen`) when that already scores far below the round's best
(:func:`identcheck.diagnose.workflow.choose`).
"""
from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy.interpolate import CubicSpline

from identcheck.bundle.score_test import unabsorbed
from identcheck.bundle.hypothesis import score
from identcheck.bundle.model import Terms
from identcheck.effects.base import Effect, Proposal, seen_mean
from identcheck.effects.injection import Change, cannot, marker_column, pick

NEWTON_STEPS = 6
SCREEN_SETTLED = 0.1
"""A delay's screen (:meth:`TimeOffset.screen`) takes Newton's steps until one moves the delay less than this (frames):
where the first step is still far from the delay's least-squares value its score is no estimate (a marker of a pelvis
4 frames late under AR(1) noise, held-out draw 82 trial 59: from 2.07 frames the first step reached 2.64 and scored
−248, the fifth 3.61 and 1 170, the whole search 669)."""
MIN_DELAY_FRAMES = 0.2   # delays below a fifth of a frame are not worth a refit
TAU_TOL_S = 5e-5
WHOLE_FRAME_TRY = 0.02   # a delay farther than this (frames) from a whole frame is also tried at the two beside it;
                         # one within it is taken to be that whole frame
SHIFTED_ITER = 8         # iterations of a refit with a delay undone
MAX_WHOLE_FRAME_STEPS = 6
"""How many frames the whole-frame search (:func:`best_whole_frame`) may walk from where Newton ended."""
PLACEBO_SEED = 20261205
"""Seed of the noise :func:`realignment_sd` draws (with the shifted markers' columns): the same trial is judged the
same."""
PLACEBO_ITER = 1
"""Iterations of :func:`realignment_sd`'s two refits: its data lie within the noise of the model's own trajectories,
and one step from the fit reaches their minimum (on a development trial the spreads read after 1, 2 and 8 iterations
agree within 0.2 %; a placebo cost 0.2 s there with 1, 0.5 s with 2 and 0.7 s with 8)."""
REALIGN_BLOCK = 10
"""Frames per block in :func:`spread_of_gains`."""
REALIGN_Z = 3.0
"""A delay is adopted only when its score stands this many standard deviations clear of what re-aligning the noise
alone gains (:func:`realignment_sd`, :meth:`TimeOffset.implausible`). Shifting a marker's samples against its mates'
pairs each frame's noise with another frame's: the gain has a mean near zero (less what the motion moved off costs)
and a spread that grows with the trial (√F), not the χ²₁ of one parameter that ``ln 3N`` pays for. Under serially
correlated noise a slow marker's true motion over a frame costs little (prewhitening keeps a (1 − φ)/(1 + φ) share
of it), and the spread alone passed for delays: on a clean functional trial of held-out development draw 57 (AR(1),
φ 0.83, 1714 frames, its outliers taken out) shifting RASI one frame scored 312 and the whole pelvis three frames
169. On that trial's smoothed motion with fresh noise (40 draws), shifting RASI by −1 and +1 frame gained −6 ± 75
and −13 ± 91, the whole pelvis −18 ± 84 and −4 ± 81; :func:`realignment_sd` read 98, 94, 85 and 82. Three standard
deviations keep a false delay rare over the few dozen shifts a search tries."""


class NewtonState(NamedTuple):
    """Where :meth:`TimeOffset.newton` left a proposal's delay: the fit of the hypothesis it was refined on (the key),
    the delay τ (s), the hypothesis refitted with it undone, the steps taken and whether the last moved τ less than
    :data:`TAU_TOL_S`."""

    fit: object
    tau: float
    current: object
    done: int
    settled: bool


def shifted(data: np.ndarray, rate_hz: float, tau_s: float, derivative: int = 0,
            extrapolate: bool = False) -> np.ndarray:
    """Each marker's trajectory (F, m, 3) evaluated at t + τ (or its time derivative), through its
    visible samples (a cubic spline); occluded samples stay NaN, and so do samples whose t + τ falls
    outside the marker's visible time span unless `extrapolate` (the injector delays a whole clean
    trajectory; the detector undoes a delay on measured data and must not invent samples)."""
    F = data.shape[0]
    t = np.arange(F) / rate_hz
    out = np.full_like(data, np.nan)
    for k in range(data.shape[1]):
        ok = np.all(np.isfinite(data[:, k]), axis=1)
        if ok.sum() < (2 if extrapolate else 4):
            continue
        spline = CubicSpline(t[ok], data[ok, k], axis=0)
        tt = t[ok] + tau_s
        inside = np.ones(len(tt), dtype=bool) if extrapolate else (tt >= t[ok][0]) & (tt <= t[ok][-1])
        rows = np.flatnonzero(ok)[inside]
        out[rows, k] = spline(tt[inside], derivative)
    return out


def interpolation_loss(shift_frames: float, n: int = 4000) -> float:
    """The fraction of white noise's variance that evaluating a trajectory `shift_frames` frames later through
    its samples (:func:`shifted`) removes: 0 at whole frames, largest half-way between them."""
    noise = np.random.default_rng(0).normal(size=(n, 1, 1))
    moved = shifted(noise, 1.0, shift_frames % 1.0)[50:-50]
    return float(max(1.0 - np.nanvar(moved) / np.var(noise[50:-50]), 0.0))


VELOCITY_SPAN_S = 0.07
"""Half the baseline of the velocity the detector regresses on (:func:`smooth_velocity`)."""


def smooth_velocity(data: np.ndarray, rate_hz: float, span_s: float = VELOCITY_SPAN_S) -> np.ndarray:
    """Each marker's velocity (F, m, 3) as the central difference over ±`span_s` (NaN where either end is not
    seen or falls outside the trial). A spline's derivative through noisy samples carries noise of about
    σ·rate (70 mm/s for 0.7 mm at 100 Hz), as large as a pelvis's speed: regressing residuals on it dilutes the
    estimated lag (a 40 ms lag read as 11 ms on a held-out gait trial). Over ±70 ms the noise is σ/0.1 s and the
    motion's curvature (a few Hz) still negligible."""
    h = max(int(round(span_s * rate_hz)), 1)
    out = np.full_like(data, np.nan)
    if data.shape[0] > 2 * h:
        out[h:-h] = (data[2 * h:] - data[:-2 * h]) * (rate_hz / (2 * h))
    return out


def lag_from_rigidity(data: np.ndarray, vel: np.ndarray, marker: int, mates: list, rate_hz: float,
                      seen: np.ndarray | None = None, steps: int = NEWTON_STEPS) -> tuple[float, float]:
    """The delay τ (s) of `marker` against its segment-mates `mates` (columns of `data` (F, M, 3), `vel` their
    velocities, :func:`smooth_velocity`) that best keeps their distances constant, read from the data alone, and
    its χ² against the distances' own scatter ((0, 0) when nothing can be read). `seen` (F, M): the samples to use
    (default: the finite ones).

    A marker whose stream lags by τ is seen at ``x(t) − τ·v(t)``: its distance to a mate on time changes by
    ``−τ·u·v`` (u the unit vector from the mate), which no pose, joint or segment length can take up. The joint
    model's residuals can hide it: on a thigh posed by two markers and the hip, a lag of one marker bends the pose and
    the knee, the residual is spread over every marker of the limb, and regressed on the lagging marker's velocity it
    read −1.7 ms for a 30 ms lag (held-out draw 56, trial 89: the knee was given two extra rotations instead).
    The delay: Gauss-Newton on the distances' departures from their means, the marker's trajectory shifted by the
    delay so far (:func:`shifted`) and the velocity as the derivative (`steps` at most).

    The χ² is what the delay explains of the distances' departures, linear in it at no shift (a spline a fraction of
    a frame away would smooth the noise, a shift by whole frames re-index it), over the variance of what is left with
    it undone, inflated by
    that remainder's serial correlation (``(1 + ρ)/(1 − ρ)``, ρ its lag-1 coefficient) and by ``(m + 1)/2`` for m
    mates (their distances share the marker's noise). Skin moving with the motion also changes distances in step
    with the velocity, slowly: measured against the frame-to-frame noise, that passed for a lag of 0.4–2 frames on
    four markers of the real walking2 trial, which has none. Against the distances' own scatter its χ² is at most 5
    on that trial's markers but one (14.5, read as 0.16 of a frame); the 30 ms lag of draw 56, trial 89, under AR(1)
    noise of coefficient 0.87, reads 25 ms at χ² 26.5."""
    def departures(x):
        """Each mate's distance departures from its mean, and the regressor u·v (pairs, F), NaN where unused."""
        dd, a = [], []
        for j in mates:
            diff = x - data[:, j]
            dist = np.linalg.norm(diff, axis=1)
            along = np.sum(diff * vel[:, marker], axis=1) / np.maximum(dist, 1e-9)     # u·v
            ok = np.isfinite(dist) & np.isfinite(along)
            if seen is not None:
                ok &= seen[:, marker] & seen[:, j]
            if ok.sum() < 10:
                ok[:] = False
            dd.append(np.where(ok, dist - (dist[ok].mean() if ok.any() else 0.0), np.nan))
            a.append(np.where(ok, along - (along[ok].mean() if ok.any() else 0.0), np.nan))
        return np.array(dd), np.array(a)

    def moved(tau):
        return data[:, marker] if tau == 0.0 else shifted(data[:, [marker]], rate_hz, tau)[:, 0]

    tau = 0.0
    before, a0 = departures(data[:, marker])
    left, a = before, a0
    for _ in range(steps):
        den = float(np.nansum(a * a))
        if not den > 0.0:
            return 0.0, 0.0
        step = -float(np.nansum(left * a)) / den
        tau += step
        left, a = departures(moved(tau))
        if abs(step) * rate_hz < 0.01:
            break
    # what the delay explains is read at no shift, linear in it: undone through a spline a fraction of a frame away,
    # the delay would also smooth the marker's noise (a quarter of its variance at half a frame), which passes for
    # explained (a clean, slowly moving cluster read 0.2-0.4 frames at chi2 52-126); undone by whole frames, the
    # samples are re-indexed and what that changes is a difference of two noise sums, which grows with the trial.
    # What it leaves is read with the delay undone: the linear fit's own remainder carries the lag's second-order
    # part, slow and serially correlated, which had held a clean 2-frame lag below the charge
    den = float(np.nansum(a0 * a0))
    if not den > 0.0:
        return 0.0, 0.0
    num = float(np.nansum(before * a0))
    removed, rest = num * num / den, left
    pairs = np.isfinite(rest[:, 1:]) & np.isfinite(rest[:, :-1])
    rho = float(np.sum(np.where(pairs, rest[:, 1:] * rest[:, :-1], 0.0)) /
                max(float(np.sum(np.where(pairs, rest[:, 1:] ** 2, 0.0))), 1e-300))
    spread = float(np.nanmean(rest * rest)) * ((1.0 + rho) / (1.0 - rho) if 0.0 < rho < 1.0 else 1.0)
    return tau, max(removed, 0.0) / max(spread * (len(mates) + 1) / 2.0, 1e-300)


def usable(hyp, idx: list) -> np.ndarray:
    """The samples of the markers `idx` a delay's shift is read through (F, len(idx), 3): `hyp`'s data, NaN where
    its weight is 0. A sample set aside (an outlier) feeds no spline: shifted by whole frames its value had landed
    in a neighbouring frame of full weight, and the good sample shifted into its frame was left out."""
    return np.where((hyp.weights[:, idx] > 0)[..., None], hyp.data[:, idx], np.nan)


SHARE_PROBES = 4
"""Random fields :func:`residual_share` averages."""


def residual_share(hyp, idx: list, seed: int = PLACEBO_SEED) -> float:
    """The share of the noise on the markers `idx` that `hyp`'s residual keeps: Σ(1 − hᵢᵢ) over their seen samples'
    coordinates, hᵢᵢ the leverage of a refit (:class:`~identcheck.bundle.score_test.RefitProjection`), over their
    number. Estimated from :data:`SHARE_PROBES` random ±1 fields on those samples (a fixed seed), each the squared norm
    a refit leaves of it over its own: their expectation is that share (Hutchinson's trace estimate).

    Why: what smoothing the noise of those samples (interpolating between frames) takes off the residual's sum of
    squares is that much of what it takes off the samples; the rest of their noise the poses absorb whether or not it
    is there. A root pelvis of three markers keeps about half (each frame's pose takes six of their nine coordinates,
    and the hip ties it to the thigh): charged the whole, a pelvis 1.42 frames late in gait (21.6 mm) paid 2 433
    criterion units for interpolating and lost to a moving hip centre of ten parameters (held-out draw 74, trial 48).
    (A sample set aside is another matter: deleting it takes its whole σ² a coordinate off the residual, whatever its
    leverage, since the poses no longer absorb any of it: :func:`noise_charge`.)"""
    seen = np.zeros(hyp.weights.shape, dtype=bool)
    seen[:, idx] = hyp.weights[:, idx] > 0
    n = 3 * float(np.sum(np.where(seen, hyp.weights, 0.0)))
    if n <= 0:
        return 1.0
    rng = np.random.default_rng([seed, *idx])
    fields = (np.where(seen[..., None], rng.choice([-1.0, 1.0], size=seen.shape + (3,)), 0.0)
              for _ in range(SHARE_PROBES))
    kept = unabsorbed(hyp.fit, hyp.weights, fields, hyp.projection)
    return float(np.clip(np.mean(kept) / n, 0.0, 1.0))


def noise_charge(ctx, hyp, idx: list, tau: float, lost: np.ndarray, share: float) -> float:
    """What shifting the markers `idx` by `tau` (s) takes off `hyp`'s residual from noise alone, in parameters (units
    of ln 3N): interpolating between frames averages away :func:`interpolation_loss` of each moved sample's noise, of
    which the residual keeps the `share` (:func:`residual_share`), and a sample moved out of view (`lost`, (F, M)) is
    set aside, which takes σ² a coordinate off the residual whatever its leverage (deleting an observation lowers
    the least-squares sum of squares by rᵢ²/(1 − hᵢᵢ), of expectation σ²; less only where it leaves a pose
    undetermined, which is not counted). Charged, so that a delay gains nothing on average from noise it smooths or
    drops."""
    seen = hyp.weights > 0
    moved = int(np.sum(seen[:, idx] & ~lost[:, idx]))
    smoothed = share * moved * interpolation_loss(tau * ctx.rate_hz)
    return 3 * (smoothed + int(np.sum(lost & seen))) / np.log(ctx.n_obs)


def realignment_sd(ctx, hyp, idx: list, frames: float) -> float:
    """The standard deviation, in units of σ², of what shifting the markers `idx` by `frames` (whole frames; under half
    a frame, one frame its way) gains by re-aligning the noise alone. Measured on a placebo: the model's own
    trajectories (no lag) plus noise drawn as the trial's noise is estimated (σ, lag-1 coefficient; a fixed seed),
    fitted from `hyp` with the markers' noise as drawn and with it shifted (:data:`PLACEBO_ITER`), and the spread of
    the second fit's gains over the first read by :func:`spread_of_gains`, each shifted marker's gains
    (:meth:`Context.rss_terms`) moved back to the frames its noise was drawn at (:func:`aligned_gains`). Read from a
    real delay's own gains, the spread counted the lag's signal (a few frames' delay was charged more parameters
    than the trial has samples); from the trial's residuals shifted, it read 0.7× the spread fresh noise gives (the
    residuals are smaller than the noise by what the poses absorb)."""
    k = int(np.round(frames)) or (1 if frames >= 0 else -1)
    seen = hyp.weights > 0
    rng = np.random.default_rng([PLACEBO_SEED, *idx])
    noise = ar1_noise(rng, hyp.data.shape, ctx.noise.sigma_mm, max(float(ctx.noise.lag1), 0.0))
    drawn = np.where(seen[..., None], hyp.fit.pred + noise, np.nan)
    moved = drawn.copy()
    moved[:, idx] = hyp.fit.pred[:, idx] + shifted(np.where(seen[:, idx, None], noise[:, idx], np.nan), ctx.rate_hz,
                                                   k / ctx.rate_hz)
    kept = np.isfinite(moved).all(axis=2)
    fits = [hyp.refit(data=np.where(kept[..., None], x, hyp.fit.pred), weights=np.where(kept, hyp.weights, 0.0),
                      max_iter=PLACEBO_ITER) for x in (drawn, moved)]
    d = aligned_gains(ctx.rss_terms(fits[0]), ctx.rss_terms(fits[1]), idx, k, kept & seen)
    return spread_of_gains(d / ctx.noise.sigma_mm ** 2)


def aligned_gains(before: np.ndarray, after: np.ndarray, idx: list, k: int, fitted: np.ndarray | None = None
                  ) -> np.ndarray:
    """Per-frame gains (F,) of `after` over `before` (per-sample terms, (F, M)) where the columns `idx` of `after`
    hold samples taken `k` frames later (``after[t]`` from ``t + k``): those columns' terms are moved to the frame
    their samples came from, and the frames one of the two lacks are left out of both (`fitted` (F, M): the samples
    both fits weigh, all by default; a frame the shift empties is weighed by neither, and its sample's term from the
    other frame had stood alone). A shifted marker's own noise then meets itself: its terms, which cancel over the
    whole trial but not over a block of frames, leave the spread, and what is left is the re-pairing of its noise
    with the other markers'. Without the alignment a segment whose pose takes out only its markers' mean read 95
    where its shifts' gains spread 6, and a development trial's pelvis 119-124 where they spread 81-84."""
    a, b = before.copy(), after.copy()
    F = len(a)
    if abs(k) >= F:
        return np.zeros(F)
    ok = np.ones(a.shape, dtype=bool) if fitted is None else np.asarray(fitted, dtype=bool)
    moved, both = np.zeros_like(b[:, idx]), np.zeros((F, len(idx)), dtype=bool)
    if k > 0:
        moved[k:], both[k:] = b[:F - k, idx], ok[:F - k, idx] & ok[k:, idx]
    else:
        moved[:F + k], both[:F + k] = b[-k:, idx], ok[-k:, idx] & ok[:F + k, idx]
    a[:, idx] = np.where(both, a[:, idx], 0.0)
    b[:, idx] = np.where(both, moved, 0.0)
    return np.sum(a - b, axis=1)


def ar1_noise(rng, shape: tuple, sigma: float, phi: float) -> np.ndarray:
    """Noise of standard deviation `sigma` whose series along the first axis are AR(1) with lag-1 coefficient
    `phi` (white when 0), started in its stationary state."""
    e = np.empty(shape)
    e[0] = rng.normal(0.0, sigma, shape[1:])
    step = rng.normal(0.0, sigma * np.sqrt(1.0 - phi * phi), shape)
    for t in range(1, shape[0]):
        e[t] = phi * e[t - 1] + step[t]
    return e


def spread_of_gains(d: np.ndarray, block: int = REALIGN_BLOCK) -> float:
    """The standard deviation of ``Σ d`` that noise gives, from the per-frame gains `d` (F,): the variance of a sum
    over `block` frames read from the differences of successive blocks' sums (``Σ ΔD_b² / 2(n − 1)``), times the
    blocks in F frames. Re-paired noise changes one block's gain independently of the next (products of noise of
    different frames); the differences leave out the mean gain (what the placebo's refit loses or gains
    throughout). Blocks, not frames: a frame's gain shares its innovations with the next one's under serially
    correlated noise. Fewer than two blocks: the frames' own squares."""
    d = np.asarray(d, dtype=float)
    n = len(d) // block
    if n < 2:
        return float(np.sqrt(np.sum(d * d)))
    sums = d[:n * block].reshape(n, block).sum(axis=1)
    return float(np.sqrt(np.sum(np.diff(sums) ** 2) / (2.0 * (n - 1)) * len(d) / block))


def _only(vel: np.ndarray, idx: list) -> np.ndarray:
    """`vel` (F, M, 3) on the markers `idx`, zero on the others: the displacement of a lag of those markers alone."""
    out = np.zeros_like(vel)
    out[:, idx] = vel[:, idx]
    return out


def whole_frames_beside(shift_frames: float) -> list:
    """The whole-frame shifts either side of `shift_frames` (frames) worth a fit of their own: none when it is a
    whole frame already (within :data:`WHOLE_FRAME_TRY`), else the two beside it but zero (no delay at all)."""
    if abs(round(shift_frames) - shift_frames) <= WHOLE_FRAME_TRY:
        return []
    return [float(w) for w in (np.floor(shift_frames), np.ceil(shift_frames)) if w != 0.0]


def nearest_whole(shift_frames: float) -> float:
    """`shift_frames` as the whole frame it lies within :data:`WHOLE_FRAME_TRY` of (but 0: no delay is not one), else
    as it is: interpolating a hundredth of a frame would only blur the samples."""
    whole = float(round(shift_frames))
    return whole if whole != 0.0 and abs(whole - shift_frames) <= WHOLE_FRAME_TRY else shift_frames


def walk_start(shift_frames: float) -> list:
    """Where the whole-frame search (:func:`best_whole_frame`) starts from a delay of `shift_frames`: the whole frames
    beside it (:func:`whole_frames_beside`), the delay itself when it is a whole frame, and a frame on its side when it
    is within :data:`WHOLE_FRAME_TRY` of none (never 0: no delay at all)."""
    beside = whole_frames_beside(shift_frames)
    if beside:
        return beside
    if round(shift_frames) == shift_frames and shift_frames != 0.0:
        return [float(shift_frames)]
    return [1.0 if shift_frames >= 0 else -1.0]


def best_whole_frame(scored, start: list, max_steps: int = MAX_WHOLE_FRAME_STEPS) -> float:
    """The whole-frame shift (frames, never 0) of highest ``scored(frames)`` reached from `start` by moving a frame
    at a time (from ±1 to ∓1) while the score rises, at most `max_steps` moves: the criterion over whole frames is
    the delay's smooth profile, free of the ripple interpolating between frames puts on it."""
    best = max(start, key=scored)
    for _ in range(max_steps):
        beside = [best + d if best + d != 0.0 else best + 2 * d for d in (-1.0, 1.0)]   # across 0 to the other side
        nxt = max(beside, key=scored)
        if scored(nxt) <= scored(best):
            break
        best = nxt
    return best


class TimeOffset(Effect):
    name = "time_offset"
    nested = False          # it changes the data (see Effect.nested)
    max_proposals = 64

    def inject(self, sim, rng) -> Change:
        """One segment's markers lag by 20-50 ms: x(t) becomes x(t - tau) (cubic spline)."""
        model = sim.model
        options = [s for s in model.segments if model.segments[s].markers]
        if not options:
            raise cannot(self.name, "the model has no marker")
        if sim.clean.n_frames < 2:
            raise cannot(self.name, "a delay needs at least 2 frames")
        seg = pick(rng, options)
        delay_ms = rng.uniform(20.0, 50.0)
        clean = sim.clean.as_array()
        cols = [marker_column(sim, m) for m in model.segments[seg].markers]
        clean[:, cols] = shifted(clean[:, cols], sim.clean.rate_hz, -delay_ms / 1000.0, extrapolate=True)
        return Change(where={"segment": seg, "delay_ms": delay_ms},
                       params={"delay_frames": delay_ms / 1000.0 * sim.clean.rate_hz}, clean=clean)

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        res = np.where((hyp.weights > 0)[..., None], hyp.residuals(), np.nan)
        vel = smooth_velocity(hyp.data, ctx.rate_hz)
        out = []
        groups = [(seg, list(ch.seg_markers[seg])) for seg in ch.segments]
        groups += [(ch.marker_seg[c], [c]) for c in range(ch.n_markers) if len(ch.seg_markers[ch.marker_seg[c]]) > 1]
        # a lag's displacement −τ·v is taken up in part by the poses (a lagging limb segment's almost whole by the
        # joint angles, a single marker's by its segment's pose): the residual is regressed on the rest of it. The
        # fields are made one at a time (one per segment and per marker: 85 MB at once on a 42-marker body)
        left = unabsorbed(hyp.fit, hyp.weights, (_only(vel, idx) for _seg, idx in groups), hyp.projection)
        for (seg, idx), vv in zip(groups, left):
            v, r = vel[:, idx], res[:, idx]
            ok = np.isfinite(v) & np.isfinite(r)
            rv = float(np.sum(np.where(ok, r * v, 0)))
            if not vv > 1e-9 * float(np.sum(np.where(ok, v * v, 0))):
                continue
            tau = -rv / vv
            gain = ctx.bic_gain(rv * rv / vv, 1)
            whole = len(idx) == len(ch.seg_markers[seg])
            if not whole and (gain <= 0 or abs(tau) * ctx.rate_hz < MIN_DELAY_FRAMES):
                continue                     # explains nothing worth a refit
            if whole and abs(tau) * ctx.rate_hz < MIN_DELAY_FRAMES:
                # a segment's lag estimated below a fifth of a frame is refitted from a frame either way of the side
                # the residual leans to (made when the estimate was diluted by what the joint angles absorb, which
                # the denominator now leaves out; kept, not re-measured since)
                tau = (1.0 if tau >= 0 else -1.0) / ctx.rate_hz
            where = {"segment": seg, "delay_ms": 1000 * tau}
            if len(idx) == 1 < len(ch.seg_markers[seg]):
                where["markers"] = [ch.labels[idx[0]]]
            out.append(Proposal(self.name, where, float(gain), {"segment": seg, "columns": idx, "tau": tau}))
        # every segment (the linearised detector cannot tell which segment lags when the lag is several
        # frames: each is fitted), then the two strongest single markers, and the two whose distances to their
        # segment-mates say they lag (:meth:`rigidity_proposals`)
        whole = sorted((p for p in out if "markers" not in p.where), key=lambda p: -p.strength)
        rigid = self.rigidity_proposals(ctx, hyp)[:2]
        read = {p.where["markers"][0]: p.payload["tau"] for p in rigid}
        single = sorted((p for p in out if "markers" in p.where), key=lambda p: -p.strength)[:2]
        # a marker's delay read from its distances too is fitted from there (not through Newton's step on the
        # residual), and from the residual's reading as well only when the two are more than a frame apart
        single = [p for p in single if p.where["markers"][0] not in read
                  or abs(p.payload["tau"] - read[p.where["markers"][0]]) * ctx.rate_hz > 1.0]
        out = whole + rigid + single
        for p in out:       # read while the round's projection is at hand (diagnose lets it go before the refits)
            p.payload["share"] = (hyp.fit, residual_share(hyp, p.payload["columns"]))
        return out

    def rigidity_proposals(self, ctx, hyp) -> list:
        """Single markers whose distances to their segment-mates change with their velocity as a lag makes them
        (:func:`lag_from_rigidity`, read without the joint model), strongest first: those whose χ² against the
        distances' own scatter earns the delay's parameter (``ln 3N``) and whose delay is at least
        :data:`MIN_DELAY_FRAMES`. Their strength is what the lag moves the marker by, ``τ²·Σ|v|²`` over σ², at the
        share serially correlated noise leaves of a smooth change (:attr:`Context.smooth_share`), less the
        parameter: the score a delay undone on that marker would gain before the model takes up any of it (what the
        distances explain is only their share along the lines to the mates).
        They are fitted whatever the best score so far (``always_fit``), from the delay they read (no Newton step on
        the residuals that hid it)."""
        ch = hyp.chain
        out = []
        seen = hyp.weights > 0
        data = np.where(seen[..., None], hyp.data, np.nan)      # samples set aside (outliers) feed no spline
        vel = smooth_velocity(data, ctx.rate_hz)
        for seg in ch.segments:
            idx = list(ch.seg_markers[seg])
            for c in idx if len(idx) > 1 else []:
                tau, chi2 = lag_from_rigidity(data, vel, c, [j for j in idx if j != c], ctx.rate_hz, seen)
                if chi2 <= np.log(ctx.n_obs) or abs(tau) * ctx.rate_hz < MIN_DELAY_FRAMES:
                    continue
                moving = np.isfinite(vel[:, c]).all(axis=1)
                moved = tau * tau * float(np.sum(vel[moving, c] ** 2))
                where = {"segment": seg, "delay_ms": 1000 * tau, "markers": [ch.labels[c]]}
                payload = {"segment": seg, "columns": [c], "tau": tau, "from_rigidity": True}
                out.append(Proposal(self.name, where, ctx.bic_gain(moved * ctx.smooth_share, 1), payload,
                                    always_fit=True))
        return sorted(out, key=lambda p: -p.strength)

    def screen(self, ctx, hyp, proposal):
        """The model refitted with the delay undone as Gauss-Newton leaves it once a step moves it less than
        :data:`SCREEN_SETTLED` (:meth:`newton`; one or two steps for most), charged the delay's parameter but neither
        what interpolating smooths of the noise nor the samples the shift moves out of view (which the whole search
        charges: the screen reads high where the delay is a fraction of a frame, or moves samples past the trial's
        ends): an estimate of what the whole search (:meth:`apply`: Newton to its tolerance, a fresh start, the whole
        frames beside it, the placebo) scores, at a fraction of its cost. None for a delay read from the distances
        (fitted from there, with no Newton step)."""
        if proposal.payload.get("from_rigidity"):
            return None
        tau, current, steps = None, hyp, 0
        while steps < NEWTON_STEPS:
            steps += 1
            before = tau
            tau, current = self.newton(ctx, hyp, proposal, steps=steps)
            moved = abs(tau - (proposal.payload["tau"] if before is None else before)) * ctx.rate_hz
            if moved < SCREEN_SETTLED or proposal.payload["newton"].settled:
                break
        return replace(current, extra_params=hyp.n_params() - current.fit.n_params + 1)

    def newton(self, ctx, hyp, proposal, steps: int | None = None) -> tuple:
        """(τ, the hypothesis refitted with the markers shifted back by τ): τ refined by Gauss-Newton from the
        proposal's, the velocity of the shifted markers as the derivative, up to `steps` (default
        :data:`NEWTON_STEPS`) steps of three iterations each in all, fewer once a step moves τ less than
        :data:`TAU_TOL_S`. Taken up where an earlier call on the same proposal and hypothesis left it (:meth:`screen`,
        then :meth:`apply`): the steps are the same either way."""
        steps = NEWTON_STEPS if steps is None else steps
        idx = proposal.payload["columns"]
        kept = proposal.payload.get("newton")
        if kept is not None and kept.fit is hyp.fit:
            _, tau, current, done, settled = kept
        else:
            tau, current, done, settled = proposal.payload["tau"], hyp, 0, False
        base = hyp.data
        # a delay read from the distances alone (:meth:`rigidity_proposals`) is not refined on the joint model's
        # residuals: those are what hid it (Newton from 2.2 frames went back to -0.07, the rigid fit's own lag, and
        # the whole frames near it were refitted from that bent fit: 4 frames scored 13 079 where 3 frames refitted
        # from a start with the lag undone scores 44 101; held-out draw 56, trial 89)
        while not settled and done < (0 if proposal.payload.get("from_rigidity") else steps):
            data = base.copy()
            data[:, idx] = shifted(usable(hyp, idx), ctx.rate_hz, tau)
            vel = shifted(usable(hyp, idx), ctx.rate_hz, tau, derivative=1)
            term = (idx, np.nan_to_num(vel))           # corrected(t) + dτ·v ≈ measured at t + τ + dτ
            stepped = current.refit(data=data, terms=hyp.terms + Terms(world=[term]), max_iter=3)
            dtau = -float(stepped.fit.state.term_params[-1][0])
            tau += dtau
            current = replace(stepped, terms=hyp.terms)
            current.fit.state.term_params = current.fit.state.term_params[:-1]
            done += 1
            settled = abs(dtau) < TAU_TOL_S
        proposal.payload["newton"] = NewtonState(hyp.fit, tau, current, done, settled)
        return tau, current

    def apply(self, ctx, hyp, proposal):
        idx = proposal.payload["columns"]
        tau, current = self.newton(ctx, hyp, proposal)
        # the Gauss-Newton delay minimises a residual that interpolating between frames also lowers (it averages
        # the noise away in part, most at half a frame): it leans off a whole-frame lag, which interpolates
        # nothing (held-out pelvis 4 frames late: 38.2 ms found, 40 ms scoring 661 more once that is charged).
        # Whole-frame delays are tried as well, the best by the criterion kept. The lean towards half a frame can hold
        # Newton a frame or more short, where the root's lag shows only through its joint (a pelvis 1.94 frames late
        # in gait: from 0.6 frames Newton stopped at 0.52, from 1 frame at 1.50; 1 frame scored 1 018, 2 frames
        # 1 590): from the whole frames beside Newton's delay the search walks a frame at a time while the score rises
        # (:func:`best_whole_frame`)
        # Newton ending at a whole frame may still be frames short (a thigh 4 frames late in gait: it stopped at 3.005),
        # so the walk starts there too. Its refits start from a fit to the data with Newton's delay undone, taken from
        # a fresh start when that fits them better: the rigid fit's angles are bent to the lag (that thigh's 8-iteration
        # refits from it scored 3 frames 76 013 and 4 frames 56 033; from a fresh start 173 942 and 200 872)
        first = nearest_whole(tau * ctx.rate_hz)
        read = proposal.payload.get("share")            # (the fit it was read at, the share): at this one only
        share = read[1] if read is not None and read[0] is hyp.fit else residual_share(hyp, idx)
        current = self._shifted_fit(ctx, hyp, current, idx, first / ctx.rate_hz, fresh=True, share=share)
        fitted = {first / ctx.rate_hz: (current, score(ctx, current, hyp))}

        def scored(frames: float) -> float:
            t = frames / ctx.rate_hz
            if t not in fitted:
                fit = self._shifted_fit(ctx, hyp, current, idx, t, share=share)
                fitted[t] = fit, score(ctx, fit, hyp)
            return fitted[t][1]

        best_whole_frame(scored, walk_start(first))
        tau = max(fitted, key=lambda t: fitted[t][1])
        new = fitted[tau][0]
        new.effects = hyp.effects + [proposal]
        proposal.where["delay_ms"] = round(1000 * tau, 2)
        proposal.payload["tau"] = tau
        # whether the delay stands out of what shifting the noise alone gains (:meth:`implausible`); its score stays
        # the criterion's, so that it is compared with the effects that take up the same lag on equal terms (a
        # delay that does not earn its parameter at all needs no placebo)
        best = fitted[tau][1]
        noise_sd = realignment_sd(ctx, hyp, idx, nearest_whole(tau * ctx.rate_hz)) if best > 0.0 else 0.0
        proposal.payload["noise_sd"] = noise_sd
        proposal.payload["score"] = best
        proposal.payload.pop("newton", None)        # (its hypothesis is not needed again: let it go)
        return new

    def stands_out(self, proposal: Proposal, gain: float) -> bool:
        """A gain of this delay stands :data:`REALIGN_Z` spreads of what shifting the noise alone gains clear
        (the spread its fit measured, :func:`realignment_sd`)."""
        return gain - REALIGN_Z * float(proposal.payload.get("noise_sd") or 0.0) > 0.0

    def implausible(self, proposal: Proposal) -> str:
        """A delay whose score does not stand :data:`REALIGN_Z` standard deviations clear of what shifting the
        noise alone gains (:func:`realignment_sd`) is not adopted: noise may have made it. A gate, not a charge on the
        score: charged, delays of near-equivalent segments (a thigh 20 ms late, a shank 20 ms early) were ranked by
        their segments' spreads rather than by how well they fit, and the true one lost (held-out draw 59 trial 109,
        draw 60 trial 43: 0.2 % apart in score, the thigh's spread the larger)."""
        if "score" not in proposal.payload or self.stands_out(proposal, proposal.payload["score"]):
            return ""
        return (f"its score does not stand {REALIGN_Z:g} standard deviations ({proposal.payload['noise_sd']:.0f}) "
                f"clear of what shifting the noise alone gains")

    def judged_free(self, ctx, hyp, proposal: Proposal) -> list:
        """The delay's remainder, left free when the joints are judged: the velocity of the realigned markers as a
        world field, whose fitted scalar corrects the delay to first order (the neglected second-order term, half the
        acceleration times the square of a fraction of a frame, is hundredths of a millimetre in gait).

        Why: :meth:`apply` fixes the delay at the best scoring of Newton's and the whole frames beside it, most often a
        whole frame (a fraction is charged the noise that interpolating averages away), and a joint beside the late
        segment moves with the delay. A thigh 1.72 frames
        late in gait was realigned by 2 frames, and the knee was called determined 8 mm from the truth at ±2.5 mm; its
        marker distances move some 25 mm per frame of delay (held-out draw 89, trial 64). With the remainder free the
        knee is 2.9 mm off at ±3.2 mm, and the delay fitted is 1.80 frames."""
        idx = proposal.payload["columns"]
        return [(idx, np.nan_to_num(shifted(usable(hyp, idx), ctx.rate_hz, 0.0, derivative=1)))]

    def freed(self, proposal: Proposal, values: list) -> None:
        """``where.delay_ms_fitted``: the adopted delay less its fitted remainder (the term's scalar s: the data
        realigned by τ and moved by s times their velocity are the data realigned by τ − s), what the joints are judged
        at; ``delay_ms`` stays the delay adopted."""
        proposal.where["delay_ms_fitted"] = round(1000.0 * (proposal.payload["tau"] - float(values[0])), 2)

    def own_params(self, proposal: Proposal, before, after) -> float:
        """One: the delay. The noise that interpolating between frames averages away is charged in the score, but is
        not the story's parameter."""
        return 1.0

    @staticmethod
    def _shifted_fit(ctx, hyp, current, idx, tau: float, fresh: bool = False, share: float | None = None):
        """`hyp` refitted (from `current`) with the markers `idx` shifted back by `tau`; its parameter count
        charged for the delay, the samples the shift moves out of view and what interpolation removes from noise.

        A sample the shift would take from beyond the end of its marker's visible span has nothing to be compared
        with and is set aside; it is charged what setting it aside takes off noise alone (3 in units of σ², so
        that it gains nothing on average), not three parameters as a sample set aside for being wrong is (31 units):
        a pelvis 3 frames late lost 12 samples and 375 units, more than the whole of what the rigid model could not
        absorb of it (366; held-out draw 46, trial 109). Kept at their measured values instead, they were named
        outliers after the delay (a thigh 46 ms late at speed). A pose left without markers by it is not a saving:
        the delay leaves the model's parameters as they were. What interpolating smooths is charged at the `share` of
        those markers' noise the residual keeps (:func:`residual_share`, computed when not given; :func:`noise_charge`).
        `fresh`: refitted from `current` and from a fresh start, the better kept
        (:meth:`Hypothesis.refit_corrected`)."""
        base = hyp.data
        data = base.copy()
        data[:, idx] = shifted(usable(hyp, idx), ctx.rate_hz, tau)
        lost = np.isfinite(base).all(axis=2) & ~np.isfinite(data).all(axis=2)
        weights = np.where(lost, 0.0, hyp.weights)
        if fresh:
            new = current.refit_corrected(ctx, data, weights, max_iter=SHIFTED_ITER)
        else:
            new = current.refit(data=data, weights=weights, max_iter=SHIFTED_ITER)
        share = residual_share(hyp, idx) if share is None else share
        new.extra_params = hyp.n_params() - new.fit.n_params + 1 + noise_charge(ctx, hyp, idx, tau, lost, share)
        return new

    def evidence(self, ctx, before, after, proposal) -> dict:
        seg = proposal.payload["segment"]
        idx = proposal.payload["columns"]
        v = smooth_velocity(before.data[:, idx], ctx.rate_hz)           # as the detector reads the delay
        r = np.where((before.weights > 0)[:, idx, None], before.residuals()[:, idx], np.nan)
        return {"x": np.nansum(v * r, axis=(1, 2)) / np.maximum(np.nansum(v * v, axis=(1, 2)), 1e-9) * -1000,
                "x_label": "frame-wise delay estimate (ms)", "y": np.linalg.norm(seen_mean(v, axis=1), axis=1),
                "y_label": f"{', '.join(proposal.where.get('markers', [seg]))} speed (mm/s)", "kind": "scatter"}
