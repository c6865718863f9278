"""How far the whole-tree fit starts from its minimum on real trials with gaps, and what getting there costs: this
working tree and a baseline commit side by side, in one run.

The whole-tree fit (``fit``, and ``diagnose``'s rigid model) starts from every segment posed by its own markers,
joined by closed-form joint estimates (:func:`identcheck.bundle.chain.initial_state`). A frame a segment's markers
leave unposed takes another frame's pose; where the subject walks on meanwhile (the end of the real walking2 trial,
its pelvis out of view), the markers still seen start far from their predictions and Levenberg-Marquardt spends
iterations undoing it.

For each real trial and model below, each version runs ``identcheck fit``'s own path in a fresh process (one BLAS
thread) up to the first whole-tree fit, which it runs to convergence and then stops (the intervals, profiles and
bootstrap that follow start from the converged fit, not from the start). Reported per version: the start's RMS
marker error over the samples seen (mm) and its worst, the iterations and CPU seconds to convergence, and the cost
reached (mm²; equal costs mean the same minimum). Also ``identcheck fit`` end to end on walking2 (wall and CPU
seconds, the JSON's digest).

Usage::

    PYTHONPATH=. python3 benchmarks/bench_gap_start.py [--baseline COMMIT] [--no-end-to-end]

Results: a printed table and ``benchmarks/results.json["gap_start"]``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
import worktree  # noqa: E402

REAL = ROOT / "examples" / "real"
SHARED = ROOT.parent / "shared" / "data" / "real"
CASES = {
    "walking2_legs": ("examples/real_walking2_legs.toml", REAL / "opensim_walking2.c3d"),
    "walking2_right_leg": ("examples/real/walking2_right_leg.toml", REAL / "opensim_walking2.c3d"),
    "walk1_leg": ("examples/real_walk_leg.toml", REAL / "opensim_subject01_walk1.trc"),
    "biobuddy_hip": ("examples/real_right_hip.toml", SHARED / "biobuddy_right_hip.c3d"),
    "biobuddy_knee": ("examples/real_right_knee.toml", SHARED / "biobuddy_right_knee.c3d"),
}


def _worker(case: str) -> dict:
    """One version's start and first whole-tree fit on `case` (run in a fresh process, its tree on sys.path)."""
    import warnings

    import numpy as np
    from threadpoolctl import threadpool_limits

    import identcheck.fit.whole_tree as W
    from identcheck import api
    from identcheck.bundle.chain import fit_chain
    from identcheck.bundle.model import Terms, forward
    from identcheck.fit.workflow import fit_trial
    from identcheck.io.model import Model

    warnings.simplefilter("ignore")
    model_path, trial_path = CASES[case]
    out: dict = {}

    class Done(Exception):
        pass

    def first_fit(chain, data, state, progress=None, weights=None):
        pred = forward(chain, Terms(), state)[3]
        err = np.linalg.norm(pred - data, axis=2)
        t0 = time.process_time()
        fit = fit_chain(chain, data, state, weights=weights, max_iter=400)
        out.update(start_rms_mm=float(np.sqrt(np.nanmean(err ** 2))), start_max_mm=float(np.nanmax(err)),
                   iterations=int(fit.iterations), converged=bool(fit.converged), cpu_s=time.process_time() - t0,
                   cost_mm2=float(fit.rss))
        raise Done

    W.converged_fit = first_fit
    with threadpool_limits(limits=1):
        try:
            fit_trial(Model.from_toml(Path.cwd() / model_path), api.read_trial(trial_path))
        except Done:
            pass
    return out


def _run_worker(tree: Path, case: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "IDENTCHECK_THREADS": "1"}
    res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", case], cwd=tree, env=env,
                         capture_output=True, text=True, timeout=1800)
    if res.returncode:
        return {"error": res.stderr.strip().splitlines()[-1:] or ["failed"]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def _end_to_end(tree: Path) -> dict:
    """``identcheck fit`` on both legs of walking2, the whole command: wall, CPU, exit code and JSON digest."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "identcheck", "fit", "examples/real_walking2_legs.toml",
                          str(REAL / "opensim_walking2.c3d"), "--json"], cwd=tree, env=env, capture_output=True,
                         text=True, timeout=1800)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"wall_s": wall, "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "exit": res.returncode, "json_sha1": hashlib.sha1(res.stdout.encode()).hexdigest()[:12]}


def table(rows: dict) -> str:
    head = (f"{'case':<20}{'version':<10}{'start rms':>10}{'start max':>10}{'iter':>6}{'cpu s':>8}"
            f"{'cost mm2':>14}")
    lines = [head, "-" * len(head)]
    for case, by in rows.items():
        for version, r in by.items():
            if "error" in r:
                lines.append(f"{case:<20}{version:<10} error: {r['error']}")
                continue
            lines.append(f"{case:<20}{version:<10}{r['start_rms_mm']:>10.1f}{r['start_max_mm']:>10.1f}"
                         f"{r['iterations']:>6}{r['cpu_s']:>8.2f}{r['cost_mm2']:>14.2f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="5a8f4ba", help="commit to compare with (default: before the gap start)")
    ap.add_argument("--no-end-to-end", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--worker", choices=sorted(CASES), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(_worker(args.worker)))
        return 0
    rows: dict = {}
    e2e: dict = {}
    with worktree.checkout(args.baseline) as base:
        for case, (_, trial) in CASES.items():
            if not trial.exists():
                print(f"{case}: {trial} not here, skipped", file=sys.stderr)
                continue
            rows[case] = {"baseline": _run_worker(base, case), "current": _run_worker(ROOT, case)}
            print(f"{case}: done", file=sys.stderr)
        if not args.no_end_to_end:
            e2e = {"baseline": _end_to_end(base), "current": _end_to_end(ROOT)}
    print(table(rows))
    for version, r in e2e.items():
        print(f"fit walking2 end to end, {version}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU, exit "
              f"{r['exit']}, JSON {r['json_sha1']}")
    write_json(args.out, "gap_start", {"baseline": args.baseline, "current": worktree.head() + "+working tree",
                                       "machine": machine_info(), "first_fit": rows, "fit_walking2_end_to_end": e2e})
    return 0


if __name__ == "__main__":
    sys.exit(main())
