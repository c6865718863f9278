"""The joints above a segment posed only through the joints below it, judged from a refit without the markers that
see that segment's roll (shared by ``fit`` and ``diagnose``: :func:`identcheck.bundle.honest.assess`).

A segment whose own markers and the points its parent joint fixes on it do not pose it (one marker and a ball's
centre: :func:`~identcheck.bundle.honest.posed_by_itself`) turns in every frame about a line only the markers below
its child joints see. A likelihood with that free roll in every frame prefers joints whose marker orbits absorb the
noise (the incidental-parameter bias), and through the shared segment the bias reaches the joints above.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.special import chdtrc

from identcheck.bundle.chain import fit_chain
from identcheck.bundle.converge import MAX_ITER
from identcheck.bundle.honest import NO_BOUND, Minimum, honest_intervals, posed_by_itself, same_distances
from identcheck.bundle.misfit import angle_dependence, model_error_sd
from identcheck.bundle.uncertainty import covariance, distance_gradients
from identcheck.skeleton import Skeleton

MAX_RIVALS = 4
"""Other minima refitted for the joints above an unbounded one (the best ones)."""


def without_incidental_rolls(best: Minimum, others: list, data, model_error: dict, scale: float,
                             weights=None) -> Minimum:
    """The other joints refitted without the markers below each joint that hangs from a segment not posed by
    itself (:func:`posed_by_itself`).

    Those markers are all that sees the segment's roll in each frame; a likelihood with one free roll per
    frame prefers joints whose marker orbits absorb the noise (the incidental-parameter bias), and through the
    shared segment that bias reaches the joints above: on simulated 3 pelvis / 1 thigh / 1 shank legs the
    hip came out 5-17 mm off at ±2-5 mm. Without them, the joints above are fitted from what poses them.
    A cut joint with no cut beneath it keeps its intervals and the whole fit's distances.

    Every such joint is cut, whether or not its own interval came out wide: when the one below the one-marker
    thigh happened to look narrow the hip kept the information the rolls lend it, and its intervals were half
    the spread of its estimates (simulated minimal legs, white and AR(1) noise, 10 replicates each: the hip's
    standard error switched between 0.2 and 1.4 mm from one noise draw to the next).

    The joints above no cut are refitted without the markers below every cut; a joint at or below a cut, without
    those below the cuts beneath it (:func:`refit_groups`): on a chain of 3 | 1 | 3 | 1 | 1 markers (balls, then a
    hinge) the third ball, below the one-marker second segment, kept the roll the hinge's one child marker lends the
    one-marker fourth segment, and its four distances were 0.2-1.4 mm off at ±0.4 mm (6 standard errors; fitted
    without that marker, ±0.8 mm around the truth)."""
    chain = best.fit.chain
    cut = [j for j in chain.joints if not posed_by_itself(chain, chain.parent[j], best.fit)]
    if not cut:
        return best
    unbounded = {j for j, per in best.intervals.items() if any(how in NO_BOUND for _, how in per.values())}
    groups = refit_groups(chain, cut, unbounded)
    if not groups:
        return best
    dist, intervals, rivals, upstream, refit_weights = dict(best.distances), dict(best.intervals), {}, {}, {}
    errors_out = {j: sd for j, sd in model_error.items() if sd > 0}
    misfits = []
    for left_out, keep in groups:
        w = np.ones(data.shape[:2]) if weights is None else np.array(weights, dtype=float)
        for c in left_out:
            w[:, chain.downstream[c]] = 0.0
        refitted, found_rivals, errors, misfit, found = _upstream_refit(best, others, data, model_error, scale, w,
                                                                        keep)
        for j in keep:
            dist[j] = refitted.distances[j]
            if j in found:
                intervals[j] = found[j]
            else:
                intervals.pop(j, None)
            rivals[j] = found_rivals
            upstream[j] = (refitted.fit, refitted.cov)
            refit_weights[j] = w
            errors_out.pop(j, None)
            if errors.get(j, 0.0) > 0:
                errors_out[j] = errors[j]
        misfits.append(misfit)
    merged = dict(best.misfit)
    for misfit in reversed(misfits):        # the first group's (the joints above every cut) stands where they meet
        merged.update(misfit)
    return replace(best, distances=dist, intervals=intervals, rivals=rivals, upstream=upstream,
                   upstream_weights=refit_weights, model_error=errors_out, misfit=merged)


def refit_groups(chain: Skeleton, cut: list, unbounded: set) -> list:
    """[(the cut joints whose markers below are left out, the joints answered from that refit)], the joints above
    every cut first: they are refitted without the markers below any cut (every roll left out); a joint at or below a
    cut without those below the cuts beneath it (its own markers stay: they are what sees it), and it keeps the
    whole fit when no cut lies beneath it. Joints whose intervals claim no bound are left as they are."""
    below = set(cut) | {k for c in cut for k in chain.joints_below(c)}
    groups: dict = {}
    for j in chain.joints:
        if j in unbounded:
            continue
        left_out = tuple(cut) if j not in below else tuple(c for c in cut if c in chain.joints_below(j))
        if left_out:
            groups.setdefault(left_out, []).append(j)
    return sorted(groups.items(), key=lambda g: g[0] != tuple(cut))


def _upstream_refit(best: Minimum, others: list, data, model_error: dict, scale: float, w: np.ndarray,
                    keep: list) -> tuple:
    """The refit of :func:`without_incidental_rolls` for the joints `keep`, the samples weighted `w`: (the refit
    as a Minimum; its rivals, [(Minimum, Δχ², p)] among the first :data:`MAX_RIVALS` other minima refitted alike; the
    model errors; the markers' misfit judged on it; the honest intervals of `keep` where the quadratic one is not
    trusted)."""
    chain = best.fit.chain
    seen = np.where(w[..., None] > 0, data, np.nan)         # the markers below the cut are not data here

    def refit(m: Minimum, errors: dict) -> Minimum:
        fit = fit_chain(chain, data, m.fit.state, m.fit.terms, weights=w, max_iter=MAX_ITER)
        cov = covariance(fit, data, weights=w)
        grads = distance_gradients(chain, fit.state, len(cov.information))
        dist = dict(m.distances)
        for j in keep:
            dist[j] = {k: (d, float(np.hypot(cov.se(g), errors.get(j, 0.0)))) for k, (d, g) in grads[j].items()}
        return replace(m, fit=fit, cov=cov, distances=dist)

    first = fit_chain(chain, data, best.fit.state, best.fit.terms, weights=w, max_iter=MAX_ITER)
    misfit = angle_dependence(first, seen)                  # judged on the fit the joints above come from
    errors = dict(model_error)
    errors.update({j: model_error_sd(first, j, misfit) for j in keep})
    errors = {j: sd for j, sd in errors.items() if sd > 0}
    upstream = refit(replace(best, fit=first), errors)
    rivals = []
    for m, _, _ in others[:MAX_RIVALS]:
        r = refit(m, errors)
        if any(not same_distances(r, upstream, [j]) for j in keep):
            delta = max(r.fit.rss - upstream.fit.rss, 0.0) / scale
            rivals.append((r, float(delta), float(chdtrc(1, delta))))
    # the joints judged by the same rules on the fit they now come from: a wide one's quadratic interval from this
    # refit is as untrustworthy as the whole fit's was (minimal legs in gait: hips 100 mm off at ±10 mm)
    judged = replace(upstream, misfit=misfit, model_error={j: errors[j] for j in keep if j in errors})
    redone = honest_intervals(judged, data, scale, weights=w)
    return upstream, rivals, errors, misfit, {j: redone[j] for j in keep if j in redone}
