"""``fit`` on trials in which the joints hardly move: does it ever call a joint determined that the trial cannot
determine?

The trials come from the independent generator in ``benchmarks/heldout_still/`` (written from the public contract
by an author who never read identcheck's code): a right leg (hip ball joint, knee and optional ankle hinges)
standing still with the body swaying, moving by 0.5-3 deg (``tiny``) or 3-8 deg (``small``), and moving normally
(``moving``, the control); marker sets ``full`` (three or more markers a segment), ``sparse`` (3 pelvis, 1 thigh,
1 shank) and ``mixed``; white or AR(1) noise. Each marker distance is scored as in
``bench_fit_calibration.py`` (:func:`bench_fit_calibration.fit_and_score`): a joint is *confidently wrong* when it
is called ``determined`` with a marker distance off by more than 3 half-widths and 2 mm. Reported per motion and
per motion x marker set: joints by verdict, confidently wrong joints, coverage.

Usage::

    python benchmarks/heldout_still/generator.py --out /tmp/still --n 48 --seed 11
    PYTHONPATH=. python benchmarks/bench_fit_still.py /tmp/still [--shard K/N --rows R.json] [--merge R0 R1]
        [--key fit_still]
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_fit_calibration import fit_and_score, group_summary  # noqa: E402
from results_io import add_shard_arguments, machine_info, run_trials, write_json  # noqa: E402


def evaluate(folder: Path, entry: dict) -> dict:
    truth = json.loads((folder / entry["files"]["truth.json"]).read_text())
    row = fit_and_score(entry["id"], folder / entry["files"]["toml"], folder / entry["files"]["trc"],
                        truth["marker_distances"])
    return {**row, "motion": entry["motion"], "markerset": entry["markerset"], "noise": entry["noise_model"]}


def summarise(rows: list) -> dict:
    groups = defaultdict(list)
    for r in rows:
        for key in ("all", r["motion"], f"{r['motion']} x {r['markerset']}"):
            groups[key].append(r)
    return {key: group_summary(rs) for key, rs in sorted(groups.items())}


def _json_safe(rows: list) -> list:
    """The rows with an unbounded half-width (inf) stored as None: results.json holds strict JSON."""
    return [{**r, "rows": [{**x, "half": x["half"] if np.isfinite(x.get("half", np.inf)) else None}
                          for x in r.get("rows", [])]} for r in rows]


def table(summary: dict) -> str:
    lines = [f"{'motion x marker set':<24} {'trials':>6} {'joints':>6} {'determined':>10} {'ambiguous':>9} "
             f"{'undetermined':>12} {'conf.wrong':>10} {'cover':>6}"]
    for key, s in summary.items():
        v = s["verdicts"]
        lines.append(f"{key:<24} {s['trials']:>6} {s['joints']:>6} {v.get('determined', 0):>10} "
                     f"{v.get('ambiguous', 0):>9} {v.get('undetermined', 0):>12} {s['confidently_wrong_joints']:>10} "
                     f"{'-' if s['coverage'] is None else format(s['coverage'], '.3f'):>6}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", type=Path, help="folder written by benchmarks/heldout_still/generator.py")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--key", default="fit_still")
    ap.add_argument("--note", default=None, help="what this run is, stored beside its rows")
    add_shard_arguments(ap)
    a = ap.parse_args(argv)
    index = json.loads((a.trials / "index.json").read_text())
    rows = run_trials(index["trials"], lambda e: evaluate(a.trials, e), a, lambda k, n, e, r: (
        f"[{k}/{n}] {r['stem']} {e['motion']} {e['markerset']} {e['noise_model']} {r['seconds']:.1f}s"
        + (f" ERROR {r['error'][:200]}" if "error" in r else "")))
    if rows is None:
        return 0
    summary = summarise(rows)
    print(table(summary))
    write_json(a.out, a.key, {"summary": summary, "rows": _json_safe(rows), "note": a.note,
                              "source": {"folder": str(a.trials), "generator": index.get("generator"),
                                         "seed": index.get("seed"), "n": index.get("n")},
                              "machine": machine_info()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
