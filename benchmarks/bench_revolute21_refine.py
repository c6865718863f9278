"""Benchmark of the revolute (2,1) least squares on noisy samples (:func:`identcheck.estimate.revolute21.fit`): the
current code beside a baseline commit's, on the same random problems in one run.

Each problem: a random true hinge (d, r, α, l, ρ), ``--samples`` noisy samples of its child marker seen from the
two parent markers (the thigh roll θ uniform, the hinge angle β over a range drawn per problem, narrow to wide),
noise 0.1, 0.5 or 1.5 mm. Both versions get the same samples and the same budget (``max_nfev``, as ``fit`` passes
it). Per version: CPU seconds per problem, the best joint's RMS distance, and how often it is at least as good
as the truth's own (the least squares' minimum cannot be worse than the truth; a start in the wrong basin can).
Beside each other: how often the current best is worse or better than the baseline's (by more than 0.01 %).

The baseline's module is loaded from ``git show REV:identcheck/estimate/revolute21.py`` (it imports only the
closed form, :mod:`identcheck.solve.revolute21`, which both share).

Run from the repository root::

    PYTHONPATH=. python3 benchmarks/bench_revolute21_refine.py --baseline bec206c          # about 3 minutes
    PYTHONPATH=. python3 benchmarks/bench_revolute21_refine.py --baseline bec206c --quick  # writes nothing

Results: ``benchmarks/results.json`` under ``"revolute21_refine"`` (or ``--key``).
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from results_io import machine_info, write_json  # noqa: E402
from identcheck.estimate import revolute21 as current  # noqa: E402
from strategies import revolute21_samples  # noqa: E402

NOISE_MM = (0.1, 0.5, 1.5)
BETTER = 1e-4          # relative RMS difference counted as better / worse


def baseline_module(rev: str):
    """The baseline commit's ``identcheck/estimate/revolute21.py``, imported under another name."""
    source = subprocess.run(["git", "show", f"{rev}:identcheck/estimate/revolute21.py"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "baseline_revolute21.py"
        path.write_text(source)
        spec = importlib.util.spec_from_file_location("baseline_revolute21", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    return module


def problems(n: int, samples: int, seed: int) -> list:
    """(truth, noise, local samples) for `n` random problems."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        truth = np.r_[rng.uniform(-100, 100), rng.uniform(5, 150), rng.uniform(0.1, np.pi - 0.1),
                      rng.uniform(-150, 150), rng.uniform(20, 200)]
        noise = float(rng.choice(NOISE_MM))
        theta = rng.uniform(-np.pi, np.pi, samples)
        beta = rng.uniform(-rng.uniform(0.3, 3.0), 1.2, samples)
        out.append((truth, noise, revolute21_samples(truth, theta, beta) + rng.normal(scale=noise, size=(samples, 3))))
    return out


def run(module, probs: list, max_nfev: int) -> list:
    """Per problem: (CPU seconds, best RMS, the truth's RMS)."""
    rows = []
    for truth, _, local in probs:
        R, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
        t = time.process_time()
        sols = module.fit(local, max_nfev=max_nfev)
        seconds = time.process_time() - t
        best = sols[0][1] if sols else float("inf")
        rows.append((seconds, float(best), float(np.sqrt(np.mean(current.residuals(truth, R, z) ** 2)))))
    return rows


def summary(rows: list) -> dict:
    sec = np.array([r[0] for r in rows])
    return {"cpu_s_per_problem_median": round(float(np.median(sec)), 4),
            "cpu_s_per_problem_mean": round(float(np.mean(sec)), 4),
            "cpu_s_total": round(float(np.sum(sec)), 2),
            "as_good_as_truth": int(sum(r[1] <= r[2] * (1 + 1e-9) for r in rows))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", required=True, help="commit whose revolute (2,1) least squares to compare with")
    ap.add_argument("--problems", type=int, default=120)
    ap.add_argument("--samples", type=int, default=400, help="samples per problem (fit's closed-form start uses 400)")
    ap.add_argument("--max-nfev", type=int, default=100, help="evaluations per refinement (fit's start uses 100)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="12 problems; writes nothing")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--key", default="revolute21_refine")
    ap.add_argument("--note", default=None, help="a sentence on what was compared, kept with the numbers")
    a = ap.parse_args(argv)
    n = 12 if a.quick else a.problems
    probs = problems(n, a.samples, a.seed)
    base = baseline_module(a.baseline)
    # the two versions take turns problem by problem, so that the machine's drift falls on both alike
    rows_cur, rows_base = [], []
    for k, prob in enumerate(probs):
        rows_base += run(base, [prob], a.max_nfev)
        rows_cur += run(current, [prob], a.max_nfev)
        print(f"[{k + 1}/{n}] noise {prob[1]} mm: best RMS {rows_base[-1][1]:.4f} -> {rows_cur[-1][1]:.4f} "
              f"(truth {rows_cur[-1][2]:.4f}), {rows_base[-1][0]:.3f} -> {rows_cur[-1][0]:.3f} s", flush=True)
    worse = [k for k in range(n) if rows_cur[k][1] > rows_base[k][1] * (1 + BETTER)]
    better = [k for k in range(n) if rows_cur[k][1] < rows_base[k][1] * (1 - BETTER)]
    ratio = [rows_cur[k][1] / rows_base[k][1] for k in worse]
    current_code = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                  text=True).stdout.strip() or None
    out = {"baseline": a.baseline, "current": current_code, "note": a.note, "problems": n, "samples": a.samples,
           "max_nfev": a.max_nfev, "seed": a.seed,
           "noise_mm": list(NOISE_MM), "machine": machine_info(),
           "baseline_code": summary(rows_base), "current_code": summary(rows_cur),
           "current_worse": len(worse), "current_better": len(better),
           "worse_rms_ratio_max": round(max(ratio), 4) if ratio else None,
           "worse_noise_mm": [probs[k][1] for k in worse]}
    b, c = out["baseline_code"], out["current_code"]
    print(f"{'':<10} {'CPU s/problem (median)':>24} {'total s':>8} {'as good as truth':>17}")
    print(f"{'baseline':<10} {b['cpu_s_per_problem_median']:>24} {b['cpu_s_total']:>8} {b['as_good_as_truth']:>13}/{n}")
    print(f"{'current':<10} {c['cpu_s_per_problem_median']:>24} {c['cpu_s_total']:>8} {c['as_good_as_truth']:>13}/{n}")
    print(f"current best worse than the baseline's on {len(worse)}, better on {len(better)} of {n} "
          f"(worst ratio {out['worse_rms_ratio_max']}, noise of the worse: {out['worse_noise_mm']})")
    if not a.quick:
        write_json(a.out, a.key, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
