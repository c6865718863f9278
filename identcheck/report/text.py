"""Results as text for a terminal: what the ``identcheck`` verbs print without ``--json``.

Each function takes a verb's result (or its JSON document) and returns the lines to print, joined by
newlines; nothing here computes a number, it only lays out what the result holds. Every table (columns with
a header) is laid out by ``tabulate`` through :func:`table`, so that columns align whatever the widths of
the names and numbers in them.
"""
from __future__ import annotations

from identcheck.report.json_out import document

MISSING = "-"       # what a table shows for a value the result does not have (None)


def _cell(value, floatfmt: str) -> str:
    if value is None:
        return MISSING
    if isinstance(value, float):
        return format(value, floatfmt)
    return str(value)


def table(rows, headers, indent: str = "", floatfmt: str = ".2f") -> list:
    """The lines of a table of `rows` under `headers` (a rule under the header), each line prefixed by
    `indent`. Floats are written with `floatfmt` and None as ``-``; a column whose values are all numbers is
    right-aligned. Text is never read as a number (a marker named ``1e3`` stays ``1e3``)."""
    rows = [list(r) for r in rows]
    numeric = [all(r[k] is None or (isinstance(r[k], (int, float)) and not isinstance(r[k], bool)) for r in rows)
               for k in range(len(headers))]
    cells = [[_cell(v, floatfmt) for v in r] for r in rows]
    from tabulate import tabulate          # imported when a table is printed: ``--json`` runs never need it

    text = tabulate(cells, headers=headers, tablefmt="simple", disable_numparse=True,
                    colalign=["right" if n else "left" for n in numeric])
    return [indent + line for line in text.splitlines()]


def derive_text(result) -> str:
    """``identcheck derive``: each derivation, its checks against the print, the generated solver modules
    against a fresh print, and where the derivations were written."""
    rep = document(result)
    lines = []
    for d in rep["derivations"]:
        lines.append(f"{d['title']}: {'ok' if d['ok'] else 'MISMATCH'}")
        rows = [[c["name"], c["where"], "agrees" if c["agrees"] else
                 (f"erratum {c['erratum']}" if c["ok"] else "DISAGREES (unrecorded)")] for c in d["checks"]]
        lines += table(rows, ["check", "where in the paper", "against the print"], indent="  ")
    for g in rep.get("generated", []):
        state = ("rewritten" if g["written"] else "up to date" if g["up_to_date"]
                 else "STALE: run identcheck derive --regenerate")
        lines.append(f"generated code {g['path']}: {state}")
    seed = rep.get("seed") or {}
    if seed:
        made = ", ".join(f"{k} {v}" for k, v in (seed.get("made_with") or {}).items()) or "no index"
        state = ("rewritten" if seed.get("written") else "up to date" if seed.get("current")
                 else f"made with {made}, not this SymPy/Python: a fresh cache derives" if not seed.get("applies")
                 else f"STALE ({len(seed.get('missing', []))} files): run identcheck derive --regenerate")
        lines.append(f"shipped derivation cache: {state}")
    lines.append(f"written to {rep['out']}")
    return "\n".join(lines)


def rank_text(cert) -> str:
    """``identcheck rank``: the case, the exact rank against the float cross-check, and the statement."""
    return "\n".join([f"{cert.joint} ({cert.p},{cert.q}): unknowns {', '.join(cert.unknowns)}",
                      f"exact rank {cert.rank} of {len(cert.unknowns)} (float cross-check: {cert.numeric_rank})",
                      cert.statement])


def verify_text(result) -> str:
    """``identcheck verify``: verified, or rejected with every problem."""
    lines = [f"certificate verified ({result.format}): recomputed from scratch" if not result.problems
             else "certificate REJECTED:"]
    lines += ["  - " + p for p in result.problems]
    return "\n".join(lines)


def table_text(result) -> str:
    """``identcheck table``: one line per case with its verdict and the kind of certificate."""
    rows = []
    for r in document(result)["cases"]:
        c = r["certificate"]
        how = c["kind"] + (f" <- {c['follows_from']} ({c['rule']})" if c["kind"] == "remark1" else "")
        ident = ("yes" if r["identifiable"] else "no") if r["identifiable_decided"] else "undecided"
        rows.append([r["joint"], f"{r['p']},{r['q']}", ident, "yes" if r["local"] else "no", r["candidates"],
                     r["min_samples"], r["local_min_samples"], how])
    lines = table(rows, ["joint", "p,q", "identifiable", "local", "candidates", "min N", "local N", "certificate"])
    lines.append("identifiable: generic data give one joint; local: finitely many (candidates, mirror images "
                 "counted); min N: samples for the stated verdict; local N: samples for local identifiability "
                 "(Jacobian engine).")
    return "\n".join(lines)


def identify_text(result) -> str:
    """``identcheck identify``: per joint, every candidate's marker distances."""
    lines = []
    for name, j in document(result)["joints"].items():
        hinge = j["type"] == "revolute"
        lines.append(f"{name}: {j['case']}, {j['n_samples']} samples -> {j['candidates']} joint(s)"
                     + (f" ({j['parameter_sets']} parameter sets x mirror images)" if hinge else "")
                     + f"; unique: {j['unique']}; largest sample residual {j['rms_residual']:.3g} mm")
        lines.append("   distances to the " + ("hinge axis" if hinge else "centre") + " (mm), one row per joint:")
        lines += _candidate_table(j)
    return "\n".join(lines)


def _candidate_table(j: dict) -> list:
    """A joint's candidates (its best first, then its alternatives) by marker: each one's marker distances."""
    rows = [j["marker_distances"]] + [alt["marker_distances"] for alt in j["alternatives"]]
    markers = list(rows[0])
    return table([[f"joint {i}"] + [row.get(m) for m in markers] for i, row in enumerate(rows)],
                 ["candidate"] + markers, indent="   ")


def fit_text(result) -> str:
    """``identcheck fit``: per joint, the verdict, residual and uncertainty, and every candidate's marker
    distances with their 95 % intervals."""
    lines = []
    for name, j in document(result)["joints"].items():
        head = f"{name}: {j['case']} by {j['estimator'] or '-'}"
        if not j["marker_distances"]:
            lines.append(f"{head}: {'NO ESTIMATE' if j['identifiable'] else 'NOT IDENTIFIABLE'}. "
                         f"{j['excitation']['reason']}")
            continue
        if not j["identifiable"]:       # equal twins nothing beyond decides (ERRATA E1): every candidate is shown
            head += "; locally identifiable only"
        unc = ("no standard error bounds every marker distance" if j["uncertainty_mm"] is None
               else f"uncertainty {j['uncertainty_mm']:.3g} mm (largest standard error of a marker distance)")
        rms = "-" if j["rms_residual"] is None else f"{j['rms_residual']:.3g}"
        lines.append(f"{head}; {j['practical']['verdict']}; unique: {j['unique']}; rms residual {rms} mm; {unc}")
        what = "centre" if j["type"] == "spherical" else "hinge axis"
        lines.append(f"   distances to the {what} (mm), one row per joint the data admit:")
        lines += _candidate_table(j)
        how = j.get("interval_method", {})
        for m, (lo, hi) in j.get("marker_distances_ci95", {}).items():
            if hi is None and how.get(m) == "not_profiled":
                lines.append(f"   {m}: 95% interval not computed (profile likelihood skipped: time budget)")
            elif hi is None:
                lines.append(f"   {m}: 95% interval {lo:.1f} mm .. not bounded by the data ({how.get(m, '')})")
            else:
                lines.append(f"   {m}: 95% interval {lo:.1f} .. {hi:.1f} mm"
                             + (" (profile likelihood)" if how.get(m) == "profile" else ""))
        if j["practical"]["verdict"] != "determined":
            lines.append(f"   {j['practical']['verdict']}: {j['excitation']['reason']}")
    return "\n".join(lines)


LIST_SHOWN = 6
"""How many entries of a list in an effect's `where` the text report shows (a distortion may fit 53 fields)."""


def _where_text(where: dict) -> str:
    """An effect's `where` as ``key=value, ...`` for the text report (a long frame list left out, other long lists cut
    to their first :data:`LIST_SHOWN` entries and a count; the JSON has them whole)."""
    def shown(val):  # noqa: E306
        if isinstance(val, list) and len(val) > LIST_SHOWN:
            return f"{val[:LIST_SHOWN]} and {len(val) - LIST_SHOWN} more"
        return val
    return ", ".join(f"{key}={shown(val)}" for key, val in where.items() if key != "frames" or len(val) <= 4)


def diagnose_text(diag) -> str:
    """``identcheck diagnose``: the noise, the gap before, each adopted effect, the gap after and the joints."""
    rep = diag.to_dict()
    lines = [f"noise: {rep['noise_sigma_mm']:.3g} mm per coordinate (within-segment distances, frame to frame; "
             f"whole-trial scatter {diag.ctx.noise.sigma_scatter_mm:.3g} mm)",
             f"gap of the rigid-joint model: {rep['gap_before']:.3g} mm (noise floor {rep['noise_floor_before']:.3g} mm)"]
    if not rep["effects"]:
        lines.append("no effect found: the rigid-joint model plus noise explains the trial"
                     if rep["consistent_before"]["consistent"]
                     else "no named effect earns its parameters; the gap stays unexplained")
    rows = [[k, e["name"], _where_text(e["where"]), e["gap_before"], e["gap_after"]]
            for k, e in enumerate(rep["effects"], 1)]
    if rows:
        lines += table(rows, ["step", "effect", "where", "gap before (mm)", "gap after (mm)"], floatfmt=".3g")
    for d in rep["dropped"]:
        lines.append(f"dropped on the way: {d['name']} ({_where_text(d['where'])}): adopted before a later effect that "
                     f"explains what it did (it gains {d['gain_given_the_others']:.0f} given them)")
    for r in rep.get("not_adopted", []):
        lines.append(f"seen but not adopted: {r['name']} ({_where_text(r['where'])}): it earns its parameters "
                     f"(gain {r['score']:.0f}) but {r['reason']}")
    test = rep["consistent_after"]
    lines.append(f"gap after: {rep['gap_after']:.3g} mm, noise floor {rep['noise_floor']:.3g} mm; residual "
                 f"{'consistent' if test['consistent'] else 'NOT consistent'} with noise "
                 f"(gap²/floor² = {test['ratio']:.3g}, limit {test['limit']:.3g})")
    rows = [[name, j["type"] if j["type"] == j["declared_type"] else f"{j['type']} (declared {j['declared_type']})",
             j["rms_residual"], j["uncertainty_mm"], ", ".join(f"{m} {d:.1f}" for m, d in j["marker_distances"].items())]
            for name, j in rep["joints"].items()]
    lines += table(rows, ["joint", "type", "rms residual (mm)", "uncertainty (mm)", "marker distances (mm)"],
                   indent="   ", floatfmt=".3g")
    lines += [f"   {name}: {j['practical']['reason']}" for name, j in rep["joints"].items()
              if not j["marker_distances"] and j["practical"]["reason"].startswith("left out")]
    scale = max((j.get("practical", {}).get("scale_sd", 0.0) for j in rep["joints"].values()), default=0.0)
    if scale > 0:
        lines.append(f"   the uncertainties include a standard deviation of {100 * scale:.2g} % of every length: "
                     "the volume is distorted, and the uniform scale of its calibration is invisible to rigid bodies")
    for name, j in rep["joints"].items():
        if "moving_centre" in j:
            f = j["moving_centre"]
            ends = [(lo, hi) for lo, hi in f["marker_distances_ci95"].values()]
            half = None if any(hi is None for _, hi in ends) else max(((hi - lo) / 2 for lo, hi in ends), default=0.0)
            lines.append(f"   {name}: its centre moves with its angles ({f['motion_rms_mm']:.3g} mm RMS): where it is "
                         "at any one pose is not identifiable (the part of the motion linear in the angles is a "
                         "shifted centre to the data); the distances are to its place over the trial, their 95 % "
                         + ("intervals there not all bounded" if half is None else
                            f"intervals there at most ±{half:.2g} mm wide"))
    return "\n".join(lines)


def without_long_lists(doc: dict, longest: int = 20) -> dict:
    """`doc` without the keys (at any depth) whose values are lists of more than `longest` items,
    so that per-frame arrays stay out of a printed summary."""
    return {k: without_long_lists(v, longest) if isinstance(v, dict) else v for k, v in doc.items()
            if not (isinstance(v, list) and len(v) > longest)}


def simulate_summary(sim, out) -> dict:
    """``identcheck simulate --json``: the file written, its frames and markers, the truth (no poses) and the
    injected effect without its per-frame arrays."""
    doc = {"out": str(out), "n_frames": sim.trial.n_frames, "markers": list(sim.trial.labels),
           "truth": sim.truth.to_dict(poses=False)}
    effect = sim.settings.get("effect")
    if effect:
        doc["effect"] = without_long_lists(effect)
    return doc


def _witness_text(w: dict) -> str:
    if w["verified"]:
        return (f"verified on a simulated trial: a second skeleton reproduces every marker of {w['frames']} frames "
                f"and of {w['held_out_frames']} held-out frames to {max(w['max_marker_error_mm'], w['held_out_max_marker_error_mm']):.0e} mm "
                f"({w['precision_digits']} digits) with {w['quantity']} changed by {100 * w['relative_change']:.1f}%")
    return w["note"]


def plan_text(result) -> str:
    """``identcheck plan``: a table of the joints' verdicts, then the plan's summary lines."""
    doc = document(result)
    rows = [[name, "identifiable" if j["identifiable"] else ("local" if j["local"] else "NOT"), j["case"],
             j["candidates"], j["min_samples"], ", ".join(j["uses_virtual_markers"])]
            for name, j in doc["joints"].items()]
    lines = table(rows, ["joint", "verdict", "case", "candidates", "samples", "uses"])
    notes = []
    for name, j in doc["joints"].items():
        said = []
        if not j["identifiable"]:
            said.append(j["reason"])
        elif j.get("rejected_by"):
            r = j["rejected_by"]
            said.append(f"{j['case']}'s other candidates rejected by {r['marker']} beyond {r['joint']} "
                        "(exact certificate)")
        if "alternative" in j:
            said.append("alternative: " + ("VERIFIED — " if j["alternative"]["verified"] else "")
                        + _witness_text(j["alternative"]))
        if j.get("motion_needed"):
            said.append(f"needs motion of: {', '.join(j['motion_needed'])}")
        if j.get("practical"):
            p = j["practical"]
            noise = f"{p['noise_mm']} mm noise" if "noise_mm" in p else "the trial's own noise, measured"
            said.append(f"in practice ({p.get('motion', '')}, {noise}): "
                        f"{p['verdict']}: {p['reason']}")
        notes += [f"{name}: {s}" for s in said]
    if notes:
        lines += ["", *notes]
    lines.append("")
    lines += _plan_summary(doc)
    if doc.get("shared_motion"):
        lines.append("shared motion: " + doc["shared_motion"])
    if doc.get("fewest_local"):
        f = doc["fewest_local"]
        stopped = "; stopped at its time budget: the markers not tried yet are kept" if f.get("complete") is False \
            else ""
        lines.append(f"fewest markers keeping every joint locally identifiable: {f['markers']} "
                     f"(can drop {', '.join(f['removable']) or 'none'}; {f['method']}{stopped})")
    if doc.get("practical_suggestions"):
        lines.append("one more marker, by predicted gain: " + _practical_suggestions_text(doc["practical_suggestions"]))
    elif doc.get("practical_suggestions_note"):
        lines.append("one more marker: " + doc["practical_suggestions_note"])
    if "robustness" in doc:
        weak = [m for m, r in doc["robustness"].items() if not r["plan_survives"]]
        partial = bool((doc.get("unfinished") or {}).get("robustness"))
        lines.append("markers the plan cannot lose" + (f" (of the {len(doc['robustness'])} checked)" if partial else "")
                     + ": " + (", ".join(weak) or "none"))
    if doc.get("unfinished"):
        u = doc["unfinished"]
        left = [f"{len(u[k])} {what}" for k, what in (("motion_needed", "joints' motion"), ("robustness", "markers"),
                                                     ("witness", "joints' witness"),
                                                     ("suggestions", "joints' fewest markers to add")) if u.get(k)]
        if u.get("suggestions_minimal") is False:
            left.append("whether fewer markers would do")
        lines.append(f"not analysed: {', '.join(left)} ({u['reason']})")
    c = doc["certificate"]
    lines.append(f"certificate: {c['method']}; {c['frames']} frames; P(wrong) <= {c['failure_probability_bound']:.1e}")
    return "\n".join(lines)


def _half_width(mm: float) -> str:
    """A predicted 95 % half-width; at the cap, a distance the motion leaves free or wider than the cap."""
    from identcheck.fit.marker_value import CAP_MM

    return f"±{mm:g}" if mm < CAP_MM else f"≥ ±{CAP_MM:g}"


def _practical_suggestions_text(sugg, shown: int = 3) -> str:
    """The best ``shown`` one-marker additions: segment, mm saved, and each joint's 95 % interval before → after."""
    parts = []
    for s in sugg[:shown]:
        joints = ", ".join(f"{j} {_half_width(v['before_mm'])} → {_half_width(v['after_mm'])} mm"
                           for j, v in s["joints"].items())
        done = f"; determined: {', '.join(s['determined_after'])}" if s["determined_after"] else ""
        parts.append(f"{s['segment']} saves {s['mm_saved']:g} mm ({joints or 'no joint narrows'}{done})")
    return "; ".join(parts)


def _markers_text(sugg) -> str:
    return ", ".join(f"{s['add_markers']} on {s['segment']}" for s in sugg)


def _plan_summary(doc: dict) -> list:
    """The plan's verdict lines: all identifiable or not; what stays undetermined and whose it is; the fewest
    markers for the whole-tree rank (and how minimality was checked); those for uniqueness by propagation."""
    if doc["all_identifiable"]:
        return ["all joints identifiable: yes"]
    check = doc.get("suggestions_check") or {}
    uncounted = [n for n, j in doc["joints"].items() if j["local"] and j["candidates"] is None]
    if doc["all_local"] and not doc["suggestions"] and check.get("markers") == 0:
        alt = {n: doc["joints"][n]["alternative"] for n in uncounted if "alternative" in doc["joints"][n]}
        twice = [n for n, w in alt.items() if w["verified"]]
        if twice:
            head = (f"all joints identifiable: no; every joint is locally identifiable (whole-tree rank), but a second "
                    f"skeleton verified at 50 digits changes {', '.join(twice)}")
        else:
            head = (f"all joints identifiable: not shown; every joint is locally identifiable (whole-tree rank), but "
                    f"{len(uncounted)} only together ({', '.join(uncounted)}), and their candidates cannot be counted "
                    "exactly (no table case settles them)")
            if alt:
                head += (f"; a search from {max(w.get('attempts', 0) for w in alt.values())} starts found no second "
                         "skeleton (evidence, not a proof)")
            else:
                head += "; `plan --witness` searches for a second skeleton"
        lines = [head + "; no marker is needed for the rank"]
    else:
        lines = ["all joints identifiable: no; fewest markers to add: " + (_markers_text(doc["suggestions"])
                                                                           or "none found")]
        if check.get("markers") and check["minimal"]:
            lines[-1] += (f" (after them every joint is locally identifiable; every plan with fewer fails: "
                          f"{check['fewer_plans_checked']} rejected by the whole-tree rank, "
                          f"{check['fewer_plans_bare']} leave a subtree without markers)")
        elif check.get("markers"):
            lines[-1] += (f" (minimality not checked: the search stopped after {check['fewer_plans_checked']} "
                          "whole-tree ranks)")
    for name, labels in (doc.get("undetermined") or {}).items():
        lines.append(f"undetermined: {name}: " + (", ".join(labels) or "nothing measures it"))
    if doc.get("suggestions_unique"):
        lines.append("fewest markers for every joint to be settled uniquely by propagation: "
                     + _markers_text(doc["suggestions_unique"]))
    return lines


def batch_text(doc: dict) -> str:
    """``identcheck batch``: the jobs by status, where the summary is, and each failed job with its message."""
    jobs = f"{doc['jobs']} job" + ("" if doc["jobs"] == 1 else "s")
    lines = [f"{jobs}: {doc['done']} done, {doc['skipped']} skipped (done earlier), {doc['failed']} failed"
             + (f"; {doc['negative']} answered no (column ok)" if doc.get("negative") else "")]
    if doc.get("summary"):
        lines.append(f"summary: {', '.join(doc['summary'])}")
    for e in doc["errors"]:
        lines.append(f"FAILED {e['job']}: {e['error']}")
    return "\n".join(lines)


def skeleton_text(result) -> str:
    """``identcheck skeleton``: the segments, the joints with their evidence, what the data leave open, and
    where the model (and the playback) went."""
    doc = document(result)
    g = doc["grouping"]
    how = (f"grouped by rigidity within {g['tolerance_mm']:.3g} mm" if g["source"] == "inferred"
           else f"as given in {g['source']}")
    lines = [f"{len(doc['segments'])} segments ({how}); root {doc['root']} ({doc['root_rule']})"]
    for name, markers in doc["segments"].items():
        lines.append(f"  {name}: {', '.join(markers)}")
    lines.append("joints (parent -> child, type, O'Brien or sphere/circle residual, confidence):")
    for j in doc["joints"]:
        ru = j["evidence"]["tree"]["runner_up"]
        flag = "  AMBIGUOUS" if j["evidence"]["tree"]["ambiguous"] else ""
        lines.append(f"  {j['name']}: {j['parent']} -> {j['child']}, {j['type']}, {j['residual_mm']:.3g} mm, "
                     f"confidence {j['confidence']:.2f}"
                     + (f" (runner-up {ru['parent']}-{ru['child']} {ru['residual_mm']:.3g} mm)" if ru else "") + flag)
        lines.append(f"     {j['evidence']['type']['rule']}")
    for a in doc["ambiguous"]:
        lines.append(f"ambiguous: {a['joint'][0]}-{a['joint'][1]} ({a['residual_mm']:.3g} mm) or "
                     f"{a['alternative'][0]}-{a['alternative'][1]} ({a['alternative_residual_mm']:.3g} mm); "
                     f"to separate them: {a['separating_motion']}")
    for p in doc.get("poor_joints", []):
        lines.append(f"poor joint {p['joint'][0]}-{p['joint'][1]}: {p['note']}")
    for lp in doc["loops"]:
        lines.append(f"loop? {lp['segments'][0]}-{lp['segments'][1]} fits a joint ({lp['residual_mm']:.3g} mm) the tree "
                     "does not use")
    for c in doc["cannot_place"]:
        lines.append(f"cannot place {c['segment']} ({', '.join(c['markers'])}): {c['reason']}")
    for w in (g.get("widened") or {}).values():
        lines.append(f"wobbling group: {w['note']}")
    for t in doc.get("may_be_two_segments", []):
        lines.append(f"may be two segments: {t['note']}")
    for m in doc.get("markers_on_joints", []):
        lines.append(f"on a joint: {m['note']}")
    for m in doc["unassigned_markers"]:
        lines.append(f"unassigned marker {m}: {doc['unassigned'][m]}")
    pb = doc.get("playback") or {}
    if pb.get("rms_mm") is not None:
        lines.append(f"playback through the articulated model: {pb['rms_mm']:.3g} mm RMS from the measured markers"
                     + (f"; written to {pb['export']}" if pb.get("export") else ""))
    if doc.get("model"):
        lines.append(f"model written to {doc['model']}")
    return "\n".join(lines)
