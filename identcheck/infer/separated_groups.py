"""Skin markers that wobble more than the trial-wide tolerance, grouped by how well they stay apart from the rest.

:func:`identcheck.infer.grouping.partition` calls a pair rigid when its spread is within one tolerance for the
whole trial, set by the noise and by the wobble of a typical marker. In a functional trial of one joint most of
the body hardly moves, and that typical wobble is the still markers': 0.35 mm in biobuddy's knee trial, where the
thigh cluster's markers, driven by the moving knee, spread up to 8.8 mm from each other. Every marker of the
moving leg was then left loose, and the leg had no segment at all. In walking2 a pelvis with two skin markers
that wobble 6-8 mm came out as one body and two loose markers.

What still tells a segment's markers apart is that they move relative to each other much less than relative to
everything else. On the complete-linkage tree of the pair spreads (the height of a node is the largest spread
between two of its markers), a node of height h whose parent joins it to the rest at a height of at least
:data:`SEPARATION_FACTOR` x h is a group held apart from everything: every marker outside it moves relative to
some member at least twice as much as the members move among themselves. :func:`widen` takes the largest such
nodes, top down, with h at most :data:`MAX_SKIN_MM` (skin markers move by up to about that on their segment),
and lets them gather what the tolerance left loose:

- a node may hold at most one of the bodies the tolerance found (three or more markers, with a pose). Two such
  bodies are two segments whose markers each stay rigid, moving relative to each other coherently: a joint that
  hardly moves, not skin wobble, and the node is left to its children, unless it also holds markers that nothing
  else will take (below);
- the node's loose markers and whole pairs join that body, or, without one, form a new group; the group made (a
  body's markers may reach beyond the node) must itself spread by at most :data:`MAX_SKIN_MM` and half its
  separation, and must not hold every marker (that would be no skeleton); a node never seen together with the
  rest often enough has no measured separation and is not taken;
- a new group of four or more markers, or a body with markers added, must pass the pose test of
  :func:`~identcheck.infer.body_frames.is_rigid` at :data:`MAX_SKIN_MM`: each marker, seen in the frame of the
  others, stays within that much (times the pose's own noise amplification) of one body-fixed place. Not at the
  node's height: a distance hardly sees a marker slide across the line to its partner, and skin slides that way
  too (biobuddy's hip trial: pelvis markers whose distances spread 3.2 mm move 7-10 mm in the frame of the other
  three), so the pose test can tell neither a skin marker's slide nor a marker near a hinge's axis from rigid.
- a loose marker that *drifts* in the body's frame (goes one way through the trial:
  :func:`~identcheck.infer.body_frames.drifts_on`) does not join it: skin moving with a joint's
  angles goes and returns, a marker sliding or coming loose does not, and it is left loose (the tree then
  reports why it is placed nowhere).

A node held apart that holds several bodies *and* loose markers is one group for this trial (:func:`_gather`): in a
functional trial of the shoulder the forearm and the hand stay rigid (the elbow and the wrist hardly move) while
the upper arm's skin markers, driven by the shoulder, wobble 5-13 mm against them; the upper arm then has no body of
its own, and its markers, loose, were placed on nothing. The bodies must hardly turn relative to each other (less
than :data:`~identcheck.infer.body_frames.STILL_DEG`): a joint the trial turns is kept, skin markers or not.
Everything in the node moves with everything else in it within skin range and apart from the rest of the body at
least twice as much, so which of its bodies carries a loose marker is a choice the trial cannot make; the tree
needs the node as one segment to find the joint that moved (the shoulder). The bodies' own joints hardly move,
and the group says so (:attr:`Widened.bodies`); the skeleton is then not called settled. Without loose markers the
bodies stay apart, as above: nothing needs them together, and a joint that hardly moves is still a joint.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.cluster.hierarchy import linkage
from scipy.spatial.distance import squareform

from identcheck.geometry.poses import MIN_MARKERS
from identcheck.infer.body_frames import STILL_DEG, drifts_on, is_rigid, relative_turn_deg

SEPARATION_FACTOR = 2.0
"""A node is held apart from the rest when its parent's height is at least this many times its own."""
MAX_SKIN_MM = 15.0
"""The largest spread between two markers of one group that :func:`widen` accepts, mm (skin markers on a thigh in
gait move by 10-20 mm relative to the bone; within a cluster, relative to each other, somewhat less)."""
UNSEEN_MM = 1.0e6
"""Stand-in spread for pairs never seen together often enough (never rigid)."""


@dataclass(frozen=True)
class Widened:
    """One group that :func:`widen` made or enlarged.

    Attributes
    ----------
    columns : tuple of int
        Its marker columns.
    added : tuple of int
        The columns that the trial-wide tolerance had left loose or in a pair.
    spread_mm : float
        The largest spread between two markers of the group made (a body's markers included).
    separation_mm : float
        Its parent's height: the smallest complete-linkage spread to the rest.
    bodies : tuple of tuple of int
        The columns of the tolerance's bodies (three or more markers) that the group merged (:func:`_gather`); empty
        when it grew one body or made a new group.
    """

    columns: tuple
    added: tuple
    spread_mm: float
    separation_mm: float
    bodies: tuple = ()


def _children(Z: np.ndarray, n: int):
    """Each node's two children and height, and each node's leaves, for a SciPy linkage over n leaves."""
    kids = {n + k: (int(a), int(b)) for k, (a, b, _, _) in enumerate(Z)}
    height = {n + k: float(h) for k, (_, _, h, _) in enumerate(Z)}
    leaves = {i: [i] for i in range(n)}
    for k in range(len(Z)):
        a, b = kids[n + k]
        leaves[n + k] = leaves[a] + leaves[b]
    return kids, height, leaves


def spread_dendrogram(spread: np.ndarray, nodes: list):
    """The complete-linkage tree of `spread` over the columns `nodes`: each inner node's two children, each node's
    height and leaves (as columns), and the root."""
    n = len(nodes)
    S = np.asarray(spread, dtype=float)[np.ix_(nodes, nodes)]
    S = np.where(np.isfinite(S), S, UNSEEN_MM)
    S = np.maximum(S, S.T)
    np.fill_diagonal(S, 0.0)
    Z = linkage(squareform(S, checks=False), method="complete")
    kids, height, leaves = _children(Z, n)
    leaves = {k: [nodes[i] for i in v] for k, v in leaves.items()}
    return kids, height, leaves, 2 * n - 2


def widen(xyz, spread: np.ndarray, tolerance: float, groups: list, loose: list,
          nodes: list) -> tuple[list, list, list]:
    """Gather the markers the trial-wide tolerance left loose or paired into groups held apart from the rest.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm (the frames the poses are tested on).
    spread : array, shape (n_markers, n_markers)
        Pair spreads, mm (NaN: not seen together often enough).
    tolerance : float
        The trial-wide rigidity tolerance, mm.
    groups, loose : list
        :func:`~identcheck.infer.grouping.partition`'s groups (lists of columns) and loose columns.
    nodes : list of int
        The columns grouped.

    Returns
    -------
    groups : list of list of int
    loose : list of int
    widened : list of Widened
    """
    if len(nodes) < 2:
        return groups, loose, []
    kids, height, leaves, root = spread_dendrogram(spread, sorted(nodes))
    body_of = {m: k for k, g in enumerate(groups) if len(g) >= MIN_MARKERS for m in g}
    pair_of = {m: k for k, g in enumerate(groups) if len(g) < MIN_MARKERS for m in g}
    taken_pairs, grown, widened = set(), {}, []
    new_groups, merged = [], set()
    stack = [(root, 0.0)]                                   # the root is never held apart from anything
    while stack:
        node, parent_h = stack.pop()
        if node not in kids:
            continue
        h = height[node]
        if h <= tolerance:
            continue
        members = sorted(leaves[node])
        result = None
        # (a parent at UNSEEN_MM: never seen with the rest, so no evidence of being apart from it)
        if h <= MAX_SKIN_MM and SEPARATION_FACTOR * h <= parent_h < UNSEEN_MM:
            result = _gather(xyz, spread, len(nodes), members, h, parent_h, groups, body_of, pair_of,
                             taken_pairs, grown, merged)
        if result is None:
            stack.extend((child, h) for child in kids[node])
            continue
        if result:
            body, added, w = result
            if isinstance(body, tuple):                     # bodies merged: their markers leave their own groups
                merged.update(body)
                new_groups.append(list(w.columns))
            elif body is None:
                new_groups.append(sorted(added))
            else:
                grown[body] = sorted(set(grown.get(body, groups[body])) | set(added))
            widened.append(w)
    used = {m for w in widened for m in w.added}
    out = []
    for k, g in enumerate(groups):
        if k in merged:
            continue
        if k in grown:
            out.append(grown[k])
        elif not (set(g) & used):
            out.append(list(g))
    out += new_groups
    return sorted((sorted(g) for g in out), key=lambda g: g[0]), sorted(m for m in loose if m not in used), widened


def _gather(xyz, spread, n_nodes, members, h, parent_h, groups, body_of, pair_of, taken_pairs, grown, merged):
    """What a candidate node (module docstring) gathers: None to look at its children instead, an empty tuple when
    it has nothing to add, else (the body it grows, None for a new group, or the bodies it merges as a tuple; the
    columns it adds; a Widened).

    A node with several bodies merges them with its loose markers (module docstring) only when it has loose markers,
    no body of it has been grown or merged by another node (a body's markers can lie in two nodes) and every pair of
    its bodies turns less than :data:`~identcheck.infer.body_frames.STILL_DEG` relative to each other. Loose markers
    that drift in the body's frame (the largest body's, for a merge) are not taken. The group made must spread
    within :data:`MAX_SKIN_MM` and half its separation, pass the pose test and not hold every marker."""
    bodies = {body_of[m] for m in members if m in body_of}
    if bodies & merged:
        return None
    added = _loose_in(members, groups, body_of, pair_of, taken_pairs)
    if len(bodies) > 1:
        if any(b in grown for b in bodies) or not _hardly_turn(xyz, groups, sorted(bodies)):
            return None                                 # a joint the trial turns is a joint, skin or not
        body = tuple(sorted(bodies))
        base = sorted(set().union(*(groups[b] for b in body)))
        frame = list(groups[max(body, key=lambda b: len(groups[b]))])
    else:
        body = next(iter(bodies)) if bodies else None
        base = frame = list(grown.get(body, groups[body])) if body is not None else []
    added = [m for m in added if m in pair_of or not drifts_on(xyz, frame, m)]
    if not added:
        return None if isinstance(body, tuple) else ()
    full = sorted(set(base) | set(added))
    if len(full) < 2 or len(full) >= n_nodes:           # never everything: that would be no skeleton at all
        return None
    S = spread[np.ix_(full, full)]                      # a body can reach beyond the node: the group's own spread
    wide = float(np.max(np.where(np.isfinite(S), S, UNSEEN_MM)))
    if wide > MAX_SKIN_MM or parent_h < SEPARATION_FACTOR * wide or not is_rigid(xyz, full, MAX_SKIN_MM):
        return None
    for m in added:
        if m in pair_of:
            taken_pairs.add(pair_of[m])
    merged_bodies = tuple(tuple(groups[b]) for b in body) if isinstance(body, tuple) else ()
    return body, tuple(sorted(added)), Widened(tuple(full), tuple(sorted(added)), wide, float(parent_h), merged_bodies)


def _loose_in(members, groups, body_of, pair_of, taken_pairs) -> list:
    """A node's markers that are in no body: loose ones, and those of pairs wholly inside it not yet taken."""
    inside = set(members)
    added = []
    for m in members:
        if m in body_of:
            continue
        if m in pair_of:
            k = pair_of[m]
            if k in taken_pairs or not set(groups[k]) <= inside:
                continue
        added.append(m)
    return added


def _hardly_turn(xyz, groups, bodies: list) -> bool:
    """Every pair of the `bodies` (indices into `groups`) turns less than
    :data:`~identcheck.infer.body_frames.STILL_DEG` relative to each other (NaN, never posed together, is not)."""
    return all(relative_turn_deg(xyz, list(groups[a]), list(groups[b])) < STILL_DEG
               for k, a in enumerate(bodies) for b in bodies[k + 1:])
