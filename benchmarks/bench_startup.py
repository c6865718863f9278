"""Benchmark of what a verb costs from a cold process: ``identify`` and ``fit`` end to end.

The closed-form solvers evaluate functions printed from the SymPy derivations. They are committed as
generated modules (:mod:`identcheck.solve.generated`), so that no verb imports SymPy or derives at run
time. This script measures what that buys: each row runs a fresh Python process five times and reports
the median CPU seconds (user + system, from ``os.wait4``) of the whole process, and whether the process
loaded SymPy.

Rows:

* ``solvers ready``: importing the revolute (2,1), spherical (2,2) and spherical (3,1) solvers and getting
  their functions, NumPy and mpmath (``call_cpu_s``: that part alone): the start-up cost the generated
  modules remove, without the noise of a whole fit;
* ``identify knee_21`` / ``identify hip_22``: ``python -m identcheck identify MODEL TRIAL --json`` on a
  300-frame exact trial of the bundled example (revolute (2,1), resp. spherical (2,2));
* ``fit sparse_leg``: ``identcheck.fit("examples/sparse_leg.toml", TRIAL)`` on a 1500-frame simulated
  trial (noise 0.5 mm); its closed-form starts use the revolute (2,1) and spherical solvers. Also given:
  the CPU seconds of the ``fit`` call alone (``call_cpu_s``);
* ``table``: ``python -m identcheck table --json``, every case with its exact certificates. Warm, the
  derivations (their values and the printed forms the certificates record), the joint models and their
  compiled Jacobians come from the disk cache (:mod:`identcheck.derive.cache`); cold, SymPy computes them;
* ``plan body16``: ``python -m identcheck plan examples/body16.toml --json``, the whole plan (rank, windows,
  motion, robustness, suggestions) of the 16-marker body.

``--baseline REV`` also runs every selected row with the code of commit ``REV`` (a temporary worktree), in
the same run, rows named ``NAME @REV``.

Each row is run with the derivation disk cache warm (``$IDENTCHECK_CACHE`` as the user has it, filled
by a first run) and cold (an empty ``$IDENTCHECK_CACHE`` for every run): before the generated modules,
a cold cache meant deriving with SymPy for seconds. Every verb runs with one BLAS thread
(``threadpoolctl``, inside the verb).

Run from the repository root::

    PYTHONPATH=. python3 benchmarks/bench_startup.py            # about a minute on 2 cores
    PYTHONPATH=. python3 benchmarks/bench_startup.py --quick    # one run per row; writes nothing

Results go to ``benchmarks/results.json`` under ``"startup"``, sub-key ``--label`` (default ``"current"``;
``"before"`` holds the baseline measured before the generated modules), other keys kept.
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402

KEY = "startup"

# ``python -m identcheck ARGS``, then report on stderr whether SymPy was loaded
CLI = """
import json, runpy, sys
sys.argv = ["identcheck", *json.loads(sys.argv[1])]
code = 0
try:
    runpy.run_module("identcheck", run_name="__main__")
except SystemExit as exc:
    code = exc.code
print("BENCH " + json.dumps({"sympy": "sympy" in sys.modules, "code": code}), file=sys.stderr)
"""

# the closed-form solvers' functions, both backends, ready to call (what fit and identify pay before solving)
SOLVERS = """
import json, sys, time
t = time.process_time()
from identcheck.solve import revolute21, spherical22, spherical31
for solver in (revolute21, spherical22, spherical31):
    solver.generated("numpy"), solver.generated("mpmath")
call = time.process_time() - t
print("BENCH " + json.dumps({"sympy": "sympy" in sys.modules, "call_cpu_s": call}), file=sys.stderr)
"""

# ``identcheck.fit(MODEL, TRIAL)``, timing the call itself too
FIT = """
import json, sys, time, warnings
import identcheck as ic
warnings.simplefilter("ignore")
t = time.process_time()
ic.fit(sys.argv[1], sys.argv[2])
call = time.process_time() - t
print("BENCH " + json.dumps({"sympy": "sympy" in sys.modules, "call_cpu_s": call}), file=sys.stderr)
"""


BYTECODE = True
"""Whether the processes may write and reuse compiled bytecode (``__pycache__``), as an installed package does (pip
compiles it at install). A shell with ``PYTHONDONTWRITEBYTECODE=1`` (this project's build machine has it) makes
every process compile every module it imports from source again, about 0.08 s a verb: ``--no-bytecode`` keeps the
shell's setting."""


def run_once(code: str, args: list, cold: bool, root: Path = ROOT) -> dict:
    """One fresh process running the code under ``root``: its CPU seconds (user + system) and what it reported."""
    env = dict(os.environ, PYTHONPATH=str(root))
    if BYTECODE:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryDirectory() as cache:
        if cold:
            env["IDENTCHECK_CACHE"] = cache
        proc = subprocess.Popen([sys.executable, "-c", code, *args], cwd=root, env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        err = proc.stderr.read()
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    lines = [ln for ln in err.splitlines() if ln.startswith("BENCH ")]
    if not lines:
        raise SystemExit(f"benchmark process failed (exit {proc.returncode}):\n{err}")
    return {"cpu_s": usage.ru_utime + usage.ru_stime, **json.loads(lines[-1][len("BENCH "):])}


def row(name: str, code: str, args: list, cold: bool, repeats: int, root: Path = ROOT) -> dict:
    """The median of ``repeats`` runs of one process (a warm row is run once first to fill the cache)."""
    if not cold:
        run_once(code, args, cold=False, root=root)
    runs = [run_once(code, args, cold, root) for _ in range(repeats)]
    out = {"name": name, "cache": "cold" if cold else "warm", "repeats": repeats,
           "cpu_s": statistics.median(r["cpu_s"] for r in runs), "all_cpu_s": [r["cpu_s"] for r in runs],
           "sympy_loaded": any(r["sympy"] for r in runs)}
    if "call_cpu_s" in runs[0]:
        out["call_cpu_s"] = statistics.median(r["call_cpu_s"] for r in runs)
    return out


def trials(tmp: Path) -> dict:
    """The trials the rows read: exact 300-frame identify trials, a noisy 1500-frame sparse leg."""
    import identcheck as ic

    ic.simulate(ROOT / "examples/knee_21.toml", tmp / "knee_21.trc", seed=1, n_frames=300)
    ic.simulate(ROOT / "examples/hip_22.toml", tmp / "hip_22.trc", seed=1, n_frames=300)
    ic.simulate(ROOT / "examples/sparse_leg.toml", tmp / "sparse_leg.trc", seed=1, n_frames=1500, noise_mm=0.5)
    return {k: tmp / f"{k}.trc" for k in ("knee_21", "hip_22", "sparse_leg")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="one run per row; writes nothing unless --out")
    ap.add_argument("--repeats", type=int, default=5, help="runs per row (median reported)")
    ap.add_argument("--label", default="current",
                    help="the sub-key of results.json['startup'] the rows go to (e.g. 'before' for a baseline)")
    ap.add_argument("--only", default=None, help="run only the rows whose name contains this (e.g. 'identify')")
    ap.add_argument("--out", type=Path, default=None, help="JSON to update (default benchmarks/results.json)")
    ap.add_argument("--baseline", default=None, help="also run the rows with this commit's code, side by side")
    ap.add_argument("--no-bytecode", action="store_true",
                    help="keep the shell's PYTHONDONTWRITEBYTECODE (every process compiles its modules again)")
    a = ap.parse_args()
    global BYTECODE
    BYTECODE = not a.no_bytecode
    repeats = 1 if a.quick else a.repeats
    rows = []
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        roots = [("", ROOT)]
        if a.baseline:
            from worktree import checkout

            roots.append((f" @{a.baseline}", stack.enter_context(checkout(a.baseline))))
        t = trials(Path(tmp))
        runs = [("solvers ready", SOLVERS, [])]
        runs += [(f"identify {ex}", CLI, [json.dumps(["identify", str(ROOT / f"examples/{ex}.toml"), str(t[ex]),
                                                      "--json"])]) for ex in ("knee_21", "hip_22")]
        runs += [("fit sparse_leg", FIT, [str(ROOT / "examples/sparse_leg.toml"), str(t["sparse_leg"])])]
        runs += [("table", CLI, [json.dumps(["table", "--json"])])]
        runs += [("plan body16", CLI, [json.dumps(["plan", str(ROOT / "examples/body16.toml"), "--json"])])]
        for cold in (False, True):
            for name, code, args in runs:
                if a.only is None or a.only in name:
                    for tag, root in roots:
                        rows.append(row(name + tag, code, args, cold, repeats, root))
    print(f"{'row':<28} {'cache':<6} {'CPU s (median)':>14} {'call CPU s':>11}  SymPy loaded")
    for r in rows:
        call = f"{r['call_cpu_s']:.2f}" if "call_cpu_s" in r else ""
        print(f"{r['name']:<28} {r['cache']:<6} {r['cpu_s']:>14.2f} {call:>11}  {'yes' if r['sympy_loaded'] else 'no'}")
    if a.quick and a.out is None:
        return
    write_json(a.out or ROOT / "benchmarks/results.json", KEY,
               {a.label: {"rows": rows, "date": datetime.date.today().isoformat(), "machine": machine_info(),
                          "bytecode": "written and reused" if BYTECODE else "as the shell has it"}},
               merge=True)


if __name__ == "__main__":
    main()
