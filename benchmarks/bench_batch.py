"""Throughput of `identcheck batch fit` on a local Dask cluster: trials per minute with 1 and 2 worker processes
against the plain serial loop (``api.fit`` on each trial in this process), and the same trial set run again on the
same output folder (every job done: all skipped, no cluster started).

Trials: `--trials` simulated trials of `examples/diagnose_leg.toml` (2 joints, 9 markers), `--frames` frames each,
0.5 mm noise, every other one C3D, written once to a temporary folder (removed afterwards). Each batch row is the
wall time of the whole `identcheck.batch(...)` call, cluster start-up and the workers' first imports included,
so that it is what a user waits for; the serial row includes this process's first fit (its warm-up). The JSON of
every job is written, as the batch does, by both. Each row also records the share of the machine's CPU that other
processes took while it ran (from /proc/stat): on a shared machine that share, not the batch, may set the pace.

Prints a table and writes key "batch" of benchmarks/results.json ("batch_quick" for --quick, which never
overwrites the full run); other keys are kept.

    PYTHONPATH=. python3 benchmarks/bench_batch.py [--trials 40] [--frames 500] [--quick] [--out benchmarks/results.json]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import results_io  # noqa: E402

MODEL = "examples/diagnose_leg.toml"
KEY = "batch"
FULL = {"trials": 40, "frames": 500}
QUICK = {"trials": 4, "frames": 200}


def cpu_now():
    """(CPU seconds the whole machine has been busy, CPU seconds of this process and its finished children): the
    difference of two calls gives the CPU that other processes took meanwhile (None where /proc/stat is missing)."""
    t = os.times()
    ours = t.user + t.system + t.children_user + t.children_system
    try:
        with open("/proc/stat") as fh:
            ticks = [int(x) for x in fh.readline().split()[1:9]]
    except OSError:
        return None, ours
    return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK"), ours


def timed(row: dict, fn):
    """Run `fn`, adding to `row` its wall seconds and the CPU share other processes took meanwhile (a shared
    machine's load: with 2 cores, a share of 0.5 leaves one core to the benchmark)."""
    busy0, ours0 = cpu_now()
    start = time.perf_counter()
    out = fn()
    row["wall_s"] = time.perf_counter() - start
    busy1, ours1 = cpu_now()
    if busy0 is not None:
        others = max(0.0, (busy1 - busy0) - (ours1 - ours0))
        row["others_cpu_share"] = others / (row["wall_s"] * (os.cpu_count() or 1))
    return out


def make_trials(folder: Path, n: int, frames: int) -> list:
    """`n` simulated trials (TRC and C3D alternately) of the benchmark model in `folder`."""
    from identcheck import api

    paths = []
    for k in range(n):
        path = folder / f"trial{k:03d}.{'trc' if k % 2 == 0 else 'c3d'}"
        api.simulate(ROOT / MODEL, path, seed=k, n_frames=frames, noise_mm=0.5)
        paths.append(path)
    return paths


def serial(trials: list, out: Path) -> None:
    """The loop a user would write without the batch: fit each trial here and write its JSON."""
    from identcheck import api
    from identcheck.report import json_out

    out.mkdir()
    for t in trials:
        (out / f"{t.name}.json").write_text(json_out.dumps(api.fit(ROOT / MODEL, t)) + "\n")


def batch(folder: Path, out: Path, workers: int):
    """`identcheck.batch("fit", ...)` on a local cluster of `workers` processes: the summary."""
    import identcheck

    return identcheck.batch("fit", [str(ROOT / MODEL), str(folder)], out, workers=workers, dashboard=":0")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=None, help=f"trials (default {FULL['trials']}; "
                                                                f"{QUICK['trials']} for --quick)")
    ap.add_argument("--frames", type=int, default=None, help=f"frames per trial (default {FULL['frames']}; "
                                                                f"{QUICK['frames']} for --quick)")
    ap.add_argument("--quick", action="store_true", help="a small run, stored under batch_quick")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder of trials and outputs")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results.json"))
    a = ap.parse_args(argv)
    cfg = dict(QUICK if a.quick else FULL)
    cfg.update({k: v for k, v in (("trials", a.trials), ("frames", a.frames)) if v is not None})
    load_before = list(os.getloadavg())
    work = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        t0 = time.perf_counter()
        (work / "trials").mkdir()
        trials = make_trials(work / "trials", cfg["trials"], cfg["frames"])
        print(f"{len(trials)} trials of {cfg['frames']} frames simulated in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr)
        n = len(trials)
        rows = [{"run": "serial loop (api.fit, this process)", "workers": 0, "jobs_run": n}]
        timed(rows[-1], lambda: serial(trials, work / "serial"))
        for workers in (1, 2):
            rows.append({"run": f"batch, {workers} worker{'s' if workers > 1 else ''}", "workers": workers,
                         "jobs_run": n})
            df = timed(rows[-1], lambda: batch(work / "trials", work / f"batch{workers}", workers))
            assert set(df["status"]) == {"done"}, df[df["status"] != "done"][["job", "error"]]
            rows[-1]["job_s_sum"] = float(df.drop_duplicates("job")["seconds"].sum())
        rows.append({"run": "batch, 2 workers, run again (resume)", "workers": 2})
        df = timed(rows[-1], lambda: batch(work / "trials", work / "batch2", 2))
        skipped = int((df.drop_duplicates("job")["status"] == "skipped").sum())
        rows[-1].update(jobs_run=n - skipped, skipped=skipped)
    finally:
        if a.keep:
            print(f"kept {work}", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)
    base = rows[0]["wall_s"]
    for r in rows:
        r["trials_per_min"] = 60.0 * n / r["wall_s"]
        r["speedup_vs_serial"] = base / r["wall_s"]
    head = f"{'run':<40} {'wall s':>8} {'trials/min':>11} {'vs serial':>10} {'jobs run':>9} {'others CPU':>11}"
    print(head)
    print("-" * len(head))
    for r in rows:
        share = f"{100 * r['others_cpu_share']:.0f} %" if "others_cpu_share" in r else "-"
        print(f"{r['run']:<40} {r['wall_s']:>8.1f} {r['trials_per_min']:>11.1f} {r['speedup_vs_serial']:>9.2f}x "
              f"{r['jobs_run']:>9} {share:>11}")
    print("others CPU: the share of the machine's CPU other processes took during the run (a shared machine)")
    results_io.write_json(a.out, KEY + ("_quick" if a.quick else ""), {
        "settings": {"quick": a.quick, "model": MODEL, "trials": n, "frames": cfg["frames"], "noise_mm": 0.5,
                     "formats": "TRC and C3D alternately", "verb": "fit"},
        "rows": rows, "machine": results_io.machine_info(loadavg_before=load_before)})
    return 0


if __name__ == "__main__":      # required: the cluster's worker processes are spawned and import this module again
    sys.exit(main())
