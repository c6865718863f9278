"""Calibration of ``fit`` on trials it was not tuned on: do the 95 % intervals cover the truth 95 % of the time?

The trials come from the independent generator in ``benchmarks/heldout/`` (written from a short spec by an
author who never read identcheck's code: its own skeleton, marker layouts, motions and noise). For every
trial the library call ``identcheck.fit`` (the CLI's fit) runs on the TRC and the model file, and each
marker distance's interval is checked against the generator's exact truth.

Reported per category (noise kind × marker set × motion) and overall:
- coverage: share of marker distances whose 95 % interval holds the truth (target 93-97 % under white and
  correlated noise; under soft-tissue motion the rigid model is wrong, and the share is reported as it is);
- sharpness: median interval half-width against the RMS error of the estimates;
- verdicts: determined / ambiguous / undetermined counts;
- confidently wrong: joints called ``determined`` with a marker distance off by more than 3 half-widths and
  more than 2 mm (must be 0);
- misfit flagged: share of trials with a ``model_misfit`` warning (of the soft-tissue ones: all, ideally);
- gap flagged: share of trials with an ``unexplained_gap`` warning (the residual beyond the noise floor: all the
  soft-tissue ones ideally, few of the others: the test's false alarms);
- seconds per trial.
An ambiguous joint counts as covered when any of its listed candidates' intervals holds the truth.

Usage::

    python benchmarks/heldout/generator.py --out /tmp/heldout --n 240 --seed 7
    PYTHONPATH=. python benchmarks/bench_fit_calibration.py /tmp/heldout [--limit N] [--figure benchmarks/fit_calibration.png]

or in two shards side by side, then together::

    python benchmarks/bench_fit_calibration.py /tmp/heldout --shard 0/2 --rows /tmp/rows0.json &
    python benchmarks/bench_fit_calibration.py /tmp/heldout --shard 1/2 --rows /tmp/rows1.json
    python benchmarks/bench_fit_calibration.py /tmp/heldout --merge /tmp/rows0.json /tmp/rows1.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import identcheck as ic  # noqa: E402
from results_io import add_shard_arguments, machine_info, run_trials, write_json  # noqa: E402

WRONG_FACTOR = 3.0
WRONG_MIN_MM = 2.0


def evaluate(trial_dir: Path, entry: dict) -> dict:
    """Fit one generated trial and score its intervals against the truth."""
    stem = entry.get("stem") or entry.get("name") or entry.get("id")
    truth = json.loads((trial_dir / f"{stem}.truth.json").read_text())
    return fit_and_score(stem, trial_dir / f"{stem}.toml", trial_dir / f"{stem}.trc",
                         {name: tj["marker_distances"] for name, tj in truth["joints"].items()})


def fit_and_score(stem: str, model: Path, trc: Path, truth: dict) -> dict:
    """``identcheck.fit`` of one trial, each marker distance of each joint scored against ``truth`` (joint ->
    marker -> exact distance, mm): covered, half-width, error, and confidently wrong (:data:`WRONG_FACTOR`,
    :data:`WRONG_MIN_MM`); the verdict, the model-misfit warning and the CPU seconds."""
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = ic.fit(model, trc).to_dict()
        except ic.InputError as exc:
            return {"stem": stem, "error": str(exc), "seconds": time.process_time() - t0}
    seconds = time.process_time() - t0
    rows = []
    for name, distances in truth.items():
        j = res["joints"].get(name)
        if j is None:
            continue
        verdict = j.get("practical", {}).get("verdict", "undetermined")
        cands = [j.get("marker_distances_ci95", {})] + [a.get("marker_distances_ci95", {}) for a in j["alternatives"]]
        for m, true in distances.items():
            ci = j.get("marker_distances_ci95", {}).get(m)
            est = j["marker_distances"].get(m)
            if ci is None or est is None:
                rows.append({"joint": name, "marker": m, "verdict": verdict, "covered": None})
                continue
            covered = any(c.get(m) is not None and c[m][0] <= true <= (np.inf if c[m][1] is None else c[m][1])
                          for c in cands)
            half = np.inf if ci[1] is None else (ci[1] - ci[0]) / 2
            err = abs(est - true)
            rows.append({"joint": name, "marker": m, "verdict": verdict, "covered": bool(covered), "half": half,
                         "err": err, "wrong": verdict == "determined" and err > max(WRONG_FACTOR * half, WRONG_MIN_MM),
                         "method": j.get("interval_method", {}).get(m)})
    kinds = {w.get("kind") for w in res.get("warnings", [])}
    return {"stem": stem, "rows": rows, "seconds": seconds, "misfit_flagged": "model_misfit" in kinds,
            "gap_flagged": "unexplained_gap" in kinds}


def _finite(x) -> float | None:
    """A JSON-safe number: None for an unbounded (infinite) one."""
    return round(float(x), 3) if np.isfinite(x) else None


def summarise(results: list, categories: dict) -> dict:
    groups = defaultdict(list)
    for r in results:
        cat = categories[r["stem"]]
        for key in (f"{cat['noise']}", f"{cat['noise']} x {cat['markerset']}", f"{cat['noise']} x {cat['motion']}",
                    "all"):
            groups[key].append(r)
    return {key: group_summary(rs) for key, rs in sorted(groups.items())}


def group_summary(rs: list) -> dict:
    """Coverage, sharpness, verdicts, confidently wrong joints and time of a group of :func:`fit_and_score` rows."""
    rows = [x for r in rs for x in r.get("rows", [])]
    scored = [x for x in rows if x["covered"] is not None]
    joints = {(r["stem"], x["joint"]): x["verdict"] for r in rs for x in r.get("rows", [])}
    verdicts = defaultdict(int)
    for v in joints.values():
        verdicts[v] += 1
    det = [x for x in scored if x["verdict"] == "determined"]
    return {
        "trials": len(rs), "errors": sum("error" in r for r in rs), "distances": len(scored),
        "joints": len(joints),
        "coverage": round(float(np.mean([x["covered"] for x in scored])), 4) if scored else None,
        "coverage_determined": round(float(np.mean([x["covered"] for x in det])), 4) if det else None,
        "median_half_width_mm": _finite(np.median([x["half"] for x in scored])) if scored else None,
        "rms_error_mm": round(float(np.sqrt(np.mean([x["err"] ** 2 for x in scored]))), 3) if scored else None,
        "verdicts": dict(verdicts),
        "confidently_wrong_joints": len({(r["stem"], x["joint"]) for r in rs for x in r.get("rows", []) if x.get("wrong")}),
        "misfit_flagged": round(float(np.mean([r.get("misfit_flagged", False) for r in rs])), 3),
        "gap_flagged": round(float(np.mean([r.get("gap_flagged", False) for r in rs])), 3),
        "median_seconds": round(float(np.median([r["seconds"] for r in rs])), 2),
    }


def figure(summary: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    keys = [k for k in summary if " x " in k and summary[k]["coverage"] is not None]
    fig = Figure(figsize=(9, 0.35 * len(keys) + 1.5))
    ax = fig.add_subplot()
    cov = [summary[k]["coverage"] for k in keys]
    ax.barh(range(len(keys)), cov, color=["tab:green" if c >= 0.93 else "tab:orange" if c >= 0.9 else "tab:red"
                                          for c in cov])
    ax.axvline(0.95, color="k", lw=1)
    ax.axvspan(0.93, 0.97, color="0.9", zorder=0)
    ax.set_yticks(range(len(keys)), keys)
    ax.set_xlim(0.5, 1.0)
    ax.set_xlabel("share of marker distances whose 95 % interval holds the truth")
    ax.set_title("fit on independently generated trials: coverage of the 95 % intervals")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", type=Path, help="folder written by benchmarks/heldout/generator.py")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--figure", type=Path, default=ROOT / "benchmarks" / "fit_calibration.png")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--key", default="fit_calibration")
    add_shard_arguments(ap)
    a = ap.parse_args(argv)
    index = json.loads((a.trials / "index.json").read_text())
    entries = index["trials"] if isinstance(index, dict) else index
    entries = entries[:a.limit] if a.limit else entries
    categories = {(e.get("stem") or e.get("name") or e.get("id")): e["category"] for e in entries}
    results = run_trials(entries, lambda e: evaluate(a.trials, e), a, lambda k, n, e, r: (
        f"[{k}/{n}] {r['stem']} {e['category']} {r['seconds']:.1f}s" + (f" ERROR {r['error']}" if "error" in r else "")))
    if results is None:
        return 0
    summary = summarise(results, categories)
    print(f"{'category':<40} {'trials':>6} {'dist':>5} {'cover':>6} {'c.det':>6} {'half':>7} {'rmse':>7} "
          f"{'wrong':>5} {'misfit':>6} {'gap':>5}  verdicts")
    for key, s in summary.items():
        print(f"{key:<40} {s['trials']:>6} {s['distances']:>5} {s['coverage'] or 0:>6.3f} "
              f"{s['coverage_determined'] or 0:>6.3f} {s['median_half_width_mm'] if s['median_half_width_mm'] is not None else float('inf'):>7.2f} {s['rms_error_mm'] or 0:>7.2f} "
              f"{s['confidently_wrong_joints']:>5} {s['misfit_flagged']:>6.2f} {s['gap_flagged']:>5.2f}  {s['verdicts']}")
    figure(summary, a.figure)
    write_json(a.out, a.key, {"summary": summary, "trials_dir": str(a.trials), "n_trials": len(results),
                              "machine": machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
