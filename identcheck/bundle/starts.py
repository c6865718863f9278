"""Where the whole-tree fits start: every combination of the closed-form candidates (joint -> JointEstimate), the
one-joint changes first, and copies of the first with a weakly seen centre moved along its line (and the joints posed
through that centre fitted again from the moved one).

Shared by ``fit``, which fits every combination to convergence and compares the minima, and by ``diagnose``, which
takes its rigid-joint fit from the best of them when the first leaves a gap above the noise (a thigh marker nearly
on the femur's line and a knee marker on the hinge: the first combination's fit settled 21 times above the noise on
a clean trial, where another combination's fits the noise, and the gap had been named an extra rotation).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np

from identcheck.errors import DegenerateError, InputError
from identcheck.geometry.poses import segment_poses
from identcheck.io.model import reserved_names
from identcheck.skeleton import Skeleton

MAX_STARTS = 16          # candidate combinations started (more when the one-joint changes alone exceed it)
CANNOT_START = (DegenerateError, InputError, np.linalg.LinAlgError, ValueError)
"""What a start that cannot be made raises: it is skipped, never the fit."""
RADIAL_FACTORS = (0.6, 1.7, 2.5)
"""A centre seen by at most two markers on one side also starts fits at these multiples of its distance from
their centroid (along the line through them, fixed on that side)."""


def candidates(closed_form: dict) -> dict:
    """joint -> list of closed-form JointEstimates to start from (one for a unique joint, all for an
    ambiguous one, including those a far marker ranked lower)."""
    out = {}
    for name, (est, _info) in closed_form.items():
        if est is None:
            continue
        out[name] = [est] + list(est.alternatives) + list(est.ranked_out)
    return out


def radial_variants(chain: Skeleton, data: np.ndarray, joint: str, est) -> list:
    """Copies of a spherical closed-form estimate with its centre moved along the line from the centroid of the
    sparser side's markers (one or two) through it, to :data:`RADIAL_FACTORS` times that distance.

    The line is taken on the side with three markers or more, where a pose is measured (the centroid averaged
    into its frame), so the moved centre is a rigid point of that side; with no such side it is scaled about
    the centroid in every frame (a rigid point of the sparse side). No copies for a revolute joint, or when both
    sides carry three markers or more (the fit is well conditioned there)."""
    if est.kind != "spherical" or est.centre is None:
        return []
    sparse_seg = sparse_side(chain, joint)
    rich_seg = chain.child[joint] if sparse_seg == chain.parent[joint] else chain.parent[joint]
    sparse, rich = chain.seg_markers[sparse_seg], chain.seg_markers[rich_seg]
    if len(sparse) == 0 or len(sparse) > 2:
        return []
    with np.errstate(invalid="ignore"):
        anchor = np.mean(data[:, sparse], axis=1)          # NaN where one of them is unseen
    moved = [anchor + k * (est.centre - anchor) for k in RADIAL_FACTORS]
    if len(rich) >= 3:
        poses = segment_poses(data[:, rich])
        c_loc, a_loc = poses.body_fixed(est.centre), poses.body_fixed(anchor)
        if np.isfinite(c_loc).all() and np.isfinite(a_loc).all():
            moved = [poses.to_world((a_loc + k * (c_loc - a_loc))[None])[:, 0] for k in RADIAL_FACTORS]
    return [replace(est, centre=c, estimator=f"{est.estimator}, distance ×{k:g}", alternatives=[], ranked_out=[],
                    unique=False)
            for k, c in zip(RADIAL_FACTORS, moved) if np.isfinite(c).all(axis=1).sum() >= 3]


def sparse_side(chain: Skeleton, joint: str) -> str:
    """The segment of `joint` with fewer markers (the parent on a tie): where a centre moved along its weak line
    moves (:func:`radial_variants`); on the other side the moved centre is a rigid point by construction."""
    return min((chain.parent[joint], chain.child[joint]), key=lambda seg: len(chain.seg_markers[seg]))


def dependents(chain: Skeleton, closed_form: dict, joint: str, side: str) -> list:
    """The joints whose closed forms took `joint`'s virtual markers (its centre or axis points) as points of segment
    `side`, and, through each of them, the joints that took its points on its other segment (away from the one it
    was reached through), in the closed forms' order. A centre is passed to both its segments, so a left hip lists
    the right hip's centre among its pelvis points: moved on the thigh's side, the right hip reaches its knee, not
    the left leg."""
    reached = {joint: side}          # joint -> the segment its change reaches onward
    grown = True
    while grown:                     # a knee's axis points may pose the thigh for the hip above it: any order
        grown = False
        for name, (_est, info) in closed_form.items():
            if name in reached or name not in chain.parent:
                continue
            ends = {chain.parent[name]: info.get("parent_markers", ()),
                    chain.child[name]: info.get("child_markers", ())}
            for src, seg in list(reached.items()):
                if seg in ends and set(reserved_names([src])) & set(ends[seg]):
                    reached[name] = chain.child[name] if seg == chain.parent[name] else chain.parent[name]
                    grown = True
                    break
    return [name for name in closed_form if name in reached and name != joint]


def with_dependents(chain: Skeleton, closed_form: dict, combo: dict, joint: str, restart) -> dict:
    """`combo` (joint -> JointEstimate) whose `joint` was moved along its weak line, started again from the closed
    forms with the moved joint fixed (``restart``) when a joint took its points on the side it moved
    (:func:`dependents`): every other joint from that restart, its first candidate, so that the start is one pass of
    the closed forms; as it is when no joint depends on it, there is no restart, or the restart cannot make one.

    A hip moved along its weak line above a knee posed through it (a 3 | 1 | 1 gait leg) had kept the knee
    computed from the unmoved hip (12-14 mm from the thigh marker, 322 in truth): from a start near the true hip
    (RTH1 113 mm from it, 119 in truth) the whole tree settled back 43 mm from the marker; the knee
    refitted from the moved hip gives a start whose fit stays near the true hip, with 4 900 mm² less residual sum of
    squares over the trial's 1 457 frames (held-out fit draw 5970, trial 75)."""
    below = dependents(chain, closed_form, joint, sparse_side(chain, joint))
    if not below or restart is None:
        return combo
    try:
        again = restart({joint: combo[joint]})
    except CANNOT_START:                # the moved centre's points too few for a closed form: as it was
        return combo
    if any(again.get(j, (None,))[0] is None for j in below):
        return combo
    return {j: combo[j] if j == joint or again.get(j, (None,))[0] is None else again[j][0] for j in combo}


def by_changes(cands: dict, names: list, cap: int) -> tuple[list, int]:
    """(index tuples into ``cands`` (joint -> candidates), how many more combinations exist): the first
    combination, then those that change one joint, then (up to ``cap`` in all) those that change several."""
    sizes = [len(cands[n]) for n in names]
    first = (0,) * len(names)
    head = [first] + [first[:k] + (i,) + first[k + 1:] for k, size in enumerate(sizes) for i in range(1, size)]
    several = (idx for idx in itertools.product(*map(range, sizes)) if sum(i > 0 for i in idx) > 1)
    rest = list(itertools.islice(several, max(cap - len(head), 0)))
    return head + rest, math.prod(sizes) - len(head) - len(rest)


def start_combinations(chain, closed_form: dict, restart, data=None) -> tuple[list, int, str, int]:
    """Start assignments (joint -> JointEstimate), how many were left out, why none could be made, and how many
    of the assignments (after the first) change one joint's candidate.
    Every combination of the candidates of the ambiguous joints, those that change one joint of the first
    combination first (each joint's every candidate is tried, whatever the number of ambiguous joints: on
    a body with four hinges of four candidates each, their twins come before the 243 combinations that
    change several hinges at once); joints the closed form left without a start because a joint above them
    was ambiguous are started from each of that joint's candidates in turn (``restart(fixed)`` reruns the
    closed form with those candidates taken as the joints). With `data`, the combinations that change one
    joint are followed by the first's copies with one weak centre moved (:func:`radial_variants`). The cap
    :data:`MAX_STARTS` never leaves out a one-joint change."""
    cands = candidates(closed_form)
    names = list(cands)
    singles = sum(len(cands[n]) - 1 for n in names)
    cap = max(MAX_STARTS, 1 + singles)
    chosen, unlisted = by_changes(cands, names, cap)
    combos = [dict(zip(names, (cands[n][i] for n, i in zip(names, idx)))) for idx in chosen]
    missing = [j for j in chain.joints if j not in cands]
    if not missing and combos and data is not None:     # the first combination with one weak centre moved
        room = max(cap - 1 - singles, 0)                  # (those the cap would cut are not restarted)
        variants = [(n, v) for n in names for v in radial_variants(chain, data, n, combos[0][n])][:room]
        moved = [with_dependents(chain, closed_form, {**combos[0], n: v}, n, restart) for n, v in variants]
        combos = combos[:1 + singles] + moved + combos[1 + singles:]
    if missing:
        ambiguous = [n for n in names if len(cands[n]) > 1]
        if not ambiguous or restart is None:
            return [], 0, f"no closed-form start for {', '.join(missing)}", 0
        combos = []
        for idx in itertools.product(*[range(len(cands[n])) for n in ambiguous]):
            if len(combos) >= MAX_STARTS:
                break
            fixed = {n: cands[n][i] for n, i in zip(ambiguous, idx)}
            again = restart(fixed)
            if all(again.get(j, (None,))[0] is not None for j in chain.joints):
                combos.append({j: again[j][0] for j in chain.joints})
        if not combos:
            return [], 0, f"no closed-form start for {', '.join(missing)}, from any candidate of {', '.join(ambiguous)}", 0
        cap, unlisted, singles = MAX_STARTS, 0, 0
    return combos[:cap], max(len(combos) - cap, 0) + unlisted, "", singles
