"""Does ``plan --noise-mm`` predict what ``fit`` will deliver? Its predicted standard error of every marker distance
(the Cramér–Rao bound from the whole-tree information at the simulated truth) beside the spread of the
maximum-likelihood estimate over many noisy captures of the same motion, in one run.

For each plan: the plan's skeleton is simulated noise-free for the named motion (``fit.predict.noise_free_fit``,
what ``plan`` itself linearises at); ``plan``'s prediction is computed from it; then ``--trials`` captures add
fresh white noise of ``--noise-mm`` to every visible coordinate, and each is fitted by the whole-tree
Levenberg-Marquardt ``fit`` runs, to convergence as ``fit`` does (``bundle.converge.converged_fit``), started
at the truth so that the spread measured is the estimator's around the true joint and not a jump to another
candidate (the multi-start and the verdict rules of ``fit`` are not re-run; the twins are ``plan``'s rejection
probabilities, not measured here). Reported per plan: for every joint-marker distance the ratio predicted SE /
Monte-Carlo SD, its median and range, and how many lie within 25 %; the Monte-Carlo SD's own sampling error is
±1/sqrt(2(N-1)) (±7 % at N = 100). A figure plots predicted against Monte-Carlo. Writes key ``plan_prediction`` of
benchmarks/results.json.

    PYTHONPATH=. python3 benchmarks/bench_plan_prediction.py [--trials 100] [--frames 500] [--noise-mm 1]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from tabulate import tabulate
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from identcheck.bundle.uncertainty import distance_gradients  # noqa: E402
from identcheck.fit.predict import noise_free_fit, predict  # noqa: E402
from identcheck.bundle.converge import converged_fit  # noqa: E402
from identcheck.io.model import Model  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402

SPARSE_LEG = (ROOT / "examples" / "sparse_leg.toml").read_text()
KNEE_22 = SPARSE_LEG.replace('markers = ["RTHI"]', 'markers = ["RTH1", "RTH2"]').replace(
    'markers = ["RTIB"]', 'markers = ["RTB1", "RTB2"]')
"""The bundled minimal leg with two thigh and two shank markers: a 2+2 knee below a 3-marker pelvis."""
PLANS = {"2+2 knee": KNEE_22, "minimal leg": "examples/sparse_leg.toml",
         "Plug-in Gait lower limb": "examples/pig_lower_limb.toml", "body16": "examples/body16.toml"}
BAND = 0.25


def _model(spec: str) -> Model:
    if "\n" in spec:                                 # the model's TOML text itself
        import tomllib

        return Model.from_dict(tomllib.loads(spec), source="inline plan")
    return Model.from_toml(ROOT / spec)


def distances(chain, state, n_params: int) -> dict:
    """(joint, marker) -> distance, mm, of a fitted state."""
    return {(j, m): d for j, by in distance_gradients(chain, state, n_params).items()
            for m, (d, _) in by.items()}


def run_plan(name: str, model: Model, trials: int, frames: int, noise_mm: float, motion: str, seed: int) -> dict:
    t0 = time.perf_counter()
    fitted = noise_free_fit(model, motion, frames, seed)
    sim, tree = fitted
    best = tree.best
    chain, truth_state = best.fit.chain, best.fit.state
    pred = predict(model, noise_mm, motion, frames, seed, fitted=fitted)
    n_params = len(best.cov.information)
    labels = [chain.labels[i] for i in range(chain.n_markers)]
    clean = sim.trial.select(labels).as_array()
    truth = distances(chain, truth_state, n_params)
    rng = np.random.default_rng(seed + 1)
    draws = {k: [] for k in truth}
    for _ in range(trials):
        noisy = clean + rng.normal(0.0, noise_mm, clean.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = converged_fit(chain, noisy, truth_state)
        for k, d in distances(chain, fit.state, n_params).items():
            draws[k].append(d)
    rows = []
    for (j, m), values in draws.items():
        se = pred[j]["predicted_se_mm"].get(m)
        sd = float(np.std(values, ddof=1))
        rows.append({"joint": j, "marker": m, "predicted_se_mm": se, "monte_carlo_sd_mm": round(sd, 4),
                     "bias_mm": round(float(np.mean(values)) - truth[(j, m)], 4),
                     "ratio": None if not sd else round(se / sd, 3)})
    ratios = np.array([r["ratio"] for r in rows if r["ratio"] is not None])
    return {"plan": name, "joints": len(chain.joints), "distances": len(rows), "trials": trials, "frames": frames,
            "noise_mm": noise_mm, "motion": motion,
            "ratio_median": round(float(np.median(ratios)), 3), "ratio_min": round(float(ratios.min()), 3),
            "ratio_max": round(float(ratios.max()), 3),
            "within_25pct": int(np.sum(np.abs(ratios - 1) <= BAND)), "seconds": round(time.perf_counter() - t0, 1),
            "verdicts": {j: pred[j]["verdict"] for j in pred}, "rows": rows}


def run_marker_value(name: str, model: Model, trials: int, frames: int, noise_mm: float, motion: str,
                     seed: int) -> dict:
    """``plan``'s one-more-marker predictions (:mod:`identcheck.fit.marker_value`) against Monte Carlo: for every
    segment, the plan with the added marker is captured ``trials`` times with fresh noise (the enlarged truth's
    trajectories, the added marker's included) and fitted to convergence from that truth; every distance's
    predicted standard error against the fits' spread, and each joint's predicted widest 95 % half-width against
    1.96 × the widest measured spread."""
    from identcheck.fit.marker_value import enlarged_information, marker_value, standard_errors

    t0 = time.perf_counter()
    _, tree = noise_free_fit(model, motion, frames, seed)
    fit = tree.best.fit
    ranked = marker_value(model, fit, noise_mm)
    rng = np.random.default_rng(seed + 2)
    out = []
    for sugg in ranked:
        chain, state, clean, S = enlarged_information(model, fit, sugg["segment"])
        se = standard_errors(chain, state, S, noise_mm)
        truth = distances(chain, state, len(S))
        draws = {k: [] for k in truth}
        for _ in range(trials):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fitted = converged_fit(chain, clean + rng.normal(0.0, noise_mm, clean.shape), state)
            for k, d in distances(chain, fitted.state, len(S)).items():
                draws[k].append(d)
        rows = [{"joint": j, "marker": m, "predicted_se_mm": round(se[j][m], 4),
                 "monte_carlo_sd_mm": round(float(np.std(v, ddof=1)), 4),
                 "ratio": round(se[j][m] / float(np.std(v, ddof=1)), 3)} for (j, m), v in draws.items()]
        widest = {j: max(r["monte_carlo_sd_mm"] for r in rows if r["joint"] == j) for j in se}
        out.append({"segment": sugg["segment"], "mm_saved": sugg["mm_saved"],
                    "joints": {j: {"predicted_after_mm": v["after_mm"], "before_mm": v["before_mm"],
                                   "monte_carlo_after_mm": round(1.96 * widest[j], 2)}
                               for j, v in sugg["joints"].items()},
                    "within_25pct": sum(abs(r["ratio"] - 1) <= BAND for r in rows if np.isfinite(r["ratio"])),
                    "distances": len(rows), "rows": rows})
    return {"plan": name, "trials": trials, "frames": frames, "noise_mm": noise_mm, "motion": motion,
            "seconds": round(time.perf_counter() - t0, 1), "suggestions": out}


E8_LEG = SPARSE_LEG + """
[segments.foot_r]
markers = ["RTOE"]
length_mm = 150
[joints.ankle_r]
type = "spherical"
parent = "shank_r"
child = "foot_r"
"""
RIVAL_PLANS = {"minimal leg": "examples/sparse_leg.toml", "E8 leg (one foot marker)": E8_LEG,
               "body16": "examples/body16.toml"}
"""Plans whose hinges have twins: alone (the minimal leg: ERRATA E1, they tie), with one marker beyond them
(ERRATA E8: the foot marker rejects them, given enough frames and little enough noise), and Pham's body, whose
knees and elbows are each decided by one foot or hand marker."""


def run_rivals(name: str, model: Model, trials: int, frames: int, noise_mm: float, motion: str, seed: int) -> dict:
    """plan's rejection probability of every other minimum of the noise-free fit against the rejection rate over
    `trials` noisy captures: each capture fitted from the truth and from the rival, to convergence, and the
    rival rejected when its likelihood-ratio statistic (ΔRSS / σ²) exceeds χ²₁(0.95) = 3.84."""
    from identcheck.bundle.honest import same_distances as _same
    from identcheck.fit.whole_tree import REJECT_CHI2

    t0 = time.perf_counter()
    fitted = noise_free_fit(model, motion, frames, seed)
    sim, tree = fitted
    pred = predict(model, noise_mm, motion, frames, seed, fitted=fitted)
    chain, truth_state = tree.best.fit.chain, tree.best.fit.state
    clean = sim.trial.select(list(chain.labels)).as_array()
    rivals = []
    for m, _, _ in tree.others:
        said = [r for j in pred for r in pred[j]["rivals"]
                if all(abs(r["marker_distances"][k] - round(v[0], 2)) < 0.02 for k, v in m.distances[j].items())]
        if said:
            rivals.append((m, said[0]))
    rng = np.random.default_rng(seed + 2)
    stats = [[] for _ in rivals]
    for _ in range(trials):
        noisy = clean + rng.normal(0.0, noise_mm, clean.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            base = converged_fit(chain, noisy, truth_state).rss
            for k, (m, _) in enumerate(rivals):
                stats[k].append((converged_fit(chain, noisy, m.fit.state).rss - base) / noise_mm ** 2)
    rows = []
    for (m, said), st in zip(rivals, stats):
        st = np.array(st)
        rate = float(np.mean(st > REJECT_CHI2))
        rows.append({"joints": [j for j in chain.joints if not _same(m, tree.best, [j])],
                     "predicted_delta_chi2": said["expected_delta_chi2"],
                     "predicted_rejection": said["rejection_probability"],
                     "monte_carlo_rejection": round(rate, 3),
                     "monte_carlo_mean_delta_chi2": round(float(np.mean(st)), 3),
                     "binomial_se": round(float(np.sqrt(max(rate * (1 - rate), 1e-4) / trials)), 3)})
    return {"plan": name, "trials": trials, "frames": frames, "noise_mm": noise_mm, "motion": motion,
            "rivals": rows, "seconds": round(time.perf_counter() - t0, 1)}


def figure(results: list, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 5.2))
    ax = fig.subplots()
    top = 0.0
    for k, res in enumerate(results):
        pts = [(r["monte_carlo_sd_mm"], r["predicted_se_mm"]) for r in res["rows"] if r["predicted_se_mm"]]
        x, y = np.array(pts).T
        ax.loglog(x, y, "o", ms=4, alpha=0.7, label=f"{res['plan']} ({res['within_25pct']}/{res['distances']} within 25 %)")
        top = max(top, x.max(), y.max())
    lo = min(min(r["monte_carlo_sd_mm"] for r in res["rows"] if r["monte_carlo_sd_mm"] > 0) for res in results)
    line = np.array([lo / 1.5, top * 1.5])
    ax.plot(line, line, "k-", lw=0.8, label="predicted = Monte Carlo")
    ax.fill_between(line, line * (1 - BAND), line * (1 + BAND), color="0.85", label="±25 %")
    ax.set_xlabel(f"Monte-Carlo SD of the fitted distance (mm, {results[0]['trials']} captures)")
    ax.set_ylabel("plan's predicted standard error (mm)")
    ax.set_title(f"plan --noise-mm {results[0]['noise_mm']} --motion {results[0]['motion']}: every joint-marker distance",
                 fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def earlier_results(path: Path, plans) -> list:
    """The stored results of the plans not run this time (``--plans`` a subset: the others are kept, each with its
    own trials, frames, noise and motion)."""
    try:
        stored = json.loads(path.read_text()).get("plan_prediction", {})
    except (OSError, json.JSONDecodeError):
        return []
    return [r for r in stored.get("results", []) if r.get("plan") not in plans]


def _run_each(a, names, plans: dict, runner, key: str, rows_of, headers) -> None:
    """``runner`` on each named plan with one BLAS thread: its table printed, the results so far written under ``key``."""
    out = []
    with threadpool_limits(1):
        for name in names:
            res = runner(name, _model(plans[name]), a.trials, a.frames, a.noise_mm, a.motion, a.seed)
            out.append(res)
            print(tabulate(rows_of(name, res), headers=headers), flush=True)
            write_json(Path(a.out), key, {"machine": machine_info(), "results": out})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--frames", type=int, default=500)
    ap.add_argument("--noise-mm", type=float, default=1.0)
    ap.add_argument("--motion", default="functional")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--plans", nargs="*", default=list(PLANS))
    ap.add_argument("--rival-plans", nargs="*", default=list(RIVAL_PLANS))
    ap.add_argument("--rivals", action="store_true",
                    help="instead: the rivals' rejection, predicted against Monte Carlo (key plan_prediction_rivals_N_frames)")
    ap.add_argument("--marker-value", action="store_true",
                    help="instead: one more marker on each segment, predicted against Monte Carlo (key "
                         "plan_prediction_marker_value)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results.json"))
    ap.add_argument("--figure", default=str(ROOT / "benchmarks" / "plan_prediction.png"))
    a = ap.parse_args(argv)
    if a.marker_value:
        _run_each(a, a.plans, PLANS, run_marker_value, "plan_prediction_marker_value",
                  lambda name, res: [[name, s["segment"], s["mm_saved"], j, v["before_mm"], v["predicted_after_mm"],
                                      v["monte_carlo_after_mm"], f"{s['within_25pct']}/{s['distances']}"]
                                     for s in res["suggestions"] for j, v in s["joints"].items()],
                  ["plan", "added on", "mm saved", "joint", "before ±mm", "predicted after ±mm", "MC after ±mm",
                   "SE within 25 %"])
        return
    if a.rivals:
        _run_each(a, a.rival_plans, RIVAL_PLANS, run_rivals, f"plan_prediction_rivals_{a.frames}_frames",
                  lambda name, res: [[name, ", ".join(r["joints"]), r["predicted_delta_chi2"], r["monte_carlo_mean_delta_chi2"],
                                      r["predicted_rejection"], f"{r['monte_carlo_rejection']} ± {r['binomial_se']}"]
                                     for r in res["rivals"]],
                  ["plan", "differs in", "predicted Δχ²", "MC mean Δχ²", "predicted P(reject)", "MC rejection rate"])
        return
    results = earlier_results(Path(a.out), a.plans)
    with threadpool_limits(1):
        for name in a.plans:
            res = run_plan(name, _model(PLANS[name]), a.trials, a.frames, a.noise_mm, a.motion, a.seed)
            results.append(res)
            results.sort(key=lambda r: list(PLANS).index(r["plan"]) if r["plan"] in PLANS else len(PLANS))
            write_json(Path(a.out), "plan_prediction", {"machine": machine_info(), "results": results})
            print(f"{name}: {res['distances']} distances, predicted/MC median {res['ratio_median']} "
                  f"[{res['ratio_min']}, {res['ratio_max']}], {res['within_25pct']} within 25 %, {res['seconds']} s",
                  flush=True)
    print()
    print(tabulate([[r["plan"], r["joints"], r["distances"], r["ratio_median"], r["ratio_min"], r["ratio_max"],
                     f"{r['within_25pct']}/{r['distances']}", r["seconds"]] for r in results],
                   headers=["plan", "joints", "distances", "predicted/MC median", "min", "max", "within 25 %", "s"]))
    figure(results, Path(a.figure))
    write_json(Path(a.out), "plan_prediction", {"machine": machine_info(), "results": results})


if __name__ == "__main__":
    main()
