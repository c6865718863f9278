"""Accuracy and speed of ``fit``: the whole-tree maximum-likelihood answer beside the closed-form estimators
that start it (seed 001 for a ball joint with three markers a side, from 500 spread frames; SARA / O'Brien's
single axis for a hinge), seed 001 on every frame, and SCoRE, on the same trials in one run.

Trials: the bundled lower limb (examples/leg.toml: 3 pelvis, 3 thigh, 2 shank, 2 foot markers), 1500 frames
at 100 Hz, 60 deg range of motion, white noise 0.7 mm per coordinate, 30 seeds (a median over a handful of
trials moves by a third from one handful to the next). Reported per joint: the largest marker-distance error
against the truth (median over trials with a bootstrap 95 % interval for that median, and the worst), the share of
marker distances inside fit's own 95 % intervals and the root mean square of error / standard error (1 when the
stated uncertainty is the real one), and CPU seconds of the whole library call (`fit_trial`: label screen, closed-form starts, whole-tree fit, covariance) per joint, with the
allocator setting the command line makes (``--allocator default`` for glibc's own: ``summary_default_allocator``).

With ``--baseline REV`` the speed is also measured side by side with an earlier commit (checked out into a
temporary worktree): the same trials fitted by the current code and by the baseline, each in its own process,
the two processes taking turns for ``--rounds`` rounds, each trial's time the least over its rounds (this
machine's speed drifts by a third within minutes; the least is what the code costs). ``summary`` then holds
``speed_vs_baseline``.

Usage::

    PYTHONPATH=. python benchmarks/bench_fit_accuracy.py [--trials 30] [--frames 1500] [--baseline REV --rounds 3]
        [--first-seed 300 --key fit_accuracy]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from identcheck.cli import keep_freed_memory  # noqa: E402
from identcheck.estimate.score_sara import score  # noqa: E402
from identcheck.estimate.seed001 import fit_centre  # noqa: E402
from identcheck.fit.workflow import fit_trial  # noqa: E402
from identcheck.io.model import Model  # noqa: E402
from identcheck.simulate.rigid import simulate  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402
from worktree import checkout, head  # noqa: E402

TIMES_WORKER = """
import json, sys, time, warnings
from threadpoolctl import threadpool_limits
from identcheck.cli import keep_freed_memory
from identcheck.fit.workflow import fit_trial
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
keep_freed_memory()
model, seeds = Model.from_toml(sys.argv[1]), json.loads(sys.argv[2])
sims = [simulate(model, n_frames=int(sys.argv[3]), noise_mm=float(sys.argv[4]), seed=s) for s in seeds]
out = []
with warnings.catch_warnings(), threadpool_limits(1):
    warnings.simplefilter("ignore")
    fit_trial(model, sims[0].trial)                      # the lazy imports, not timed
    for sim in sims:
        t0 = time.process_time()
        rep = fit_trial(model, sim.trial)
        out.append((time.process_time() - t0) / len(rep["joints"]))
print(json.dumps(out))
"""
"""One process's CPU seconds per joint of ``fit_trial`` on each simulated trial (one BLAS thread): the same script
for the current code and the baseline, so only the library differs."""


def _worker_times(code_root: Path, seeds: list, frames: int, noise_mm: float) -> list:
    env = {**os.environ, "PYTHONPATH": str(code_root)}
    out = subprocess.run([sys.executable, "-c", TIMES_WORKER, str(ROOT / "examples" / "leg.toml"), json.dumps(seeds),
                          str(frames), str(noise_mm)], cwd=code_root, env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def speed_vs_baseline(baseline: str, seeds: list, frames: int, noise_mm: float, rounds: int) -> dict:
    """CPU seconds per joint of the current code and of `baseline` on the same trials, the processes taking turns;
    per trial the least over the rounds, then the median over trials."""
    with checkout(baseline) as base:
        current, old = [], []
        for k in range(rounds):
            print(f"speed round {k + 1} of {rounds}: current, then {baseline}", flush=True)
            current.append(_worker_times(ROOT, seeds, frames, noise_mm))
            old.append(_worker_times(base, seeds, frames, noise_mm))
    cur, bas = np.min(current, axis=0), np.min(old, axis=0)
    return {"baseline": baseline, "current": head(), "rounds": rounds,
            "current_seconds_per_joint": round(float(np.median(cur)), 3),
            "baseline_seconds_per_joint": round(float(np.median(bas)), 3),
            "speed_up": round(float(np.median(bas) / np.median(cur)), 2),
            "per_trial_current": [round(float(x), 3) for x in cur],
            "per_trial_baseline": [round(float(x), 3) for x in bas]}


def _max_err(dist: dict, truth: dict) -> float:
    return max(abs(dist[m] - truth[m]) for m in truth if dist.get(m) is not None)


def _z_scores(joint: dict, truth: dict) -> list:
    """(estimate - truth) / standard error for each marker distance, the standard error read from fit's 95 %
    interval (half-width / 1.96)."""
    out = []
    for m, t in truth.items():
        lo, hi = joint["marker_distances_ci95"].get(m) or (None, None)
        if lo is not None and hi is not None and hi > lo:
            out.append((joint["marker_distances"][m] - t) / ((hi - lo) / (2 * 1.959964)))
    return out


def median_interval(values, draws: int = 4000, seed: int = 0) -> list:
    """A percentile-bootstrap 95 % interval for the median of `values` (trials resampled with replacement)."""
    v = np.asarray(values, float)
    rng = np.random.default_rng(seed)
    medians = np.median(v[rng.integers(0, len(v), (draws, len(v)))], axis=1)
    return [round(float(q), 4) for q in np.quantile(medians, [0.025, 0.975])]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--first-seed", type=int, default=300, help="the trials are simulated with seeds from this one on")
    ap.add_argument("--key", default="fit_accuracy", help="results.json key (another set of seeds: another key)")
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--noise-mm", type=float, default=0.7)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--allocator", choices=("default", "kept"), default="kept",
                    help="kept: the allocator setting the command line makes (identcheck.cli.keep_freed_memory), "
                         "so that the times are what `identcheck fit` spends; default: glibc's own")
    ap.add_argument("--baseline", help="an earlier commit to time side by side with the current code")
    ap.add_argument("--rounds", type=int, default=3, help="turns each of the two processes takes (with --baseline)")
    a = ap.parse_args(argv)
    if a.allocator == "kept":
        keep_freed_memory()
    model = Model.from_toml(ROOT / "examples" / "leg.toml")
    rows = {}
    for seed in range(a.trials):
        sim = simulate(model, n_frames=a.frames, noise_mm=a.noise_mm, seed=a.first_seed + seed)
        with warnings.catch_warnings(), threadpool_limits(1):
            warnings.simplefilter("ignore")
            t0 = time.process_time()
            rep = fit_trial(model, sim.trial)
            secs = time.process_time() - t0
            pelvis = sim.trial.select(model.segments["pelvis"].markers).as_array()
            thigh = sim.trial.select(model.segments["thigh_r"].markers).as_array()
            t0 = time.process_time()
            sc = score(pelvis, thigh)
            score_secs = time.process_time() - t0
            t0 = time.process_time()
            s1 = fit_centre(pelvis, thigh)                     # seed 001 on every frame (fit starts from fewer)
            seed001_secs = time.process_time() - t0
        n_joints = len(rep["joints"])
        for name, j in rep["joints"].items():
            truth = sim.truth.marker_distances(name)
            r = rows.setdefault(name, {"whole_tree": [], "closed_form": [], "closed_form_name": j["start"]["estimator"],
                                       "seconds_per_joint": [], "uncertainty_mm": [], "z": []})
            r["whole_tree"].append(_max_err(j["marker_distances"], truth))
            r["closed_form"].append(_max_err(j["start"]["marker_distances"], truth))
            r["seconds_per_joint"].append(secs / n_joints)
            r["uncertainty_mm"].append(j["uncertainty_mm"])
            r["z"].extend(_z_scores(j, truth))
        hip_truth = sim.truth.marker_distances("hip_r")
        x = sim.trial.as_array()
        col = {m: i for i, m in enumerate(sim.trial.labels)}
        d_score = {m: float(np.nanmedian(np.linalg.norm(x[:, col[m]] - sc.centre_world, axis=1))) for m in hip_truth}
        r = rows["hip_r"].setdefault("score", [])
        r.append(_max_err(d_score, hip_truth))
        rows["hip_r"].setdefault("score_seconds", []).append(score_secs)
        c1 = s1.parent.to_world(s1.centre_parent[None])[:, 0]
        d_seed001 = {m: float(np.nanmedian(np.linalg.norm(x[:, col[m]] - c1, axis=1))) for m in hip_truth}
        rows["hip_r"].setdefault("seed001", []).append(_max_err(d_seed001, hip_truth))
        rows["hip_r"].setdefault("seed001_seconds", []).append(seed001_secs)
    summary = {}
    print(f"{'joint':<8} {'method':<36} {'median max err (mm), 95 % CI':>29} {'worst':>8} {'CPU s / joint':>14}")
    for name, r in rows.items():
        s = {}
        for key, label in (("whole_tree", "whole-tree maximum likelihood"),
                           ("closed_form", f"fit's start: {r['closed_form_name']}"),
                           ("seed001", "seed 001 on every frame"), ("score", "SCoRE")):
            if key not in r:
                continue
            errs = np.array(r[key])
            secs = r["seconds_per_joint"] if key == "whole_tree" else r.get(f"{key}_seconds", [float("nan")])
            s[key] = {"method": label, "median_max_error_mm": round(float(np.median(errs)), 4),
                      "median_ci95_mm": median_interval(errs),
                      "worst_max_error_mm": round(float(errs.max()), 4),
                      "median_cpu_seconds": round(float(np.median(secs)), 3) if key != "closed_form" else None}
            lo, hi = s[key]["median_ci95_mm"]
            print(f"{name:<8} {label[:36]:<36} {np.median(errs):>8.4f} [{lo:.3f}, {hi:.3f}] {errs.max():>8.4f} "
                  f"{'' if key == 'closed_form' else f'{np.median(secs):>14.3f}'}")
        s["median_uncertainty_mm"] = round(float(np.median(r["uncertainty_mm"])), 4)
        z = np.array(r["z"])
        s["interval_coverage"] = round(float(np.mean(np.abs(z) <= 1.959964)), 4)
        s["rms_error_over_se"] = round(float(np.sqrt(np.mean(z ** 2))), 3)
        s["distances"] = int(len(z))
        print(f"{'':<8} {'fit: distances inside their 95 % CI':<36} {s['interval_coverage']:>8.3f} of {len(z)}; "
              f"rms error/SE {s['rms_error_over_se']:.2f}")
        summary[name] = s
    print("CPU seconds of the whole-tree row: the whole fit_trial call divided by the number of joints "
          "(closed-form starts included, whose own time is not separated here).")
    if a.allocator == "kept":
        entry = {"summary": summary, "trials": a.trials, "frames": a.frames, "noise_mm": a.noise_mm,
                 "allocator": a.allocator, "machine": machine_info()}
    else:                                 # beside the main run's entry, whose settings it shares but for this one
        entry = {"summary_default_allocator": summary}
    if a.baseline:
        speed = speed_vs_baseline(a.baseline, [a.first_seed + k for k in range(a.trials)], a.frames, a.noise_mm, a.rounds)
        print(f"CPU s per joint, least of {a.rounds} turns, median over trials: current {speed['current_seconds_per_joint']}"
              f", {a.baseline} {speed['baseline_seconds_per_joint']} ({speed['speed_up']}x)")
        entry["speed_vs_baseline"] = speed
    entry["first_seed"] = a.first_seed
    write_json(a.out, a.key, entry, merge=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
