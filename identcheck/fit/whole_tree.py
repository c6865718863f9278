"""The answer of ``fit``: one maximum-likelihood fit of the whole skeleton to every marker sample, started
from every candidate the closed-form estimators leave, with intervals that hold under correlated noise.

Why one fit: the estimators of :mod:`identcheck.estimate` (seed 001, O'Brien/SARA, spheres and circles in
a posed parent, S22, Pham (2,1)) each see one joint and a share of the data, and each judged its own
uncertainty its own way. Here they only start the whole-chain least squares of :mod:`identcheck.bundle`
(root pose and joint angles per frame, markers, centres and axes constant), which uses every sample at
once, including the segments with one or two markers whose pose comes through the joints.

Every candidate: where a case admits several joints (revolute (2,1): four, ERRATA E1), each one starts a
fit. The distinct minima are compared by the likelihood ratio: ``Δχ² = ΔRSS / (σ̂² τ)``, τ the variance
inflation of the trial's correlated residuals (:mod:`identcheck.bundle.uncertainty`); a candidate with
``Δχ² > χ²₁(0.95) = 3.84`` is rejected, any other stays an alternative with its Δχ² and p-value.

Every centre along its weak line: a sphere fitted to one or two child markers over a small arc (gait: a hip
through one thigh marker) fixes the direction to the centre far better than its distance, and the whole-tree
fit from that one start can settle in a wrong minimum. Each such centre also starts fits with its distance
from those markers scaled by :data:`~identcheck.bundle.starts.RADIAL_FACTORS` (held-out minimal gait trial: the
closed-form start settled with the hip 100 mm off, while a minimum near the truth fitted better by Δχ² 139), and
the joints whose closed forms took that centre (a knee posed through the hip) fitted again from the moved one; the
combinations are made in :mod:`identcheck.bundle.starts`.

Practical identifiability (:mod:`identcheck.bundle.practical`): from the sandwich covariance, each joint is
``determined`` (unique, and every marker distance's 95 % interval within ±:data:`~identcheck.bundle.practical.TOLERANCE_MM`),
``ambiguous`` (other candidates explain the trial as well) or ``undetermined`` (the information leaves
a direction free, or an interval is wider than the tolerance), with the weakest direction and the motion
that would help.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import chdtrc

from identcheck.bundle.converge import converged_fit
from identcheck.bundle.honest import (SAME_MM, Minimum, ci, honest_intervals, joint_answer, likelihood_scale, minimum,
                                      posed_above, posed_by_itself, same_distances, with_misfit, with_model_error,
                                      with_sampling_spread, without_bounds)
from identcheck.bundle.incidental import without_incidental_rolls
from identcheck.bundle.model import n_const
from identcheck.bundle.start import rarely_seen, state_from_joints
from identcheck.bundle.starts import candidates, start_combinations
from identcheck.bundle.uncertainty import distance_gradients
from identcheck.errors import DegenerateError, InputError
from identcheck.io.model import left_out_reasons, unposed_root
from identcheck.skeleton import Skeleton

STARTS_BUDGET_S = 90.0   # no new start after this many seconds (the ones left out are counted and reported)
REJECT_CHI2 = 3.841      # χ²₁ 95 % quantile: a candidate this much worse (noise model's units) is rejected


@dataclass
class TreeFit:
    """The whole-tree answer: the best minimum, the others with their likelihood-ratio statistics."""

    best: Minimum | None
    others: list = field(default_factory=list)     # (Minimum, delta_chi2, p_value)
    problem: str = ""                               # why no whole-tree fit could be made ('' when one was)
    n_starts: int = 0
    starts_left_out: int = 0
    one_joint_starts: int = 0       # the first combination's one-joint changes (each joint's other candidates)
    one_joint_left_out: int = 0     # of which the time budget left this many unfitted
    left_out: dict = field(default_factory=dict)    # joint -> why the fit left it (and the joints below it) out


def skeleton_of(model, trial) -> Skeleton:
    """The model's tree with only the markers the trial shows at least once."""
    return Skeleton.from_model(model, markers=trial.seen(model.markers))


def without_an_unposed_root(model, closed_form: dict) -> tuple:
    """(the model below its root when nothing poses the root, the closed forms of its joints, {joint left out: why}):
    a root without a marker, whose joints lend fewer than three points (:meth:`Model.below_root`),
    leaves every joint undetermined, a fully marked knee below a pelvis without markers among them (an independent
    check found 28 such joints). The subtree of the root's child that holds joints, and the most markers, is fitted;
    the root's joints, and its other subtrees, are left out and say why. The model as it is when the root is posed."""
    smaller, gone = model.below_root()
    if not gone:
        return model, closed_form, {}
    left_out = left_out_reasons(gone, unposed_root(model, smaller, "fitted"), "the fit")
    return smaller, {k: v for k, v in closed_form.items() if k in smaller.joints}, left_out


def _rarely_seen(model, trial, joints) -> str:
    """The markers of the segments below `joints` that the trial shows in fewer than half its frames, with their
    counts: the usual reason a segment cannot be posed or seen to move."""
    shown = [m for seg in dict.fromkeys(model.joints[j].child for j in joints) for m in model.segments[seg].markers]
    data = np.full((trial.n_frames, len(shown), 3), np.nan)          # a marker the trial lacks: never seen
    present = [k for k, m in enumerate(shown) if m in trial.labels]
    if present:
        data[:, present] = trial.select([shown[k] for k in present]).as_array()
    rare = rarely_seen(data, shown)
    return f" ({'; '.join(rare)})" if rare else ""


def fit_tree(model, trial, closed_form: dict, progress=None, restart=None,
             starts_budget_s: float = STARTS_BUDGET_S) -> TreeFit:
    """Whole-tree maximum likelihood from every combination of closed-form candidates (see module doc); no new
    start after ``starts_budget_s`` seconds (those left out are counted in ``starts_left_out``).

    A joint no start can be made for (no closed form, a child segment no frame poses, a hinge that never turns) is
    left out with every joint below it, and the rest of the tree is fitted without their markers: a foot marker
    seen in five frames no longer keeps the hip and knee from their fit. ``left_out`` says why, per joint."""
    model, closed_form, left_out = without_an_unposed_root(model, closed_form)
    if left_out and progress:
        progress(f"whole-tree fit without {', '.join(left_out)}: {next(iter(left_out.values()))}")
    while True:
        tree, stuck = _fit_once(model, trial, closed_form, progress, restart, starts_budget_s)
        stuck = {j for j in stuck if j in model.joints}
        if tree.best is not None or not stuck:
            break
        smaller, gone = model.without_subtrees(stuck)
        if not smaller.joints:
            break
        left_out.update(left_out_reasons(gone, tree.problem + _rarely_seen(model, trial, stuck), "the fit"))
        if progress:
            progress(f"whole-tree fit without {', '.join(gone)}: {tree.problem}")
        model, closed_form = smaller, {k: v for k, v in closed_form.items() if k in smaller.joints}
    tree.left_out = {**left_out, **tree.left_out}
    return tree


def _fit_once(model, trial, closed_form: dict, progress, restart, starts_budget_s: float) -> tuple:
    """(the whole-tree fit of `model`, the joints that kept it from starting: no closed-form start, or a child
    segment the start could not pose or move)."""
    chain = skeleton_of(model, trial)
    data = trial.select(chain.labels).as_array()
    combos, left_out, why, singles = start_combinations(chain, closed_form, restart, data)
    if not combos:
        return TreeFit(None, problem=why), {j for j in chain.joints if j not in candidates(closed_form)}
    minima, problems, tried, singles_cut = [], [], 0, 0
    stuck: set = set()
    t0 = time.monotonic()
    for k, combo in enumerate(combos):
        if minima and time.monotonic() - t0 > starts_budget_s:
            left_out += len(combos) - k          # said in the report: fewer candidates were tried
            singles_cut = max(1 + singles - k, 0)
            break
        tried += 1
        if progress and len(combos) > 1:
            progress(f"whole-tree fit from candidate start {k + 1} of {len(combos)}")
        try:
            state = state_from_joints(model, chain, data, combo)
        except (DegenerateError, InputError) as exc:
            problems.append(str(exc))
            stuck |= {j for j in chain.joints if chain.child[j] == exc.segment}
            continue
        fit = converged_fit(chain, data, state, progress)
        minima.append(_located(fit, tuple(id(e) for e in combo.values())))
    if not minima:
        return TreeFit(None, problem="; ".join(dict.fromkeys(problems)), n_starts=tried, starts_left_out=left_out,
                       one_joint_starts=singles, one_joint_left_out=singles_cut), stuck
    # only the distinct minima are judged: a covariance for every start (its SIMEX draws included) had been
    # computed and thrown away for each start that ended where another had
    minima = [minimum(m.fit, data, start=m.start) for m in _distinct(sorted(minima, key=lambda m: m.fit.rss))]
    best = minima[0]
    scale = likelihood_scale(best)
    others = []
    for m in minima[1:]:
        delta = (m.fit.rss - best.fit.rss) / scale
        others.append((m, float(delta), float(chdtrc(1, delta))))
    best = with_misfit(best, data)
    model_error = best.model_error
    others = [(with_model_error(m, model_error), delta, p) for m, delta, p in others]
    best = replace(best, intervals=honest_intervals(best, data, scale, progress))
    best = without_incidental_rolls(best, others, data, model_error, scale)
    best = with_sampling_spread(best, data, trial.rate_hz, progress)
    return TreeFit(best, others, n_starts=tried, starts_left_out=left_out, one_joint_starts=singles,
                   one_joint_left_out=singles_cut), set()


def _located(fit, start: tuple) -> Minimum:
    """A minimum known by its marker distances alone (no covariance, standard errors NaN): enough for
    :func:`_distinct` to tell it from the others before any is judged (:func:`identcheck.bundle.honest.minimum`)."""
    grads = distance_gradients(fit.chain, fit.state, n_const(fit.chain, fit.terms))
    return Minimum(fit, None, {j: {m: (d, float("nan")) for m, (d, _) in per.items()} for j, per in grads.items()},
                   start)


def _distinct(minima: list) -> list:
    """Minima with the same marker distances (within SAME_MM) kept once, best first."""
    kept = []
    for m in minima:
        if not any(same_distances(m, k) for k in kept):
            kept.append(m)
    return kept


def joint_answers(tree: TreeFit, model, undecidable: dict | None = None) -> dict:
    """Per joint: the contract's fit keys from the whole-tree fit (:func:`identcheck.bundle.honest.joint_answer`),
    with the other candidates the likelihood keeps (``alternatives``, with their likelihood-ratio statistics) and
    rejects. ``undecidable`` maps each joint whose closed-form case admits several joints that fit any rigid data
    equally, with nothing beyond it to decide (revolute (2,1) alone: ERRATA E1), to that case and the closed
    form's rendered alternatives: such a joint is never ``determined``, nor ``undetermined`` with intervals, but
    ``ambiguous`` (:func:`_undecided_twins`); left undetermined without bounds (the data leave it free), it stays so.
    Judged ``undetermined`` only for an interval just wider than the tolerance, a minimal
    gait knee had kept that quadratic interval (±4 and ±10 mm, 197 mm from the truth) and no alternative, where a
    fit that stopped a little earlier had called it ambiguous with two (held-out fit draw 5858, trial 135)."""
    undecidable = undecidable or {}
    best = tree.best
    chain = best.fit.chain
    out = {}
    for j in chain.joints:
        differing = [(m, delta, p) for m, delta, p in best.rivals.get(j, tree.others)
                     if not same_distances(m, best, [j])]                                     # this joint differs
        alts = [{"marker_distances": {k: round(v[0], 3) for k, v in m.distances[j].items()},
                 "marker_distances_ci95": ci(m.distances[j]),
                 "delta_chi2": round(delta, 3), "p_value": round(p, 4),
                 "rms_residual": round(float(np.sqrt(m.fit.rss / max(m.fit.n_samples, 1))), 4)}
                for m, delta, p in differing if delta <= REJECT_CHI2]          # not rejected at the 95 % level
        rejected = [{"marker_distances": {k: round(v[0], 3) for k, v in m.distances[j].items()},
                     "delta_chi2": round(delta, 3), "p_value": float(f"{p:.3g}")}
                    for m, delta, p in differing if delta > REJECT_CHI2]
        judged = best
        if alts and not posed_above(chain, j, best.fit):
            # candidates the likelihood cannot tell apart, compared through a segment whose roll in every frame
            # only they see (the incidental-parameter bias): their own intervals are not to be trusted either
            # (minimal legs: ambiguous knees 90-280 mm off at ±3-8 mm, the truth among none of them); a fit that did
            # not converge has none already (honest_intervals) and says why (joint_answer)
            judged = replace(best, intervals={**best.intervals,
                                              j: {m: ([0.0, None], "unbounded") for m in best.distances[j]}})
        out[j] = joint_answer(judged, j, alts, rejected)
        if j in undecidable and claims_a_joint(out[j]):
            out[j] = _undecided_twins(out[j], rejected, *undecidable[j], bounded=posed_above(chain, j, best.fit))
    return out


def claims_a_joint(answer: dict) -> bool:
    """Whether a joint's answer points at one joint: ``determined``, or ``undetermined`` while still giving intervals
    (too wide for the tolerance, but bounds about this joint). What a joint whose case admits equal twins may not
    claim (:func:`_undecided_twins`)."""
    verdict = answer["practical"]["verdict"]
    bounded = any(hi is not None for _, hi in answer["marker_distances_ci95"].values())
    return verdict == "determined" or (verdict == "undetermined" and bounded)


def _undecided_twins(answer: dict, rejected: list, case: str, start_alternatives: list, bounded: bool) -> dict:
    """A joint the likelihood ranked first (or left undetermined) although its case admits several joints that fit
    any rigid data equally (revolute (2,1): ERRATA E1) and no marker beyond it decides: its likelihood differences can
    only come from how the trial departs from the rigid model, so it is ``ambiguous``, with the candidates it beat
    (or the closed form's) as alternatives. Below a segment not posed by itself (``bounded`` False) its quadratic
    interval is no more to be trusted than the ranking (held-out minimal gait knee: ±0.3-1.9 mm while 32-85 mm
    off, no candidate near the truth), so it claims none, as candidates the likelihood cannot tell apart there
    already do in :func:`joint_answers`."""
    out = dict(answer)
    out["practical"] = dict(answer["practical"], verdict="ambiguous", reason=(
        f"{case} admits several joints that fit rigid data equally well (ERRATA E1/E2: four for revolute "
        "(2,1), mirror images included) and no other marker decides between them; their likelihood differences "
        "here come from how the trial departs from the rigid model, not from the joint"),
        motion_advice="add a marker on the one-marker segment, or one beyond it (ERRATA E8)")
    out["alternatives"] = [dict(r, p_value=None) for r in rejected] or \
        _distinct_alternatives(start_alternatives, answer["marker_distances"])
    return out if bounded else without_bounds(out)


def noise_report(tree: TreeFit) -> dict:
    """The top-level ``noise`` key: the residual noise model the intervals rest on."""
    cov = tree.best.cov
    return {"sigma_mm": round(cov.sigma_mm, 4), "correlation": {"lag1": round(cov.lag1, 3),
                                                                 "bartlett_bandwidth_frames": cov.bandwidth},
            "source": "whole-tree fit residuals; covariance by the sandwich with a Bartlett long-run score "
                      "covariance (correlated noise and model misfit allowed), never below the white-noise one"}


def misfit_warnings(tree: TreeFit, model, trial) -> list:
    """A ``model_misfit`` warning (dict with ``message``, ``markers``, ``joints``, ``kind``) when markers move
    on their segments with the joint angles (:mod:`identcheck.bundle.misfit`): skin motion, or a joint that
    is not the declared rigid one. It names the markers and how far they move, the joints whose intervals
    were widened for it, and ``identcheck diagnose`` as the next step."""
    best = tree.best
    moving = sorted((m for m in best.misfit.values() if m.moves), key=lambda m: -m.explained_mm)
    if not moving:
        return []
    shown = ", ".join(f"{m.marker} ({m.explained_mm:.2g} mm)" for m in moving[:6]) + (" ..." if len(moving) > 6 else "")
    joints = sorted(best.model_error)
    chain = best.fit.chain
    weak = [s for s in chain.segments if not posed_by_itself(chain, s, best.fit)]
    cause = ("skin motion, or a joint that is not rigid" if not weak else
             f"skin motion, a joint that is not rigid, or the fit's own bias where {', '.join(weak)} "
             f"{'is' if len(weak) == 1 else 'are'} posed only through the joints")
    return [{"message": f"{trial.source}: the residuals follow the joint angles beyond what noise explains: {shown}. "
                        f"The rigid-joint model does not hold ({cause}); the intervals of {', '.join(joints)} are "
                        "widened for it by a rule of thumb, not a calibrated bias. `identcheck diagnose` models the "
                        "motion.",
             "markers": [m.marker for m in moving], "joints": joints, "kind": "model_misfit"}]


def gap_warnings(tree: TreeFit, model, trial) -> list:
    """An ``unexplained_gap`` warning (dict with ``message``, ``kind``, ``ratio``, ``limit``) when the whole-tree fit
    leaves more than the measurement noise explains, by ``diagnose``'s stated test
    (:func:`identcheck.bundle.hypothesis.consistency`: the prewhitened residual against a noise floor estimated without
    the joint model, from the distances within segments); [] when it does not, or when no segment has two markers to
    estimate the noise from. What it catches that :func:`misfit_warnings` does not: motion the joint angles do not
    drive (a knee turning a few degrees about axes across its hinge, in a smooth random profile, read by the fit's
    noise model as correlated noise: an independent check's knees were reported determined at ±1-3 mm with no
    warning, exit 0, the residual twice the noise)."""
    from identcheck.bundle.hypothesis import Context, Hypothesis, consistency
    from identcheck.estimate.noise import noise_floor

    fit = tree.best.fit
    chain = fit.chain
    data = trial.select(chain.labels).as_array()
    try:
        noise = noise_floor(data, chain.labels, {s: [chain.labels[i] for i in chain.seg_markers[s]]
                                                 for s in chain.segments})
    except (InputError, DegenerateError, ValueError):
        return []
    seen = np.isfinite(data).all(axis=2)
    if not noise.sigma_mm > 0 or not seen.any():
        return []
    ctx = Context(model, chain.labels, trial.rate_hz, data, noise, int(seen.sum()), trial.source)
    h = Hypothesis(chain, fit.terms, data, seen.astype(float), fit)
    test = consistency(ctx, h)
    if test["consistent"]:
        return []
    weak = [s for s in chain.segments if not posed_by_itself(chain, s, fit)]
    bias = (f", or the fit's own bias where {', '.join(weak)} {'is' if len(weak) == 1 else 'are'} posed only through "
            "the joints" if weak else "")
    gap, floor = h.gap(ctx), h.floor(ctx)
    noise_said = (f"{noise.sigma_mm:.3g} mm a coordinate, lag-1 correlation {noise.lag1:.2f} from frame to frame, "
                  f"from {noise.n_pairs} distance{'s' if noise.n_pairs != 1 else ''} within segments")
    beyond = (gap / floor) ** 2 > test["limit"] if floor > 0 else gap > 0      # the plain RMS fails the test too
    if beyond:
        found = (f"the whole-tree fit leaves {gap:.3g} mm RMS where the measurement noise ({noise_said}) would leave "
                 f"{floor:.3g} (prewhitened gap²/floor² {test['ratio']:.3g}, limit {test['limit']:.3g})")
        cause = ""
    else:   # the RMS is within the test's allowance: what exceeds it is the residual's change from frame to frame
        found = (f"the whole-tree fit leaves {gap:.3g} mm RMS, against the {floor:.3g} the measurement noise "
                 f"({noise_said}) would leave (within the test's allowance), but its changes from frame to frame "
                 f"exceed what noise that correlated makes (prewhitened gap²/floor² {test['ratio']:.3g}, limit "
                 f"{test['limit']:.3g})")
        cause = (", or noise less correlated from frame to frame than the distances within segments suggest"
                 if noise.lag1 > 0 else "")
    return [{"kind": "unexplained_gap", "ratio": round(test["ratio"], 3), "limit": round(test["limit"], 3),
             "message": (f"{trial.source}: {found}: the rigid-joint model misses something (a joint that turns "
                         f"about more axes than declared, skin or marker motion, errors in the data{bias}{cause}), "
                         "and the intervals describe the best rigid approximation to the trial, not the joint. "
                         "`identcheck diagnose` names what it misses")}]


def _distinct_alternatives(alternatives: list, best: dict) -> list:
    """The closed form's alternatives with the same marker distances (within SAME_MM: mirror images, the same
    joint reached twice) kept once, and none equal to the answer itself."""
    kept = []
    for alt in alternatives:
        d = alt["marker_distances"]
        same = lambda other: all(d.get(m) is None or other.get(m) is None or abs(d[m] - other[m]) <= SAME_MM  # noqa: E731
                                 for m in d)
        if not same(best) and not any(same(k["marker_distances"]) for k in kept):
            kept.append(alt)
    return kept


def rep_unique(j: dict) -> bool:
    """False when a closed-form joint report's case admits several joints that fit any rigid data equally and no
    marker beyond it can decide (revolute (2,1) alone: ERRATA E1); True otherwise."""
    return not (j.get("twins_undecidable") and j.get("alternatives"))


def _closed_form_only(joint: dict, problem: str, left_out: str | None = None) -> str:
    """Why a joint has only its closed-form estimate: its own estimator's excitation finding first (on a static
    trial a hip's is its own stillness, where the whole-tree fit's problem may be a knee's), then why the
    whole-tree fit did not run, or (`left_out`) why it left this joint out."""
    tree_why = (f"the whole-tree fit left it out: {left_out}" if left_out
                else f"the whole-tree fit did not run: {problem or 'no start'}")
    own = joint.get("excitation") or {}
    parts = [own["reason"]] if own.get("ok") is False and own.get("reason") and own["reason"] not in tree_why else []
    return "closed-form estimate only, no calibrated interval: " + "; ".join(parts + [tree_why])


def _jumped(j: dict, joint: str, deg: float, row: int, trial) -> dict:
    """A joint's answer when its angle jumps (:mod:`identcheck.bundle.continuity`): undetermined, every interval
    unbounded, the jump and its frames named (the geometry fitted through it is not the joint's)."""
    a, b = trial.frame_number(row), trial.frame_number(row + 1)
    why = (f"{joint}'s angle jumps by {deg:.0f} deg between frames {a} and {b} ({deg * trial.rate_hz:.0f} deg/s, "
           "faster than any joint turns): markers of its segments exchanged labels there (two markers placed alike "
           "about the joint swap without changing a distance), or one was lost and another took its label; the "
           "fit through it is not the joint's: fix the labels from that frame, or fit the frames before it "
           "(--frames)")
    j = without_bounds(dict(j, unique=False))
    j["practical"] = dict(j.get("practical") or {}, verdict="undetermined", reason=why, motion_advice="")
    j["excitation"] = {"ok": False, "reason": why}
    return j


def merge_report(rep: dict, tree: TreeFit, model, trial, jumps: dict | None = None, decided=None) -> dict:
    """The contract's ``fit`` JSON with the whole-tree answer in place of the closed-form one: each joint's
    marker distances, 95 % intervals, uncertainty, alternatives (likelihood ratio), practical verdict and
    ``unique`` (= determined); the closed-form estimate stays as ``start`` (and in ``notes``). Without a
    whole-tree fit, no joint is called unique: the closed-form numbers stay, marked undetermined. A joint in
    ``jumps`` (:func:`identcheck.bundle.continuity.angle_jumps`) with any interval bounded is undetermined with
    unbounded intervals (the fit through the jump is not the joint's), and ``warnings`` holds an ``angle_jump`` for
    each such joint. A joint whose closed-form case admits equal twins with nothing beyond it to decide
    (:func:`rep_unique`) is ``ambiguous`` (:func:`joint_answers`) unless `decided` (called with those joints) says the
    whole model's exact certificate calls it unique: points from other joints on its segments decide the twins in the
    whole-tree likelihood (a hinge after a one-marker root, its child's two markers joined by a second hinge's axis:
    the closed form's twins fitted thousands of χ² units worse, and ``fit`` had called it ambiguous beside
    ``plan``'s unique)."""
    joints, jumped = {}, []
    undecidable = {name: (j["case"], j["alternatives"]) for name, j in rep["joints"].items()
                   if j.get("marker_distances") and not rep_unique(j)}
    sure: set = set()
    if undecidable and decided is not None and tree.best is not None:     # (unused without a whole-tree fit)
        sure = decided(list(undecidable))
        undecidable = {name: v for name, v in undecidable.items() if name not in sure}
    answers = joint_answers(tree, model, undecidable) if tree.best is not None else {}
    residual = None
    if tree.best is not None:
        fit = tree.best.fit
        data = trial.select(fit.chain.labels).as_array()
        residual = dict(zip(fit.chain.labels, np.linalg.norm(data - fit.pred, axis=2).T))
    for name, j in rep["joints"].items():
        j = dict(j)
        if name in sure:                    # the whole model's markers decide what the closed form's case could not
            j["twins_undecidable"] = False
        j["start"] = {"estimator": j.get("estimator"), "marker_distances": j.get("marker_distances"),
                      "uncertainty_mm": j.get("uncertainty_mm"), "unique": j.get("unique")}
        j["start_alternatives"] = j.get("alternatives", [])
        if name in answers:
            a = answers[name]
            j["estimator"] = "whole-tree maximum likelihood"
            j["marker_distances"] = {m: a["marker_distances"].get(m) for m in j["marker_distances"]} \
                if j["marker_distances"] else a["marker_distances"]
            j["marker_distances_ci95"] = a["marker_distances_ci95"]
            j["interval_method"] = a["interval_method"]
            j["uncertainty_mm"] = a["uncertainty_mm"]
            j["alternatives"] = a["alternatives"]
            j["rejected_candidates"] = a["rejected_candidates"]
            j["practical"] = a["practical"]
            j["geometry"] = a["geometry"]
            if "sampling_spread" in a:
                j["sampling_spread"] = a["sampling_spread"]
            j["unique"] = j["practical"]["verdict"] == "determined"
            res = [residual[m] for m in a["marker_distances"] if m in residual]
            j["rms_residual"] = round(float(np.sqrt(np.nanmean(np.square(res)))), 4) if res else None
            verdict = j["practical"]
            j["excitation"] = {"ok": verdict["verdict"] != "undetermined",
                               "reason": "ok" if verdict["verdict"] == "determined"
                               else f"{verdict['reason']}. {verdict['motion_advice']}".strip()}
            if jumps and name in jumps and any(hi is not None for _, hi in j["marker_distances_ci95"].values()):
                # (a joint already bounded by nothing keeps its own reason: a static trial's angles are free to jump)
                j = _jumped(j, name, *jumps[name], trial)
                deg, row = jumps[name]
                jumped.append({"kind": "angle_jump", "joints": [name], "frames": [row, row + 1],
                               "file_frames": [trial.frame_number(row), trial.frame_number(row + 1)],
                               "markers": list(model.segments[model.joints[name].child].markers),
                               "message": j["practical"]["reason"]})
        else:
            why = j["excitation"]["reason"] if j.get("estimator") is None else _closed_form_only(
                j, tree.problem, tree.left_out.get(name))
            j["unique"] = False
            # the closed form's numbers stay (they are what a user would otherwise compute), but nothing bounds them
            j = without_bounds(j)
            j["rejected_candidates"] = []
            j["geometry"] = None
            j["practical"] = {"verdict": "undetermined", "reason": why, "tolerance_mm": None,
                              "weakest_direction_parent": None, "weakest_se_mm": None, "motion_advice": ""}
            j["excitation"] = {"ok": False, "reason": why}
        joints[name] = j
    out = dict(rep)
    out["joints"] = joints
    out["warnings"] = jumped
    out["noise"] = noise_report(tree) if tree.best is not None else {
        "sigma_mm": None, "correlation": None, "source": "no whole-tree fit: " + (tree.problem or "no start")}
    return out
