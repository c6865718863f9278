"""Where a whole-tree fit starts when a segment has fewer than three markers: its pose taken from its markers plus
the points the closed-form joint fits leave on it (joint centres, hinge points), or, with two points, any roll
about their line (the data do not see it: gauge).

Used by ``fit`` for every candidate start, and by ``diagnose`` for its rigid fit when a segment has one or two
markers (an anatomical layout: a thigh's lateral marker and its epicondyle), where poses from a segment's own
markers alone (:func:`identcheck.bundle.chain.segment_frames`) need three.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import filled_poses, fit_chain, initial_state
from identcheck.bundle.starts import CANNOT_START, candidates, start_combinations
from identcheck.errors import DegenerateError
from identcheck.estimate.closed_forms import fit_model, not_identifiable
from identcheck.estimate.joint import start_stride
from identcheck.geometry.poses import farthest_pair, poses_segment, refine_local, segment_poses
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial

START_SHAPE_TOL_MM = 0.1
"""Body-fixed coordinates of a start's segment poses are averaged over the frames (:func:`refine_local`) until they
move less than this: the whole-tree fit refines them, so its start needs them to a fraction of the noise, not to
the 1e-9 mm of the closed forms' own poses (on the bundled leg: 2 passes a segment instead of 4, the same fits
in the same number of iterations)."""


def virtual_frames(chain: Skeleton, data: np.ndarray, virtual: dict) -> dict:
    """Poses of every segment from its seen markers plus the virtual points (joint centres, hinge points)
    the closed-form fits give it; raises DegenerateError naming a segment with fewer than 3 points."""
    out = {}
    for seg in chain.segments:
        idx = chain.seg_markers[seg]
        extra = [v for v in virtual.get(seg, {}).values() if np.isfinite(v).all(axis=1).any()]
        pts = np.concatenate([data[:, idx]] + [e[:, None] for e in extra], axis=1) if extra else data[:, idx]
        if pts.shape[1] == 2 or (pts.shape[1] >= 3 and not poses_segment(pts)):
            # two points, or points on one line, leave the roll about their line free: any roll will do
            a, b = farthest_pair(pts)
            pts = np.concatenate([pts, _roll_point(pts[:, a], pts[:, b])[:, None]], axis=1)
        if pts.shape[1] < 3:
            raise DegenerateError(f"segment {seg!r}: {len(idx)} marker(s) and {len(extra)} joint point(s) cannot "
                                  "pose it (three are needed to start the whole-tree fit)", segment=seg)
        try:
            local, poses = _start_poses(pts)
        except ValueError as exc:
            raise DegenerateError(f"segment {seg!r}: {exc}", segment=seg) from None
        if poses.valid.sum() < 3:
            rare = rarely_seen(data[:, idx], [chain.labels[c] for c in idx])
            why = f"segment {seg!r}: fewer than 3 frames show three of its points" + (
                f" ({'; '.join(rare)})" if rare else "")
            raise DegenerateError(why, segment=seg, leave_out=why)
        out[seg] = filled_poses(pts, local, poses, n_markers=len(idx))
    return out


def rarely_seen(data: np.ndarray, labels) -> list:
    """The markers of `data` (F, m, 3; `labels` their names) seen in fewer than half its frames, each as
    ``"M is seen in n of F frames"``: the usual reason a segment cannot be posed or seen to move."""
    seen = np.isfinite(data).all(axis=2).sum(axis=0)
    return [f"{m} is seen in {int(n)} of {len(data)} frames" for m, n in zip(labels, seen) if n < len(data) / 2]


def _start_poses(pts: np.ndarray) -> tuple:
    """A segment's body-fixed shape averaged over spread frames (:func:`~identcheck.estimate.joint.start_stride`),
    and its poses in every frame for that shape; over every frame when a marker is not seen in the spread ones."""
    every = start_stride(len(pts))
    if every > 1:
        try:
            local, _ = refine_local(pts[::every], tol=START_SHAPE_TOL_MM)
            return local, segment_poses(pts, local)
        except ValueError:
            pass
    return refine_local(pts, tol=START_SHAPE_TOL_MM)


def _roll_point(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A third point (F, 3) 100 mm from `a`, perpendicular to a→b, turning smoothly with it: it fixes the
    roll that two points leave free (the data do not see it, so the whole-tree fit treats it as gauge)."""
    u = (b - a) / np.maximum(np.linalg.norm(b - a, axis=1, keepdims=True), 1e-12)
    ref = np.where(np.abs(u[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    w = np.cross(u, ref)
    return a + 100.0 * w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12)


def state_from_joints(model, chain: Skeleton, data: np.ndarray, joints: dict):
    """The whole tree's starting state from closed-form joints (`joints`: name -> JointEstimate, one candidate each):
    each lends its points (centre, hinge points) to both of its segments, every segment is posed from its markers and
    those points (:func:`virtual_frames`), and the joints start from those poses
    (:func:`~identcheck.bundle.chain.initial_state`). Raises DegenerateError naming a segment no points pose."""
    virtual: dict = {}
    for name, est in joints.items():
        jt = model.joints[name]
        for seg in (jt.parent, jt.child):
            virtual.setdefault(seg, {}).update(est.virtual_markers(name))
    return initial_state(chain, data, frames=virtual_frames(chain, data, virtual))


REFINE_ITER = 60
"""Levenberg-Marquardt iterations of a joint's two-segment refinement (:func:`refined_closed_forms`)."""


def refined_closed_forms(model, trial, fitted: dict) -> dict:
    """The closed-form joints (:func:`~identcheck.estimate.closed_forms.fit_model`'s), each unique joint whose
    points pose a segment its own markers do not (fewer than three, with another joint hanging from it) first
    refined by the least squares of its two segments alone, and the joints below it fitted again from the refined
    one's points (``fixed``), top down.

    Why: a closed form fits one joint from the points it is given, and a joint below takes the points of the one
    above as they came out. On a chain of one-marker segments below a posed root (3 | 1 | 1 markers, two hinges, clean
    0.3 mm data) the first hinge's circle put its marker 34.5 mm from the axis (truth 43.3, rms 0.79 mm), the shank's
    pose through those points put the second's at 26.5 mm (truth 92.4, rms 10 mm), and the whole-tree fit from there
    stopped at 2.7 times the noise with both joints 10-60 mm off, in 3 of 12 simulated trials; ``diagnose`` then named
    effects that were not there. Refined, the first hinge is its two segments' maximum likelihood before it lends
    its points (a joint whose parent has three markers of its own and whose sparse child has a joint below it).
    Not always the better start: a real gait trial's hip seen through one thigh marker (151 frames), refined alone,
    led the whole tree to a minimum at 2.13 mm instead of 1.73. So it is a start beside the raw closed forms' (``fit``
    tries it when its first whole-tree fit misfits and a fit from it on spread frames ends well below,
    :func:`identcheck.fit.workflow.fit_closed_then_tree`; ``diagnose`` compares it with the other starts when its
    rigid fit leaves a gap, :func:`better_start`), never in their place."""
    from dataclasses import replace

    fixed: dict = {}
    for j in model.joint_order:         # (`fitted` itself is returned when no joint is refined)
        est = fitted[j][0]
        if est is None or not est.unique or est.alternatives or not _lends_to_a_sparse_segment(model, j):
            continue
        better = _two_segment_fit(model, trial, j, est)
        if better is None:
            continue
        fixed[j] = replace(better, estimator=f"{est.estimator}, refined on its two segments")
        fitted = fit_model(model, trial, fixed=fixed)[0]
    return fitted


def _lends_to_a_sparse_segment(model, joint: str) -> bool:
    """Whether `joint`'s points pose its child, a segment with fewer than three markers from which another joint
    hangs, while its parent is posed by three markers of its own (the two-segment fit's root: a one-marker parent
    leaves that fit more unknowns a frame than samples, and it drifts)."""
    jt = model.joints[joint]
    return (len(model.segments[jt.parent].markers) >= 3 and len(model.segments[jt.child].markers) < 3
            and any(o.parent == jt.child for n, o in model.joints.items() if n != joint))


def _two_segment_fit(model, trial, joint: str, est):
    """`est` refined by the whole-tree least squares of `joint`'s two segments alone (from `est`), as a
    JointEstimate of world trajectories (NaN where `est` had none); None when that fit cannot start."""
    from dataclasses import replace

    jt = model.joints[joint]
    sub = replace(model, segments={s: model.segments[s] for s in (jt.parent, jt.child)}, joints={joint: jt})
    markers = [m for m in sub.markers if m in trial.labels]
    chain = Skeleton.from_model(sub, markers=set(markers))
    data = trial.select(chain.labels).as_array()
    try:
        state = state_from_joints(sub, chain, data, {joint: est})
        fit = fit_chain(chain, data, state, weights=np.all(np.isfinite(data), axis=2).astype(float),
                        max_iter=REFINE_ITER)
    except CANNOT_START:
        return None
    R, t, s = fit.seg_R[jt.parent], fit.seg_t[jt.parent], fit.state
    world = lambda v: np.einsum("fij,j->fi", R, v)  # noqa: E731
    if est.kind == "spherical":
        centre = world(s.c_parent[joint]) + t
        return replace(est, centre=np.where(np.isfinite(est.centre), centre, np.nan))
    point, direction = world(s.c_parent[joint]) + t, world(s.axis[joint])
    keep = np.isfinite(est.point)
    return replace(est, point=np.where(keep, point, np.nan), direction=np.where(keep, direction, np.nan))


def closed_form_state(model, trial, chain: Skeleton, data: np.ndarray):
    """:func:`state_from_joints` from each joint's first candidate of the closed-form fits
    (:func:`~identcheck.estimate.closed_forms.fit_model`). A joint the closed forms left without one, because an
    ambiguous joint above it lent no points, is started as ``fit`` starts it: from the first combination that
    restarts it from that joint's candidates (:func:`start_combinations`). A one-marker shank below a one-marker
    thigh had stopped ``diagnose`` as a foot no points pose, where ``fit`` determined every joint."""
    fitted, _ = fit_model(model, trial)
    joints = {n: est for n, (est, _info) in fitted.items() if est is not None}
    if any(j not in joints for j in chain.joints):
        combos = start_combinations(chain, fitted, lambda fixed: fit_model(model, trial, fixed=fixed)[0], data)[0]
        joints = combos[0] if combos else joints
    try:
        return state_from_joints(model, chain, data, joints)
    except DegenerateError as exc:
        # the segment no points pose hangs from a joint whose case no motion identifies: say that (``fit``'s answer
        # for the joint), for a caller that can leave the joint out (DegenerateError.leave_out)
        above = model.parent_joint(exc.segment) if exc.segment in model.segments else None
        if above is not None and fitted[above.name][0] is None and "reason" not in fitted[above.name][1]:
            exc.leave_out = not_identifiable(fitted[above.name][1])
        raise


def start_state(model, chain: Skeleton, data: np.ndarray, rate_hz: float, source: str = "<array>"):
    """A fresh starting state for `chain` on `data` (F, M, 3) in its marker order: from every segment's own poses
    (:func:`~identcheck.bundle.chain.initial_state`) when each has three markers or more, not on one line
    (:func:`~identcheck.geometry.poses.poses_segment`), otherwise from the closed-form joints of `model`
    (:func:`closed_form_state`). `source` names the trial the data came from in
    what the closed forms may say about it."""
    if all(poses_segment(data[:, chain.seg_markers[seg]]) for seg in chain.segments):
        return initial_state(chain, data)
    return closed_form_state(model, Trial.from_array(data, chain.labels, rate_hz, source=source), chain, data)


PICK_FRAMES = 120
"""Start combinations are compared by fits to this many frames (all when fewer), evenly spread over the trial: the
constants a start settles on decide its minimum (a few dozen of them), and an eighth of a 1000-frame trial costs an
eighth of a fit."""


PICK_ITER = 40
"""Iterations of each of those fits: the starts that reach the noise had been the highest after 8 (see
:func:`better_start`), and converged within 35."""


def better_start(model, chain: Skeleton, data: np.ndarray, weights: np.ndarray, rate_hz: float, margin: float,
                 source: str = "<array>", max_iter: int = PICK_ITER):
    """The starting state (every frame, not yet fitted) of the combination of the closed-form candidates
    (:func:`start_combinations`, those ``fit`` starts from, joints below an ambiguous one restarted from each of its
    candidates) whose fit to spread frames (:data:`PICK_FRAMES`, `max_iter` iterations each) ends lowest, when that
    is below the first combination's by more than `margin` (mm², on those frames: a caller passes the noise's
    variance times the charge of a parameter, since combinations that reach the same minimum differ by 1e-10 of it
    and which of them comes out lower is chance; when a joint had no closed form of its own the first combination is
    not :func:`start_state`'s, and the lowest is offered for the caller to compare); None otherwise, when every
    segment is posed by its own markers (no closed form is needed to start), or when the closed forms cannot start
    any (this is an improvement on a start the caller has: it never raises for want of one).

    Why: the first combination can settle in a wrong minimum whose gap passes for an effect. A thigh marker 9 mm
    off the femur's line and a knee marker on the hinge, a clean simulated trial: from the first combination the
    rigid fit stopped 21 times above the noise, another fitted the noise, and ``diagnose`` named the gap an extra
    rotation of the knee (score 474 764) where ``fit``, which starts from every combination, found the joint. A
    comparison after a few iterations on all frames does not choose: the starts that reach the noise were the
    highest after 8 iterations."""
    if all(poses_segment(data[:, chain.seg_markers[seg]]) for seg in chain.segments):
        return None
    trial = Trial.from_array(data, chain.labels, rate_hz, source=source)
    try:
        fitted, _ = fit_model(model, trial)
        combos = start_combinations(chain, fitted, lambda fixed: fit_model(model, trial, fixed=fixed)[0], data)[0]
    except CANNOT_START:
        return None
    try:                                    # the refined closed forms' start too, when they can be made
        refined = refined_closed_forms(model, trial, fitted)
        if refined is not fitted and all(refined.get(j, (None,))[0] is not None for j in chain.joints):
            combos.append({j: refined[j][0] for j in chain.joints})
    except CANNOT_START:
        pass
    if len(combos) < 2:
        return None
    idx = np.unique(np.linspace(0, len(data) - 1, min(len(data), PICK_FRAMES)).astype(int))
    ends = []                                    # (rss on the spread frames, start state) per combination
    for combo in combos:
        try:
            state = state_from_joints(model, chain, data, combo)
            ends.append((fit_chain(chain, data[idx], state.at_frames(idx), weights=weights[idx],
                                   max_iter=max_iter).rss, state))
        except CANNOT_START:
            ends.append((np.inf, None))
    k = min(range(len(ends)), key=lambda i: ends[i][0])
    # the first combination is :func:`start_state`'s unless a joint had no closed form of its own (then every
    # combination restarts it, and the first is no baseline: the best is offered, for the caller to compare)
    own = all(j in candidates(fitted) for j in chain.joints)
    if not np.isfinite(ends[k][0]) or (own and (k == 0 or not ends[k][0] < ends[0][0] - margin)):
        return None
    return ends[k][1]
