"""Wall and CPU time of ``diagnose`` on a folder of trials, this tree against an earlier commit, in one run.

Each trial (a ``.trc`` or ``.c3d`` with its ``.toml`` model beside it, as the held-out generators write them) is
diagnosed by both versions, each in a fresh process with one BLAS thread and the threads ``diagnose`` itself
chooses (``$IDENTCHECK_THREADS``, else the cores); the two run one after the other, the order alternating from
trial to trial, so that neither slows the other and drifts in the machine's load fall on both. Each row keeps
both versions' wall time and CPU time (the child's user + system time, from ``os.wait4``) and whether their
reports agree: the same effects at the same places (fitted sizes left out) and gaps within 1 %. A difference is
listed, never hidden.

    python benchmarks/heldout_effects/generator.py --out /tmp/hx --n 120 --seed 19
    python benchmarks/bench_diagnose_speed.py /tmp/hx --baseline 67b32f7 [--limit 40] [--key diagnose_speed]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_io  # noqa: E402
import worktree  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
RUN = """
import json, sys, warnings
warnings.simplefilter("ignore")
from identcheck.api import diagnose
d = diagnose(sys.argv[1], sys.argv[2]).to_dict()
json.dump({"effects": [[e["name"], {k: v for k, v in e["where"].items() if not isinstance(v, float)}]
                       for e in d["effects"]], "gap_before": d["gap_before"], "gap_after": d["gap_after"]},
          open(sys.argv[3], "w"))
"""


def _run(code: Path, model: Path, trial: Path) -> dict:
    """One diagnosis in a fresh process running the package at `code`: its wall and CPU seconds and its summary."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", RUN, str(model), str(trial), str(out)], cwd=code, env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        err = proc.stderr.read().decode(errors="replace")
        _, status, usage = os.wait4(proc.pid, 0)
        proc.stderr.close()
        took = {"wall_s": time.perf_counter() - t0, "cpu_s": usage.ru_utime + usage.ru_stime}
        if status != 0 or not out.exists():
            return {**took, "error": err.strip().splitlines()[-1:] or ["failed"]}
        return {**took, **json.loads(out.read_text())}


def _agree(a: dict, b: dict) -> bool:
    if "error" in a or "error" in b:
        return False
    return a["effects"] == b["effects"] and all(abs(a[k] - b[k]) <= 0.01 * max(a[k], 1e-9)
                                                for k in ("gap_before", "gap_after"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="trials with their .toml models beside them")
    ap.add_argument("--baseline", required=True, help="the commit to compare with")
    ap.add_argument("--limit", type=int, default=None, help="only the first N trials (by name)")
    ap.add_argument("--key", default="diagnose_speed", help="results.json key (default diagnose_speed)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    trials = sorted(p for p in a.folder.iterdir() if p.suffix in (".trc", ".c3d") and p.with_suffix(".toml").exists())
    trials = trials[:a.limit] if a.limit else trials
    if not trials:
        raise SystemExit(f"{a.folder}: no .trc or .c3d trial with a .toml model beside it")
    rows = []
    with worktree.checkout(a.baseline) as base:
        for k, trial in enumerate(trials, 1):
            model = trial.with_suffix(".toml")
            order = [("current", ROOT), ("baseline", base)][::1 if k % 2 else -1]
            row = {"trial": trial.name, **{name: _run(code, model, trial) for name, code in order}}
            row["agree"] = _agree(row["current"], row["baseline"])
            rows.append(row)
            old, now = row["baseline"], row["current"]
            print(f"[{k}/{len(trials)}] {trial.name}: wall {old['wall_s']:.1f} -> {now['wall_s']:.1f} s, "
                  f"CPU {old['cpu_s']:.1f} -> {now['cpu_s']:.1f} s{'' if row['agree'] else '  (reports differ)'}",
                  file=sys.stderr, flush=True)
    summary = {}
    for clock in ("wall_s", "cpu_s"):
        cur = np.array([r["current"][clock] for r in rows])
        old = np.array([r["baseline"][clock] for r in rows])
        summary[clock] = {stat: {"baseline": float(f(old)), "current": float(f(cur))}
                          for stat, f in (("median", np.median), ("mean", np.mean),
                                          ("p90", lambda x: np.percentile(x, 90)), ("max", np.max))}
        summary[clock]["within_5_s"] = {"baseline": int((old <= 5).sum()), "current": int((cur <= 5).sum())}
    differ = [r for r in rows if not r["agree"]]
    print(f"\n{'seconds per trial':<18}{'wall, before':>14}{'wall, now':>11}{'CPU, before':>13}{'CPU, now':>10}")
    for stat in ("median", "mean", "p90", "max", "within_5_s"):
        w, c = summary["wall_s"][stat], summary["cpu_s"][stat]
        print(f"{stat:<18}{w['baseline']:>14.2f}{w['current']:>11.2f}{c['baseline']:>13.2f}{c['current']:>10.2f}")
    print(f"reports differ on {len(differ)} of {len(rows)} trials" + "".join(
        f"\n  {r['trial']}: {r['baseline'].get('effects', r['baseline'].get('error'))} -> "
        f"{r['current'].get('effects', r['current'].get('error'))}" for r in differ))
    results_io.write_json(a.out, a.key, {"folder": str(a.folder), "baseline": a.baseline, "current": worktree.head(),
                                         "n": len(rows), "summary": summary, "differ": len(differ), "rows": rows,
                                         "machine": results_io.machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
