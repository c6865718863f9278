"""``fit``: the closed-form start (:mod:`identcheck.estimate.closed_forms`), the whole-tree maximum likelihood from
every candidate it leaves (:mod:`identcheck.fit.whole_tree`), and the contract's ``fit`` JSON."""
from __future__ import annotations

import logging
import math

from identcheck.errors import InputError
from identcheck.estimate.closed_forms import fit_model, not_identifiable
from identcheck.estimate.screen_findings import with_screen_findings
from identcheck.io.model import refuse_exported_points

log = logging.getLogger("identcheck")

__all__ = ["fit_model", "report", "fit_closed_then_tree", "fit_trial", "with_restarted"]

def _num(x):
    return None if x is None or not math.isfinite(x) else float(x)


def report(model, fitted: dict, points: dict) -> dict:
    """The contract's ``fit`` JSON (plus ``case``, ``estimator``, ``notes``)."""
    out = {}
    for name, (est, info) in fitted.items():
        jt = model.joints[name]
        adjacent = {m: points[seg][:, i] for seg in (jt.parent, jt.child)
                    for i, m in enumerate(model.segments[seg].markers)}
        if est is None:
            out[name] = {"type": jt.type, "case": info["case"], "unique": False, "identifiable": "reason" in info,
                         "marker_distances": {}, "alternatives": [], "rms_residual": None, "uncertainty_mm": None,
                         "excitation": {"ok": False, "reason": info.get("reason") or not_identifiable(info)},
                         "estimator": None, "markers_used": info}
            continue
        dist = lambda e: {m: _num(e.distance(x)) for m, x in adjacent.items()}  # noqa: E731
        # structurally, as the table and plan say it: a case whose twins nothing beyond it decides (revolute (2,1),
        # ERRATA E1) is locally identifiable only, whatever the closed form found
        out[name] = {"type": jt.type, "case": info["case"], "unique": bool(est.unique),
                     "identifiable": not est.nothing_beyond,
                     "marker_distances": dist(est),
                     "alternatives": [{"marker_distances": dist(a), "rms_residual": _num(a.rms_residual)}
                                      for a in est.alternatives],
                     "rms_residual": _num(est.rms_residual), "uncertainty_mm": _num(est.uncertainty_mm),
                     "excitation": {"ok": bool(est.excitation_ok), "reason": est.excitation_reason or "ok"},
                     "estimator": est.estimator, "markers_used": info, "notes": list(est.notes),
                     "twins_undecidable": bool(est.nothing_beyond)}
    return {"joints": out}


def fit_closed_then_tree(model, trial, progress=None, starts_budget_s: float | None = None):
    """(closed-form estimates, their virtual points, the whole-tree fit): every joint started from the closed
    forms, and the joints whose closed form needs a candidate of an ambiguous joint above them started again
    from each of its candidates (the restart). What ``fit`` runs after its label screen, and what ``plan
    --noise-mm`` linearises at (``starts_budget_s``: seconds after which no new start is fitted, default
    :data:`identcheck.fit.whole_tree.STARTS_BUDGET_S`).

    When that fit ends with the residuals following the angles and a joint's points pose a sparse segment, the
    closed forms refined joint by joint on their two segments (:func:`~identcheck.bundle.start.refined_closed_forms`)
    are fitted too, first alone (one Levenberg-Marquardt fit of the same tree): only when that ends well below
    (:data:`REFINED_GAIN`) is the whole-tree fit made again from them, and kept if its minimum is lower on the same
    markers. A 3 | 1 | 1 hinge chain had stalled at 2.5-2.7 times the noise in 3 of 12 clean trials; a second
    whole-tree fit every time (intervals, bootstrap) had doubled ``fit`` on a real gait trial with skin motion
    (48 -> 95 s), where the refined start is no lower."""
    from identcheck.fit.whole_tree import STARTS_BUDGET_S, misfit_warnings  # imported when used

    fitted, points = fit_model(model, trial, progress=progress)
    budget = STARTS_BUDGET_S if starts_budget_s is None else starts_budget_s
    start, (tree, restarts) = fitted, _tree_from(model, trial, fitted, progress, budget)
    if tree.best is not None and misfit_warnings(tree, model, trial):
        refined = _refined_start(model, trial, fitted, tree)
        if refined is not None:
            import warnings as _w

            from identcheck.bundle.starts import CANNOT_START

            with _w.catch_warnings(record=True) as said:   # said again only if this fit is kept
                _w.simplefilter("always")
                try:
                    again, again_restarts = _tree_from(model, trial, refined, progress, budget)
                except CANNOT_START:
                    again = None
            kept = tree.best.fit
            if again is not None and again.best is not None \
                    and again.best.fit.chain.labels == kept.chain.labels and again.best.fit.rss < kept.rss:
                start, tree, restarts = refined, again, again_restarts
                for w in said:
                    _w.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return with_restarted(start, restarts, tree), points, tree


REFINED_GAIN = 0.9
"""The refined start's fit must end below this share of the first whole-tree fit's cost for the whole-tree fit to be
made again from it: a wrong minimum sits far above (a 3 | 1 | 1 chain at 2.5-2.7 times the noise: 6-8 times the
cost); walk2's sparse legs, whose residuals follow the angles through skin motion, ended 0.2 % lower from it, which
had cost a second whole-tree fit (48 -> 95 s) for no verdict changed."""


def _tree_from(model, trial, fitted: dict, progress, budget: float) -> tuple:
    """(the whole-tree fit from the closed forms `fitted`, the restarts it made: (fixed, closed forms) each)."""
    from identcheck.fit.whole_tree import fit_tree

    restarts: list = []

    def restart(fixed: dict) -> dict:
        again = fit_model(model, trial, fixed=fixed)[0]
        restarts.append((fixed, again))
        return again

    return fit_tree(model, trial, fitted, progress=progress, restart=restart, starts_budget_s=budget), restarts


def _refined_start(model, trial, fitted: dict, tree):
    """The refined closed forms (:func:`~identcheck.bundle.start.refined_closed_forms`) when a fit of the whole tree
    from them to spread frames ends below :data:`REFINED_GAIN` of `tree`'s best minimum's cost on those frames (the
    same markers); None otherwise, or when they cannot be made or started (the raw closed forms' fit stands)."""
    import warnings as _w

    import numpy as np

    from identcheck.bundle.chain import fit_chain
    from identcheck.bundle.start import PICK_FRAMES, PICK_ITER, refined_closed_forms, state_from_joints
    from identcheck.bundle.starts import CANNOT_START

    best = tree.best.fit
    chain = best.chain
    with _w.catch_warnings():               # a start that is not kept must not leave its warnings in the report
        _w.simplefilter("ignore")
        try:
            refined = refined_closed_forms(model, trial, fitted)
            if refined is fitted or any(refined.get(j, (None,))[0] is None for j in chain.joints):
                return None
            data = trial.select(chain.labels).as_array()
            state = state_from_joints(model, chain, data, {j: refined[j][0] for j in chain.joints})
            # compared on frames spread over the trial, as diagnose compares its starts (better_start): the first
            # fit's cost there against the refined start's fit to them alone
            idx = np.unique(np.linspace(0, len(data) - 1, min(len(data), PICK_FRAMES)).astype(int))
            seen = np.all(np.isfinite(data[idx]), axis=2)
            fit = fit_chain(chain, data[idx], state.at_frames(idx), weights=seen.astype(float), max_iter=PICK_ITER)
        except CANNOT_START:
            return None
    first = float(np.sum(np.where(seen[..., None], best.pred[idx] - data[idx], 0.0) ** 2))
    return refined if fit.rss < REFINED_GAIN * first else None


def with_restarted(fitted: dict, restarts: list, tree) -> dict:
    """The closed-form joints, with each joint the first pass left without a start (an ambiguous joint above it
    lent no virtual points) taken from the restart the best whole-tree minimum began at, when a marker beyond could
    decide every joint that restart took a candidate of: its case is then the one its markers and that candidate's
    points make. A one-marker shank below a one-marker thigh, with a marker on the foot, is posed by the knee's axis
    points once a knee candidate is taken, so the ankle is revolute (3,1), identifiable, where ``fit`` had called it
    revolute (1,1), not identifiable (exit 1), beside a whole-tree answer that determined it, against ``plan``'s
    certificate. A joint below a knee nothing decides (ERRATA E1) inherits its candidates: it stays as the first
    pass left it, not identifiable, as ``plan`` says (locally, not uniquely). `restarts`: (the candidates taken,
    the closed forms they gave) per restart."""
    if tree.best is None:
        return fitted
    joints = tree.best.fit.chain.joints
    for fixed, again in restarts:
        if all(j in again for j in joints) and tuple(id(again[j][0]) for j in joints) == tree.best.start:
            if any(getattr(fitted[n][0], "nothing_beyond", True) for n in fixed):
                return fitted
            return {name: again[name] if est is None and again[name][0] is not None else (est, info)
                    for name, (est, info) in fitted.items()}
    return fitted


def fit_trial(model, trial, progress=None, export=None, on_fit=None, decided=None) -> dict:
    """Everything ``identcheck fit`` does, as one library call: screen the labels, start every joint with
    the closed-form estimators, fit the whole tree by maximum likelihood from every candidate, and report
    (the contract's ``fit`` JSON: joints, ``noise``, ``warnings``).

    A subject prefix removed from the labels (:meth:`Trial.unprefixed`), the label screen's findings, warnings
    raised by the estimators and a model misfit are all in ``warnings`` (dicts with ``message`` and ``kind`` and,
    where there is one, ``markers`` / ``frames``). `on_fit`, when given, is called as ``on_fit(trial, fit, offset)``
    with the whole-tree fit (if one was made), the trial it was fitted to and what that trial was moved by: what a
    figure of the fit needs (:func:`identcheck.fit.scene.fit_scene`). `decided`, when given, is called with the joints
    whose closed-form case admits equal twins with nothing beyond it to decide them, and returns those the whole
    model's exact certificate calls unique all the same (:func:`identcheck.fit.whole_tree.merge_report`)."""
    import warnings as _w

    from identcheck.bundle.continuity import angle_jumps
    from identcheck.estimate.labels import screen
    from identcheck.estimate.spikes import without_spikes
    from identcheck.fit.anatomy import anatomical_report
    from identcheck.fit.export import export_markers
    from identcheck.fit.whole_tree import gap_warnings, merge_report, misfit_warnings
    from identcheck.errors import warning_kind
    from identcheck.io.trc import centimetres_suspected, scaled_up_suspected

    trial, unprefixed = trial.unprefixed(model.markers)     # Vicon's 'Subject:Marker' labels
    refuse_exported_points(trial, model.joints)
    model.require_markers_in(trial)
    trial, spikes = without_spikes(trial)
    centred, offset = trial.recentred()
    screened, swaps = screen(model, centred)
    with _w.catch_warnings(record=True) as caught:
        _w.simplefilter("always")
        try:
            fitted, points, tree = fit_closed_then_tree(model, screened, progress)
        except InputError as exc:
            raise with_screen_findings(exc, swaps, spikes) from None
    jumps = {}
    if tree.best is not None:
        jumps = angle_jumps(tree.best.fit, screened.select(tree.best.fit.chain.labels).as_array(), screened.rate_hz)
    rep = merge_report(report(model, fitted, points), tree, model, screened, jumps, decided)
    notes = ([{"kind": "subject_prefix", "message": unprefixed}] if unprefixed else []) + ([spikes] if spikes else [])
    notes += list(swaps)
    notes += [{"message": str(c.message), "kind": warning_kind(c.category)} for c in caught
              if issubclass(c.category, UserWarning)]
    notes += rep["warnings"]                # the joints whose angle jumped (merge_report)
    if tree.best is not None:
        notes += misfit_warnings(tree, model, screened)
        notes += gap_warnings(tree, model, screened)
        if not tree.best.fit.converged:
            notes.append({"kind": "not_converged", "message": (
                f"{trial.source}: the whole-tree fit did not converge (its iteration and time budget ran out): no "
                "joint is reported as determined; a longer or richer trial, or more markers, make it converge")})
    if tree.starts_left_out:
        notes.append({"kind": "starts_left_out", "message": (
            f"{trial.source}: {tree.starts_left_out} of {tree.n_starts + tree.starts_left_out} combinations of candidate "
            "joints were not tried (a cap on count and time): a joint listed unique could have a rival among them")})
    units = [centimetres_suspected(trial.as_array(), trial.source),
             scaled_up_suspected(trial.select(model.markers).as_array(), trial.source)]
    notes += [{"kind": "units", "message": said} for said in units if said]
    rep["warnings"] = list({n["message"]: n for n in notes}.values())
    rep["anatomical"] = None
    if tree.best is not None:
        chain = tree.best.fit.chain
        rep["anatomical"] = anatomical_report(screened.select(chain.labels).as_array(), chain.labels, tree.best.fit,
                                              getattr(model, "subject", None))
    if export is not None:
        if tree.best is None:
            raise InputError([f"--export-markers {export}: no whole-tree fit to export ({tree.problem})"],
                             source=trial.source)
        export_markers(export, trial, tree.best.fit, offset)
    if on_fit is not None and tree.best is not None:
        on_fit(screened, tree.best.fit, offset)
    return rep
