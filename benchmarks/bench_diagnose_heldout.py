"""``diagnose`` on trials it was not tuned on: which effects does it name, and which does it miss?

The trials come from the independent generator in ``benchmarks/heldout_effects/`` (written from a short spec
by an author who never read identcheck's code: its own skeleton, motions, noise and effect *shapes*: skin
that slides along the bone or bulges with two angles, slips that drift, knees that roll back, wobble or
rotate axially, segment-wide delays, lens-like and shear volume distortions, outlier bursts). For each trial
``identcheck.diagnose`` runs on the TRC and model, and its named effects are compared with the truth:

- single-effect trials: the true effect named first ("first"), named at all ("any"), or missed;
- two-effect trials: both named;
- clean trials: nothing named;
- effects named that a single- or two-effect trial does not hold;
- a confusion table (true effect -> first named effect, ``none`` when nothing was named), with the
  magnitude of each miss, so detection limits can be read off.

Usage::

    python benchmarks/heldout_effects/generator.py --out /tmp/hx --n 120 --seed 11
    PYTHONPATH=. python benchmarks/bench_diagnose_heldout.py /tmp/hx [--shard K/N --rows R.json] [--merge R0 R1]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

import numpy as np
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent / "heldout_effects"))    # its generator: the truth's simulate

import identcheck as ic  # noqa: E402
from results_io import add_shard_arguments, machine_info, run_trials, write_json  # noqa: E402


def visible_chi2(trial_dir: Path, entry: dict, only: int | None = None) -> float | None:
    """What of the trial's effects a rigid-joint model cannot absorb, in units of the noise: the noise-free trial
    (the generator's own ``simulate(spec, noise=False)``) fitted by the rigid whole-chain model, its residual
    prewhitened with the trial's true noise correlation, over the true noise variance. An effect whose visible
    χ² is a few tens or less is below what any method could name from this trial: the misses are read against it.
    The rigid fit is started both from its own closed-form start and from the rigid fit of the measured trial, and
    the better is kept: on noise-free data the first can creep for a thousand iterations far above the minimum
    (seed 12, trial_0082: 30 194 mm² against 93 mm² from the second start), which made a barely visible
    distortion read as χ² 54 000.

    `only`: the trial's effect of that index alone (the generator's spec with the others taken out, the same motion
    and noise): what a two-effect trial shows of each of its effects, read apart."""
    import generator as heldout
    from identcheck.bundle.chain import fit_chain, initial_state
    from identcheck.bundle.hypothesis import whitened_rss
    from identcheck.skeleton import Skeleton

    truth = json.loads((trial_dir / f"{entry['stem']}.truth.json").read_text())
    spec = truth["spec"]
    if only is not None:
        spec = {**spec, "effects": [spec["effects"][only]]}
    X = heldout.simulate(spec, noise=False)
    X = X[0] if isinstance(X, tuple) else X
    noise = truth["params"]["noise"]
    model = ic.load_model(trial_dir / f"{entry['stem']}.toml")
    names = [m for _, m in heldout.marker_order(heldout.geometry_from_json(spec["geometry"]))]
    data = X[:, [names.index(m) for m in model.markers]]
    chain = Skeleton.from_model(model)
    fits = []
    try:
        fits.append(fit_chain(chain, data, initial_state(chain, data), max_iter=40))
    except Exception:                     # noqa: BLE001 - a trial the rigid model cannot even start on
        pass
    try:
        from identcheck.diagnose.workflow import start
        measured = ic.read_trial(trial_dir / f"{entry['stem']}.trc")
        fits.append(fit_chain(chain, data, start(model, measured)[1].fit.state, max_iter=40))
    except Exception:                     # noqa: BLE001
        pass
    if not fits:
        return None
    fit = min(fits, key=lambda f: f.rss)
    phi = float(noise.get("phi") or 0.0)
    w = np.all(np.isfinite(data), axis=2).astype(float)
    return float(whitened_rss(data - fit.pred, w, phi) / noise["sigma_mm"] ** 2)


def where_right(name: str, truth: dict, named: dict) -> bool:
    """Whether `diagnose` put the effect where the generator did: the same markers for a slip or a swap, a
    segment (or marker) the truth names for soft tissue, the same joint for a translation or an extra degree
    of freedom, the same segment (and marker, when one lags alone) for a delay, overlapping markers for
    outliers; a distortion acts everywhere."""
    tm = set(truth.get("markers") or ([truth["marker"]] if truth.get("marker") else []))
    nm = set(named.get("markers") or [])
    segs = truth.get("segments") or truth.get("segment")
    segs = set(segs if isinstance(segs, list) else [segs]) - {None}
    if name in ("marker_slip", "marker_swap"):
        return nm == tm
    if name == "soft_tissue":
        return named.get("segment") in segs and (not nm or bool(nm & tm) or named.get("together", False))
    if name in ("joint_translation", "extra_dof"):
        return named.get("joint") == truth.get("joint")
    if name == "time_offset":
        if len(tm) == 1 and nm:
            return nm == tm
        return named.get("segment") in segs
    if name == "outliers":
        return bool(nm & tm)
    return True


MOVING_CENTRE = ("joint_translation",)
"""Effects after which a joint's true marker distances (to its centre at the generator's zero angle) are not what the
data determine: the part of a moving centre that is linear in the angle is a shifted joint (the contract's
``joint_translation``), so a determined joint may sit away from that reference without being wrong about the data."""


def moving_axis(effects: list, joint: str, named: list) -> bool:
    """Whether the truth turns the hinge `joint` about a second axis with a profile of time (an ``extra_dof`` other
    than a ball) and ``diagnose`` modelled a second rotation there (its `named` effects, as its JSON gives them): its
    axis in the child then has no one place, and the truth's distances are to it at the generator's zero turn, where
    ``diagnose`` places it at the trial's mean turn (a constant turn is the axis placed otherwise: no data tell the two
    apart, and the report says which it gives). A joint whose extra turn went unnamed is judged as any other."""
    turned = any(e["name"] == "extra_dof" and (e.get("where") or {}).get("joint") == joint
                 and (e.get("where") or {}).get("dof") not in (None, "ball") for e in effects)
    return turned and any(e.get("name") == "extra_dof" and (e.get("where") or {}).get("joint") == joint
                          for e in named)


def other_type(diag_joint: dict, truth_joint: dict, effects: list, joint: str) -> bool:
    """Whether the joint `diagnose` reports is not of the truth's declared type, so that their marker distances measure
    different things (to a hinge's axis, to a ball's centre): the report's type differs, or the truth turns the
    joint like a ball (an ``extra_dof`` of kind ``ball``: a hinge's axis is then the generator's reference only)."""
    if diag_joint.get("type") and truth_joint.get("type") and diag_joint["type"] != truth_joint["type"]:
        return True
    return any(e["name"] == "extra_dof" and (e.get("where") or {}).get("joint") == joint
               and (e.get("where") or {}).get("dof") == "ball" for e in effects)


def joints_against_truth(diag: dict, truth: dict) -> dict:
    """Each joint's verdict and how its marker distances' 95 % intervals hold the truth's distances: joint ->
    {"verdict", "markers", "covered" (intervals holding the truth), "worst_miss_mm" (the largest distance from an
    interval to the truth, 0 when all hold it), "worst_error_mm" (largest |estimate - truth|), "moving_centre" (the
    truth moves its centre: :data:`MOVING_CENTRE`), "moving_axis" (:func:`moving_axis`), "other_type"
    (:func:`other_type`)}."""
    out = {}
    for j, ans in diag.get("joints", {}).items():
        true = (truth.get("joints", {}).get(j) or {}).get("marker_distances") or {}
        marks = [m for m in ans.get("marker_distances", {}) if m in true]
        misses, errors = [], []
        for m in marks:
            lo, hi = ans["marker_distances_ci95"][m]
            t = true[m]
            misses.append(max(lo - t, 0.0, t - (float("inf") if hi is None else hi)))
            errors.append(abs(ans["marker_distances"][m] - t))
        moving = any(e["name"] in MOVING_CENTRE and (e.get("where") or {}).get("joint") == j
                     for e in truth.get("effects", []))
        out[j] = {"verdict": ans["practical"]["verdict"], "markers": len(marks), "moving_centre": moving,
                  "moving_axis": moving_axis(truth.get("effects", []), j, diag.get("effects", [])),
                  "other_type": other_type(ans, truth.get("joints", {}).get(j) or {}, truth.get("effects", []), j),
                  "covered": sum(x == 0.0 for x in misses),
                  "worst_miss_mm": round(max(misses, default=0.0), 3),
                  "worst_error_mm": round(max(errors, default=0.0), 3)}
    return out


def evaluate(trial_dir: Path, entry: dict) -> dict:
    """Diagnose one trial; the named effects in order, against the truth."""
    stem = entry["stem"]
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            diag = ic.diagnose(trial_dir / f"{stem}.toml", trial_dir / f"{stem}.trc").to_dict()
        except ic.InputError as exc:
            return {"stem": stem, "error": str(exc), "seconds": time.process_time() - t0}
    named = [e["name"] for e in diag.get("effects", [])]
    wheres = {e["name"]: e["where"] for e in reversed(diag.get("effects", []))}     # each name's first place
    right = [where_right(t["name"], t.get("where", {}), wheres[t["name"]]) if t["name"] in wheres else None
             for t in entry["effects"]]
    indistinct = [[o["name"] for o in e.get("indistinguishable_from", [])] for e in diag.get("effects", [])]
    visible = visible_chi2(trial_dir, entry) if entry["effects"] else None
    own = [visible_chi2(trial_dir, entry, only=k) for k in range(len(entry["effects"]))] if len(entry["effects"]) > 1 \
        else [visible]
    truth = json.loads((trial_dir / f"{stem}.truth.json").read_text())
    return {"stem": stem, "named": named, "joints": joints_against_truth(diag, truth),
            "visible_chi2": None if visible is None else round(visible, 1),
            "own_visible_chi2": [None if v is None else round(v, 1) for v in own] if entry["effects"] else [],
            "where_right": right, "indistinguishable": indistinct,
            "gap_ratio": round(diag["gap_after"] / diag["noise_floor"], 3) if diag.get("noise_floor") else None,
            "noise": entry["category"]["noise"], "motion": entry["category"]["motion"],
            "gaps": entry["category"].get("gaps", False), "layout": entry["category"].get("layout", "clusters"),
            "truth": [e["name"] for e in entry["effects"]],
            "magnitudes": [round(e.get("magnitude_mm", float("nan")), 2) for e in entry["effects"]],
            "shapes": [e.get("shape", "") for e in entry["effects"]], "kind": entry["category"]["kind"],
            "seconds": time.process_time() - t0}


def summarise(results: list) -> dict:
    ok = [r for r in results if "error" not in r]
    single = [r for r in ok if r["kind"] == "single"]
    pairs = [r for r in ok if r["kind"] == "pair"]
    clean = [r for r in ok if r["kind"] == "clean"]
    confusion = defaultdict(Counter)
    misses = []
    for r in single:
        first = r["named"][0] if r["named"] else "none"
        confusion[r["truth"][0]][first] += 1
        if first != r["truth"][0]:
            misses.append({"stem": r["stem"], "truth": r["truth"][0], "shape": r["shapes"][0],
                           "magnitude_mm": r["magnitudes"][0], "named": r["named"],
                           "visible_chi2": r.get("visible_chi2"), "noise": r.get("noise")})
    per_effect = {}
    for name, row in sorted(confusion.items()):
        n = sum(row.values())
        per_effect[name] = {"trials": n, "named_first": row.get(name, 0),
                            "named_any": sum(name in r["named"] for r in single if r["truth"][0] == name)}
    firsts = [r for r in single if r["named"] and r["named"][0] == r["truth"][0] and r.get("where_right")]
    gaps = [r["gap_ratio"] for r in single + pairs if r.get("gap_ratio") is not None and r["named"]]
    return {
        "where_right": {"trials": len(firsts), "right": sum(bool(r["where_right"][0]) for r in firsts)},
        "gap_after_over_floor": {"trials": len(gaps), "within_1_5": sum(g <= 1.5 for g in gaps),
                                 "median": float(np.median(gaps)) if gaps else None,
                                 "max": float(np.max(gaps)) if gaps else None},
        "named_first_or_indistinguishable": sum(
            bool(r["named"]) and (r["named"][0] == r["truth"][0] or r["truth"][0] in (r.get("indistinguishable") or [[]])[0])
            for r in single),
        "detection_limits": detection_limits(single),
        "trials": len(results), "errors": sum("error" in r for r in results),
        "single": {"trials": len(single), "named_first": sum(bool(r["named"]) and r["named"][0] == r["truth"][0]
                                                             for r in single),
                   "named_any": sum(r["truth"][0] in r["named"] for r in single)},
        "pairs": {"trials": len(pairs), "both_named": sum(all(t in r["named"] for t in r["truth"]) for r in pairs),
                  "one_named": sum(any(t in r["named"] for t in r["truth"]) for r in pairs)},
        "clean": {"trials": len(clean), "nothing_named": sum(not r["named"] for r in clean)},
        "named_not_in_truth": named_not_in_truth(single + pairs),
        "per_effect": per_effect,
        "confusion": {k: dict(v) for k, v in sorted(confusion.items())},
        "misses": misses,
        "by_category": by_category(single, clean),
        "by_visibility": by_visibility(single, pairs),
        "joints": joints_summary(ok),
        "median_seconds": sorted(r["seconds"] for r in results)[len(results) // 2] if results else None,
    }


def named_not_in_truth(rows: list) -> dict:
    """Effects named on trials that do not hold them, or named more often than the trial holds them (a second delay
    beside the true one), on single- and two-effect trials (clean trials are counted apart): how many trials name at
    least one, and how often each effect is so named."""
    extra = [list((Counter(r["named"]) - Counter(r["truth"])).elements()) for r in rows]
    return {"trials": len(rows), "with_any": sum(bool(e) for e in extra),
            "by_effect": dict(sorted(Counter(n for e in extra for n in e).items()))}


def joints_summary(rows: list) -> dict:
    """The joints' answers against the truth over every trial: how many were called determined, how many of
    those had every 95 % interval hold the truth, and the determined ones whose intervals missed it by more than
    5 mm (a confident wrong number), with the worst miss, also counted without the joints whose true centre moves
    (:data:`MOVING_CENTRE`), whose hinge turns about a second axis (:func:`moving_axis`) or that are not of the
    truth's type (:func:`other_type`); and the share of all intervals that hold the truth, also without those joints
    (whose truth is a distance to a centre or axis the data cannot place)."""
    joints = [(r["stem"], j, a) for r in rows for j, a in (r.get("joints") or {}).items()]
    det = [(s, j, a) for s, j, a in joints if a["verdict"] == "determined"]
    wrong = [(s, j, a) for s, j, a in det if a["worst_miss_mm"] > 5.0]
    fixed = lambda a: not (a.get("moving_centre") or a.get("moving_axis") or a.get("other_type"))    # noqa: E731
    return {"joints": len(joints), "determined": len(det),
            "determined_fixed_centre": sum(fixed(a) for _, _, a in det),
            "determined_fixed_centre_missed_by_over_5mm": sum(fixed(a) for _, _, a in wrong),
            "determined_all_covered": sum(a["covered"] == a["markers"] for _, _, a in det),
            "determined_missed_by_over_5mm": len(wrong),
            "worst_determined_miss_mm": max((a["worst_miss_mm"] for _, _, a in det), default=None),
            "confident_wrong": [{"stem": s, "joint": j, "moving_centre": a.get("moving_centre"),
                                 "other_type": a.get("other_type"),
                                 "worst_miss_mm": a["worst_miss_mm"],
                                 "worst_error_mm": a["worst_error_mm"]} for s, j, a in wrong],
            "intervals": sum(a["markers"] for _, _, a in joints),
            "intervals_covering": sum(a["covered"] for _, _, a in joints),
            "intervals_fixed_centre": sum(a["markers"] for _, _, a in joints if fixed(a)),
            "intervals_fixed_centre_covering": sum(a["covered"] for _, _, a in joints if fixed(a))}


def by_category(single: list, clean: list) -> dict:
    """Single effects named first, and clean trials with nothing named, split by each trial category (gaps or none,
    marker layout, motion): where the misses gather."""
    out = {}
    for key in ("gaps", "layout", "motion", "noise"):
        for value in sorted({str(r.get(key)) for r in single + clean}):
            s = [r for r in single if str(r.get(key)) == value]
            c = [r for r in clean if str(r.get(key)) == value]
            out[f"{key}={value}"] = {
                "single": len(s), "named_first": sum(bool(r["named"]) and r["named"][0] == r["truth"][0] for r in s),
                "clean": len(c), "nothing_named": sum(not r["named"] for r in c)}
    return out


VISIBILITY_BINS = (0.0, 30.0, 100.0, 300.0, float("inf"))
"""Edges of the visible χ² bins :func:`by_visibility` counts in: below 30 an effect leaves less than the noise of a
few dozen samples, what no method could name; 30-100 is about what a criterion charging ln 3N (10-11 here) a
parameter pays for the few parameters of the simplest story; above, every effect's own model earns its keep."""


def told_apart(name: str, row: dict) -> bool:
    """Whether the truth's effect `name` is named in `row`, or reported as indistinguishable from a named one (a
    story the data cannot tell from the one named: as honest an answer)."""
    return name in row["named"] or any(name in alts for alts in (row.get("indistinguishable") or []))


def by_visibility(single: list, pairs: list, edges: tuple = VISIBILITY_BINS) -> list:
    """The named rates by how visible the effects were (:func:`visible_chi2`): single-effect trials by their
    effect's visible χ², named first (and named first or tied with the first as indistinguishable); two-effect trials
    by the smaller of their effects' own visible χ² (each effect simulated alone, ``own_visible_chi2``), both named
    (and both named or reported indistinguishable from a named one, :func:`told_apart`). Trials without the numbers
    (rows of an older run) are left out. What the held-out rates mean depends on how many trials hide an effect
    below anything a rigid-model method could see; this says."""
    def binned(value):
        return next(i for i in range(len(edges) - 1) if edges[i] <= value < edges[i + 1])
    out = [{"visible_chi2_from": edges[i], "visible_chi2_below": edges[i + 1] if np.isfinite(edges[i + 1]) else None,
            "single": 0, "named_first": 0,
            "named_first_or_indistinguishable": 0, "pairs": 0, "both_named": 0, "both_told_apart": 0}
           for i in range(len(edges) - 1)]
    for r in single:
        if r.get("visible_chi2") is None:
            continue
        b = out[binned(r["visible_chi2"])]
        first = bool(r["named"]) and r["named"][0] == r["truth"][0]
        b["single"] += 1
        b["named_first"] += first
        b["named_first_or_indistinguishable"] += first or (
            bool(r["named"]) and r["truth"][0] in (r.get("indistinguishable") or [[]])[0])
    for r in pairs:
        own = r.get("own_visible_chi2") or []
        if len(own) != len(r["truth"]) or any(v is None for v in own):
            continue
        b = out[binned(min(own))]
        b["pairs"] += 1
        b["both_named"] += all(t in r["named"] for t in r["truth"])
        b["both_told_apart"] += all(told_apart(t, r) for t in r["truth"])
    return out


def detection_limits(single: list, rate: float = 0.9) -> dict:
    """Per effect: the smallest visible χ² (:func:`visible_chi2`, which folds the magnitude, the noise level and
    correlation and the trial length into one number) above which the effect is named first in at least `rate`
    of the trials, with the counts behind it; ``None`` when no threshold reaches the rate."""
    out = {}
    for name in sorted({r["truth"][0] for r in single}):
        rows = sorted((r for r in single if r["truth"][0] == name and r.get("visible_chi2") is not None),
                      key=lambda r: r["visible_chi2"])
        hits = [bool(r["named"]) and r["named"][0] == name for r in rows]
        limit = None
        for k in range(len(rows)):
            if np.mean(hits[k:]) >= rate:
                limit = {"visible_chi2": rows[k]["visible_chi2"], "named": int(sum(hits[k:])), "trials": len(rows) - k,
                         "magnitude_mm_from": min(r["magnitudes"][0] for r in rows[k:])}
                break
        out[name] = {"limit": limit, "below": [[r["visible_chi2"], r["magnitudes"][0], h] for r, h in zip(rows, hits)]}
    return out


def pair_points(pairs: list) -> list:
    """Each two-effect trial with both effects' own visible χ² as (the smaller of the two, both named or reported
    indistinguishable from a named one): the row :func:`limits_figure` draws for the pairs."""
    return [(min(r["own_visible_chi2"]), all(told_apart(t, r) for t in r["truth"])) for r in pairs
            if len(r.get("own_visible_chi2") or []) == len(r["truth"]) and None not in r["own_visible_chi2"]]


def limits_figure(limits: dict, path: Path, pairs: list = ()) -> None:
    """Named (filled) and missed (open) single-effect trials against their visible χ², one row per effect, the
    90 % detection limit marked; below them, when given, the two-effect trials at the smaller of their effects' own
    visible χ² (filled: both named or reported indistinguishable from a named one, :func:`pair_points`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(limits)
    fig, ax = plt.subplots(figsize=(9, 0.5 * (len(names) + bool(pairs)) + 2.0))
    for i, name in enumerate(names):
        pts = limits[name]["below"]
        hit = [p[0] for p in pts if p[2]]
        miss = [p[0] for p in pts if not p[2]]
        ax.scatter(hit, [i] * len(hit), color="tab:green", s=30, label="named first" if i == 0 else None)
        ax.scatter(miss, [i] * len(miss), facecolors="none", edgecolors="tab:red", s=30,
                   label="missed or named second" if i == 0 else None)
        lim = limits[name]["limit"]
        if lim:
            ax.plot([lim["visible_chi2"]] * 2, [i - 0.35, i + 0.35], color="k", lw=1.5)
    if pairs:
        row = -1
        ax.scatter([x for x, ok in pairs if ok], [row] * sum(ok for _, ok in pairs), color="tab:green", s=30)
        ax.scatter([x for x, ok in pairs if not ok], [row] * sum(not ok for _, ok in pairs), facecolors="none",
                   edgecolors="tab:red", s=30)
        names = ["pairs: both named or tied (weaker effect)"] + names
    ax.set_xscale("log")
    ax.set_yticks(range(-1 if pairs else 0, len(names) - (1 if pairs else 0)), names)
    ax.set_xlabel("visible χ² of the effect (what the rigid model cannot absorb, over the noise)")
    ax.set_title("diagnose on independently generated trials: | = 90 % detection limit")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", type=Path)
    ap.add_argument("--limit", type=int, default=None)
    add_shard_arguments(ap)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--key", default="diagnose_heldout", help="results.json key to write (default %(default)s)")
    a = ap.parse_args(argv)
    entries = json.loads((a.trials / "index.json").read_text())["trials"]
    entries = entries[:a.limit] if a.limit else entries
    results = run_trials(entries, lambda e: evaluate(a.trials, e), a, lambda k, n, e, r: (
        f"[{k}/{n}] {r['stem']} truth {r.get('truth')} named {r.get('named')} {r['seconds']:.0f}s"
        + (f" ERROR {r['error']}" if "error" in r else "")))
    if results is None:
        return 0
    s = summarise(results)
    print(f"single effects: {s['single']['named_first']}/{s['single']['trials']} named first, "
          f"{s['single']['named_any']}/{s['single']['trials']} named at all")
    print(f"pairs: {s['pairs']['both_named']}/{s['pairs']['trials']} both named, "
          f"{s['pairs']['one_named']}/{s['pairs']['trials']} at least one")
    print(f"clean: {s['clean']['nothing_named']}/{s['clean']['trials']} with nothing named")
    x = s["named_not_in_truth"]
    print(f"effects named that the trial does not hold: on {x['with_any']}/{x['trials']} single and two-effect trials "
          f"{x['by_effect']}")
    print(f"single effects named first or tied with the first (indistinguishable): "
          f"{s['named_first_or_indistinguishable']}/{s['single']['trials']}")
    print(f"where right: {s['where_right']['right']}/{s['where_right']['trials']} of the effects named first")
    g = s["gap_after_over_floor"]
    print(f"gap after / noise floor: median {g['median']}, max {g['max']}, within 1.5x in {g['within_1_5']}/{g['trials']}")
    print(f"{'effect':<20} {'trials':>6} {'first':>6} {'any':>5}  first named instead")
    for name, p in s["per_effect"].items():
        others = {k: v for k, v in s["confusion"][name].items() if k != name}
        print(f"{name:<20} {p['trials']:>6} {p['named_first']:>6} {p['named_any']:>5}  {others}")
    for cat, c in s["by_category"].items():
        print(f"  {cat:<22} single named first {c['named_first']}/{c['single']}, "
              f"clean {c['nothing_named']}/{c['clean']}")
    for m in s["misses"]:
        print(f"  miss {m['stem']}: {m['truth']} ({m['shape']}, {m['magnitude_mm']} mm, visible χ² "
              f"{m.get('visible_chi2')}, {m.get('noise')} noise) -> {m['named'] or 'nothing'}")
    print("by visible chi2 (single: its effect's; pairs: the smaller of the two effects' own):")
    for b in s["by_visibility"]:
        print(f"  {b['visible_chi2_from']:>5g} - {b['visible_chi2_below'] or float('inf'):<5g} single named first "
              f"{b['named_first']}/{b['single']} (or indistinguishable {b['named_first_or_indistinguishable']}), "
              f"pairs both named {b['both_named']}/{b['pairs']} (or indistinguishable {b['both_told_apart']})")
    jt = s["joints"]
    print(f"joints: {jt['determined']}/{jt['joints']} called determined, {jt['determined_all_covered']} of them with "
          f"every interval holding the truth, {jt['determined_missed_by_over_5mm']} missing it by over 5 mm "
          f"(worst {jt['worst_determined_miss_mm']} mm; joints whose true centre stays put, of the truth's type: "
          f"{jt['determined_fixed_centre_missed_by_over_5mm']}/{jt['determined_fixed_centre']}); "
          f"intervals holding the truth {jt['intervals_covering']}/{jt['intervals']}")
    print("detection limits (named first in >= 90 % of trials from this visible chi2 up):")
    for name, d in s["detection_limits"].items():
        lim = d["limit"]
        print(f"  {name:<20} " + (f"chi2 >= {lim['visible_chi2']:g} ({lim['named']}/{lim['trials']}, "
                                  f"magnitudes from {lim['magnitude_mm_from']} mm)" if lim else "not reached"))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    try:
        limits_figure(s["detection_limits"], a.out.parent / "diagnose_detection_limits.png",
                      pair_points([r for r in results if r.get("kind") == "pair" and "error" not in r]))
    except ImportError:
        print("matplotlib missing: no figure", file=sys.stderr)
    write_json(a.out, a.key, {"summary": s, "trials_dir": str(a.trials), "machine": machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
