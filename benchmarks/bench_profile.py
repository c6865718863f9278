"""Profile-likelihood intervals, this tree against a baseline commit, side by side: their cost and what they claim.

The profile likelihood holds one marker distance and refits everything else (``bundle/profile.py``). Each case runs
as a whole command, the baseline's and this tree's processes taking turns, one thread each:

* ``identcheck fit`` on both legs of the real walking2 trial (examples/real: its knees are profiled);
* ``identcheck diagnose`` on the trials of a held-out folder given with ``--diagnose`` (names with ``--trials``),
  whose final models have weakly determined joints.

Reported per case and version: CPU and wall seconds of the process, how many distances each interval method
gave, and each profiled distance's interval; per case, the largest difference between the two versions' bounds
where both profiled a distance.

Usage::

    PYTHONPATH=. python3 benchmarks/bench_profile.py --baseline 8743cb5 [--diagnose /tmp/h55 --trials trial_0000]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import worktree  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402

KEY = "profile_soft_spring"


def run(path: Path, version: str, verb: str, model: Path, trial: Path) -> dict:
    """One ``identcheck VERB MODEL TRIAL --json`` with the package at `path`, one thread: wall and CPU seconds of
    the process, the interval method of every marker distance, and the profiled intervals."""
    env = dict(os.environ, PYTHONPATH=str(path), IDENTCHECK_THREADS="1")
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "identcheck", verb, str(model), str(trial), "--json"], env=env,
                            cwd=path, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    stdout = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    methods: dict = {}
    profiled: dict = {}
    for name, joint in json.loads(stdout)["joints"].items():
        for marker, how in joint["interval_method"].items():
            methods[how] = methods.get(how, 0) + 1
            if "profile" in how:
                profiled[f"{name}/{marker}"] = joint["marker_distances_ci95"][marker]
    row = {"case": f"{verb} {model.name} {trial.name}", "version": version, "wall_s": round(wall, 2),
           "cpu_s": round(usage.ru_utime + usage.ru_stime, 2), "exit_code": os.waitstatus_to_exitcode(status),
           "interval_methods": methods, "profiled": profiled}
    print(f"{row['case'][:60]:60s} {version:9s} {wall:7.1f} s wall {row['cpu_s']:7.1f} s CPU  {methods}", flush=True)
    return row


def largest_bound_change(a: dict, b: dict) -> float | None:
    """The largest difference between two versions' bounds, over the distances both profiled (None if none)."""
    diffs = [abs(x - y) for key in set(a) & set(b) for x, y in zip(a[key], b[key]) if x is not None and y is not None]
    return round(max(diffs), 3) if diffs else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="the commit to compare with")
    ap.add_argument("--diagnose", type=Path, help="a held-out folder (trial_XXXX.toml/.trc) to diagnose from")
    ap.add_argument("--trials", nargs="*", default=[], help="stems of the --diagnose folder's trials")
    ap.add_argument("--key", default=KEY)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    real = ROOT / "examples"
    cases = [("fit", real / "real_walking2_legs.toml", real / "real" / "opensim_walking2.c3d")]
    cases += [("diagnose", a.diagnose / f"{s}.toml", a.diagnose / f"{s}.trc") for s in a.trials]
    rows, summary = [], []
    with worktree.checkout(a.baseline) as base:
        for verb, model, trial in cases:
            pair = {v: run(p, v, verb, model, trial) for v, p in (("baseline", base), ("current", ROOT))}
            rows += pair.values()
            summary.append({"case": pair["current"]["case"],
                            "cpu_s": {v: r["cpu_s"] for v, r in pair.items()},
                            "largest_bound_change_mm": largest_bound_change(pair["baseline"]["profiled"],
                                                                            pair["current"]["profiled"])})
    print("\ncase                                                          baseline  current  (CPU s)  bounds moved")
    for s in summary:
        print(f"{s['case'][:60]:60s} {s['cpu_s']['baseline']:8.1f} {s['cpu_s']['current']:8.1f}  "
              f"{s['largest_bound_change_mm']}")
    write_json(a.out, a.key, {"machine": machine_info(), "baseline": a.baseline, "current": worktree.head(),
                              "rows": rows, "summary": summary, "date": time.strftime("%Y-%m-%dT%H:%M:%S")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
