"""``identcheck skeleton`` on full-body functional trials it was not tuned on: is the joint that moved found?

The trials come from the independent generator in ``benchmarks/heldout_functional/`` (written from a spec without
reading identcheck): a full-body marker set (15 segments, 44-75 markers) on a subject standing nearly still while
one or two joints do a functional motion (star arc, circumduction, flexion cycles), soft tissue driven by the
joint angles (3-15 mm on the moving segments, about 1 mm or less on the still ones), white, AR(1) or low-pass noise
of 0.05-1 mm, gaps. Only its output files are read: ``index.json``, each trial's TRC and ``truth.json``
(``segments``, ``joints`` with ``moving``, ``units``: the segments that stay together through still joints).

The still body sways by up to 3 degrees per joint, so which of its segments the data separate is open; what a lab
needs from such a trial is the moving joint. For each moving joint (parent P, child C):

- ``child_whole`` / ``parent_whole``: every marker of C (of P) is in one inferred group, and that group holds no
  marker from across the moving joint (C's group stays within C's unit, P's within P's);
- ``joint_found``: the tree joins the group holding most of C's markers to the group holding most of P's, each
  staying on its side of the moving joint (a still pelvis may lose a marker to the trunk, through which it sways);
- ``type_right``: that joint's type is the truth's (a moving hinge revolute, a moving ball joint spherical);
- ``leak``: some inferred group mixes markers from both sides of the moving joint (a segment across the joint
  that moved), and ``leak_reported``: every marker on the minority side of such a group is reported in
  ``markers_on_joints`` (near the joint's axis or centre, which segment carries it is a choice);

and per trial ``all_found`` (every moving joint found and typed right), ``ok`` (the tool calls the skeleton
settled: exit 0), and the time of the library call. The rates are also given by moving joint, by the generator's
categories, by marker noise (:data:`NOISE_BINS`) and by trial length (:data:`FRAME_BINS`). ``--merge`` takes the
row files of several draws as well as of several shards: a pooled summary.

Usage::

    python benchmarks/heldout_functional/generator.py --out /tmp/hf --n 100 --seed 7
    PYTHONPATH=. python benchmarks/bench_skeleton_functional.py /tmp/hf [--key K] [--shard K/N --rows R] [--merge R0 R1]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import identcheck as ic  # noqa: E402
from identcheck.api import skeleton  # noqa: E402
from results_io import (add_shard_arguments, benchmark_folder, by_bin, by_category, error_rows,  # noqa: E402
                        errors_line, percent, seconds_summary)


def evaluate(folder: Path, entry: dict) -> dict:
    """Run ``skeleton`` on one trial and score its moving joints against the truth."""
    truth = json.loads((folder / entry["truth"]).read_text())
    trial = ic.read_trial(folder / entry["trc"])
    row = {"id": entry["id"], "categories": entry["categories"], "n_markers": trial.n_markers,
           "n_frames": trial.n_frames, "sigma_mm": truth["noise"]["sigma_mm"]}
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            doc = skeleton(trial).to_dict()
        except ic.InputError as exc:
            return {**row, "error": str(exc), "seconds": time.perf_counter() - t0}
    row["seconds"] = time.perf_counter() - t0
    unit_of = {s: k for k, unit in enumerate(truth["units"]) for s in unit}
    segment_of = {m: s for s, ms in truth["segments"].items() for m in ms}
    group_of = {m: g for g, ms in doc["segments"].items() for m in ms}
    edges = {frozenset((j["parent"], j["child"])): j["type"] for j in doc["joints"]}

    def whole(segment: str):
        groups = {group_of.get(m) for m in truth["segments"][segment]}
        if len(groups) != 1 or None in groups:
            return None
        (g,) = groups
        inside = {unit_of[segment_of[m]] for m in doc["segments"][g] if m in segment_of}
        return g if inside == {unit_of[segment]} else None

    def holder(segment: str):
        """The group holding most of the segment's markers (at least two, or its only one), if it stays within the
        segment's unit."""
        votes = [group_of[m] for m in truth["segments"][segment] if m in group_of]
        if not votes:
            return None
        g = max(sorted(set(votes)), key=votes.count)
        if votes.count(g) < min(2, len(truth["segments"][segment])):
            return None
        inside = {unit_of[segment_of[m]] for m in doc["segments"][g] if m in segment_of}
        return g if inside == {unit_of[segment]} else None

    moving = []
    for j in truth["joints"]:
        if not j["moving"]:
            continue
        gc, gp = holder(j["child"]), holder(j["parent"])
        sides = {unit_of[j["child"]], unit_of[j["parent"]]}
        leaking = [ms for ms in doc["segments"].values()
                   if len({unit_of[segment_of[m]] for m in ms if m in segment_of} & sides) > 1]
        leak = bool(leaking)
        on_joint = {m["marker"] for m in doc.get("markers_on_joints") or []}
        strays = set()                                   # the markers of each mixed group on its minority side
        for ms in leaking:
            count = defaultdict(int)
            for m in ms:
                count[unit_of[segment_of[m]]] += 1 if m in segment_of else 0
            major = max(sorted(count), key=count.get)
            strays |= {m for m in ms if m in segment_of and unit_of[segment_of[m]] != major}
        found = gc is not None and gp is not None and gc != gp and frozenset((gc, gp)) in edges
        moving.append({"joint": j["name"], "type": j["type"], "child_whole": whole(j["child"]) is not None,
                       "parent_whole": whole(j["parent"]) is not None, "joint_found": found,
                       "type_right": found and edges[frozenset((gc, gp))] == j["type"],
                       "found_type": edges[frozenset((gc, gp))] if found else None, "leak": leak,
                       "leak_reported": (strays <= on_joint) if leak else None})
    row["moving"] = moving
    row["all_found"] = all(m["joint_found"] and m["type_right"] for m in moving)
    row["ok"] = bool(doc["ok"])
    row["n_segments_found"] = len(doc["segments"])
    row["widened"] = len((doc.get("grouping") or {}).get("widened") or {})
    return row


NOISE_BINS = (0.1, 0.3)
"""Marker noise σ (mm per coordinate, the generator's truth: log-uniform 0.05-1 mm) bins of the rates."""
FRAME_BINS = (1000, 1500)
"""Trial length (frames, 600-2000) bins of the rates."""


def summarise(rows: list) -> dict:
    ok = [r for r in rows if "error" not in r]

    def block(rs):
        joints = [m for r in rs for m in r["moving"]]

        def rate(key):
            return float(np.mean([m[key] for m in joints])) if joints else None

        return {"trials": len(rs), "moving_joints": len(joints), "child_whole": rate("child_whole"),
                "parent_whole": rate("parent_whole"), "joint_found": rate("joint_found"),
                "type_right": rate("type_right"), "leak": rate("leak"),
                "leak_reported": (float(np.mean([m["leak_reported"] for m in joints if m["leak"]]))
                                  if any(m["leak"] for m in joints) else None),
                "all_found": float(np.mean([r["all_found"] for r in rs])) if rs else None,
                "ok": float(np.mean([r["ok"] for r in rs])) if rs else None,
                "ok_when_not_all_found": (float(np.mean([r["ok"] for r in rs if not r["all_found"]]))
                                          if any(not r["all_found"] for r in rs) else None),
                **seconds_summary(rs)}

    by_joint = defaultdict(list)
    for r in ok:
        for m in r["moving"]:
            by_joint[m["joint"].rsplit("_", 1)[0]].append({**r, "moving": [m]})
    return {"all": block(ok), "by_category": {c: block(rs) for c, rs in by_category(ok).items()},
            "by_moving_joint": {c: block(rs) for c, rs in sorted(by_joint.items())},
            "by_noise": {k: block(rs) for k, rs in by_bin(ok, "sigma_mm", NOISE_BINS, "mm").items()},
            "by_frames": {k: block(rs) for k, rs in by_bin(ok, "n_frames", FRAME_BINS, "frames").items()},
            "errors": error_rows(rows)}


def table(summary: dict) -> str:
    head = (f"{'trials':<22}{'n':>4} {'joints':>6} {'child%':>7} {'parent%':>8} {'found%':>7} {'type%':>6} "
            f"{'leak%':>6} {'rep%':>5} {'all%':>5} {'ok%':>4} {'ok|miss':>8} {'med s':>6} {'max s':>6}")
    lines = [head, "-" * len(head)]
    rows = ([("all", summary["all"])] + [(f"moving {k}", b) for k, b in summary["by_moving_joint"].items()]
            + list(summary["by_category"].items())
            + [(f"noise {k}", b) for k, b in summary.get("by_noise", {}).items()]
            + [(f"length {k}", b) for k, b in summary.get("by_frames", {}).items()])
    for name, b in rows:
        lines.append(f"{name:<22}{b['trials']:>4} {b['moving_joints']:>6} {percent(b['child_whole']):>7} "
                     f"{percent(b['parent_whole']):>8} {percent(b['joint_found']):>7} {percent(b['type_right']):>6} "
                     f"{percent(b['leak']):>6} {percent(b['leak_reported']):>5} {percent(b['all_found']):>5} "
                     f"{percent(b['ok']):>4} {percent(b['ok_when_not_all_found']):>8} {b['median_seconds'] or 0:6.2f} "
                     f"{b['max_seconds'] or 0:6.2f}")
    lines += errors_line(summary["errors"])
    lines.append("per moving joint: child%/parent%: its child's/parent's markers are one group that stays on its side; "
                 "found%: the tree joins the two; type%: found and typed right; leak%: a group mixes markers from "
                 "both sides of it; rep%: of those, every stray marker is reported as moving with both segments. "
                 "Per trial: all%: every moving joint found and typed right; ok%: called settled (exit 0); ok|miss: "
                 "called settled among trials where some moving joint was missed")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("trials", nargs="?", type=Path, help="a folder written by benchmarks/heldout_functional")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results.json")
    ap.add_argument("--key", default="skeleton_functional", help="key of results.json to write")
    add_shard_arguments(ap)
    args = ap.parse_args(argv)
    if args.trials is None and not args.merge:
        ap.error("give a trials folder (or --merge)")
    return benchmark_folder(
        args, args.trials, lambda e: evaluate(args.trials, e),
        lambda k, n, e, r: f"[{k}/{n}] {e['id']}: " + (
            f"ERROR {r['error'][:100]}" if "error" in r else
            f"all found {r['all_found']}, " + ", ".join(
                f"{m['joint']} {'found' if m['joint_found'] else 'missed'}" for m in r["moving"])
            + f", {r['seconds']:.2f} s"),
        summarise, table, lambda path: skeleton(ic.read_trial(path)))

if __name__ == "__main__":
    sys.exit(main())
