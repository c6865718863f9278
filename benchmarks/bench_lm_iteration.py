"""What one Levenberg-Marquardt iteration of the whole-chain fit costs, side by side with an earlier commit, and
what the command line's allocator setting adds; and what ``identcheck fit`` costs end to end on a real trial.

Every ``fit`` and ``diagnose`` call spends most of its time in :func:`identcheck.bundle.chain.fit_chain`
iterations (the normal equations of every marker sample, the per-frame unknowns eliminated, the step tried).
This script runs the same fits with this working tree and with a baseline commit (checked out into a temporary
``git worktree``), each in a fresh process with one BLAS thread, with glibc's default allocator and with the
setting ``identcheck`` makes at start (:func:`identcheck.cli.keep_freed_memory`: freed memory is kept for
reuse instead of fresh pages being mapped, and page-faulted, for every large temporary).

Chains (1500 frames at 100 Hz, 0.7 mm white noise, simulated unless said otherwise):

* ``leg9``: examples/diagnose_leg.toml (3 + 3 + 3 markers, hip and knee; 44 constants);
* ``walking2``: both legs of the real Vicon walking trial, examples/real_walking2_legs.toml on
  examples/real/opensim_walking2.c3d (16 markers, 4 joints, 1249 frames with gaps; 82 constants);
* ``body42``: a full body of 14 segments with 3 markers each (pelvis, trunk, thighs, shanks, feet, upper arms,
  forearms, hands; 13 joints: 7 ball, 6 hinge; 234 constants).

Each fit starts from :func:`identcheck.bundle.chain.initial_state` and runs ``--iterations`` iterations (fewer
if it converges first; both versions take the same steps up to rounding). Reported: CPU seconds per iteration
(median of ``--repeats`` processes) and the process's peak resident memory.

``body42_end_to_end`` rows: ``identcheck fit`` and ``identcheck diagnose`` on a simulated ``body42`` trial, baseline and
current taking turns: wall, CPU and the peak resident memory of each process, and a digest of its JSON.

End to end (``end_to_end`` rows; ``--no-end-to-end`` skips them): ``identcheck fit`` on both legs of walking2
with the baseline, and with this tree on one thread and on its default threads (``IDENTCHECK_THREADS``): wall
and CPU seconds of the whole command, and how many marker distances got a profile-likelihood interval rather
than none (the profiles stop starting after 60 s of wall time).

Usage::

    PYTHONPATH=. python3 benchmarks/bench_lm_iteration.py [--baseline b5194a3] [--iterations 8] [--repeats 3]

Results go to ``benchmarks/results.json`` under ``"lm_iteration"``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
import worktree  # noqa: E402

KEY = "lm_iteration"
CHAINS = ("leg9", "walking2", "body42")


LAB_MARKERS = {"thigh": ("GT", "THI", "KNE"), "shank": ("TIB", "TIB2", "ANK"), "foot": ("HEE", "TOE", "MT5"),
               "upperarm": ("SHO", "UPA", "ELB"), "forearm": ("FRA", "WRA", "WRB"), "hand": ("FIN", "HND", "HN2")}
"""The ``body42`` limbs' markers, each prefixed with the side (R or L)."""


def body42() -> str:
    """The ``body42`` model file: 14 segments with 3 markers each, 13 joints (the body of
    :func:`bench_scaling.body_model`, with lab-style marker names)."""
    from bench_scaling import body_model

    names = {"pelvis": ["LASI", "RASI", "SACR"], "trunk": ["C7", "T10", "STRN"]}
    names.update({f"{seg}_{side.lower()}": [side + m for m in marks] for seg, marks in LAB_MARKERS.items()
                  for side in ("R", "L")})
    return body_model(3, names=names)


# ---------------------------------------------------------------------- one measurement, in a fresh process
def _keep_freed_memory() -> None:
    """The allocator setting of :func:`identcheck.cli.keep_freed_memory`, written out here so that the baseline
    (which may predate it) is measured with it too."""
    import ctypes
    import ctypes.util

    mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    mallopt(-3, 32 << 20)
    mallopt(-1, 1 << 30)


def _chain_data(name: str):
    import warnings

    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate
    from identcheck.skeleton import Skeleton

    warnings.simplefilter("ignore")
    if name == "walking2":
        from identcheck import api

        model = Model.from_toml(ROOT / "examples" / "real_walking2_legs.toml")
        trial = api.read_trial(ROOT / "examples" / "real" / "opensim_walking2.c3d").recentred()[0]
        data = trial.select(model.markers).as_array()
    else:
        if name == "leg9":
            model = Model.from_toml(ROOT / "examples" / "diagnose_leg.toml")
        else:
            with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as fh:
                fh.write(body42())
            model = Model.from_toml(fh.name)
            os.unlink(fh.name)
        data = simulate(model, n_frames=1500, noise_mm=0.7, seed=11).trial.as_array()
    return Skeleton.from_model(model), data


def worker(name: str, alloc: bool, iterations: int) -> dict:
    from threadpoolctl import threadpool_limits

    from identcheck.bundle.chain import fit_chain, initial_state

    if alloc:
        _keep_freed_memory()
    chain, data = _chain_data(name)
    state = initial_state(chain, data)
    with threadpool_limits(1):
        t0 = time.process_time()
        fit = fit_chain(chain, data, state, max_iter=iterations)
        cpu = time.process_time() - t0
    return {"cpu_s": cpu, "iterations": fit.iterations, "s_per_iteration": cpu / max(fit.iterations, 1),
            "rss": fit.rss, "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def measure(pythonpath: Path, name: str, alloc: bool, iterations: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(pythonpath), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--worker", name, "--alloc", str(int(alloc)),
                          "--iterations", str(iterations)], env=env, cwd=ROOT, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def fit_command(path: Path, version: str, threads: str | None) -> dict:
    """``identcheck fit`` on both legs of walking2 with the package at `path`: wall and CPU seconds of the
    process, and the interval methods of the knees' and hips' marker distances. Run from `path`: ``python -m``
    puts the working directory ahead of ``PYTHONPATH``."""
    env = dict(os.environ, PYTHONPATH=str(path))
    env.pop("IDENTCHECK_THREADS", None)
    if threads:
        env["IDENTCHECK_THREADS"] = threads
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "identcheck", "fit", str(ROOT / "examples" / "real_walking2_legs.toml"),
                          str(ROOT / "examples" / "real" / "opensim_walking2.c3d"), "--json"], env=env, cwd=path,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    methods: dict = {}
    for joint in json.loads(out.stdout)["joints"].values():
        for how in joint["interval_method"].values():
            methods[how] = methods.get(how, 0) + 1
    row = {"command": "identcheck fit examples/real_walking2_legs.toml examples/real/opensim_walking2.c3d",
           "version": version, "threads": threads or "default", "exit_code": out.returncode, "wall_s": wall,
           "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), "interval_methods": methods}
    print(f"fit walking2 {version:9s} threads {row['threads']:8s} {wall:6.1f} s wall {row['cpu_s']:6.1f} s CPU  "
          f"intervals {methods}", flush=True)
    return row


def run_body42(path: Path, version: str, folder: Path, verb: str = "fit") -> dict:
    """``identcheck fit`` (or `verb`: ``diagnose``) on the simulated ``body42`` trial (1500 frames, 0.7 mm) with the
    package at `path`: wall and CPU seconds and the peak resident memory of that one process (``os.wait4``), and a
    digest of its JSON."""
    model, trial = folder / "body42.toml", folder / "body42.trc"
    if not trial.exists():
        model.write_text(body42())
        subprocess.run([sys.executable, "-m", "identcheck", "simulate", str(model), "--out", str(trial), "--frames",
                        "1500", "--noise-mm", "0.7", "--seed", "11"], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                       cwd=ROOT, capture_output=True, check=True)
    env = dict(os.environ, PYTHONPATH=str(path), IDENTCHECK_THREADS="1")
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "identcheck", verb, str(model), str(trial), "--json"], env=env,
                            cwd=path, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    stdout = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    row = {"command": f"identcheck {verb} body42.toml body42.trc --json", "version": version,
           "wall_s": time.perf_counter() - t0, "cpu_s": usage.ru_utime + usage.ru_stime,
           "max_rss_mib": usage.ru_maxrss / 1024, "exit_code": proc.returncode,
           "json_sha256": hashlib.sha256(stdout).hexdigest()[:16]}
    print(f"{verb:8s} body42 {version:9s} {row['wall_s']:6.1f} s wall {row['cpu_s']:6.1f} s CPU  peak "
          f"{row['max_rss_mib']:.0f} MiB  JSON {row['json_sha256']}", flush=True)
    return row


# ---------------------------------------------------------------------- the table
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="b5194a3", help="commit to compare with (default: before the block-wise "
                                                          "normal equations)")
    ap.add_argument("--iterations", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chains", nargs="+", default=list(CHAINS), choices=CHAINS)
    ap.add_argument("--no-end-to-end", action="store_true")
    ap.add_argument("--key", default=KEY, help="results.json key (another baseline: another key)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--worker", choices=CHAINS, help=argparse.SUPPRESS)
    ap.add_argument("--alloc", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.worker, bool(a.alloc), a.iterations)))
        return 0
    head = worktree.head()
    rows = []
    with worktree.checkout(a.baseline) as base:
        for name in a.chains:
            for version, path in (("baseline", base), ("current", ROOT)):
                for alloc in (False, True):
                    runs = [measure(path, name, alloc, a.iterations) for _ in range(a.repeats)]
                    row = {"chain": name, "version": version, "allocator": "kept" if alloc else "default",
                           "s_per_iteration": statistics.median(r["s_per_iteration"] for r in runs),
                           "all_s_per_iteration": [r["s_per_iteration"] for r in runs],
                           "iterations": runs[0]["iterations"], "rss": runs[0]["rss"],
                           "max_rss_mib": max(r["max_rss_mib"] for r in runs)}
                    rows.append(row)
                    print(f"{name:9s} {version:9s} allocator {row['allocator']:8s} "
                          f"{1000 * row['s_per_iteration']:8.1f} ms/iteration  ({row['iterations']} iterations, "
                          f"peak {row['max_rss_mib']:.0f} MiB, rss {row['rss']:.6g})", flush=True)
        end_to_end = [] if a.no_end_to_end else [
            fit_command(base, "baseline", None), fit_command(ROOT, "current", "1"), fit_command(ROOT, "current", None)]
        with tempfile.TemporaryDirectory() as tmp:
            body = [run_body42(p, v, Path(tmp), verb) for verb in ("fit", "diagnose") for _ in range(a.repeats)
                    for v, p in (("baseline", base), ("current", ROOT))]
    speedup = {}
    for name in a.chains:
        pick = {(r["version"], r["allocator"]): r["s_per_iteration"] for r in rows if r["chain"] == name}
        speedup[name] = {"current_vs_baseline_default_allocator": pick[("baseline", "default")] / pick[("current", "default")],
                         "current_kept_vs_baseline_default": pick[("baseline", "default")] / pick[("current", "kept")]}
        print(f"{name:9s} speed-up {speedup[name]['current_vs_baseline_default_allocator']:.2f}x (same allocator), "
              f"{speedup[name]['current_kept_vs_baseline_default']:.2f}x (with the command line's allocator)")
    write_json(a.out, a.key, {"machine": machine_info(), "baseline": a.baseline, "current": head.strip(),
                            "iterations": a.iterations, "repeats": a.repeats, "rows": rows, "speedup": speedup,
                            "end_to_end": end_to_end, "body42_end_to_end": body,
                            "date": time.strftime("%Y-%m-%dT%H:%M:%S")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
