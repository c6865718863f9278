"""What the soft-tissue detector costs a round, side by side with earlier commits, and whether it proposes the same.

``soft_tissue.propose`` regresses every marker's residual on the functions of its segment's driving angles. Since
its functions are chosen by forward selection (:mod:`identcheck.bundle.score_selection`) a proposal is a selection
per marker and per set of driving joints, which on a full body is hundreds of selections a round. This script times
one ``propose`` on the rigid fit of a simulated trial, one BLAS thread, the least CPU time of ``--repeats`` calls, in
a fresh process per commit (the working tree and each ``--baseline``), the processes taking turns, and prints a
digest of the proposals (places and strengths) so that codes that should propose alike can be seen to.

Chains: ``body42`` (14 segments of 3 markers, 13 joints) and ``leg9`` (the bundled nine-marker leg), 1500 frames,
0.5 mm noise, with one thigh marker moving 8 mm with the hip's flexion and one pelvis marker with it too (so that
proposals exist on the root and elsewhere).

    PYTHONPATH=. python3 benchmarks/bench_skin_propose.py --baseline 1f2a249 93ff160

Writes ``results.json["skin_propose"]`` (``--key``).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402

import worktree  # noqa: E402
from bench_lm_iteration import body42  # noqa: E402

WORKER = r"""
import hashlib, json, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
from threadpoolctl import threadpool_limits
import identcheck as ic
from identcheck.diagnose import workflow
from identcheck.io.model import Model
from identcheck.effects.registry import EFFECTS
from identcheck.effects.injection import marker_column, rotate, rotations
from identcheck.bundle.hypothesis import joint_angles

path, repeats = sys.argv[1], int(sys.argv[2])
model = Model.from_toml(path)
sim = ic.simulate(path, n_frames=1500, noise_mm=0.5, seed=3)
with threadpool_limits(1):
    ctx, h = workflow.start(model, sim.trial.recentred()[0])
    hip = next(j for j in model.joints if j.startswith("hip"))
    flex = joint_angles(h)[hip][:, 0]
    shape = (flex - flex.mean()) / np.abs(flex - flex.mean()).max()
    clean = sim.clean.as_array()
    rng = np.random.default_rng(3)
    for seg in (model.joints[hip].parent, model.joints[hip].child):
        marker = model.segments[seg].markers[0]
        clean[:, marker_column(sim, marker)] += rotate(rotations(sim, seg), np.outer(8.0 * shape, rng.normal(size=3) / 3 ** 0.5))
    trial = sim.trial.replace(xyz=clean + (sim.trial.as_array() - sim.clean.as_array()))
    ctx, h = workflow.start(model, trial.recentred()[0])
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        props = EFFECTS["soft_tissue"].propose(ctx, h)
        best = min(best, time.process_time() - t)
places = [[p.where["segment"], list(p.where["markers"]), bool(p.where.get("together")), round(p.strength, 1)]
          for p in props]
print(json.dumps({"cpu_s": best, "proposals": len(props),
                  "digest": hashlib.sha256(json.dumps(places).encode()).hexdigest()[:16], "top": places[:3]}))
"""


def leg9() -> str:
    return (ROOT / "examples" / "diagnose_leg.toml").read_text()


CHAINS = {"body42": body42, "leg9": leg9}


def run(root: Path, model: Path, repeats: int) -> dict:
    out = subprocess.run([sys.executable, "-c", WORKER, str(model), str(repeats)], cwd=root, capture_output=True,
                         text=True, env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin", "IDENTCHECK_THREADS": "1",
                                         "HOME": str(Path.home())})
    if out.returncode:
        raise SystemExit(f"worker failed in {root}:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", nargs="*", default=["1f2a249"], help="commits to time beside the working tree")
    ap.add_argument("--chains", nargs="+", default=list(CHAINS), choices=list(CHAINS))
    ap.add_argument("--repeats", type=int, default=3, help="propose calls a process, least CPU time kept")
    ap.add_argument("--turns", type=int, default=2, help="processes per commit and chain, taking turns")
    ap.add_argument("--key", default="skin_propose")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        roots = [("current", ROOT)] + [(rev, stack.enter_context(worktree.checkout(rev))) for rev in a.baseline]
        for chain in a.chains:
            model = Path(tmp) / f"{chain}.toml"
            model.write_text(CHAINS[chain]())
            for turn in range(a.turns):
                for name, root in roots:
                    r = run(root, model, a.repeats)
                    rows.append({"chain": chain, "code": name, "turn": turn, **r})
                    print(f"{chain:<7} {name:<8} turn {turn}  {r['cpu_s']:.3f} CPU s  {r['proposals']:>3} proposals  "
                          f"digest {r['digest']}", flush=True)
    summary = {}
    for chain in a.chains:
        for name, _ in roots:
            mine = [r for r in rows if r["chain"] == chain and r["code"] == name]
            summary[f"{chain} {name}"] = {"cpu_s": min(r["cpu_s"] for r in mine), "digest": mine[0]["digest"],
                                          "proposals": mine[0]["proposals"]}
    print(json.dumps(summary, indent=1))
    write_json(a.out, a.key, {"machine": machine_info(), "current": worktree.head(), "baselines": a.baseline,
                              "repeats": a.repeats, "rows": rows, "summary": summary})


if __name__ == "__main__":
    main()
