"""The default `identcheck plan` — verdicts plus the per-joint motion and per-marker robustness analyses — against
the size of the skeleton, side by side with an earlier commit (checked out into a temporary ``git worktree``) in
one run.

Before, every variant of the plan (a marker removed, a joint held still) was ranked on the whole tree; now its
verdicts come from small windows of the tree that bound the whole tree's from both sides
(:mod:`identcheck.plan.windows`). Each row runs ``identcheck plan MODEL --json --max-seconds 86400`` (no budget:
everything analysed) in a fresh process, for the baseline (stopped after ``--cap`` seconds) and for this tree,
and checks that the two JSON documents are identical.

Models: the chains and stars of ``bench_tree_rank_scaling.py`` (1–3 markers per segment, ball or hinge joints,
from a fixed seed), a 47-segment body with hands (three phalanges a finger, one marker each) and feet, Pham's
16-marker body and the Plug-in Gait lower limb. Prints a table and writes key "plan_analyses" in
benchmarks/results.json.

    PYTHONPATH=. python3 benchmarks/bench_plan_analyses.py [--baseline 9c5bcb3] [--cap 240]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_tree_rank_scaling import run_plan, tree_toml  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402
import worktree  # noqa: E402

KEY = "plan_analyses"
CHAINS = (20, 50, 100, 200)
STARS = (60,)


def body_toml() -> str:
    """A full body with hands and feet: pelvis, trunk and head (4 markers each); per arm an upper arm and forearm
    (2), a hand (3) and five fingers of three phalanges (1 each); per leg a thigh and shank (2), a foot (3) and toes
    (1). Ball joints at the spine, neck, shoulders, wrists, finger bases, hips and ankles; hinges elsewhere."""
    segments, joints = {}, []

    def seg(name, n, parent=None, kind=None):
        segments[name] = [f"{name}_{i}" for i in range(n)]
        if parent:
            joints.append((f"{parent}-{name}", kind, parent, name))

    seg("pelvis", 4)
    seg("trunk", 4, "pelvis", "spherical")
    seg("head", 4, "trunk", "spherical")
    for side in "lr":
        seg(f"upperarm_{side}", 2, "trunk", "spherical")
        seg(f"forearm_{side}", 2, f"upperarm_{side}", "revolute")
        seg(f"hand_{side}", 3, f"forearm_{side}", "spherical")
        for f in range(5):
            parent = f"hand_{side}"
            for p in range(3):
                name = f"finger{f}{p}_{side}"
                seg(name, 1, parent, "spherical" if p == 0 else "revolute")
                parent = name
        seg(f"thigh_{side}", 2, "pelvis", "spherical")
        seg(f"shank_{side}", 2, f"thigh_{side}", "revolute")
        seg(f"foot_{side}", 3, f"shank_{side}", "spherical")
        seg(f"toes_{side}", 1, f"foot_{side}", "revolute")
    lines = ['units = "mm"']
    for name, ms in segments.items():
        lines.append(f"[segments.{name}]\nmarkers = [{', '.join(repr(m).replace(chr(39), chr(34)) for m in ms)}]")
    for name, kind, par, chi in joints:
        lines.append(f'[joints."{name}"]\ntype = "{kind}"\nparent = "{par}"\nchild = "{chi}"')
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="9c5bcb3", help="commit to compare with (default: every variant ranked "
                                                          "on the whole tree)")
    ap.add_argument("--cap", type=float, default=240.0, help="seconds the baseline may take per model")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    rows = []
    no_budget = ["--max-seconds", "86400"]
    with tempfile.TemporaryDirectory() as tmp, worktree.checkout(a.baseline) as base:
        models = [(f"chain{n}", n + 1, tree_toml(n, False)) for n in CHAINS]
        models += [(f"star{n}", n + 1, tree_toml(n, True)) for n in STARS]
        body = body_toml()
        models.append(("body_hands_feet", body.count("[segments."), body))
        models.append(("body16", 14, (ROOT / "examples" / "body16.toml").read_text()))
        models.append(("pig_lower_limb", 7, (ROOT / "examples" / "pig_lower_limb.toml").read_text()))
        for name, segments, text in models:
            path = Path(tmp) / f"{name}.toml"
            path.write_text(text)
            old = run_plan(base, path, no_budget, a.cap)
            new = run_plan(ROOT, path, no_budget, 10 * a.cap)
            row = {"model": name, "segments": segments, "baseline_s": old["wall_s"], "current_s": new["wall_s"],
                   "identical_json": (old["doc"] == new["doc"]) if old["doc"] else None,
                   "unfinished": sorted((new["doc"] or {}).get("unfinished", {}))}
            rows.append(row)
            fmt = lambda t: f"{t:7.2f} s" if t is not None else f"> {a.cap:.0f} s"
            print(f"{name:16s} {segments:4d} segments  baseline {fmt(row['baseline_s'])}  current {fmt(row['current_s'])}"
                  f"  identical JSON: {row['identical_json']}", flush=True)
    write_json(a.out, KEY, {"machine": machine_info(), "baseline": a.baseline, "current": worktree.head(),
                            "cap_s": a.cap, "rows": rows,
                            "command": "identcheck plan MODEL --json --max-seconds 86400 (wall seconds, fresh process)"})
    return 0


if __name__ == "__main__":
    sys.exit(main())
