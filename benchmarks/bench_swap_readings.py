"""The model-free label-swap readings on trials they were not tuned on: is every swap found, with its span, and nothing
else?

The trials come from the independent effects generator (``benchmarks/heldout_effects/``, version 2: occlusion gaps,
anatomical layouts with two-marker segments, swaps that begin inside a gap, within a segment and across neighbouring
ones). Each reading of :mod:`identcheck.estimate.labels` runs on the raw trial, as ``diagnose`` proposes from it:

- ``distances``: :func:`detect` (within-segment distances as labelled and exchanged), kept when the exchanged
  distances fit (:func:`fits_exchanged`, what ``fit``'s screen leaves out), at the trial's noise floor;
- ``flips``: :func:`flips` (a segment's pose turning by a half turn at both ends of the span);
- ``exchanges``: :func:`exchanges` (trajectories going on under each other's label, handovers across gaps).

Per reading and in all: the true swaps found with their exact span (``exact``), with their pair but another span
(``other_span``: the hidden frames of a gap of both markers may make two spans exchange the same samples), missed, and
found where the trial has no such swap (``false``). No thresholds are tuned here.

Usage::

    python benchmarks/heldout_effects/generator.py --out /tmp/hx --n 120 --seed 35 --version 2
    PYTHONPATH=. python benchmarks/bench_swap_readings.py /tmp/hx [--key K]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import identcheck as ic  # noqa: E402
from identcheck.estimate.labels import detect, exchanges, fits_exchanged, flips  # noqa: E402
from identcheck.estimate.noise import noise_floor  # noqa: E402
from identcheck.skeleton import Skeleton  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402

READINGS = ("distances", "flips", "exchanges")


def readings(model, data: np.ndarray) -> dict:
    """Each reading's swaps on `data` as (set of labels, [first, last]), and the seconds each took."""
    chain = Skeleton.from_model(model)
    noise = noise_floor(data, chain.labels, {s: model.segments[s].markers for s in model.segments})
    n_obs = int(np.all(np.isfinite(data), axis=2).sum())
    calls = {"distances": lambda: [d for d in detect(data, chain, noise.sigma_mm, n_obs) if fits_exchanged(d)],
             "flips": lambda: flips(data, chain), "exchanges": lambda: exchanges(data, chain)}
    out, seconds = {}, {}
    for name, call in calls.items():
        t0 = time.perf_counter()
        found = call()
        seconds[name] = time.perf_counter() - t0
        out[name] = [(sorted(chain.labels[c] for c in d["cols"]), [int(d["span"][0]), int(d["span"][1])])
                     for d in found]
    return {"found": out, "seconds": seconds}


def score(found: list, truth: list) -> dict:
    """Counts of `found` swaps against the `truth` swaps (both as (labels, span))."""
    pairs = [t[0] for t in truth]
    exact = [t for t in truth if t in found]
    other = [t for t in truth if t not in found and t[0] in [f[0] for f in found]]
    return {"exact": len(exact), "other_span": len(other), "missed": len(truth) - len(exact) - len(other),
            "false": len([f for f in found if f[0] not in pairs])}


def evaluate(folder: Path, entry: dict) -> dict:
    stem = entry["stem"]
    model = ic.load_model(folder / f"{stem}.toml")
    data = ic.read_trial(folder / f"{stem}.trc").select(model.markers).as_array()
    truth = [(sorted(e["where"]["markers"]), list(e["where"]["frames"])) for e in entry["effects"]
             if e["name"] == "marker_swap"]
    r = readings(model, data)
    every = [f for name in READINGS for f in r["found"][name]]
    union = [f for k, f in enumerate(every) if f not in every[:k]]
    return {"stem": stem, "truth": truth, "shapes": [e.get("shape", "") for e in entry["effects"]
                                                     if e["name"] == "marker_swap"],
            "found": r["found"], "seconds": r["seconds"],
            "score": {**{name: score(r["found"][name], truth) for name in READINGS}, "any": score(union, truth)}}


def summarise(rows: list) -> dict:
    out = {}
    for name in READINGS + ("any",):
        counts = {k: sum(r["score"][name][k] for r in rows) for k in ("exact", "other_span", "missed", "false")}
        counts["false_trials"] = sum(1 for r in rows if r["score"][name]["false"])
        if name != "any":
            counts["median_ms"] = round(1e3 * float(np.median([r["seconds"][name] for r in rows])), 1)
        out[name] = counts
    return {"trials": len(rows), "swaps": sum(len(r["truth"]) for r in rows), "by_reading": out,
            "in_gap": {k: sum(r["score"]["any"][k] for r in rows if any("in_gap" in s for s in r["shapes"]))
                       for k in ("exact", "other_span", "missed")}}


def table(s: dict) -> str:
    lines = [f"{s['trials']} trials, {s['swaps']} swaps (begun in a gap: {s['in_gap']})",
             f"{'reading':<10} {'exact':>6} {'other':>6} {'missed':>7} {'false':>6} {'ms':>6}"]
    for name, c in s["by_reading"].items():
        lines.append(f"{name:<10} {c['exact']:>6} {c['other_span']:>6} {c['missed']:>7} {c['false']:>6} "
                     f"{c.get('median_ms', ''):>6}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", type=Path)
    ap.add_argument("--key", default="swap_readings")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--note", default="", help="what the run is (the code, the draw's history)")
    a = ap.parse_args(argv)
    index = json.loads((a.trials / "index.json").read_text())
    rows = [evaluate(a.trials, e) for e in index["trials"]]
    s = summarise(rows)
    print(table(s))
    for r in rows:
        every = [f for n in READINGS for f in r["found"][n]]
        for t in r["truth"]:
            if t not in every:
                print(f"  not exact: {r['stem']} {t} -> {every}")
        if r["score"]["any"]["false"]:
            print(f"  false: {r['stem']} {r['found']}")
    write_json(a.out, a.key, {"summary": s, "rows": rows, "source": {
        "folder": str(a.trials), "generator": index.get("generator"), "version": index.get("version"),
        "seed": index.get("seed")}, "note": a.note, "machine": machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
