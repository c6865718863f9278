"""Segment hierarchy from motion alone, and playback through the fitted articulated model.

O'Brien et al. (2000), section 3.3: fit a joint (:func:`identcheck.estimate.obrien.joint_location`)
between every pair of segments; the pair's fit residual is the weight of an edge between
them; the hierarchy is the minimum spanning tree of that complete graph, which minimises the
sum of the joint residuals over all trees. The residual of a pair does not depend on which
segment is the parent (:meth:`JointFit.reversed`), so the tree is undirected and the root is a
choice the residuals cannot make: the caller names it, or it defaults to the tree's centre (the
segment with the fewest joints to its farthest segment; ties go to the smaller summed joint
count, then to input order), which for a human-like tree usually falls on the trunk, where the
paper puts the root.

Edge weight: the RMS residual (mm), not eq. (19) as printed, which divides by √n once more and
so favours pairs with more usable frames when occlusion differs between pairs (erratum O2 in
``derivations/ERRATA.md, seed 002``). With equal frame counts the two give the same tree.
When the caller can say what residual a perfect joint would leave at each pair's fit (``expected``,
e.g. from the marker noise and the two clusters' geometry), the tree is the minimum spanning tree
of the *excess* r² − r_expected² instead: a joint between two small or far clusters leaves a large
residual from their pose noise alone, and a raw comparison would prefer a wrong joint between two
well-posed clusters that fits a few mm worse than a joint can (erratum O5).

Section 3.4, playback: the articulated model made of the fitted joints, driven by the root's
pose and each joint's measured relative rotation, rebuilds every segment's pose by eqs. (4) and
(9); the joints then stay together exactly, and the rebuild error against the measured markers
shows what discarding the residual cost.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree

from identcheck.geometry.kinematics import chain_poses
from identcheck.errors import InputError
from identcheck.estimate.obrien import HINGE_TOL_DEG, as_poses, joint_location
from identcheck.geometry.poses import MIN_MARKERS, Poses


# ---------------------------------------------------------------------- input
def points_by_segment(trial, model) -> dict[str, np.ndarray]:
    """Each model segment's marker positions from a trial.

    Parameters
    ----------
    trial : identcheck.trial.Trial
    model : identcheck.io.model.Model

    Returns
    -------
    dict of str to numpy.ndarray
        Segment name → shape (n_frames, n_markers_of_segment, 3), mm, NaN = occluded.

    Raises
    ------
    InputError
        Markers of the model missing from the trial (all named at once).
    """
    return {name: trial.select(seg.markers).as_array() for name, seg in model.segments.items()}


# ---------------------------------------------------------------------- result
@dataclass(frozen=True)
class Hierarchy:
    """An inferred segment tree (O'Brien et al., section 3.3).

    Attributes
    ----------
    segments : tuple of str
        The segments in the tree (those with a pose), in input order.
    root : str
    parent : dict of str to str
        Child segment → parent segment (every segment but the root).
    order : tuple of str
        Segments breadth first from the root (every parent before its children).
    residual_mm : numpy.ndarray
        Pairwise RMS joint residual, shape (n, n) in ``segments`` order, symmetric, 0 on the
        diagonal, inf where the pair has too few frames with both poses.
    fits : dict of str to JointFit
        Child segment → the fit of its joint with its parent, oriented parent → child.
    margin_mm : dict of str to float
        Child segment → how much the summed residual of the best tree without this joint
        exceeds the chosen tree's (≥ 0; inf if no other tree exists). Near 0: the data hardly
        prefer this joint to an alternative. (With ``expected`` the tree minimises the excess
        instead, and a margin can be negative: the cheapest replacement fits with a smaller raw
        residual, but further beyond what its own pose noise allows.)
    unused_fits : tuple of (str, str, float)
        Pairs left out of the tree whose residual is no larger than the largest residual in
        it: a loop joint (section 5) or a hierarchy the data cannot settle.
    total_residual_mm : float
        Sum of the tree's joint residuals.
    root_rule : str
        "given" or "centre" (the default rule, module docstring).
    skipped : dict of str to str
        Segments left out → why (fewer than 3 markers, no pose).
    poses : dict of str to Poses
        The segment poses used.
    excess_mm2 : numpy.ndarray or None
        With ``expected``: r² − r_expected² per pair, mm² (the tree's edge weights), inf where
        ``residual_mm`` is; None without.
    """

    segments: tuple
    root: str
    parent: dict
    order: tuple
    residual_mm: np.ndarray
    fits: dict
    margin_mm: dict
    unused_fits: tuple
    total_residual_mm: float
    root_rule: str
    skipped: dict = field(default_factory=dict)
    poses: dict = field(default_factory=dict, repr=False)
    excess_mm2: np.ndarray | None = field(default=None, repr=False)

    @property
    def weight(self) -> np.ndarray:
        """The edge weights the tree minimises: ``excess_mm2`` when known, else ``residual_mm`` (same order as r²)."""
        return self.residual_mm if self.excess_mm2 is None else self.excess_mm2

    def edges(self) -> list[tuple[str, str, float]]:
        """(parent, child, RMS residual mm) for every joint, breadth first."""
        return [(self.parent[c], c, self.fits[c].rms_residual) for c in self.order[1:]]

    def joints(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Child → (joint location in the parent frame, in the child frame), mm."""
        return {c: (f.centre_parent, f.centre_child) for c, f in self.fits.items()}


@dataclass(frozen=True)
class Playback:
    """Motion rebuilt through an articulated model (O'Brien et al., section 3.4).

    Attributes
    ----------
    R, t : dict of str to numpy.ndarray
        Rebuilt world-from-segment rotations, shape (n_frames, 3, 3), and translations,
        shape (n_frames, 3), mm; NaN where the segment or an ancestor has no pose.
    markers : dict of str to numpy.ndarray
        Rebuilt marker positions, shape (n_frames, n_markers, 3), mm.
    rms_mm : float
        RMS over segments, markers and frames (where both are finite) of the distance between
        rebuilt and reference markers, mm.
    rms_by_segment : dict of str to float
    n_frames : int
        Frames in which every segment was rebuilt.
    reference : str
        "measured" (marker points given) or "rigid" (each segment's own unconstrained pose).
    """

    R: dict
    t: dict
    markers: dict
    rms_mm: float
    rms_by_segment: dict
    n_frames: int
    reference: str


# ---------------------------------------------------------------------- section 3.3
def infer_hierarchy(segments: Mapping, root: str | None = None,
                    hinge_tol_deg: float = HINGE_TOL_DEG, expected=None) -> Hierarchy:
    """Infer the segment tree from motion by a minimum spanning tree over joint residuals.

    Parameters
    ----------
    segments : mapping of str to Poses or array
        Segment name → its poses, or its marker positions, shape (n_frames, n_markers, 3), mm,
        NaN = occluded. Segments given as points with fewer than 3 markers are skipped (and
        listed in ``skipped``).
    root : str, optional
        The root segment; by default the tree's centre (module docstring).
    hinge_tol_deg : float
        Passed to :func:`identcheck.estimate.obrien.joint_location`.
    expected : callable, optional
        ``expected(name_a, name_b, fit) -> float``: the RMS residual (mm) a perfect joint at the pair's fit
        would leave (NaN: unknown, counted as 0). When given, the tree minimises the excess r² − expected²
        (module docstring).

    Returns
    -------
    Hierarchy

    Raises
    ------
    InputError
        Fewer than two usable segments, an unknown ``root``, mismatched frame counts, or
        segments that cannot be connected (no pair across the gap shares 3 frames with poses).

    Examples
    --------
    >>> h = infer_hierarchy(points_by_segment(trial, model))     # doctest: +SKIP
    >>> h.root, h.parent                                         # doctest: +SKIP
    """
    poses, skipped, problems = {}, {}, []
    for name, seg in segments.items():
        if not isinstance(seg, Poses):
            arr = np.asarray(seg, dtype=float)
            if arr.ndim == 3 and arr.shape[2] == 3 and arr.shape[1] < MIN_MARKERS:
                skipped[name] = f"{arr.shape[1]} marker(s); a segment pose needs at least {MIN_MARKERS}"
                continue
        try:
            poses[name] = as_poses(seg, name)
        except InputError as exc:
            problems.extend(exc.problems)
    frames = {p.R.shape[0] for p in poses.values()}
    if len(frames) > 1:
        problems.append(f"segments have different frame counts {sorted(frames)}; they must come "
                        "from one trial")
    if problems:
        raise InputError(problems)
    names = tuple(poses)
    if len(names) < 2:
        raise InputError([f"a hierarchy needs at least 2 segments with {MIN_MARKERS}+ markers, got "
                          f"{len(names)}" + (f" (skipped: {', '.join(skipped)})" if skipped else "")])
    if root is not None and root not in poses:
        why = f" ({skipped[root]})" if root in skipped else ""
        raise InputError([f"root {root!r} is not among the usable segments {', '.join(names)}{why}"])

    n = len(names)
    W = np.full((n, n), np.inf)
    np.fill_diagonal(W, 0.0)
    pair_fit = {}
    for i in range(n):
        for j in range(i + 1, n):
            try:
                f = joint_location(poses[names[i]], poses[names[j]], hinge_tol_deg,
                                   names=(names[i], names[j]))
            except InputError:
                continue
            pair_fit[i, j] = f
            W[i, j] = W[j, i] = f.rms_residual

    excess = None
    if expected is not None:
        excess = np.full((n, n), np.inf)
        np.fill_diagonal(excess, 0.0)
        for (i, j), f in pair_fit.items():
            e = float(expected(names[i], names[j], f))
            excess[i, j] = excess[j, i] = W[i, j] ** 2 - (e ** 2 if np.isfinite(e) else 0.0)
    weight = W if excess is None else excess
    # Every spanning tree has n - 1 edges, so adding a constant to every weight leaves the minimum
    # tree unchanged; shifted to 1 and above, zero residuals (exact data) and negative excesses do not
    # read as "no edge".
    off = ~np.eye(n, dtype=bool) & np.isfinite(weight)
    shift = 1.0 - min(0.0, float(weight[off].min())) if off.any() else 1.0
    graph = np.where(off, weight + shift, 0.0)
    n_comp, label = connected_components(graph, directed=False)
    if n_comp > 1:
        groups = ["{" + ", ".join(names[k] for k in range(n) if label[k] == c) + "}" for c in range(n_comp)]
        raise InputError([f"segments fall into {n_comp} groups with no pair across them sharing enough "
                          f"frames with poses: {' '.join(groups)}"])
    tree = minimum_spanning_tree(graph).toarray()
    adj = (tree > 0) | (tree.T > 0)

    hops = _hops(adj)
    if root is None:
        ecc = hops.max(axis=1)
        key = [(ecc[k], hops[k].sum(), k) for k in range(n)]
        r, rule = min(key)[2], "centre"
    else:
        r, rule = names.index(root), "given"

    parent_idx, order = {}, [r]
    queue = deque([r])
    while queue:
        u = queue.popleft()
        for v in np.flatnonzero(adj[u]):
            if v != r and v not in parent_idx:
                parent_idx[v] = u
                order.append(v)
                queue.append(v)

    fits = {}
    for v, u in parent_idx.items():
        f = pair_fit[(u, v)] if u < v else pair_fit[(v, u)].reversed()
        fits[names[v]] = f
    margins = {names[v]: _margin(W, adj, u, v) for v, u in parent_idx.items()}
    worst = max(W[u, v] for v, u in parent_idx.items())
    unused = tuple((names[i], names[j], float(W[i, j])) for i in range(n) for j in range(i + 1, n)
                   if not adj[i, j] and W[i, j] <= worst)
    return Hierarchy(segments=names, root=names[r],
                     parent={names[v]: names[u] for v, u in parent_idx.items()},
                     order=tuple(names[k] for k in order), residual_mm=W, fits=fits,
                     margin_mm=margins, unused_fits=unused,
                     total_residual_mm=float(sum(W[u, v] for v, u in parent_idx.items())),
                     root_rule=rule, skipped=skipped, poses=poses, excess_mm2=excess)


def _hops(adj: np.ndarray) -> np.ndarray:
    """Number of tree edges between every pair of nodes (BFS from each)."""
    n = len(adj)
    out = np.zeros((n, n), dtype=int)
    for s in range(n):
        dist = np.full(n, -1)
        dist[s] = 0
        queue = deque([s])
        while queue:
            u = queue.popleft()
            for v in np.flatnonzero(adj[u]):
                if dist[v] < 0:
                    dist[v] = dist[u] + 1
                    queue.append(v)
        out[s] = dist
    return out


def _margin(W: np.ndarray, adj: np.ndarray, u: int, v: int) -> float:
    """Extra summed residual of the best tree without edge (u, v): cheapest edge across the cut."""
    cut = adj.copy()
    cut[u, v] = cut[v, u] = False
    side = np.zeros(len(W), dtype=bool)
    side[v] = True
    queue = deque([v])
    while queue:
        a = queue.popleft()
        for b in np.flatnonzero(cut[a]):
            if not side[b]:
                side[b] = True
                queue.append(b)
    across = W[np.ix_(side, ~side)].copy()
    across[np.flatnonzero(side) == v, np.flatnonzero(~side) == u] = np.inf   # the edge itself
    best = across.min() if across.size else np.inf
    return float(best - W[u, v])


# ---------------------------------------------------------------------- section 3.4
def relative_rotations(hierarchy: Hierarchy, poses: Mapping | None = None) -> dict[str, np.ndarray]:
    """Each joint's measured rotation ``R^{i→P(i)} = R_Pᵀ R_i``, child → shape (n_frames, 3, 3)."""
    poses = hierarchy.poses if poses is None else poses
    return {c: np.einsum("fji,fjk->fik", poses[p].R, poses[c].R) for c, p in hierarchy.parent.items()}


def rebuild(parent: Mapping[str, str], root: str, joints: Mapping, root_R, root_t,
            rel_R: Mapping, local: Mapping) -> tuple[dict, dict, dict]:
    """Pose every segment of an articulated model and place its markers (eqs. 4, 6, 9).

    Parameters
    ----------
    parent : mapping of str to str
        Child → parent; together with `root`, a tree.
    root : str
    joints : mapping of str to (array (3,), array (3,))
        Child → (joint location in the parent frame l_i, in the child frame c_i), mm.
    root_R : array, shape (n_frames, 3, 3)
    root_t : array, shape (n_frames, 3)
        The root's world-from-segment pose, mm.
    rel_R : mapping of str to array, shape (n_frames, 3, 3)
        Child → rotation from the child to the parent frame at each frame.
    local : mapping of str to array, shape (n_markers, 3)
        Segment → its markers in its own frame, mm.

    Returns
    -------
    R, t, markers : dict
        World-from-segment rotations (n_frames, 3, 3), translations (n_frames, 3) and marker
        positions (n_frames, n_markers, 3) of every segment in the tree.

    Raises
    ------
    InputError
        `parent` and `root` do not form a tree, or a joint, rotation or marker set is missing.
    """
    children: dict[str, list] = {}
    for c, p in parent.items():
        children.setdefault(p, []).append(c)
    order, seen, queue = [], {root}, deque([root])
    while queue:
        u = queue.popleft()
        order.append(u)
        for v in children.get(u, []):
            if v in seen:
                raise InputError([f"segment {v!r} is reached twice: the parent map has a cycle"])
            seen.add(v)
            queue.append(v)
    problems = [f"segment {c!r} is not connected to the root {root!r}" for c in parent if c not in seen]
    problems += [f"no joint location for {c!r}" for c in parent if c not in joints]
    problems += [f"no relative rotation for {c!r}" for c in parent if c not in rel_R]
    problems += [f"no marker coordinates for {s!r}" for s in order if s not in local]
    if root in parent:
        problems.append(f"the root {root!r} has a parent")
    if problems:
        raise InputError(problems)
    R, t, _ = chain_poses([(c, parent[c], c) for c in order[1:]], root,           # eqs. (4), (9)
                          np.asarray(root_R, dtype=float), np.asarray(root_t, dtype=float),
                          {c: np.asarray(rel_R[c], dtype=float) for c in order[1:]},
                          {c: np.asarray(joints[c][0], dtype=float) for c in order[1:]},
                          {c: np.asarray(joints[c][1], dtype=float) for c in order[1:]})
    markers = {s: np.einsum("fij,kj->fki", R[s], np.asarray(local[s], dtype=float)) + t[s][:, None, :]
               for s in order}
    return R, t, markers


def playback(hierarchy: Hierarchy, points: Mapping | None = None) -> Playback:
    """Play the trial back through the articulated model fitted by :func:`infer_hierarchy`.

    The root follows its measured pose and every joint its measured relative rotation; the
    translations come from the fitted joints, so the joints never come apart (section 3.4).

    Parameters
    ----------
    hierarchy : Hierarchy
    points : mapping of str to array, optional
        Segment → measured markers, shape (n_frames, n_markers, 3), mm, in the order the
        segment's poses were computed from. Without it, the reference is each segment's own
        rigid pose applied to its markers (the residual the joints discard).

    Returns
    -------
    Playback

    Raises
    ------
    InputError
        A segment of the tree missing from `points`, or no frame in which anything was rebuilt.
    """
    poses = hierarchy.poses
    R, t, markers = rebuild(hierarchy.parent, hierarchy.root, hierarchy.joints(),
                            poses[hierarchy.root].R, poses[hierarchy.root].t,
                            relative_rotations(hierarchy), {s: poses[s].local for s in hierarchy.order})
    if points is not None:
        missing = [s for s in hierarchy.order if s not in points]
        if missing:
            raise InputError([f"no marker points for segment(s) {', '.join(missing)}"])
        ref = {s: np.asarray(points[s], dtype=float) for s in hierarchy.order}
        kind = "measured"
    else:
        ref = {s: poses[s].to_world(poses[s].local) for s in hierarchy.order}
        kind = "rigid"
    by_seg, total, count = {}, 0.0, 0
    for s in hierarchy.order:
        d2 = np.sum((markers[s] - ref[s]) ** 2, axis=2)
        ok = np.isfinite(d2)
        by_seg[s] = float(np.sqrt(d2[ok].mean())) if ok.any() else float("nan")
        total += float(d2[ok].sum())
        count += int(ok.sum())
    if count == 0:
        raise InputError(["playback rebuilt no marker in any frame (no frame has poses along the tree)"])
    full = np.all([np.all(np.isfinite(t[s]), axis=1) for s in hierarchy.order], axis=0)
    return Playback(R=R, t=t, markers=markers, rms_mm=float(np.sqrt(total / count)),
                    rms_by_segment=by_seg, n_frames=int(full.sum()), reference=kind)
