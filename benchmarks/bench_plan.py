"""Speed of `identcheck plan` on the example plans, against the exact-rational engine (the obvious alternative).

Rows: the verdict alone (whole-tree rank over GF(p) + propagation), the full plan (plus motion,
robustness and suggestions), and the same verdict over QQ (exact rationals) where it finishes in
reasonable time; with ``--witness``, also the time of ``plan --witness`` (a simulated trial and a
50-digit-verified second skeleton searched for every joint the plan does not identify) and how many
were verified. Prints a table and writes key "plan" in benchmarks/results.json.

    PYTHONPATH=. python3 benchmarks/bench_plan.py [--qq-max-markers 10] [--witness] [--out benchmarks/results.json]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import results_io  # noqa: E402
from identcheck.plan import analysis as plan  # noqa: E402
from identcheck.certify import tree_rank
from identcheck.io.model import Model  # noqa: E402
PLANS = ["examples/body16.toml", "examples/pig_lower_limb.toml", "examples/sparse_leg.toml", "examples/leg.toml"]


def best_of(fn, k=3):
    times = []
    for _ in range(k):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qq-max-markers", type=int, default=10, help="run the QQ row only for plans this small")
    ap.add_argument("--witness", action="store_true", help="also time `plan --witness` (about a minute for body16)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results.json"))
    a = ap.parse_args(argv)
    rows = []
    for path in PLANS:
        model = Model.from_toml(ROOT / path)
        spec = tree_rank.TreeSpec.from_model(model)
        n_markers = sum(len(m) for m in spec.markers.values())
        t_verdict, doc = best_of(lambda: plan.plan_model(model, motion=False, robust=False, suggest=False))
        t_full, full = best_of(lambda: plan.plan_model(model), k=1)
        t_gfp, _ = best_of(lambda: tree_rank.analyse(spec, "GFp"))
        t_qq = None
        if n_markers <= a.qq_max_markers:
            t_qq, _ = best_of(lambda: tree_rank.analyse(spec, "QQ"), k=1)
        rows.append({"plan": path, "markers": n_markers, "joints": len(spec.joints),
                     "verdict_s": t_verdict, "full_s": t_full, "rank_gfp_s": t_gfp, "rank_qq_s": t_qq,
                     "qq_over_gfp": (t_qq / t_gfp) if t_qq else None,
                     "all_identifiable": full.all_identifiable, "all_local": full.all_local,
                     "suggested_markers": sum(s["add_markers"] for s in full.suggestions)})
        if a.witness:
            t_w, wdoc = best_of(lambda: plan.plan_model(model, motion=False, robust=False, suggest=False,
                                                        witness=True), k=1)
            alts = [j["alternative"] for j in wdoc.joints.values() if "alternative" in j]
            rows[-1].update({"witness_s": t_w, "witness_searched": len(alts),
                             "witness_verified": sum(bool(w["verified"]) for w in alts)})
    head = (f"{'plan':<32} {'mk':>3} {'jt':>3} {'verdict':>9} {'full':>8} {'rank GFp':>9} {'rank QQ':>9} {'QQ/GFp':>7}"
            + (f" {'witness':>9} {'verified':>9}" if a.witness else ""))
    print(head)
    print("-" * len(head))
    for r in rows:
        qq = "-" if r["rank_qq_s"] is None else f"{r['rank_qq_s']:.3f}s"
        ratio = "-" if r["qq_over_gfp"] is None else f"{r['qq_over_gfp']:.0f}x"
        print(f"{r['plan']:<32} {r['markers']:>3} {r['joints']:>3} {r['verdict_s']:>8.3f}s {r['full_s']:>7.2f}s "
              f"{r['rank_gfp_s']:>8.3f}s {qq:>9} {ratio:>7}"
              + (f" {r['witness_s']:>8.1f}s {r['witness_verified']:>4}/{r['witness_searched']:<4}" if a.witness else ""))
    results_io.write_json(a.out, "plan", {"rows": rows, "machine": results_io.machine_info()})


if __name__ == "__main__":
    main()
