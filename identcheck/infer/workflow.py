"""``identcheck skeleton`` as one library call: group the markers (or take the user's groups), infer the tree and
the joint types, write the model file with its evidence, and play the trial back through the articulated model.

The trial is moved near the origin first (:meth:`~identcheck.trial.Trial.recentred`); whatever is written in
world coordinates (``--export-markers``) is moved back.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from identcheck.errors import InputError
from identcheck.io.trc import units_problem
from identcheck.estimate.hierarchy import rebuild, relative_rotations
from identcheck.estimate.joint import AXIS_HANDLE_MM
from identcheck.estimate.noise import noise_floor
from identcheck.estimate.obrien import as_poses, joint_location
from identcheck.infer.grouping import given_grouping, group_markers
from identcheck.infer.joint_markers import markers_on_joints
from identcheck.infer.joint_types import classify_posed, classify_small, noise_wobble_deg
from identcheck.infer.model_writer import check_model, model_text, write_model
from identcheck.infer.result import SkeletonResult
from identcheck.io.model import refuse_exported_points
from identcheck.infer.tree import FLOOR_TRUST, infer_tree
from identcheck.infer.two_segments import check_groups
from identcheck.io.model import virtual_names

PREDICTED_SUFFIX = ".model"
"""``--export-markers``: the articulated model's prediction of marker M is written as ``M.model``."""


def _num(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _noise(trial, grouping):
    """The marker noise from the distances within the groups (:func:`identcheck.estimate.noise.noise_floor`), or
    None when no group has two markers seen together often enough."""
    groups = {g: ms for g, ms in grouping.groups.items() if len(ms) >= 2}
    try:
        return noise_floor(trial.xyz, trial.labels, groups) if groups else None
    except InputError:
        return None


def _joint_names(edges) -> list:
    names, seen = [], set()
    for e in edges:
        name, k = f"{e.parent}_{e.child}", 2
        while name in seen:
            name, k = f"{e.parent}_{e.child}_{k}", k + 1
        seen.add(name)
        names.append(name)
    return names


def _joints(tree, sigma: float) -> list:
    """One JSON entry per joint of the tree, with its type and the evidence."""
    h = tree.hierarchy
    out = []
    for name, e in zip(_joint_names(tree.edges), tree.edges):
        if e.method == "obrien":
            nd = noise_wobble_deg(h.poses[e.parent].local, h.poses[e.child].local, sigma)
            jt = classify_posed(e.fit, nd)
            how = {"method": "O'Brien et al. joint fit between two posed segments (section 3.1)",
                   "motion": e.fit.motion, "fit_uncertainty_mm": _num(e.fit.uncertainty_mm)}
        else:
            jt = classify_small(e.small, sigma)
            small, posed = (e.child, e.parent) if len(tree.segments[e.child]) < 3 else (e.parent, e.child)
            how = {"method": f"sphere and circle fits of {small}'s {len(tree.segments[small])} marker(s) in "
                             f"{posed}'s frame", "reach_mm": _num(e.small.reach_mm)}
            if e.runner_up and e.runner_up.get("replaced"):
                ru = e.runner_up
                a, b = ru.get("between", (ru["parent"], ru["child"]))
                how["inserted"] = (f"{small} put between {a} and {b}, in place of the joint {ru['parent']}-"
                                   f"{ru['child']}, which left {ru['residual_mm']:.3g} mm")
        tree_ev = {**how, "residual_mm": e.residual_mm, "runner_up": e.runner_up, "confidence": e.confidence,
                   "ambiguous": e.ambiguous}
        out.append({"name": name, "parent": e.parent, "child": e.child, "type": jt.type,
                    "residual_mm": e.residual_mm, "confidence": float(min(e.confidence, jt.confidence)),
                    "evidence": {"tree": tree_ev, "type": {**jt.evidence, "confidence": jt.confidence}}})
    return out


def _joint_comment(j: dict) -> list:
    """The model file's comment on one joint: its residual and the runner-up's, each beside what marker noise alone
    would leave there when that is known (the tree is chosen on the excess over it, so a runner-up can have the
    smaller residual), the confidence, the type and its evidence."""
    t, ty = j["evidence"]["tree"], j["evidence"]["type"]
    ru = t["runner_up"]
    floors = (ru or {}).get("noise_only_mm") or [None, None]
    noise = lambda f: f" (noise alone {f:.3g})" if f is not None else ""  # noqa: E731
    lines = [f"{j['name']}: {j['parent']} -> {j['child']}, residual {j['residual_mm']:.3g} mm{noise(floors[0])}"
             + (f" (runner-up {ru['parent']}-{ru['child']}: {ru['residual_mm']:.3g} mm{noise(floors[1])})"
                if ru else "")
             + f"; confidence {j['confidence']:.2f}" + ("; AMBIGUOUS (see the header)" if t["ambiguous"] else "")]
    lines.append(f"  {j['type']}: {ty['rule']}")
    if "rotation_spread_deg" in ty:
        sp, sv = ty["rotation_spread_deg"], ty["singular_values"]
        lines.append(f"  rotation spreads {', '.join(f'{x:.3g}' for x in sp)} deg; singular values of the stacked "
                     f"system {', '.join(f'{x:.3g}' for x in sv)} ({ty['n_frames']} frames)")
    return lines


def _header(doc: dict, grouping, excess: bool) -> list:
    """The model file's header comment: the trial, the rules that made the segments, the tree (``excess``: weighed
    against what noise alone leaves) and the types, then what the data leave open."""
    tol = grouping.tolerance
    lines = [f"Inferred by `identcheck skeleton` from {doc['trial']} (frames {doc['frames'][0]}-{doc['frames'][1]}, "
             f"{doc['n_frames']} frames): edit the names freely, check the ambiguities below.",
             ("Segments: markers whose distances stay constant within "
              f"{tol.tolerance_mm:.3g} mm ({tol.rule})." if grouping.source == "inferred"
              else f"Segments: as given in {grouping.source}."),
             "Tree: minimum spanning tree over pairwise O'Brien joint fits (O'Brien et al. 2000, 3.3), each weighed by "
             + (f"its mean squared residual less {FLOOR_TRUST:g} x what marker noise alone would leave there; "
                if excess else "its RMS residual; ")
             + f"root {doc['root']} ({doc['root_rule']}).",
             "Types: single-axis relative rotation -> revolute, else spherical (see each joint)."]
    why: dict = {}
    for m in doc["unassigned_markers"]:
        why.setdefault(doc["unassigned"][m], []).append(m)
    for reason, markers in why.items():
        lines.append(f"Not in any segment: {', '.join(markers)}: {reason}")
    for c in doc["cannot_place"]:
        lines.append(f"Left out, cannot place {c['segment']} {c['markers']}: {c['reason']}")
    for w in (doc["grouping"].get("widened") or {}).values():
        lines.append(f"WOBBLING GROUP: {w['note']}")
    for t in doc["may_be_two_segments"]:
        lines.append(f"MAY BE TWO SEGMENTS: {t['note']}")
    for m in doc["markers_on_joints"]:
        lines.append(f"ON A JOINT: {m['note']}")
    for a in doc["ambiguous"]:
        lines.append(f"AMBIGUOUS: {a['joint'][0]}-{a['joint'][1]} ({a['residual_mm']:.3g} mm) or "
                     f"{a['alternative'][0]}-{a['alternative'][1]} ({a['alternative_residual_mm']:.3g} mm): "
                     f"{a['separating_motion']}")
    for p in doc["poor_joints"]:
        lines.append(f"POOR JOINT {p['joint'][0]}-{p['joint'][1]}: {p['note']}")
    for lp in doc["loops"]:
        lines.append(f"Loop? {lp['segments'][0]}-{lp['segments'][1]} fits a joint with {lp['residual_mm']:.3g} mm "
                     "but is not in the tree")
    return lines


def _play(tree, offset, types: list) -> tuple[dict, dict]:
    """The articulated model's markers and joints in the world: (predicted markers by label, virtual joint
    markers by name), each (n_frames, 3), plus the playback summary. `types`: each edge's joint type.

    The posed segments are rebuilt through their O'Brien joints (O'Brien et al., section 3.4:
    :func:`identcheck.estimate.hierarchy.rebuild`), the root following its measured pose. Where the tree goes
    through a group without a pose, the part beyond it follows its own top segment's measured pose; groups without
    a pose are not played back."""
    h = tree.hierarchy
    posed = [g for g in tree.segments if tree.points[g].shape[1] >= 3]
    obrien = [e for e in tree.edges if e.method == "obrien"]
    if h is not None:      # the tree's own joints, oriented as in the tree (a group put between re-roots a part)
        h = replace(h, parent={e.child: e.parent for e in obrien}, fits={e.child: e.fit for e in obrien})
    parent = h.parent if h else {}
    poses = h.poses if h else {g: as_poses(tree.points[g], g) for g in posed}
    rel = relative_rotations(h) if h else {}
    joints = h.joints() if h else {}
    R, t, markers, tops = {}, {}, {}, [g for g in posed if g not in parent]
    for top in tops:
        below = {top}
        while True:
            more = {c for c, p in parent.items() if p in below} - below
            if not more:
                break
            below |= more
        sub = {c: p for c, p in parent.items() if c in below}
        r, tt, mk = rebuild(sub, top, joints, poses[top].R, poses[top].t, rel, {g: poses[g].local for g in below})
        R.update(r)
        t.update(tt)
        markers.update(mk)
    by_seg, total, count = {}, 0.0, 0
    for g in posed:
        d2 = np.sum((markers[g] - tree.points[g]) ** 2, axis=2)
        ok = np.isfinite(d2)
        by_seg[g] = _num(float(np.sqrt(d2[ok].mean()))) if ok.any() else None
        total, count = total + float(d2[ok].sum()), count + int(ok.sum())
    full = np.all([np.all(np.isfinite(t[g]), axis=1) for g in posed], axis=0)
    summary = {"rms_mm": _num(float(np.sqrt(total / count))) if count else None, "rms_by_segment": by_seg,
               "n_frames": int(full.sum()), "played_from": tops}
    predicted = {}
    for g, xyz in markers.items():
        for k, m in enumerate(tree.segments[g]):
            predicted[m + PREDICTED_SUFFIX] = xyz[:, k] + offset
    virtual = {}
    for e, name, kind in zip(tree.edges, _joint_names(tree.edges), types):
        if e.method != "obrien":
            continue
        c = e.child
        if kind == "spherical":
            pts = [np.einsum("fij,j->fi", R[c], e.fit.centre_child) + t[c]]
        else:
            hinge = joint_location(poses[e.parent], poses[c], hinge=True)
            p0 = np.einsum("fij,j->fi", R[c], hinge.centre_child) + t[c]
            pts = [p0, p0 + AXIS_HANDLE_MM * np.einsum("fij,j->fi", R[c], hinge.axis_child)]
        virtual.update({n: p + offset for n, p in zip(virtual_names(name, kind), pts)})
    return {**predicted, **virtual}, summary


def _export(path, trial, columns: dict) -> None:
    """Write the measured markers and `columns` (name → (n_frames, 3)) to `path` (TRC or C3D by extension) with the
    trial writers; frames in which no marker was measured are left empty."""
    clash = sorted(set(columns) & set(trial.labels))
    if clash:
        raise InputError([f"--export-markers {path}: the trial already has marker(s) named {', '.join(clash)}, the "
                          "names the playback gives its own markers; rename them"], source=trial.source)
    data = trial.as_array()
    seen = np.isfinite(data).all(axis=2).any(axis=1)
    extra = np.stack([np.where(seen[:, None], xyz, np.nan) for xyz in columns.values()], axis=1)
    trial.replace(xyz=np.concatenate([data, extra], axis=1), labels=trial.labels + tuple(columns)).to_file(path)


def exported_joints(labels) -> list:
    """The joints whose virtual markers `labels` hold as ``--export-markers`` writes them: ``J.centre``, or both
    ``J.axis0`` and ``J.axis1`` (a trial has no model here, so the names alone tell; a single ``X.axis0`` may be a
    marker's own name)."""
    names = set(labels)
    balls = [m[:-len(".centre")] for m in names if m.endswith(".centre") and len(m) > len(".centre")]
    hinges = [m[:-len(".axis0")] for m in names if m.endswith(".axis0") and m[:-1] + "1" in names]
    return sorted(set(balls) | set(hinges))


def infer_skeleton(trial, segments: dict | None = None, segments_source: str = "--segments",
                   root: str | None = None, out=None, export=None, progress=None) -> SkeletonResult:
    """Infer the segments, the tree and the joint types from a trial, write the model file, play the trial back.

    Parameters
    ----------
    trial : identcheck.trial.Trial
    segments : dict of str to sequence of str, optional
        The grouping, when known (segment → markers); by default it is inferred.
    segments_source : str
        Where `segments` came from, for messages.
    root : str, optional
        Root segment (or one of its markers); default: the tree's centre.
    out : str or os.PathLike, optional
        The model file to write.
    export : str or os.PathLike, optional
        TRC or C3D file for the measured markers beside the articulated model's (``M.model``) and the joints'
        virtual markers.
    progress : callable, optional
        Called with a one-line message per stage.

    Returns
    -------
    SkeletonResult

    Raises
    ------
    InputError
        Bad trial or grouping (fewer than two markers, a never-visible marker, one rigid body, an unknown marker
        in `segments`, no group with a pose), or a bad root.
    """
    say = progress or (lambda msg: None)
    refuse_exported_points(trial, exported_joints(trial.labels))
    shrunk, _ = units_problem(trial.as_array(), 1.0, "the file's units field (POINT:UNITS or Units)")
    if shrunk:      # the readers only warn (a small rig could span that little), but the grouping's tolerances are mm
        raise InputError([f"{shrunk} The markers are grouped into segments by tolerances in mm (0.5 mm and more), "
                          "within which every marker of a body that small is rigid with every other: fix the units "
                          "field (or the coordinates) first"], source=trial.source)
    say("grouping the markers into rigid segments" if segments is None else f"segments from {segments_source}")
    grouping = group_markers(trial) if segments is None else given_grouping(trial, segments, segments_source)
    centred, offset = trial.recentred()
    noise = _noise(centred, grouping)
    sigma = noise.sigma_mm if noise is not None else grouping.tolerance.distance_noise_mm / np.sqrt(2.0)
    say(f"{len(grouping.groups)} group(s); fitting a joint between every pair of posed segments")
    tree = infer_tree(centred, grouping, root, sigma_mm=sigma)
    joints = _joints(tree, sigma)
    unassigned = {**{m: why for m, why in grouping.unused.items()}, **tree.unassigned}
    placed = {g: list(ms) for g, ms in tree.segments.items()}
    segs = {g: list(ms) for g, ms in grouping.groups.items() if g in placed or
            any(c["segment"] == g for c in tree.cannot_place)}
    segs.update({g: ms for g, ms in placed.items() if g not in segs})
    doc = {"trial": trial.source, "frames": [trial.first_frame, trial.first_frame + trial.n_frames - 1],
           "n_frames": trial.n_frames, "n_markers": trial.n_markers,
           "segments": segs, "unassigned_markers": [m for m in trial.labels if m in unassigned],
           "unassigned": unassigned, "joints": joints,
           "runner_up": [{"joint": j["name"], **j["evidence"]["tree"]["runner_up"]} for j in joints
                         if j["evidence"]["tree"]["runner_up"] and not j["evidence"]["tree"]["runner_up"].get("replaced")],
           "ambiguous": list(tree.ambiguous), "loops": list(tree.loops), "cannot_place": list(tree.cannot_place),
           "poor_joints": list(tree.poor),
           "root": tree.root, "root_rule": tree.root_rule, "grouping": grouping.to_dict(),
           "noise": None if noise is None else {"sigma_mm": noise.sigma_mm, "lag1": noise.lag1,
                                                "n_pairs": noise.n_pairs},
           "warnings": list(grouping.warnings) + ([
               "the marker noise could not be estimated (no two markers of one group are seen together in enough "
               "frames): whether a group may be two segments was not checked, so the skeleton is not called "
               "settled"] if noise is None and grouping.source == "inferred" else []),
           "model": None, "playback": None,
           "may_be_two_segments": (check_groups(trial.xyz, trial.labels, segs, grouping.spread_mm, noise.sigma_mm)
                                   if noise is not None and grouping.source == "inferred" else []),
           "markers_on_joints": (markers_on_joints(trial.xyz, trial.labels, placed, joints)
                                 if grouping.source == "inferred" else [])}
    excess = tree.hierarchy is not None and tree.hierarchy.excess_mm2 is not None
    text = model_text(placed, [{**j, "comment": _joint_comment(j)} for j in joints], _header(doc, grouping, excess))
    if out is not None:
        write_model(out, text)
        doc["model"] = str(out)
        say(f"model written to {out}")
    else:
        check_model(text, "<inferred model>")
    doc["model_text"] = text
    columns, summary = _play(tree, offset, [j["type"] for j in joints])
    doc["playback"] = {**summary, "export": None}
    if export is not None:
        _export(export, trial, columns)
        doc["playback"]["export"] = str(export)
        say(f"measured and played-back markers written to {export}")
    return SkeletonResult.from_dict(doc)
