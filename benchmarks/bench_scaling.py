"""How the whole-tree fit and ``diagnose`` grow with the frames and with the markers, side by side with the dense
normal equations they replaced, with the scaling exponents fitted and a figure.

Two sweeps of simulated, clean, rigid trials (:func:`identcheck.simulate.rigid.simulate`, 100 Hz, 0.7 mm white
noise, one seed; written once by this tree and read by both versions, so both fit the same numbers):

* **frames**: the bundled lower limb (``examples/diagnose_leg.toml``, 9 markers, hip and knee) at
  ``--frames`` (default 500, 1000, 2000, 4000, 8000);
* **markers**: at 1500 frames, the lower limb (9), both legs with the pelvis (pelvis, thighs, shanks, feet; 21) and
  a full body of 14 segments (pelvis, trunk, thighs, shanks, feet, upper arms, forearms, hands; 13 joints) with 3,
  4 and 5 markers a segment (42, 56, 70; ``diagnose`` needs three on every segment).

Each point is measured in fresh processes with one BLAS thread:

* ``fit``: CPU seconds per Levenberg-Marquardt iteration of :func:`identcheck.bundle.chain.fit_chain` from
  :func:`~identcheck.bundle.chain.initial_state` (``--iterations``, fewer if it converges; the median of
  ``--repeats`` processes) and the process's peak resident memory, with this tree and with ``--baseline``
  (default b5194a3, the last commit whose normal equations were dense: every marker's row against every
  constant), taking turns;
* ``diagnose``: the whole command (``python -m identcheck diagnose MODEL TRIAL --json``) with this tree, CPU
  seconds of the process and its peak resident memory, once, capped at ``--cap`` seconds of wall time (a capped
  run is reported as such, with no time). Not with the baseline: its ``diagnose`` is another program (fewer
  effects and detectors, joints judged without intervals), so its time says nothing of the normal equations.

The exponent is the least-squares slope of log time against log frames (or log markers) over the points both
versions finished; 1 is linear. Usage::

    python benchmarks/bench_scaling.py [--baseline b5194a3] [--key scaling] [--quick]

Results: ``benchmarks/results.json`` under ``--key``; the figure ``benchmarks/scaling.png`` (time against frames
and against markers, both versions, log-log).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import results_io  # noqa: E402
import worktree  # noqa: E402

ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "IDENTCHECK_THREADS": "1"}
BODY_SEGMENTS = (("pelvis", None), ("trunk", 450))
LIMBS = (("thigh", 420, "hip", "spherical", "pelvis"), ("shank", 400, "knee", "revolute", "thigh"),
         ("foot", 200, "ankle", "revolute", "shank"), ("upperarm", 300, "shoulder", "spherical", "trunk"),
         ("forearm", 260, "elbow", "revolute", "upperarm"), ("hand", 90, "wrist", "spherical", "forearm"))


def body_model(markers_per_segment: int, legs_only: bool = False, names: dict | None = None) -> str:
    """A model file: a full body of 14 segments (or, with `legs_only`, the pelvis and both legs: 7 segments), each
    with `markers_per_segment` markers (named SEGMENT1, SEGMENT2, ..., or as `names` gives them: segment -> labels),
    ball joints at the lumbar spine, hips, shoulders and wrists and hinges at the knees, ankles and elbows."""
    segs = [(name, length) for name, length in BODY_SEGMENTS if not (legs_only and name == "trunk")]
    joints = [] if legs_only else [("lumbar", "spherical", "pelvis", "trunk")]
    for side in ("r", "l"):
        for seg, length, joint, kind, parent in LIMBS[:3] if legs_only else LIMBS:
            segs.append((f"{seg}_{side}", length))
            joints.append((f"{joint}_{side}", kind, parent if parent in ("pelvis", "trunk") else f"{parent}_{side}",
                           f"{seg}_{side}"))
    text = ['units = "mm"']
    for name, length in segs:
        marks = (names or {}).get(name) or [f"{name.upper()}{i + 1}" for i in range(markers_per_segment)]
        text += [f"[segments.{name}]", "markers = [" + ", ".join(f'"{m}"' for m in marks) + "]"]
        text += [f"length_mm = {length}"] if length else []
    for name, kind, parent, child in joints:
        text += [f"[joints.{name}]", f'type = "{kind}"', f'parent = "{parent}"', f'child = "{child}"']
    return "\n".join(text) + "\n"


def cases(frames: list, quick: bool) -> list:
    """(sweep, label, frames, model text) of every point: the frames sweep on the lower limb, the markers sweep at
    1500 frames."""
    leg = (ROOT / "examples" / "diagnose_leg.toml").read_text()
    out = [("frames", f"leg9 {f} frames", f, leg) for f in frames]
    bodies = [("legs21", body_model(3, legs_only=True)), ("body42", body_model(3))]
    bodies += [] if quick else [("body56", body_model(4)), ("body70", body_model(5))]
    out += [("markers", "leg9", 1500, leg)] + [("markers", name, 1500, text) for name, text in bodies]
    return out


def write_trial(folder: Path, label: str, n_frames: int, model_text: str, seed: int = 11) -> tuple[Path, Path, int]:
    """The case's model and a simulated clean trial (TRC) in `folder`: their paths and the trial's marker count."""
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate

    stem = label.replace(" ", "_")
    model_path = folder / f"{stem}.toml"
    model_path.write_text(model_text)
    sim = simulate(Model.from_toml(model_path), n_frames=n_frames, noise_mm=0.7, seed=seed)
    trial_path = folder / f"{stem}.trc"
    sim.trial.to_trc(trial_path)
    return model_path, trial_path, sim.trial.n_markers


# ---------------------------------------------------------------------- measured in a fresh process
def fit_worker(model: str, trial: str, iterations: int) -> dict:
    """``fit_chain`` from its initial state on the trial, `iterations` iterations at most (run by either version: only
    the model reader, the trial reader, the skeleton and the fit itself, which both have)."""
    import warnings

    warnings.simplefilter("ignore")
    from identcheck import api
    from identcheck.bundle.chain import fit_chain, initial_state
    from identcheck.io.model import Model
    from identcheck.skeleton import Skeleton

    m = Model.from_toml(model)
    data = api.read_trial(trial).recentred()[0].select(m.markers).as_array()
    chain = Skeleton.from_model(m)
    state = initial_state(chain, data)
    t0 = time.process_time()
    fit = fit_chain(chain, data, state, max_iter=iterations)
    cpu = time.process_time() - t0
    return {"cpu_s": cpu, "iterations": int(fit.iterations), "s_per_iteration": cpu / max(int(fit.iterations), 1),
            "rss_mm2": float(fit.rss), "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run_fit(code: Path, model: Path, trial: Path, iterations: int) -> dict:
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
    out = subprocess.run([sys.executable, __file__, "--fit-worker", str(model), str(trial), str(iterations)],
                         env=env, cwd=code, capture_output=True, text=True)
    if out.returncode != 0:
        return {"error": (out.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_diagnose(code: Path, model: Path, trial: Path, cap_s: float) -> dict:
    """The whole ``diagnose`` command with the package at `code`: CPU seconds and peak memory of the process (from
    ``os.wait4``), its exit code and the effects it named; ``capped`` when it ran past `cap_s` seconds of wall time."""
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        t0 = time.perf_counter()
        with open(out, "w") as fh:
            proc = subprocess.Popen([sys.executable, "-m", "identcheck", "diagnose", str(model), str(trial), "--json"],
                                    cwd=tmp, env=env, stdout=fh, stderr=subprocess.DEVNULL)
            capped = False
            while True:                       # reaped by wait4 itself (poll() would take its resource usage)
                pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
                if pid:
                    break
                if time.perf_counter() - t0 > cap_s and not capped:
                    proc.kill()
                    capped = True
                time.sleep(0.05)
        row = {"wall_s": time.perf_counter() - t0, "cpu_s": usage.ru_utime + usage.ru_stime,
               "max_rss_mib": usage.ru_maxrss / 1024, "exit_code": os.waitstatus_to_exitcode(status)}
        if capped:
            return {"capped": True, "cap_s": cap_s, "max_rss_mib": row["max_rss_mib"]}
        if row["exit_code"] not in (0, 1):                  # an error is no diagnosis: its time is not one
            return {"error": row["exit_code"], "max_rss_mib": row["max_rss_mib"]}
        try:
            doc = json.loads(out.read_text())
            row["effects"] = [e["name"] for e in doc.get("effects", [])]
        except (ValueError, KeyError, TypeError):
            row["effects"] = None
        return row


def slope(xs: list, ys: list) -> float | None:
    """The least-squares slope of log y against log x, None with fewer than two points."""
    pts = [(x, y) for x, y in zip(xs, ys) if y is not None and y > 0]
    if len(pts) < 2:
        return None
    lx, ly = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(lx, ly, 1)[0])


def exponents(rows: list, startup_cpu_s: float) -> dict:
    """Per sweep: the slope of log time against log frames (or markers) of the fit's iterations, both versions over
    the points both finished, and of ``diagnose`` (this tree) three ways: the whole process, the process less the
    CPU of starting Python and importing the package for the command (`startup_cpu_s`, which a longer trial does not
    change), and that over the upper half of the points (where growth shows rather than fixed costs)."""
    out = {}
    for sweep, x in (("frames", "frames"), ("markers", "markers")):
        pts = [r for r in rows if r["sweep"] == sweep]
        both = [r for r in pts if all(r[v]["fit"].get("s_per_iteration") for v in ("baseline", "current"))]
        for version in ("baseline", "current"):
            out[f"{sweep}/fit_s_per_iteration/{version}"] = slope(
                [r[x] for r in both], [r[version]["fit"]["s_per_iteration"] for r in both])
        done = [r for r in pts if r["current"]["diagnose"].get("cpu_s")]
        xs, ys = [r[x] for r in done], [r["current"]["diagnose"]["cpu_s"] for r in done]
        net = [y - startup_cpu_s for y in ys]
        upper = len(done) // 2
        out[f"{sweep}/diagnose_cpu_s/current"] = slope(xs, ys)
        out[f"{sweep}/diagnose_cpu_s_less_startup/current"] = slope(xs, net)
        out[f"{sweep}/diagnose_cpu_s_less_startup_upper_half/current"] = slope(xs[upper:], net[upper:])
    return out


def startup_cpu(code: Path) -> float:
    """CPU seconds of a process that starts Python and imports what ``diagnose`` imports, and does nothing else (the
    median of three)."""
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(code)}
    took = []
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, "-c", "import identcheck.cli, identcheck.api, "
                                 "identcheck.diagnose.workflow"], cwd=code, env=env)
        _, _, usage = os.wait4(proc.pid, 0)
        took.append(usage.ru_utime + usage.ru_stime)
    return statistics.median(took)


def figure(rows: list, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (sweep, x, xlabel) in zip(axes, (("frames", "frames", "frames (lower limb, 9 markers)"),
                                             ("markers", "markers", "markers (1500 frames)"))):
        pts = [r for r in rows if r["sweep"] == sweep]
        for version, colour in (("baseline", "tab:grey"), ("current", "tab:blue")):
            for measure, field, style in (("fit: s per iteration", ("fit", "s_per_iteration"), "o-"),
                                          ("diagnose: CPU s", ("diagnose", "cpu_s"), "s--")):
                xy = [(r[x], r[version][field[0]].get(field[1])) for r in pts]
                xy = [(a, b) for a, b in xy if b]
                if xy:
                    ax.plot(*zip(*xy), style, color=colour, label=f"{measure}, {version}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ticks = sorted({r[x] for r in pts})
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel(xlabel)
        ax.set_ylabel("CPU seconds")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Whole-tree fit and diagnose (clean simulated trials) against frames and markers: "
                 "the dense normal equations grey, this tree blue")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table(rows: list, exps: dict) -> str:
    out = [f"{'case':22s} {'markers':>7s} {'frames':>6s} | {'fit s/iter':>21s} | {'fit MiB':>13s} | "
           f"{'diagnose CPU s':>17s} | {'diagnose MiB':>13s}",
           f"{'':22s} {'':7s} {'':6s} | {'dense':>10s} {'now':>10s} | {'dense':>6s} {'now':>6s} | "
           f"{'dense':>8s} {'now':>8s} | {'dense':>6s} {'now':>6s}"]

    def f(v, fmt):
        width = int(fmt.split(".")[0])
        return (str(v) if v == "capped" else "-" if v is None else format(v, fmt)).rjust(width)
    for r in rows:
        b, c = r["baseline"], r["current"]
        cells = []
        for part, key, fmt in (("fit", "s_per_iteration", "10.4f"), ("fit", "max_rss_mib", "6.0f"),
                               ("diagnose", "cpu_s", "8.1f"), ("diagnose", "max_rss_mib", "6.0f")):
            cells.append(" ".join(f("capped" if v[part].get("capped") and key == "cpu_s" else v[part].get(key), fmt)
                                  for v in (b, c)))
        out.append(f"{r['label']:22s} {r['markers']:7d} {r['frames']:6d} | " + " | ".join(cells))
    out.append("")
    out.append("exponents (slope of log time against log frames or markers; 1 = linear):")
    for k, v in exps.items():
        out.append(f"  {k:40s} {'-' if v is None else f'{v:.2f}'}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default="b5194a3", help="the commit to compare with (default: dense normal "
                                                          "equations)")
    ap.add_argument("--frames", default="500,1000,2000,4000,8000")
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cap", type=float, default=600.0, help="wall seconds a diagnose may take (default 600)")
    ap.add_argument("--quick", action="store_true", help="no 56- and 70-marker bodies (a check of the script)")
    ap.add_argument("--key", default="scaling")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--figure", type=Path, default=ROOT / "benchmarks" / "scaling.png")
    ap.add_argument("--fit-worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.fit_worker:
        model, trial, iterations = args.fit_worker
        print(json.dumps(fit_worker(model, trial, int(iterations))))
        return 0
    frames = [int(x) for x in args.frames.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp, worktree.checkout(args.baseline) as base:
        folder = Path(tmp)
        todo = cases(frames, args.quick)
        for n, (sweep, label, n_frames, text) in enumerate(todo):
            model, trial, n_markers = write_trial(folder, label, n_frames, text)
            row = {"sweep": sweep, "label": label, "frames": n_frames, "markers": n_markers}
            order = [("baseline", base), ("current", ROOT)]
            for version, code in order if n % 2 == 0 else order[::-1]:
                fits = [run_fit(code, model, trial, args.iterations) for _ in range(args.repeats)]
                good = [x for x in fits if "error" not in x]
                fit = {"error": fits[0].get("error")} if not good else {
                    "s_per_iteration": statistics.median(x["s_per_iteration"] for x in good),
                    "all_s_per_iteration": [x["s_per_iteration"] for x in good],
                    "iterations": good[0]["iterations"], "rss_mm2": good[0]["rss_mm2"],
                    "max_rss_mib": max(x["max_rss_mib"] for x in good)}
                row[version] = {"fit": fit, "diagnose": run_diagnose(code, model, trial, args.cap)
                                if version == "current" else {}}
            print(f"[{n + 1}/{len(todo)}] {label}: fit s/iter {row['baseline']['fit'].get('s_per_iteration')} -> "
                  f"{row['current']['fit'].get('s_per_iteration')}; diagnose CPU "
                  f"{row['current']['diagnose'].get('cpu_s', 'capped')}", flush=True)
            rows.append(row)
    startup = startup_cpu(ROOT)
    exps = exponents(rows, startup)
    print(table(rows, exps))
    print(f"(starting Python and importing what diagnose imports: {startup:.2f} CPU s)")
    figure(rows, args.figure)
    results_io.write_json(args.out, args.key, {
        "baseline": args.baseline, "current": worktree.head(), "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "machine": results_io.machine_info(), "iterations": args.iterations, "repeats": args.repeats,
        "cap_s": args.cap, "startup_cpu_s": startup, "rows": rows, "exponents": exps, "figure": str(args.figure.relative_to(ROOT))
        if args.figure.is_relative_to(ROOT) else str(args.figure)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
