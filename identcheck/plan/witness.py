"""Evidence for a plan's negative verdicts: simulate the plan and build, for every joint it does not
identify, a whole-tree alternative verified at 50 digits (:mod:`identcheck.plan.witness_search`).

The search is the one the verdict calls for: along the family of equally good skeletons when the
joint is not locally identifiable; from the table case's other candidates (and those of the joints
whose virtual markers it uses) when it is. When such a search finds nothing, the note says how each
start ended; that is evidence, not a proof of uniqueness (for the revolute (2,1) pattern with a
marker beyond the one-point segment, :mod:`identcheck.certify.twin` gives the proof).
"""
from __future__ import annotations

import time

import numpy as np

from identcheck.plan import tree_kinematics as K
from identcheck.plan import witness_search as W
from identcheck.simulate.rigid import simulate

MIN_FRAMES = 20
RANDOM_STARTS = 6
"""Random whole-tree skeletons a joint identifiable only together with others is also searched from
(:func:`identcheck.plan.witness_search.random_starts`), beside the twins of every hinge it shares motion with."""
BUDGET_S = 120.0
"""Seconds the witness searches may take together by default (``plan --witness --max-seconds``); past it, the
joints not yet searched say so instead of the search running on."""


def simulated_truth(model, spec, n_frames: int, seed: int = 0) -> tuple:
    """(construction vector, held-out vector): the simulator's subject over ``n_frames`` even frames and as
    many odd frames in between, in :mod:`identcheck.plan.tree_kinematics`'s layout."""
    L = K.Layout(spec)
    sim = simulate(model, n_frames=2 * n_frames, rate_hz=20.0, seed=seed)
    x = K.from_truth(L, sim.truth)
    const, frames = L.split(x, 2 * n_frames)
    return (np.concatenate([const, frames[0::2].ravel()]), np.concatenate([const, frames[1::2].ravel()]))


def witnesses(model, spec, plan, seed: int = 0, progress=None, max_seconds: float | None = None) -> dict:
    """joint -> witness dict (``verified`` true) or a dict saying what the search found, for every joint the
    plan does not identify. Searches run within ``max_seconds`` (default :data:`BUDGET_S`) of the call (the
    simulated trial included; a search under way stops there too: its joint's Gauss-Newton runs had gone on
    past 120 s on a 20-segment chain with a 5 s budget); the joints left are answered ``"method": "not_searched"``
    with the budget named."""
    budget = BUDGET_S if max_seconds is None else float(max_seconds)
    start = time.monotonic()
    todo = [n for n, j in plan.joints.items() if not j["identifiable"]]
    if not todo:
        return {}
    F = max(MIN_FRAMES, 2 * plan.rank.frames)
    truth, held = simulated_truth(model, spec, F, seed)
    case_points = {n: (st.parent_points, st.child_points) for n, st in plan.settled.items()}
    judged = tuple((n, jr.points) for n, jr in plan.rank.joints.items())
    out, memo = {}, {}
    if not any(spec.markers.values()):
        return {n: {"joint": n, "method": None, "verified": False, "found": None,
                    "note": "the plan has no markers: there is no trial for a second skeleton to reproduce"}
                for n in todo}
    for k, name in enumerate(todo):
        j = plan.joints[name]
        if time.monotonic() - start > budget:
            out[name] = {"joint": name, "method": "not_searched", "verified": False, "found": None,
                         "note": f"not searched: the witness searches stopped at their budget of {budget:g} s "
                                 f"(`plan --max-seconds` raises it)"}
            continue
        if progress:
            progress(f"searching for an alternative to {name} ({k + 1} of {len(todo)}, "
                     f"{time.monotonic() - start:.0f} s of at most {budget:g} s)")
        method = "isolated" if j["local"] else "family"
        together = j.get("jointly_only", False)
        via = tuple(j["depends_on"])
        if together:             # its unknown motion is shared: any of those hinges' twins may carry its alternative
            via += tuple(n for n, o in plan.joints.items() if o.get("jointly_only") and n != name
                         and o["type"] == "revolute")
        if not plan.rank.joints[name].quantities:
            out[name] = {"joint": name, "method": None, "verified": False, "found": None,
                         "note": "no marker measures this joint: there is no quantity a second skeleton could change"}
            continue
        search = W.construct(spec, truth, F, name, method, undetermined=plan.rank.joints[name].undetermined,
                             held_out_truth=held, n_held_out=F, via=via, case_points=case_points, judged=judged,
                             n_random=RANDOM_STARTS if together else 0, seed=seed, memo=memo,
                             deadline=start + budget)
        w = search.witness
        if w is not None and w.verified:
            out[name] = w.to_dict()
            continue
        if search.out_of_time:
            out[name] = {"joint": name, "method": "not_searched", "verified": False, "found": None,
                         "note": f"not searched to the end: the witness searches stopped at their budget of {budget:g} "
                                 f"s after {search.attempts} start(s) for this joint (`plan --max-seconds` raises it)"}
            continue
        if method == "isolated" and search.attempts == 0:
            note = ("not searched: no table case with several candidates settles this joint, so there is no "
                    "candidate to start from; how many skeletons generic data admit is not known")
        elif method == "isolated":
            parts = []
            if together:
                twins = search.attempts - RANDOM_STARTS
                parts.append(f"{RANDOM_STARTS} random skeletons" + (f" and {twins} twins of the hinges sharing its "
                                                                    "motion" if twins > 0 else ""))
            if search.back_to_truth:
                parts.append(f"{search.back_to_truth} led back to the true joint")
            if search.closest_miss_mm is not None:
                parts.append(f"Gauss-Newton stalled with markers still {search.closest_miss_mm:.2g} mm or more off")
            if w is not None:
                parts.append(f"one fitted the construction frames but missed held-out frames by "
                             f"{w.held_out_residual_mm:.2g} mm")
            where = "" if together else " at the table case's other candidates"
            note = (f"no whole-tree alternative found from {search.attempts} start(s){where}: {'; '.join(parts)} "
                    "(evidence from one simulated trial, not a proof of uniqueness)")
            if together:
                note += (". Its candidates cannot be counted exactly: no table case settles it, so neither the "
                         "case's count nor the twin certificate (a hinge with two points on one side and a marker "
                         "beyond) applies, and the whole tree's equations over enough frames to pin it are too "
                         "many for exact elimination")
        else:
            note = "the search along the undetermined family failed (the verdict rests on the exact rank alone)"
        out[name] = {"joint": name, "method": method, "verified": False, "attempts": search.attempts,
                     "back_to_truth": search.back_to_truth,
                     "closest_miss_mm": search.closest_miss_mm, "found": None if w is None else w.to_dict(),
                     "note": note}
    return out
