"""Fit every joint of a model to a trial in closed form, propagating identified joints as virtual markers: the
start of ``fit``'s whole-tree fit, and of ``diagnose``'s where a segment has fewer than three markers.

Joints are visited until nothing changes: a joint is fitted as soon as its links carry enough
markers — real, or virtual ones left by joints already fitted (a centre, or two points of a hinge,
sits still on both of its links; only a unique joint is passed on) — and the estimator is the one :mod:`identcheck.estimate.joint`
picks for the markers available. So three pelvis markers, one thigh and one shank marker give
the hip by a (3,1) sphere and then the knee by Pham's (2,1) hinge on the hip centre and the thigh
marker. A joint neither of whose links carries three points waits while one with a posed link can go first:
with 2 pelvis, 2 thigh and 3 shank markers the knee comes first (thigh markers on circles in the shank's frame),
and its axis points pose the thigh for the hip (pelvis markers on spheres in the thigh's frame), rather than
S22's (2,2) hip posing the thigh for the knee. A joint whose markers never suffice is reported as not
identifiable, with the table's row for its case.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import logging
import threading
import warnings
from collections import OrderedDict

import numpy as np

from identcheck.errors import DegenerateError, InputError
from identcheck.estimate import joint as E
from identcheck.geometry.poses import farthest_pair, poses_segment

log = logging.getLogger("identcheck")
SPHERE_MARGIN = 3.0        # a far marker decides among revolute (2,1) candidates by 3x and this many (2,1) rms


def _case(kind: str, p: int, q: int) -> str:
    return f"{kind}({p},{q})"


def _estimator(kind: str, p: int, q: int):
    """The estimator for p parent and q child markers (p >= q; see :mod:`identcheck.estimate.joint`),
    called as f(parent_list, child_list, case); None when the markers do not identify the joint."""
    stack = lambda xs: np.stack(xs, axis=1)  # noqa: E731
    if q == 0 or p < q:
        return None
    if p >= 3 and q >= 3:
        return lambda P, C, case: E.posed_pair(stack(P), stack(C), kind, case)
    if p >= 3:
        fn = E.posed_sphere if kind == "spherical" else E.posed_circle
        return lambda P, C, case: fn(stack(P), stack(C), case)
    if kind == "spherical" and (p, q) == (2, 2):
        return lambda P, C, case: E.pair_spherical(P[0], P[1], C[0], C[1], case)
    if kind == "revolute" and p == 2:
        return lambda P, C, case: E.pair_revolute(P[0], P[1], stack(C[:1]), case)
    return None


def _posing_count(points: dict) -> int:
    """How many of a link's points count in choosing its estimator: all of them when they pose the link
    (:func:`~identcheck.geometry.poses.poses_segment`), at most two when they lie on one line (three anatomical thigh
    markers, greater trochanter to epicondyle: the link's roll is not theirs to give, and an estimator that poses the
    link by them alone is fed poses flipping by half turns)."""
    if len(points) >= 3 and not poses_segment(np.stack(list(points.values()), axis=1)):
        return 2
    return len(points)


def _choose(kind: str, parent: dict, child: dict, p: int, q: int):
    """(estimator, parent markers, child markers) with the links ordered so that p >= q, or None; p and q count
    the points that pose each link (:func:`_posing_count`), and every point is passed on (a two-point estimator
    takes the first two: of points on one line, the two farthest apart)."""
    if p < q:
        parent, child, p, q = child, parent, q, p
    fn = _estimator(kind, p, q)
    if fn is None:
        return None
    return fn, _ends_first(parent, p), _ends_first(child, q)


def _ends_first(points: dict, count: int) -> list:
    """The points' trajectories, the two farthest apart first when only two of them pose the link (`count` 2 of
    three or more on one line)."""
    values = list(points.values())
    if count >= 3 or len(values) <= 2:
        return values
    a, b = farthest_pair(np.stack(values, axis=1))
    return [values[a], values[b]] + [v for k, v in enumerate(values) if k not in (a, b)]


def _markers(model, points: dict, virtual: dict, seg: str) -> dict:
    real = dict(zip(model.segments[seg].markers, np.moveaxis(points[seg], 1, 0)))
    usable = {k: v for k, v in real.items() if np.isfinite(v).all(axis=1).any()}
    known = {k: v for k, v in virtual.get(seg, {}).items() if np.isfinite(v).all(axis=1).any()}
    return {**usable, **known}


CACHED_ESTIMATES = 64
"""How many closed-form joint estimates :func:`estimate_once` keeps (the most recently used): at 1 500 frames an
estimate takes 0.04-0.3 MB (a (2, 1) hinge with its candidates the most), so at most about 20 MB."""
_cache: OrderedDict = OrderedDict()
_cache_lock = threading.Lock()


def estimate_once(fn, P: list, C: list, kind: str, case: str):
    """``fn(P, C, case)``, the estimator :func:`_choose` picked for a joint of `kind`, computed once for the same
    points under the same warning filters: every estimator is a deterministic function of its points (the scattered
    starts of a (2, 1) hinge are seeded), so the answer kept for an earlier call with equal arrays is the answer (a
    copy: callers mark estimates). The warnings it gave are given again on every call, as if it had run (a verb
    reports them: a sphere centre the motion barely determines); an estimate's notes record some warnings as the
    filters in force let them through, so those filters are part of what is kept apart.

    Why: ``diagnose`` starts the whole tree again from the closed forms on data an effect corrected (a delay undone,
    swapped labels put back), and such a correction leaves most joints' points as they were; on a walking trial with
    four joints, eight such restarts spent 86 of 245 s refitting the same (2, 1) hinges."""
    digest = hashlib.blake2b(f"{kind}|{case}|{len(P)}|{len(C)}|{warnings.filters!r}".encode(), digest_size=20)
    for a in list(P) + list(C):
        a = np.ascontiguousarray(a, dtype=float)
        digest.update(str(a.shape).encode())
        digest.update(a.tobytes())
    key = digest.hexdigest()
    with _cache_lock:
        kept = _cache.get(key)
        if kept is not None:
            _cache.move_to_end(key)
    if kept is None:
        with warnings.catch_warnings(record=True) as caught:       # the caller's filters, the warnings recorded
            est = fn(P, C, case)
        kept = (copy.deepcopy(est), [(w.message, w.category, w.filename, w.lineno) for w in caught])
        with _cache_lock:
            _cache[key] = kept
            while len(_cache) > CACHED_ESTIMATES:
                _cache.popitem(last=False)
    else:
        est = copy.deepcopy(kept[0])
    for message, category, filename, lineno in kept[1]:
        warnings.warn_explicit(message, category, filename, lineno)
    return est


def fit_model(model, trial, progress=None, fixed: dict | None = None) -> dict:
    """Every joint of ``model`` fitted to ``trial``: name → (JointEstimate | None, info dict).

    ``fixed``: joint → one of its candidate JointEstimates, taken as the joint (its virtual markers passed
    down) instead of fitting it: the whole-tree fit starts the joints below an ambiguous one from each of
    its candidates this way."""
    points = {name: trial.select(seg.markers).as_array() for name, seg in model.segments.items()}
    virtual: dict = {}
    done: dict = {}
    pending = list(model.joint_order)
    # Pham (2,1) leaves 4 joints: fit one only when no other joint can go first (level 0), and prefer one
    # whose far marker can decide it (level 1) to one that will stay ambiguous (level 2).
    # A joint neither of whose links carries three points (S22's (2,2), a hinge's (2,2)) also waits at level 0: a
    # joint with a posed link may first lend one of its links a centre or axis points. Held-out 2+2 legs (2 pelvis,
    # 2 thigh, 3 shank markers): S22 first put the hip 12 mm off, the thigh posed through it put SARA's knee 67 mm
    # off, and the whole-tree fit from there stopped in a minimum at 4x the noise (3 of 20 functional trials); the
    # knee first (thigh markers on circles in the posed shank) poses the thigh for a hip by spheres in it.
    level = 0
    while pending:
        progressed = False
        for name in list(pending):
            jt = model.joints[name]
            par, chi = _markers(model, points, virtual, jt.parent), _markers(model, points, virtual, jt.child)
            p, q = _posing_count(par), _posing_count(chi)       # what poses each link: its case and its turn
            case = _case(jt.type, p, q)
            if fixed and name in fixed:
                est = dataclasses.replace(fixed[name], unique=True, alternatives=[], ranked_out=[])
                done[name] = (est, {"case": case, "parent_markers": list(par), "child_markers": list(chi)})
                for seg in (jt.parent, jt.child):
                    virtual.setdefault(seg, {}).update(est.virtual_markers(name))
                pending.remove(name)
                progressed = True
                continue
            chosen = _choose(jt.type, par, chi, p, q)
            if chosen is None:
                continue        # wait: a later joint may add virtual markers
            if jt.type == "revolute" and sorted((p, q)) == [1, 2]:
                one_side = jt.child if p >= q else jt.parent
                if level == 0 or (level == 1 and not _far_markers(model, name, one_side, points)):
                    continue    # wait: another joint's virtual markers may make it unique
            elif max(p, q) < 3 and level == 0:
                continue        # wait: a joint with a posed link may first pose one of these
            if progress:
                progress(f"fitting {name}: {case} with {', '.join(par)} | {', '.join(chi)}")
            fn, P, C = chosen
            try:
                est = estimate_once(fn, P, C, jt.type, case)
            except DegenerateError as exc:   # degenerate motion: report this joint, fit the others
                done[name] = (None, {"case": case, "parent_markers": list(par), "child_markers": list(chi),
                                     "reason": f"degenerate data: {exc}"})
                pending.remove(name)
                progressed = True
                continue
            except InputError as exc:        # the estimators see arrays: name the file and the joint
                raise exc.naming(trial.source, f"joint {name!r} ({case} with {', '.join(par)} | "
                                               f"{', '.join(chi)}): ") from None
            if not est.unique and jt.type == "revolute" and max(p, q) == 2:
                one_side = jt.child if p >= q else jt.parent
                est = _decide_revolute21(model, name, one_side, est, C, points)
            done[name] = (est, {"case": case, "parent_markers": list(par), "child_markers": list(chi)})
            if est.unique:      # a joint among equally good alternatives must not be passed down as if known
                for seg in (jt.parent, jt.child):
                    virtual.setdefault(seg, {}).update(est.virtual_markers(name))
            pending.remove(name)
            progressed = True
            level = 0
        if not progressed:
            if level == 2:
                break
            level += 1
    for name in pending:
        jt = model.joints[name]
        par, chi = _markers(model, points, virtual, jt.parent), _markers(model, points, virtual, jt.child)
        done[name] = (None, {"case": _case(jt.type, _posing_count(par), _posing_count(chi)),
                             "parent_markers": list(par), "child_markers": list(chi)})
    return {n: done[n] for n in model.joint_order}, points


def not_identifiable(info: dict) -> str:
    """Why a joint `fit_model` left without an estimate and without a reason of its data (its ``info``: case and
    markers) has none: its case is not identifiable from those markers, whatever the motion (the table's answer)."""
    return (f"not identifiable: {info['case']} with markers {info['parent_markers']} | {info['child_markers']} "
            "(see `identcheck table`); add markers")


def _sphere_rms(p: np.ndarray) -> float:
    """RMS distance of points (N, 3) from their least-squares sphere (algebraic fit), mm."""
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < 5:
        return float("nan")
    A = np.c_[2 * p, np.ones(len(p))]
    sol = np.linalg.lstsq(A, np.sum(p * p, axis=1), rcond=None)[0]
    c = sol[:3]
    radius = np.sqrt(max(sol[3] + c @ c, 0.0))
    return float(np.sqrt(np.mean((np.linalg.norm(p - c, axis=1) - radius) ** 2)))


def _far_markers(model, name, one_side, points) -> list:
    """(name, trajectory) of the markers beyond the other joints of ``one_side``."""
    far = []
    for k in model.joint_order:
        jk = model.joints[k]
        if k != name and one_side in (jk.parent, jk.child):
            seg = jk.child if one_side == jk.parent else jk.parent
            far += [(m, points[seg][:, i]) for i, m in enumerate(model.segments[seg].markers)]
    return far


def _fixed_rms(p: np.ndarray) -> float:
    """RMS distance of points (N, 3) from their mean: zero for a point fixed in the frame, mm."""
    p = p[np.all(np.isfinite(p), axis=1)]
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))) if len(p) >= 2 else float("nan")


def _decide_revolute21(model, name, one_side, est, one_points, points):
    """Pham's revolute (2,1) leaves 4 joints (ERRATA E1, E2); more data on the one-point segment decide.
    Each candidate gives that segment's frame per frame (its hinge and the first point B). Seen in it,
    another point of the segment (revolute (2,2)) must stand still, and a marker beyond another joint of
    the segment must stay on a sphere (twin_certificate proves it does only for the true joint). The
    candidate that is clearly best on these is kept; otherwise all stay, with the scores in a note."""
    b, others = one_points[0], list(one_points[1:])
    far = _far_markers(model, name, one_side, points)
    if not others and not far:
        est.nothing_beyond = True        # the case's joints fit any rigid data equally: no likelihood can decide
        return est
    cands = [est] + list(est.alternatives)
    scores = []
    for cand in cands:
        o = cand.point + np.sum((b - cand.point) * cand.direction, axis=1, keepdims=True) * cand.direction
        x = b - o
        x = x / np.linalg.norm(x, axis=1, keepdims=True)
        z = cand.direction
        frame = np.stack([x, np.cross(z, x), z], axis=1)            # rows: the segment's axes, per frame
        local = lambda f: np.einsum("fij,fj->fi", frame, f - o)    # noqa: E731
        scores.append(np.nanmean([_fixed_rms(local(f)) for f in others]
                                 + [_sphere_rms(local(f)) for _, f in far]))
    what = (["the segment's other points"] if others else []) + [m for m, _ in far]
    order = np.argsort(scores)
    best, second = scores[order[0]], scores[order[1]]
    margin = SPHERE_MARGIN * max(est.rms_residual, 0.0) if np.isfinite(est.rms_residual) else np.inf
    if not (np.isfinite(best) and second > 3 * best + margin):
        est.notes.append(f"{', '.join(what)} could not tell the candidates apart: residuals "
                         f"{', '.join(f'{v:.2g}' for v in scores)} mm")
        return est
    chosen = cands[order[0]]
    chosen.ranked_out = [c for i, c in enumerate(cands) if i != order[0]]
    for c in chosen.ranked_out:
        c.alternatives = []
    chosen.unique, chosen.alternatives = True, []
    chosen.notes = [n for n in est.notes if "explain the samples equally well" not in n]
    chosen.notes.append(f"chosen among {len(cands)} revolute (2,1) joints by {', '.join(what)} (fixed in, or on a "
                        f"sphere in, {one_side}'s frame only for the true joint): residual {best:.2g} mm, next "
                        f"{second:.2g} mm")
    chosen.excitation_ok, chosen.excitation_reason = est.excitation_ok, est.excitation_reason
    chosen.uncertainty_mm = est.uncertainty_mm
    return chosen
