"""The rules by which one whole-tree fit answers for each joint, shared by ``fit`` and ``diagnose`` (one
estimator, one set of rules): the sandwich covariance, model error for markers that move with the angles,
intervals the likelihood supports (profile likelihood where the parabola misleads, unbounded where the data
or the tree leave a joint free), and the per-joint answer with its practical verdict.

``fit`` (:mod:`identcheck.fit.whole_tree`) adds the candidates: several minima started from the closed forms,
compared by the likelihood ratio. ``diagnose`` answers from its final model, effects included.
"""
from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from identcheck.bundle.bootstrap import sampling_spread, t95
from identcheck.bundle.converge import not_converged_reason
from identcheck.bundle.joint_frames import joint_geometry
from identcheck.bundle.misfit import angle_dependence, model_error_sd
from identcheck.bundle.practical import TOLERANCE_MM, Z95, free_markers, hardly_moved, judge, single_axis
from identcheck.bundle.profile import OutOfTime, profile_interval
from identcheck.bundle.uncertainty import covariance, distance_gradients
from identcheck.geometry.poses import poses_segment
from identcheck.skeleton import Skeleton

SIGMA_FLOOR_MM = 0.01
"""The likelihood ratio's noise is never taken below this: far below any capture system's noise, above
float32 file precision and the optimiser's own slack, so that two exactly tying joints on noise-free data
are not told apart by rounding."""


@dataclass(frozen=True)
class Minimum:
    """One local minimum of the whole-tree likelihood: its fit, covariance and marker distances."""

    fit: object
    cov: object
    distances: dict            # joint -> marker -> (distance mm, standard error mm)
    start: tuple               # which candidate of each ambiguous joint started it
    intervals: dict = field(default_factory=dict)
    """joint -> marker -> ([lo, hi], method) where the quadratic interval is not to be trusted (see
    :func:`honest_intervals`); the other distances' 95 % intervals are ``d ± 1.96 SE``."""
    misfit: dict = field(default_factory=dict)
    """marker -> :class:`~identcheck.bundle.misfit.MarkerMisfit`: how much of its residual follows the angles."""
    model_error: dict = field(default_factory=dict)
    """joint -> model-error standard deviation (mm) already inside its distances' standard errors."""
    rivals: dict = field(default_factory=dict)
    """joint -> [(Minimum, Δχ², p)]: the other minima as judged without the markers below an unbounded joint
    (:func:`identcheck.bundle.incidental.without_incidental_rolls`), for the joints refitted so; others use
    ``TreeFit.others``."""
    upstream: dict = field(default_factory=dict)
    """joint -> (fit, covariance) its answer comes from when that is not this minimum's own: the refit without the
    markers below a segment not posed by itself (:func:`identcheck.bundle.incidental.without_incidental_rolls`). Its
    distances, centre, axis, covariance and verdict all come from that one refit, never a mix of two fits (a
    covariance the bootstrap widened, :func:`with_sampling_spread`, is put here too)."""
    upstream_weights: dict = field(default_factory=dict)
    """joint -> the sample weights of its refit in ``upstream`` (the markers below the cuts weighted 0)."""
    spread: dict = field(default_factory=dict)
    """joint -> {"draws": n, "ratio": largest bootstrap-over-linear standard error} where the sampling spread was
    measured (:func:`with_sampling_spread`)."""
    modelled: tuple = ()
    """The motions with the angles the fit's effect terms take up (:class:`~identcheck.bundle.misfit.ModelledMotion`),
    counted in the model error as if seen (:func:`with_misfit`)."""
    scale_sd: float = 0.0
    """Relative standard deviation of every length, inside the distances' standard errors and intervals
    (:func:`with_scale_error`): the capture's own scale, where the trial shows its calibration off."""


SAME_MM = 0.5
"""Two minima whose every marker distance agrees within this (mm) are one: converged fits reach the same minimum to
about 1e-3 mm."""


def same_distances(a: Minimum, b: Minimum, joints=None) -> bool:
    """Whether two minima give the same marker distances (within :data:`SAME_MM`) for `joints` (default: all)."""
    return all(abs(d - b.distances[j][mk][0]) <= SAME_MM
               for j in (joints or a.distances) for mk, (d, _) in a.distances[j].items())


MOVING_CENTRE_REASON = (
    "its centre moves with its angles (`diagnose` models a translation, or an effect the data cannot tell from one): "
    "the part of that motion linear in the angles is, to any data, a shifted centre (a shifted axis, for a hinge), so "
    "where the centre is in either segment at any one pose is not identifiable and no interval is claimed for the "
    "distances to it; `moving_centre` gives their intervals to the place the fit gives the centre over the trial, a "
    "convention")
"""Why a joint whose own centre an adopted effect moves (:func:`with_moving_centre`) is ``undetermined``. Only a
caveat until held-out draw 80: knees whose centres shifted posteriorly with flexion were called determined 6.4 and
10.7 mm from the truth's distances (1 and 0 of 7 intervals holding them), a hip whose pelvis cluster moved as one
with its angles, named its centre moving, 32.5 mm (draw 53's rolling knees: within ±1.6 mm, 5 mm off). The fitted
motion is what the data show beyond the part a fixed centre absorbs; the absorbed part, a shifted centre, no data
of the joint measure, so the centre at the truth's reference pose is not identifiable."""


def with_moving_centre(answer: dict, motion_rms_mm: float) -> dict:
    """A joint's answer (:func:`joint_answer`) once its own centre moves with its angles in the final model (a
    translation fitted there, or a motion fitted otherwise that the data cannot tell from one: the largest such, RMS
    `motion_rms_mm` about its mean over the trial): ``undetermined`` (:data:`MOVING_CENTRE_REASON`, before the reason
    the answer had, which says what widens its intervals), every interval ``[0, None]`` (method ``moving_centre``),
    and the intervals, methods and largest standard error of the distances to the centre as the fit places it over
    the trial kept under ``moving_centre`` with the motion's size: what the data do determine, the place a functional
    method gives the centre, which is a convention of the trial's poses."""
    functional = {"marker_distances_ci95": answer["marker_distances_ci95"],
                  "interval_method": answer["interval_method"], "uncertainty_mm": answer["uncertainty_mm"],
                  "motion_rms_mm": round(float(motion_rms_mm), 3)}
    out = without_bounds(answer)
    out["interval_method"] = {m: "moving_centre" for m in out["interval_method"]}
    was = answer["practical"]
    reason = (f"{MOVING_CENTRE_REASON}; to that place, {was['reason']}" if was["verdict"] == "determined" else
              f"{was['reason']}; {MOVING_CENTRE_REASON}")
    out["practical"] = dict(out["practical"], verdict="undetermined", reason=reason, motion_advice="")
    out["moving_centre"] = functional
    return out


def with_model_error(m: Minimum, model_error: dict) -> Minimum:
    """The minimum with each joint's model-error SD added in quadrature to its distances' standard errors."""
    if not model_error:
        return m
    dist = {j: {k: (d, float(np.hypot(se, model_error.get(j, 0.0)))) for k, (d, se) in per.items()}
            for j, per in m.distances.items()}
    return replace(m, distances=dist, model_error=dict(model_error))


def with_scale_error(m: Minimum, rel_sd: float) -> Minimum:
    """The minimum with every distance uncertain by the fraction `rel_sd` of itself besides what it had: a
    distance d's standard error gains ``d · rel_sd`` in quadrature, each interval that claims a bound is widened
    about d by ``1.96 d · rel_sd`` in quadrature on each side (its method marked ``+scale``), an interval that
    claims none stays. For the uniform scale of a capture volume found distorted
    (:meth:`identcheck.effects.base.Effect.scale_sd`): rigid segments cannot see it, so no interval the
    likelihood gives holds it."""
    if not rel_sd > 0:
        return m
    distances, intervals = {}, {}
    for j, per in m.distances.items():
        distances[j] = {k: (d, float(np.hypot(se, d * rel_sd))) for k, (d, se) in per.items()}
        ivs = {}
        for k, ((lo, hi), how) in m.intervals.get(j, {}).items():
            if how in NO_BOUND:
                ivs[k] = ([lo, hi], how)
                continue
            d, half = per[k][0], Z95 * per[k][0] * rel_sd
            ivs[k] = ([round(max(d - float(np.hypot(d - lo, half)), 0.0), 3),
                       None if hi is None else round(d + float(np.hypot(hi - d, half)), 3)], how + "+scale")
        intervals[j] = ivs
    return replace(m, distances=distances, intervals=intervals, scale_sd=float(rel_sd))


PROFILE_BUDGET_S = 60.0
"""Seconds of profile-likelihood refits per trial at most (a profile under way when they run out is abandoned, not
finished: a weakly determined hip's profiles had run 89 s past a budget that was only checked between them);
distances left over get no bound, ``[0, None]`` with the method ``not_profiled`` (not ``unbounded``: nothing was
learnt about them), never a quadratic interval known to be untrustworthy."""
NO_BOUND = ("unbounded", "not_profiled")
"""Interval methods that claim no bound: the likelihood does not bound the distance, or its profile was not
computed within :data:`PROFILE_BUDGET_S`."""


def posed_by_itself(chain: Skeleton, segment: str, fit=None) -> bool:
    """Whether a segment's pose in each frame follows from its own markers plus the points its parent joint
    fixes on it (a ball's centre: one; a hinge's axis: two), as three points do. When it does not, the
    segment's roll in every frame is a free unknown seen only through the joints below it: an incidental
    parameter per frame, which biases the likelihood towards joints whose marker orbits absorb noise (on
    simulated 3 pelvis / 1 thigh / 1 shank legs, wrong knees beat the truth's basin by Δχ² 150-820).

    With `fit`, the points must also not lie on one line (their fitted places in the segment's frame,
    :func:`~identcheck.geometry.poses.poses_segment`): three markers along a femur, or two and the hip's centre,
    leave the segment's roll about that line to the noise, as one marker does. A hinge's axis is a line already:
    any marker off it poses the segment, and that is not checked."""
    idx = chain.seg_markers[segment]
    if len(idx) + points_fixed_from_above(chain, segment) < 3:
        return False
    up = [j for j in chain.joints if chain.child[j] == segment]
    if fit is None or (up and chain.types[up[0]] == "revolute"):
        return True
    points = fit.state.local[idx] if not up else np.vstack([fit.state.local[idx], fit.state.c_child[up[0]][None]])
    return poses_segment(points[None])


def points_fixed_from_above(chain: Skeleton, segment: str) -> int:
    """How many of a segment's points its parent joint fixes once the parent is posed: a ball's centre one, a
    hinge's axis two, none for the root."""
    up = [j for j in chain.joints if chain.child[j] == segment]
    return 0 if not up else (2 if chain.types[up[0]] == "revolute" else 1)


def posed_above(chain: Skeleton, joint: str, fit=None) -> bool:
    """Whether every segment from the root down to `joint`'s parent is posed by itself
    (:func:`posed_by_itself`, with `fit`: its points not on one line): otherwise a per-frame roll seen only through
    the joints below reaches `joint`."""
    seg = chain.parent[joint]
    while True:
        if not posed_by_itself(chain, seg, fit):
            return False
        up = [j for j in chain.joints if chain.child[j] == seg]
        if not up:
            return True
        seg = chain.parent[up[0]]


def skin_unseen(chain: Skeleton, joint: str) -> bool:
    """Whether a segment beside `joint` has fewer than three markers: no distance within it shows its markers'
    skin motion, which the joint then absorbs whole (a thigh marker that slides by e with the hip angle is a hip
    centre moved by about e / θ). When skin motion is seen elsewhere in the trial, nothing bounds it here: on
    simulated minimal legs (3 pelvis, 1 thigh, 1 shank marker) with 2-10 mm of skin motion, hips whose intervals
    took the motion seen on the pelvis as their model error were 4-23 half-widths off."""
    return any(len(chain.seg_markers[s]) < 3 for s in (chain.parent[joint], chain.child[joint]))


def honest_intervals(best: Minimum, data, scale: float, progress=None, weights=None) -> dict:
    """95 % intervals for the marker distances of the joints the quadratic interval cannot describe:
    those with a direction the data leave free, or an interval wider than ±TOLERANCE_MM (``undetermined``).

    - direction free (or a ball joint turned about one axis only, :func:`~identcheck.bundle.practical.single_axis`,
      or a joint beside a segment not posed by itself that hardly moved,
      :func:`~identcheck.bundle.practical.hardly_moved`), or the joint hangs below a segment that is not posed by
      itself (:func:`posed_above`) and is wide or misfitted, or it is misfitted beside a segment that cannot show its
      own skin motion (:func:`skin_unseen`): ``[0, None]`` (the likelihood does not bound it), method
      ``unbounded``;
    - markers moving with the angles (model error, :mod:`identcheck.bundle.misfit`): the widened quadratic
      interval stays (a profile of a wrong likelihood would not be better);
    - otherwise the profile likelihood (:mod:`identcheck.bundle.profile`), method ``profile``; an upper
      side that does not close within its span is ``None``; a profile that meets a better fit than the
      minimum (the fit had not found the best joint) makes every profiled interval of that joint unbounded (they
      all measure Δχ² from a minimum that is not one along it), and its profiles not yet begun are not run
      (held-out draw 55, trial 0: a knee turning about three axes whose fit still crept by 0.02 χ² an iteration;
      each of its seven profiles found a fit 1-3 χ² better, 3-13 s apiece).
    A fit that did not converge (:func:`identcheck.bundle.converge.converged_fit`) is no maximum of the likelihood:
    every distance is ``unbounded`` and nothing is profiled (its profiles had met fits better than the "minimum",
    a minute of refits to learn that).
    Returns joint -> marker -> ([lo, hi], method)."""
    fit, cov = best.fit, best.cov
    chain = fit.chain
    if not fit.converged:
        return {j: {m: ([0.0, None], "unbounded") for m in best.distances[j]} for j in chain.joints}
    n_params = len(cov.information)
    grads = distance_gradients(chain, fit.state, n_params)
    start, out, jobs = time.monotonic(), {}, []
    for j in chain.joints:
        dist = best.distances[j]
        free = (free_markers(cov, grads[j]) or single_axis(chain, fit, cov.sigma_mm, j)[0]
                or hardly_moved(chain, fit, cov.sigma_mm, j) is not None)
        wide = any(Z95 * se > TOLERANCE_MM for _, se in dist.values())
        misfit = j in best.model_error
        if not (free or wide or misfit):
            continue
        if free or not posed_above(chain, j, fit) or (misfit and skin_unseen(chain, j)):
            out[j] = {m: ([0.0, None], "unbounded") for m in dist}
            continue
        if misfit:
            continue                   # the likelihood itself is off: its widened quadratic interval stays
        out[j] = {}
        jobs += [(j, m, se) for m, (d, se) in dist.items()]

    no_minimum = {j: threading.Event() for j in out}     # a profile of the joint met a better fit than the minimum

    def profiled(job):
        j, m, se = job
        if no_minimum[j].is_set():
            return ([0.0, None], "unbounded")
        if time.monotonic() - start > PROFILE_BUDGET_S:
            return ([0.0, None], "not_profiled")
        if progress:
            progress(f"profile likelihood of {m}'s distance to {j}")
        try:
            pi = profile_interval(fit, data, j, m, scale, se, n_params, weights=weights,
                                  deadline=start + PROFILE_BUDGET_S)
        except OutOfTime:
            return ([0.0, None], "not_profiled")
        if pi.better_fit or pi.lowest_rss < fit.rss - scale:
            no_minimum[j].set()
            return ([0.0, None], "unbounded")
        return ([round(pi.lo, 3), None if pi.hi is None else round(pi.hi, 3)], "profile")

    with ThreadPoolExecutor(max(1, min(profile_threads(), len(jobs)))) as pool:
        for (j, m, _), answer in zip(jobs, pool.map(profiled, jobs)):
            out[j][m] = answer
    for j, m, _ in jobs:
        if no_minimum[j].is_set() and out[j][m][1] == "profile":
            out[j][m] = ([0.0, None], "unbounded")
    return out


SPREAD_TRIGGER = 1.1
"""A joint's sampling spread is measured (:mod:`identcheck.bundle.bootstrap`) when the noise in the per-frame
unknowns widened one of its distances' standard errors by more than this factor
(:meth:`~identcheck.bundle.uncertainty.Covariance.frame_noise_ratio`): the linearisation is then off by over 10 %
and the estimator's second-order response to that noise, which no linear correction sees, is of the same order."""


def with_sampling_spread(best: Minimum, data, rate_hz: float, progress=None, weights=None) -> Minimum:
    """The minimum with each joint whose standard errors the per-frame noise stretched by over
    :data:`SPREAD_TRIGGER` given its distances' sampling spread by smoothed parametric bootstrap
    (:func:`identcheck.bundle.bootstrap.sampling_spread`, one run per fit the joints answer from): each distance's
    standard error becomes the larger of its own and ``t₉₅ · spread / 1.96`` (model error added in quadrature), a
    quadratic interval becomes ``d ± 1.96 SE`` with the method ``bootstrap`` (``bootstrap+model_error``), a profile
    interval is widened to hold ``d ± t₉₅ · spread`` (``profile+bootstrap``), an interval that claims no bound stays;
    the joint's covariance (centre, axis, weakest direction) grows by the largest variance ratio among its distances.
    ``weights``: the sample weights of ``best.fit`` (an upstream refit's are in ``best.upstream_weights``)."""
    groups: dict = {}
    if not best.fit.converged:                    # no maximum of the likelihood: its intervals are withdrawn anyway
        return best
    for j in best.fit.chain.joints:
        if any(how in NO_BOUND for _, how in best.intervals.get(j, {}).values()):
            continue
        fit, cov = best.upstream.get(j, (best.fit, best.cov))
        grads = distance_gradients(fit.chain, fit.state, len(cov.information))[j]
        if grads and max(cov.frame_noise_ratio(g) for _, g in grads.values()) > SPREAD_TRIGGER ** 2:
            groups.setdefault(id(fit), (fit, cov, best.upstream_weights.get(j, weights), []))[3].append(j)
    if not groups:
        return best
    distances, intervals, upstream, spread = dict(best.distances), dict(best.intervals), dict(best.upstream), {}
    for fit, cov, fit_weights, joints in groups.values():
        found, draws = sampling_spread(fit, data, joints, cov.sigma_mm, cov.lag1, rate_hz,
                                       weights=fit_weights, progress=progress,
                                       threads=profile_threads())
        for j, per in found.items():
            dist, ivs, ratio = dict(distances[j]), dict(intervals.get(j, {})), 1.0
            for m, rms in per.items():
                d, se = dist[m]
                boot = float(np.hypot(t95(draws) * rms / Z95, best.model_error.get(j, 0.0)))
                if boot <= se:
                    continue
                ratio = max(ratio, boot / se)
                dist[m] = (d, boot)
                if m in ivs:
                    (lo, hi), _ = ivs[m]
                    ivs[m] = ([round(max(min(lo, d - Z95 * boot), 0.0), 3),
                               None if hi is None else round(max(hi, d + Z95 * boot), 3)], "profile+bootstrap")
                else:
                    ivs[m] = (ci({m: (d, boot)})[m], "bootstrap" + ("+model_error" if j in best.model_error else ""))
            distances[j], intervals[j] = dist, ivs
            upstream[j] = (fit, cov.scaled(ratio ** 2))
            spread[j] = {"draws": draws, "ratio": round(ratio, 3)}
    return replace(best, distances=distances, intervals=intervals, upstream=upstream, spread=spread)


def profile_threads() -> int:
    """Threads for the profile likelihoods: ``$IDENTCHECK_THREADS``, else the cores this process may use, at most
    4. Each profile is independent and NumPy releases the GIL in its array work: on 2 cores, four of walking2's
    knee profiles took 21.5 s of wall time on two threads against 32.1 s on one, with identical intervals (the
    batch runner sets 1: its cluster already runs one job per core)."""
    env = os.environ.get("IDENTCHECK_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, 4))


def minimum(fit, data, weights=None, start: tuple = ()) -> Minimum:
    """A fitted chain as a :class:`Minimum`: its sandwich covariance and every joint's marker distances with
    their standard errors (no model error, no intervals yet)."""
    cov = covariance(fit, data, weights)
    grads = distance_gradients(fit.chain, fit.state, len(cov.information))
    dist = {j: {m: (d, cov.se(g)) for m, (d, g) in per.items()} for j, per in grads.items()}
    return Minimum(fit, cov, dist, start)


def likelihood_scale(best: Minimum) -> float:
    """mm² per unit of χ² in likelihood ratios and profiles: the noise variance (never below
    :data:`SIGMA_FLOOR_MM`) times the median variance inflation of the distances under correlated noise."""
    grads = distance_gradients(best.fit.chain, best.fit.state, len(best.cov.information))
    tau = max(1.0, float(np.median([best.cov.inflation(g) for per in grads.values() for _, g in per.values()])))
    return max(best.cov.sigma_mm, SIGMA_FLOOR_MM) ** 2 * tau


def with_misfit(m: Minimum, data, modelled: tuple = ()) -> Minimum:
    """The minimum with the markers' angle-following motion measured and each joint's model error added to its
    distances' standard errors (:mod:`identcheck.bundle.misfit`); `modelled`: the motions with the angles that
    the fit's effect terms take up (:class:`~identcheck.bundle.misfit.ModelledMotion`), which count as seen."""
    misfit = angle_dependence(m.fit, data)
    errors = {j: model_error_sd(m.fit, j, misfit, modelled) for j in m.fit.chain.joints}
    return with_model_error(replace(m, misfit=misfit, modelled=tuple(modelled)),
                            {j: sd for j, sd in errors.items() if sd > 0})


def assess(fit, data, weights=None, progress=None, rate_hz: float | None = None, scale_sd: float = 0.0,
           modelled: tuple = ()) -> Minimum:
    """One fit judged by every rule: covariance, model error, honest intervals, the joints above a segment posed only
    through the joints below it refitted without the markers that see its roll (when the fit has no effect terms:
    :func:`identcheck.bundle.incidental.without_incidental_rolls`), and with the trial's frame rate the sampling spread
    where the linearisation is off (what ``diagnose`` reports; ``fit`` does the same for its best minimum, then weighs
    the other candidates); `scale_sd`: the relative uncertainty of the capture's scale the
    trial showed (:func:`with_scale_error`), 0 when it showed none; `modelled`: the motions with the angles the
    fit's effect terms take up (:func:`with_misfit`)."""
    from identcheck.bundle.incidental import without_incidental_rolls   # (it builds on this module)

    best = with_misfit(minimum(fit, data, weights), data, modelled)
    scale = likelihood_scale(best)
    best = replace(best, intervals=honest_intervals(best, data, scale, progress, weights))
    if not fit.terms.ordered():
        # the joints above a segment posed only through the joints below it, from a refit without what sees its roll
        # (as ``fit`` judges them): with effect terms, the refit would leave the terms of the markers it sets aside free
        best = without_incidental_rolls(best, [], data, best.model_error, scale, weights)
    if rate_hz is not None:
        best = with_sampling_spread(best, data, rate_hz, progress, weights)
    return with_scale_error(best, scale_sd)


def ci(dist: dict) -> dict:
    """marker -> the quadratic 95 % interval ``[max(d − 1.96 SE, 0), d + 1.96 SE]``."""
    return {k: [round(max(d - Z95 * se, 0.0), 3), round(d + Z95 * se, 3)] for k, (d, se) in dist.items()}


def without_bounds(answer: dict) -> dict:
    """A joint's answer claiming nothing: every interval ``[0, None]`` (method ``unbounded``) and no standard error
    (``uncertainty_mm`` and ``practical.weakest_se_mm`` null), for a joint that nothing in the trial bounds."""
    names = answer.get("marker_distances") or {}
    out = dict(answer, marker_distances_ci95={m: [0.0, None] for m in names},
               interval_method={m: "unbounded" for m in names}, uncertainty_mm=None)
    if out.get("practical") is not None:
        out["practical"] = dict(out["practical"], weakest_se_mm=None)
    return out


def joint_answer(best: Minimum, j: str, alternatives: list = (), rejected: list = ()) -> dict:
    """The contract's per-joint keys from a judged minimum: geometry, marker distances, 95 % intervals and how each
    was made, the largest standard error, the practical verdict; ``alternatives`` / ``rejected`` (already
    rendered) are the other candidates the likelihood keeps / rejects."""
    chain = best.fit.chain
    fit, cov = best.upstream.get(j, (best.fit, best.cov))
    dist = best.distances[j]
    skipped = [k for k, (_, how) in best.intervals.get(j, {}).items() if how == "not_profiled"]
    unbounded = None
    if any(how == "unbounded" for _, how in best.intervals.get(j, {}).values()):
        unbounded = (
            f"the likelihood does not bound {j}: the data leave it free, or it hangs below a segment its own "
            "markers do not pose (a roll in every frame seen only through the joints below), with wide "
            "intervals or markers moving with the angles, or markers move with the angles in this trial and "
            "a segment beside it has too few markers (under three) to show its own skin motion, or its profile "
            "likelihood met a fit better than the one reported (the fit still creeping along a flat valley)")
    elif skipped:
        unbounded = (
            f"the quadratic intervals of {j} are too wide or too curved to trust, and the profile likelihood of "
            f"{', '.join(skipped)} was not computed within the {PROFILE_BUDGET_S:g} s budget: no bound is claimed "
            "for them (fit fewer frames, or one joint at a time, to have them profiled)")
    practical = judge(chain, fit, cov, j, dist, n_alternatives=len(alternatives), unbounded=unbounded)
    moving = [m.rms_mm for m in best.modelled if m.joint == j]          # its own centre moves (with_moving_centre)
    explained = practical["verdict"] != "determined" or bool(moving)      # the reason says what widens the intervals
    if not best.fit.converged:           # its intervals are all unbounded (honest_intervals): say why
        practical["reason"] = not_converged_reason()
    if j in best.model_error:
        practical["model_error_sd_mm"] = round(best.model_error[j], 3)
        if explained:
            practical["reason"] += (f"; the intervals include ±{Z95 * best.model_error[j]:.1f} mm of model error, "
                                    "for markers that move with the joint angles " + (
                                        "(the effects fit the motion they show; their segment's markers moving "
                                        "together with the angles would not show, and would move the joint)"
                                        if any(m.beside(chain, j) for m in best.modelled) else
                                        "(see warnings; `identcheck diagnose` models that motion)"))
            readings = sorted({m.reading for m in best.modelled if m.reading and m.beside(chain, j)})
            if readings:
                practical["reason"] += "; it counts the same motion read as " + ", and as ".join(readings)
    if best.scale_sd > 0:
        practical["scale_sd"] = round(best.scale_sd, 6)
        if explained:
            practical["reason"] += ("; the intervals include the capture's uncertain scale "
                                    f"(±{100 * Z95 * best.scale_sd:.2f} % of each distance: the trial shows the "
                                    "volume distorted)")
    interval = ci(dist)
    suffix = ("+model_error" if j in best.model_error else "") + ("+scale" if best.scale_sd > 0 else "")
    method = {k: "quadratic" + suffix for k in dist}
    for k, (iv, how) in best.intervals.get(j, {}).items():
        interval[k], method[k] = iv, how
    # no standard error for a distance the data leave free (the quadratic one is computed without that direction),
    # nor for a joint with an interval that claims no bound: the quadratic error there is the one found
    # untrustworthy (held-out minimal gait hips: ±0.9-4.2 mm while 8-32 mm off)
    open_ended = any(hi is None for _, hi in interval.values())
    no_se = bool(free_markers(cov, distance_gradients(chain, fit.state, len(cov.information))[j])) or open_ended
    if open_ended:
        practical["weakest_se_mm"] = None
    out = {"geometry": joint_geometry(chain, fit.state, cov, j),
           "marker_distances": {k: round(v[0], 3) for k, v in dist.items()},
           "marker_distances_ci95": interval, "interval_method": method,
           "uncertainty_mm": round(max(v[1] for v in dist.values()), 4) if dist and not no_se else None,
           "alternatives": list(alternatives), "rejected_candidates": list(rejected), "practical": practical}
    if j in best.spread:
        out["sampling_spread"] = dict(best.spread[j])
    return with_moving_centre(out, max(moving)) if moving else out
