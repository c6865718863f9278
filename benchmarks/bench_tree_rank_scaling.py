"""How `identcheck plan`'s whole-tree rank scales with the size of the skeleton, side by side with an earlier
commit (checked out into a temporary ``git worktree``) in one run.

Models: chains of 10–200 segments and stars of 20 and 60 branches (1–3 markers per segment and ball or hinge
joints, drawn from a fixed seed), and Pham's 16-marker body (examples/body16.toml). Each row runs
``identcheck plan MODEL --json --fast`` (the verdict alone: whole-tree rank and propagation) in a fresh
process, for the baseline (capped at ``--cap`` seconds) and for this tree, and checks that both give the same
verdicts, frames, dim W and minimum samples (the degree and failure bounds may differ: they count the
equations each version writes). ``--full`` also runs this tree's default plan (with the per-joint motion and
per-marker robustness analyses, bounded by their 30 s budget) and reports what it left unfinished.

The scaling exponent is the slope of log(time) against log(segments) over the chains of 40 segments and
more. Prints a table and writes key "tree_rank_scaling" in benchmarks/results.json.

    PYTHONPATH=. python3 benchmarks/bench_tree_rank_scaling.py [--baseline b0889ba] [--cap 150] [--full]
"""
from __future__ import annotations

import argparse
import json
import math
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
import worktree  # noqa: E402

KEY = "tree_rank_scaling"
CHAINS = (10, 20, 40, 100, 200)
STARS = (20, 60)


def tree_toml(n_joints: int, star: bool, seed: int = 1) -> str:
    """A chain (each segment the child of the previous) or a star (every segment a child of the root)."""
    rng = random.Random(f"{seed}/{n_joints}/{star}")
    lines = ['units = "mm"']
    for i in range(n_joints + 1):
        k = 3 if i == 0 else rng.choice([1, 2, 3])
        markers = ", ".join(f'"M{i}_{j}"' for j in range(k))
        lines.append(f"[segments.s{i}]\nmarkers = [{markers}]")
    for i in range(1, n_joints + 1):
        lines.append(f'[joints.j{i}]\ntype = "{rng.choice(["spherical", "revolute"])}"\n'
                     f'parent = "s{0 if star else i - 1}"\nchild = "s{i}"')
    return "\n".join(lines) + "\n"


def run_plan(code: Path, model: Path, extra: list, cap: float) -> dict:
    """``identcheck plan`` with the package at ``code``: wall seconds and the JSON (None past ``cap``)."""
    env = {"PYTHONPATH": str(code), "PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1", "HOME": str(Path.home())}
    t0 = time.perf_counter()
    try:
        out = subprocess.run([sys.executable, "-m", "identcheck", "plan", str(model), "--json", *extra], cwd=code,
                             env=env, capture_output=True, text=True, timeout=cap)
    except subprocess.TimeoutExpired:
        return {"wall_s": None, "doc": None}
    return {"wall_s": time.perf_counter() - t0, "doc": json.loads(out.stdout) if out.stdout.strip() else None}


def verdicts(doc: dict | None):
    """What must not change: the joints' verdicts and samples, and the certificate but for its bounds."""
    if doc is None:
        return None
    cert = {k: v for k, v in doc["certificate"].items() if k not in ("degree_bound", "failure_probability_bound")}
    return cert, {n: (j["local"], j["identifiable"], j["min_samples"]) for n, j in doc["joints"].items()}


def slope(points: list) -> float | None:
    pts = [(math.log(n), math.log(t)) for n, t in points if t]
    if len(pts) < 2:
        return None
    mx, my = sum(x for x, _ in pts) / len(pts), sum(y for _, y in pts) / len(pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="b0889ba", help="commit to compare with (default: before the staged "
                                                          "elimination)")
    ap.add_argument("--cap", type=float, default=150.0, help="seconds the baseline may take per model")
    ap.add_argument("--full", action="store_true", help="also run this tree's default plan (with the analyses)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp, worktree.checkout(a.baseline) as base:
        models = [(f"chain{n}", n + 1, tree_toml(n, False)) for n in CHAINS]
        models += [(f"star{n}", n + 1, tree_toml(n, True)) for n in STARS]
        models.append(("body16", 14, (ROOT / "examples" / "body16.toml").read_text()))
        for name, segments, text in models:
            path = Path(tmp) / f"{name}.toml"
            path.write_text(text)
            old = run_plan(base, path, ["--fast"], a.cap)
            new = run_plan(ROOT, path, ["--fast"], a.cap)
            row = {"model": name, "segments": segments, "baseline_s": old["wall_s"], "current_s": new["wall_s"],
                   "same_verdicts": (verdicts(old["doc"]) == verdicts(new["doc"])) if old["doc"] else None}
            if a.full:
                full = run_plan(ROOT, path, ["--max-seconds", "30"], 10 * a.cap)
                row["current_full_s"] = full["wall_s"]
                row["full_unfinished"] = {k: len(v) for k, v in (full["doc"] or {}).get("unfinished", {}).items()
                                          if k != "reason"}
            rows.append(row)
            fmt = lambda t: f"{t:7.2f} s" if t is not None else f"> {a.cap:.0f} s"
            print(f"{name:8s} {segments:4d} segments  baseline {fmt(row['baseline_s'])}  current {fmt(row['current_s'])}"
                  f"  same verdicts: {row['same_verdicts']}"
                  + (f"  default plan {fmt(row['current_full_s'])} unfinished {row['full_unfinished']}" if a.full else ""),
                  flush=True)
    big = [r for r in rows if r["model"].startswith("chain") and r["segments"] > 40]
    exponents = {"baseline": slope([(r["segments"], r["baseline_s"]) for r in big]),
                 "current": slope([(r["segments"], r["current_s"]) for r in big])}
    print(f"scaling exponent over chains of 40+ segments: baseline {exponents['baseline']}, current {exponents['current']}")
    write_json(a.out, KEY, {"machine": machine_info(), "baseline": a.baseline, "current": worktree.head(),
                            "cap_s": a.cap, "rows": rows, "exponent_chains": exponents,
                            "command": "identcheck plan MODEL --json --fast (wall seconds, fresh process)"})
    return 0


if __name__ == "__main__":
    sys.exit(main())
