"""What ``diagnose`` names on trials that hold no effect at all: this tree against an earlier commit, on the same
trials, in one run.

Each trial is the bundled diagnose leg (`examples/diagnose_leg.toml`) simulated without noise, then given noise of
a standard deviation drawn from 0.3-1.5 mm: white on even seeds, AR(1) with a lag-1 coefficient drawn from 0.5-0.9
on odd ones (a filtered export's). Every effect named is a false alarm. Both versions diagnose every trial, each in
one process of its own with one BLAS thread, the two processes side by side; the rows keep what each named, where,
and its CPU seconds. Prints a table (trials with any effect named, by noise and by effect) and writes
``results.json[--key]``.

    python benchmarks/bench_clean_false_alarms.py --baseline 77dc02a [--trials 480] [--frames 1500]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from collections import Counter
from contextlib import nullcontext
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_io  # noqa: E402
import worktree  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "examples" / "diagnose_leg.toml"
ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "IDENTCHECK_THREADS")}
RUN = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
from identcheck.api import diagnose
rows = []
for trial in json.load(open(sys.argv[2])):
    t0 = time.process_time()
    d = diagnose(sys.argv[1], trial["path"]).to_dict()
    rows.append({"seed": trial["seed"], "named": [e["name"] for e in d["effects"]],
                 "where": [{k: v for k, v in e["where"].items() if not isinstance(v, float)} for e in d["effects"]],
                 "cpu_s": time.process_time() - t0})
json.dump(rows, open(sys.argv[3], "w"))
"""


def make_trials(folder: Path, n: int, frames: int, first_seed: int) -> list:
    """`n` clean trials written as TRC files in `folder`: [{seed, path, sigma_mm, phi}]."""
    from identcheck.effects.time_offset import ar1_noise
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate

    model = Model.from_toml(MODEL)
    out = []
    for seed in range(first_seed, first_seed + n):
        rng = np.random.default_rng([seed, 17])
        sigma = float(rng.uniform(0.3, 1.5))
        phi = 0.0 if seed % 2 == 0 else float(rng.uniform(0.5, 0.9))
        trial = simulate(model, n_frames=frames, noise_mm=0.0, seed=seed).trial
        xyz = trial.as_array()
        path = folder / f"clean_{seed}.trc"
        trial.replace(xyz=xyz + ar1_noise(rng, xyz.shape, sigma, phi)).to_file(path)
        out.append({"seed": seed, "path": str(path), "sigma_mm": sigma, "phi": phi})
    return out


def run_both(trials_json: Path, codes: dict, tmp: Path) -> dict:
    """Each version's rows ({label: rows}), the versions' processes run side by side."""
    procs = {}
    for label, code in codes.items():
        out = tmp / f"{label}.json"
        env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
        procs[label] = (subprocess.Popen([sys.executable, "-c", RUN, str(MODEL), str(trials_json), str(out)],
                                         cwd=code, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE), out)
    rows = {}
    for label, (proc, out) in procs.items():
        err = proc.stderr.read().decode(errors="replace")
        if proc.wait() != 0 or not out.exists():
            raise SystemExit(f"{label}: diagnose failed: {err.strip().splitlines()[-1:] or 'no output'}")
        rows[label] = json.loads(out.read_text())
    return rows


def summarise(trials: list, rows: list) -> dict:
    """Trials with any effect named (all, white, AR(1)), and how often each effect was named."""
    noise = {t["seed"]: ("white" if t["phi"] == 0.0 else "ar1") for t in trials}
    out = {"trials": len(rows), "with_an_effect": sum(bool(r["named"]) for r in rows),
           "by_effect": dict(Counter(name for r in rows for name in r["named"])),
           "cpu_s": float(sum(r["cpu_s"] for r in rows))}
    for kind in ("white", "ar1"):
        mine = [r for r in rows if noise[r["seed"]] == kind]
        out[kind] = {"trials": len(mine), "with_an_effect": sum(bool(r["named"]) for r in mine)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default=None, help="the commit to compare with (none: this tree alone)")
    ap.add_argument("--trials", type=int, default=480)
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=1000, help="the first trial's seed")
    ap.add_argument("--key", default="diagnose_clean_false_alarms")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp, (worktree.checkout(a.baseline) if a.baseline else nullcontext()) as base:
        tmp = Path(tmp)
        trials = make_trials(tmp, a.trials, a.frames, a.seed)
        (tmp / "trials.json").write_text(json.dumps(trials))
        codes = {"current": ROOT, **({"baseline": base} if a.baseline else {})}
        rows = run_both(tmp / "trials.json", codes, tmp)
    summary = {label: summarise(trials, r) for label, r in rows.items()}
    print(f"{'':10s} {'trials':>7s} {'named any':>10s} {'white':>9s} {'AR(1)':>9s} {'CPU s':>8s}  effects named")
    for label, s in summary.items():
        print(f"{label:10s} {s['trials']:7d} {s['with_an_effect']:10d} {s['white']['with_an_effect']:4d}/"
              f"{s['white']['trials']:<4d} {s['ar1']['with_an_effect']:4d}/{s['ar1']['trials']:<4d} "
              f"{s['cpu_s']:8.1f}  {s['by_effect'] or '-'}")
    for label, r in rows.items():
        for row in r:
            if row["named"]:
                print(f"  {label} seed {row['seed']}: {row['named']} {row['where']}")
    results_io.write_json(a.out, a.key, {
        "machine": results_io.machine_info(), "current": worktree.head(), "baseline": a.baseline,
        "trials": a.trials, "frames": a.frames, "first_seed": a.seed, "summary": summary,
        "noise": [{k: t[k] for k in ("seed", "sigma_mm", "phi")} for t in trials], "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
