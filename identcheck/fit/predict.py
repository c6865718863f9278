"""Practical verdicts before capture (``identcheck plan MODEL --noise-mm SIGMA --motion NAME``): how well would
this marker plan determine each joint, with this motion and this noise?

The plan's skeleton is simulated without noise for the named motion; the whole-tree fit of ``fit`` is run on
it from every closed-form candidate. At the truth the fit's information ``S`` (per unit noise variance,
per-frame unknowns profiled out) gives each marker distance's predicted standard error ``σ √(gᵀ S⁺ g)``, and
each other minimum the fit finds (an ERRATA E1 twin, a mirror image) gives the expected likelihood-ratio
statistic against the truth, its noncentrality ``λ = ΔRSS / σ²``: with real noise it is rejected at the 95 %
level with probability ``P(χ²₁(λ) > 3.84)``, and never when it ties exactly (:data:`TIE_RSS_MM2`, or when the
exact structural verdict proves that the joint has that many candidates for any rigid data, ``exact_candidates``:
then its ``c − 1`` closest rivals are those twins, whatever the noise-free fit's convergence left). The
verdicts follow ``fit``'s rules: ``undetermined`` when a direction is free or a predicted interval is wider than
±10 mm; ``ambiguous`` when another joint would be rejected with probability below 95 %; ``determined``
otherwise. White noise is assumed: serially correlated noise and skin motion widen real intervals beyond these.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.special import chndtr

from identcheck.bundle.honest import posed_by_itself, same_distances
from identcheck.bundle.practical import TOLERANCE_MM, Z95
from identcheck.bundle.uncertainty import distance_gradients
from identcheck.errors import InputError
from identcheck.fit.whole_tree import REJECT_CHI2
from identcheck.fit.workflow import fit_closed_then_tree
from identcheck.simulate.rigid import simulate

MOTIONS = {"functional": {"rom_deg": 60.0, "n_axes": None}, "flexion": {"rom_deg": 60.0, "n_axes": 1},
           "small": {"rom_deg": 15.0, "n_axes": None}}
"""Named motions: every joint through ±30° about each of its axes (``functional``), about one axis only
(``flexion``), or through ±7.5° (``small``)."""
POWER = 0.95
TIE_RSS_MM2 = 1e-3
"""A rival that fits the noise-free capture within this of the truth (mm², summed over every sample: what the
noise-free fits' convergence leaves; the minimal leg's twins are below 5e-4) ties exactly: it reproduces every
capture as well as the truth (an ERRATA E1 twin: any rigid data admit both), so its likelihood-ratio statistic is
about 0 whatever the noise and no capture rejects it (measured: none of 100 noisy captures of the minimal leg
rejected its three, ``benchmarks/bench_plan_prediction.py --rivals``). The noncentral χ²₁ law, which would say
5 %, holds for rivals the noise-free capture already tells apart."""


STARTS_BUDGET_S = 600.0
"""Seconds the noise-free fit may go on starting candidates (``fit`` itself stops at 90 s): the rivals a plan
reports are the minima those starts reach, so each one-joint change of the candidates should be fitted. Pham's
body at 1000 frames tried 6 of its 16 first starts in 90 s, and the twins of its right knee and of its elbows
went unreported. The number of starts stays capped (:data:`identcheck.bundle.starts.MAX_STARTS`, or one per
one-joint change), each one bounded in time; the one-joint changes left out are said (``rivals_note``)."""


def motion_problem(motion: str) -> str:
    """'' when `motion` names one of :data:`MOTIONS` or an existing recorded trial (.trc, .c3d), else what is wrong:
    checked with the arguments, before any analysis (``plan`` and ``batch``)."""
    import os

    if motion in MOTIONS:
        return ""
    if str(motion).lower().endswith((".trc", ".c3d")):
        return "" if os.path.isfile(motion) else f"--motion {motion}: no such trial file"
    return f"--motion {motion}: one of {', '.join(MOTIONS)}, or a recorded trial (.trc, .c3d)"


def noise_free_fit(model, motion: str = "functional", n_frames: int = 1000, seed: int = 0, progress=None):
    """(the noise-free simulated capture of `model` under `motion`, the whole-tree fit of it from every candidate
    start): the truth the prediction linearises at (its best fit reproduces the simulator's skeleton)."""
    if motion not in MOTIONS:
        raise InputError([f"--motion {motion!r}: one of {', '.join(MOTIONS)}"])
    sim = simulate(model, n_frames=n_frames, noise_mm=0.0, seed=seed, **MOTIONS[motion])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, _, tree = fit_closed_then_tree(model, sim.trial, progress=progress, starts_budget_s=STARTS_BUDGET_S)
    return sim, tree


MAX_NOISE_MM = 1000.0
"""The largest marker noise a prediction is made for: a metre is beyond any capture system (at 1e300 mm a prediction
had printed a 300-digit standard error)."""


def predict(model, noise_mm: float, motion: str = "functional", n_frames: int = 1000, seed: int = 0,
            fitted=None, exact_candidates: dict | None = None) -> dict:
    """joint -> predicted ``practical`` dict (see the module docstring) for `model` under `motion`; `fitted`:
    :func:`noise_free_fit`'s output for the same arguments when the caller has it already; `exact_candidates`:
    joint -> the number of joints that explain any rigid data of the plan equally well, by the exact structural
    verdict (``plan``'s ``candidates``: ERRATA E1's four for a revolute (2,1) with nothing beyond it). A
    joint's closest rivals, that many minus one, tie exactly: on 200 noise-free frames of the minimal leg two of
    the knee's three twins were still 1.4 mm² above the truth after 2000 iterations, crawling along the roll of a
    thigh posed by two points, and would have been called rejected 22 % of the time."""
    if not (0 < noise_mm <= MAX_NOISE_MM):
        raise InputError([f"--noise-mm {noise_mm}: a positive noise level in mm per coordinate, at most "
                          f"{MAX_NOISE_MM:g} (no capture system's markers are a metre off)"])
    sim, tree = fitted if fitted is not None else noise_free_fit(model, motion, n_frames, seed)
    if tree.best is None:
        return {j: {"verdict": "undetermined", "reason": f"no whole-tree fit of the simulated trial: {tree.problem}",
                    "predicted": True, "noise_mm": noise_mm, "motion": motion, "frames": n_frames}
                for j in model.joints}
    best = tree.best
    chain = best.fit.chain
    Sinv = best.cov.inverse                      # per unit noise variance: scaled below by the noise asked about
    grads = distance_gradients(chain, best.fit.state, len(Sinv))
    out = {}
    for j in chain.joints:
        se = {m: noise_mm * float(np.sqrt(max(g @ Sinv @ g, 0.0))) for m, (_, g) in grads[j].items()}
        free = [m for m, (_, g) in grads[j].items() if best.cov.free(g)]
        rivals = []
        twins = max(int((exact_candidates or {}).get(j) or 1) - 1, 0)
        differing = sorted((m for m, _, _ in tree.others if not same_distances(m, best, [j])), key=lambda m: m.fit.rss)
        for k, m in enumerate(differing):
            gap = max(m.fit.rss - best.fit.rss, 0.0)
            lam = gap / noise_mm ** 2
            tie = gap <= TIE_RSS_MM2 or k < twins
            rivals.append({"marker_distances": {k_: round(v[0], 2) for k_, v in m.distances[j].items()},
                           "expected_delta_chi2": round(lam, 3), "ties_exactly": tie,
                           "rejection_probability": 0.0 if tie else
                           round(1.0 - float(chndtr(REJECT_CHI2, 1, max(lam, 1e-12))), 3)})
        worst = max(se.items(), key=lambda kv: kv[1]) if se else (None, 0.0)
        if free:
            verdict, why = "undetermined", f"the motion leaves {', '.join(free)}'s distances free"
        elif Z95 * worst[1] > TOLERANCE_MM:
            verdict, why = "undetermined", f"{worst[0]}'s distance would be ±{Z95 * worst[1]:.1f} mm (95 %)"
            if not posed_by_itself(chain, chain.parent[j], best.fit):
                why += (f"; {chain.parent[j]} is not posed by its own markers, so its roll in every frame is seen only "
                        "through this joint and fit will report the distances unbounded")
        elif any(r["rejection_probability"] < POWER for r in rivals):
            weak = min(r["rejection_probability"] for r in rivals)
            verdict, why = "ambiguous", (f"another joint fits as well unless the noise happens to favour the truth: "
                                         f"rejected with probability {weak:.2f} at the 95 % level")
        else:
            verdict, why = "determined", f"every marker distance within ±{Z95 * worst[1]:.2g} mm (95 %)"
        out[j] = {"verdict": verdict, "reason": why, "predicted": True, "noise_mm": noise_mm, "motion": motion,
                  "frames": n_frames, "predicted_se_mm": {m: round(v, 4) for m, v in se.items()},
                  "rivals": rivals}
        if tree.one_joint_left_out:
            out[j]["rivals_note"] = (f"{tree.one_joint_left_out} of the {tree.one_joint_starts} starts at one joint's "
                                     f"other candidates were not fitted within {STARTS_BUDGET_S:g} s: rivals reached "
                                     "only from those are not listed (fewer --frames fit faster)")
    return out
