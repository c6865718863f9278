"""Which segment joins which: the minimum spanning tree over joint-fit residuals (O'Brien et al. 2000, section
3.3), how sure the data are of each joint, what else fits, and where the one- and two-marker groups attach.

Segments with three or more markers have a pose in every frame, and every pair of them gets an O'Brien joint fit
(:func:`identcheck.estimate.hierarchy.infer_hierarchy`). With the marker noise known, the tree is the minimum
spanning tree of each pair's *excess*, its mean squared residual less :data:`FLOOR_TRUST` times the square of what
noise alone would leave for a perfect joint at that fit (:func:`noise_residual_mm`): pose noise grows with a
cluster's distance from the joint and shrinks with its spread, so raw residuals favour joints between two
well-posed clusters over true joints of small or distant ones (erratum O5 of seed 002); without a noise estimate,
it is the minimum spanning tree of the RMS residuals. For each joint of the tree the *runner-up* is the cheapest
pair that could replace it (across the cut the joint makes; the best tree without the joint uses it), and the two
are compared frame by frame: the difference of their excesses (the tree's weights) over its standard error (batch
means over :data:`N_BATCHES` stretches of the trial, so smooth motion's serial correlation does not shrink it),
turned into millimetres of RMS. A joint is **ambiguous** when the runner-up's excess exceeds its own by less than
:data:`Z_AMBIGUOUS` units, a unit being that standard error but at least :data:`REL_AMBIGUOUS` of the joint's
residual (soft tissue makes residuals systematic: a difference of a few per cent is not evidence even when it is
"significant"). It is ambiguous as well when both residuals are within :data:`NOISE_OK` times what marker noise
alone would leave for a perfect joint there (:func:`noise_residual_mm`): two exact joints whose residuals differ
only through how the two pairs' poses carry the noise. Its ``confidence`` is Φ(margin / unit) (0.5 when ambiguous
by noise). **Loops** are pairs the tree does not use whose residual is no larger than the worst joint in it, or
within the noise (section 5: a closed chain, or segments that hardly move relative to each other).

A group of one or two markers has no pose, so O'Brien's fit cannot join it. In the frame of each segment with a
pose, its markers are fitted by a sphere (one centre for both: a ball joint) and by a circle (a hinge)
(:func:`small_fit`); a fit counts only if the markers travel at least
:data:`~identcheck.estimate.joint.MIN_TRAVEL_MM` there and the centre and radius lie within
:data:`MAX_REACH_MM` of the segment. The group attaches as a leaf to the segment it fits best, if that residual
is within the grouping's rigidity tolerance (noise and wobble: a single marker's path over one movement cycle is
a curve, and some sphere passes within a few millimetres of almost any smooth curve, so nothing looser is
evidence); otherwise it *cannot be placed*, and the reason is given. A joint of the posed tree far worse than
the others (:func:`_insert`) is taken for two segments joined through something without a pose: a small group
that fits a joint with both goes between them; without one, the joint is reported as poor.

A single marker that *drifts* is placed nowhere (:func:`drift_reason`): in the frame of the segment where it moves
least, it goes one way through the whole trial (its place along its path ranks with time, Spearman's |ρ| at least
:data:`~identcheck.infer.body_frames.DRIFT_RHO`). A joint's motion goes and returns; a marker sliding on the skin
or coming loose does not, and a sphere or a circle of large radius passes within the noise of a short straight
path.
"""
from __future__ import annotations

import math
import warnings
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from identcheck.errors import DegenerateError, InputError
from identcheck.estimate.hierarchy import Hierarchy, infer_hierarchy
from identcheck.estimate.joint import MIN_TRAVEL_MM
from identcheck.estimate.obrien import MIN_FRAMES, as_poses, joint_location
from identcheck.geometry.poses import MIN_MARKERS, pose_noise_factor
from identcheck.infer.body_frames import STILL_DEG, is_drift, path_monotone, turn_deg
from identcheck.solve.gamage_lasenby import sphere_centre
from identcheck.solve.minimal import circle_deviations, circle_fit

FLOOR_TRUST = 0.8
"""Share of the noise-only mean square (the floor) taken off each pair's before the tree is chosen. The floor scales
with the estimated noise σ², which is good to about 5 % in σ under serially correlated noise (and is inflated by
soft tissue), so 10 % in σ²; two standard errors of that are kept as a margin: a pair whose fitted point lies far
from both clusters has a large floor, and a full subtraction would let the floor's own error decide."""
REL_AMBIGUOUS = 0.10
"""A runner-up within this fraction of a joint's residual (times :data:`Z_AMBIGUOUS`) is within the noise."""
Z_AMBIGUOUS = 2.0
"""Margins below this many units (module docstring) make a joint ambiguous."""
NOISE_OK = 1.5
"""A residual within this many times what marker noise alone would leave counts as a perfect joint's."""
LOOP_SEARCH = 3.0
"""Unused pairs up to this many times the worst joint's residual are checked against the noise (:func:`_loops`)."""
N_BATCHES = 20
"""Stretches of the trial for the batch-means standard error of a residual difference."""
MAX_REACH_MM = 600.0
"""A sphere or circle fit whose centre or radius is farther than this from its segment is no joint."""
MAX_FIT_FRAMES = 500
"""A one- or two-marker group's sphere and circle are fitted to at most this many frames, evenly spread."""
POOR_FACTOR = 3.0
"""A joint leaving more than this many times the median joint's residual is poor (:func:`_insert`)."""
POOR_FLOOR_MM = 20.0
"""... and more than this (mm): skin markers leave real joints residuals of several to 15 mm."""
THROUGH_RATIO = 4.5
"""A joint leaving more than this many times a small group's worst fit with the segments on its two sides is
replaced by two joints through the group (:func:`_insert`). An O'Brien residual is the length of a 3-D difference
and a sphere's a 1-D radial one, so noise alone makes the first about twice the second, and skin motion spreads
both. Set on two development draws of the held-out skeleton generator (seeds 6969, 7272): of the insertions this
rule made at ratios from 3 to 4.3, 7 of 8 were wrong (a leaf's marker fitting a loose sphere where the direct joint
carried soft tissue), from 4.9 to 9, 9 of 13 right."""
THROUGH_TRAVEL = 2.0
"""... if the group moves at least this many times the rigidity tolerance, and this many times the travel a joint
fit needs (:data:`~identcheck.estimate.joint.MIN_TRAVEL_MM`), in both segments' frames: a skin marker that wobbled
out of its group moves some 10 mm in its own segment's frame and can fit a small sphere there (a full-body
functional trial's upper arm marker: 11 mm, where subject01_walk1's biceps markers move 35-77 mm)."""


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class SmallFit:
    """A one- or two-marker group's fit in a posed segment's frame (all mm).

    Attributes
    ----------
    sphere_mm, circle_mm : float
        RMS residual of the ball-joint (sphere) and hinge (circle) fits; NaN when the fit failed or is not
        plausible (centre or radius beyond :data:`MAX_REACH_MM`).
    travel_mm : float
        How far the group's markers move in the segment's frame (largest range of a coordinate).
    reach_mm : float
        The centre's distance from the segment's marker centroid, of the fit :attr:`residual_mm` gives (the sphere's
        where plausible, else the circle's axis).
    n_frames : int
    reason : str
        Why neither fit counts ('' when one does).
    noise_factor : float
        What marker noise σ alone would leave of these fits, in units of σ (the marker's own noise and the
        posed segment's, :func:`identcheck.geometry.poses.pose_noise_factor`, at the markers).
    """

    sphere_mm: float
    circle_mm: float
    travel_mm: float
    reach_mm: float
    n_frames: int
    reason: str = ""
    noise_factor: float = 1.0
    monotone: float = float("nan")
    """For one marker: |Spearman's ρ| between time and its place along its path here (the path's first principal
    direction): 1 when it goes one way through the trial, near 0 when it goes and returns."""

    @property
    def residual_mm(self) -> float:
        """How well a joint ties the group to the segment, for the tree: the ball joint's (sphere's) residual, the
        general joint, whose family holds every circle; the hinge's (circle's) only where no plausible sphere fits.
        The circle's residual types the joint (:func:`identcheck.infer.joint_types.classify_small`). (The smaller of
        the two had been taken while the circle fit carried its first sample's noise and came out the larger: fitted
        as least squares, its residual joined the tree's comparisons, against thresholds set on the sphere's.)"""
        if np.isfinite(self.sphere_mm):
            return float(self.sphere_mm)
        return float(self.circle_mm) if np.isfinite(self.circle_mm) else float("nan")


@dataclass(frozen=True)
class Edge:
    """One joint of the inferred tree.

    Attributes
    ----------
    parent, child : str
    residual_mm : float
        O'Brien RMS residual (segments with poses) or the sphere / circle fit's (a small group).
    method : str
        "obrien" or "sphere_circle".
    runner_up : dict or None
        The best pair that could replace this joint: ``parent``, ``child``, ``residual_mm``, ``margin_mm``.
    confidence : float
        Φ(margin / unit), module docstring; 1 when nothing else could replace it.
    ambiguous : bool
    fit : JointFit or None
        The O'Brien fit, oriented parent → child.
    small : SmallFit or None
    """

    parent: str
    child: str
    residual_mm: float
    method: str
    runner_up: dict | None
    confidence: float
    ambiguous: bool
    fit: object = None
    small: SmallFit | None = None


@dataclass(frozen=True)
class Tree:
    """The inferred tree and what the data left open.

    Attributes
    ----------
    root : str
    root_rule : str
        "given" or "centre" (:mod:`identcheck.estimate.hierarchy`).
    edges : tuple of Edge
        Every joint, parents before children.
    segments : dict of str to tuple of str
        Every segment in the tree → its markers (one-marker segments included).
    ambiguous : tuple of dict
    loops : tuple of dict
    cannot_place : tuple of dict
        Groups of 2+ markers with no joint: ``segment``, ``markers``, ``reason``.
    unassigned : dict of str to str
        Markers rigid with no other and attached to nothing → why.
    hierarchy : Hierarchy or None
        The O'Brien hierarchy of the segments with poses (None with fewer than two of them).
    points : dict of str to numpy.ndarray
        Segment → its markers' positions (n_frames, n_markers, 3), mm.
    poor : tuple of dict
        Joints of the tree that leave far more than the others (:func:`_insert`).
    """

    root: str
    root_rule: str
    edges: tuple
    segments: dict
    ambiguous: tuple
    loops: tuple
    cannot_place: tuple
    unassigned: dict
    hierarchy: Hierarchy | None = field(default=None, repr=False)
    points: dict = field(default_factory=dict, repr=False)
    poor: tuple = ()


# ---------------------------------------------------------------------- helpers
def _nan_none(x: float):
    return float(x) if np.isfinite(x) else None


def _phi(x: float) -> float:
    """Standard normal CDF."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0))) if np.isfinite(x) else (1.0 if x > 0 else 0.0)


def compare_residuals(e_chosen: np.ndarray, e_other: np.ndarray, r_chosen: float, r_other: float,
                      floors: tuple = (0.0, 0.0)) -> tuple:
    """How far a runner-up's residual exceeds a joint's, beyond what each would leave as a perfect joint, in units
    of what noise and soft tissue allow.

    Parameters
    ----------
    e_chosen, e_other : array, shape (n_frames,)
        Per-frame residuals |e_f| of the two fits, mm, NaN where a fit has no frame.
    r_chosen, r_other : float
        Their RMS residuals, mm.
    floors : (float, float)
        The RMS residuals a perfect joint would leave at each fit (:func:`noise_residual_mm`), mm; NaN or 0 when
        unknown. The margin compares the excesses r² − floor².

    Returns
    -------
    x : float
        ``margin / unit``.
    unit_mm : float
        The batch-means standard error of the margin, at least :data:`REL_AMBIGUOUS` ``r_chosen``.
    margin_mm : float
        ``((r_other² − floor_other²) − (r_chosen² − floor_chosen²)) / (r_other + r_chosen)``: ``r_other − r_chosen``
        when the floors are 0.
    """
    ok = np.isfinite(e_chosen) & np.isfinite(e_other)
    d = e_other[ok] ** 2 - e_chosen[ok] ** 2
    se_mm = 0.0
    n_b = min(N_BATCHES, len(d) // 5)
    if n_b >= 2:
        means = np.array([b.mean() for b in np.array_split(d, n_b)])
        se_mm = float(means.std(ddof=1) / np.sqrt(n_b)) / max(r_other + r_chosen, 1e-12)
    unit = max(se_mm, REL_AMBIGUOUS * r_chosen, 1e-9)
    f_c, f_o = (float(f) if f is not None and np.isfinite(f) else 0.0 for f in floors)
    margin = ((r_other ** 2 - f_o ** 2) - (r_chosen ** 2 - f_c ** 2)) / max(r_other + r_chosen, 1e-12)
    return float(margin / unit), float(unit), float(margin)


def _subtree(parent: dict, v: str) -> set:
    children: dict = {}
    for c, p in parent.items():
        children.setdefault(p, []).append(c)
    out, queue = {v}, deque([v])
    while queue:
        for c in children.get(queue.popleft(), []):
            out.add(c)
            queue.append(c)
    return out


def noise_residual_mm(poses: dict, parent: str, child: str, fit, sigma_mm: float) -> float:
    """The RMS O'Brien residual marker noise σ alone would leave for a perfect joint at the fit's location: the
    two posed segments (``poses``: segment -> Poses) carry their pose noise to the joint point,
    ``sqrt(3 σ² (f_P² + f_C²))`` with f the pose noise factors there
    (:func:`identcheck.geometry.poses.pose_noise_factor`); NaN without σ."""
    if not np.isfinite(sigma_mm):
        return float("nan")
    fp = pose_noise_factor(poses[parent].local, fit.centre_parent)[0]
    fc = pose_noise_factor(poses[child].local, fit.centre_child)[0]
    return float(sigma_mm * np.sqrt(3.0 * (fp ** 2 + fc ** 2)))


def orient(pairs, root: str) -> list:
    """Undirected pairs → ``[parent, child]`` breadth first from `root` (pairs not reached are left out)."""
    adj: dict = {}
    for a, b in pairs:
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    out, seen, queue = [], {root}, deque([root])
    while queue:
        u = queue.popleft()
        for v in adj.get(u, []):
            if v not in seen:
                seen.add(v)
                out.append([u, v])
                queue.append(v)
    return out


def _separating_motion(u, v, a, b, h: Hierarchy) -> str:
    """What to record so that the data tell joint (u, v) from its runner-up (b, a)."""
    if a == v or b == v:
        w = b if a == v else a
        still = turn_deg(h.poses[u], h.poses[w])
        if np.isfinite(still) and still < STILL_DEG:
            return (f"{u} and {w} hardly rotate relative to each other in this trial "
                    f"(rotation spread {still:.3g} deg), "
                    f"so {v} fits a joint with either: record a trial in which {u} and {w} rotate relative to each "
                    f"other, about more than one axis")
        return (f"{v} moves about as much like a joint with {w} as with {u}: record {v} moving about several axes "
                f"relative to {u} while {w} stays still relative to {u} (and the reverse)")
    return (f"the part of the tree beyond {v} joins the rest either at {u}-{v} or at {b}-{a}: record {v} rotating "
            f"relative to {u}, about more than one axis, while {a} stays still relative to {b}")


# ---------------------------------------------------------------------- segments with poses
def _tree_edges(h: Hierarchy, sigma_mm: float) -> tuple[list, list]:
    """Edges of the O'Brien tree with runner-ups and confidence; and the ambiguity reports."""
    names = list(h.segments)
    W = h.weight
    edges, ambiguous = [], []
    undirected = [(h.parent[c], c) for c in h.order[1:]]
    for v in h.order[1:]:
        u, fit = h.parent[v], h.fits[v]
        side = _subtree(h.parent, v)
        best, cand = np.inf, None
        for a in side:
            for b in names:
                if b in side or (a == v and b == u):
                    continue
                w = W[names.index(a), names.index(b)]
                if w < best:
                    best, cand = w, (a, b)
        runner, conf, amb = None, 1.0, False
        if cand is not None and np.isfinite(best):
            a, b = cand
            other = joint_location(h.poses[b], h.poses[a], names=(b, a))
            floor = (noise_residual_mm(h.poses, u, v, fit, sigma_mm), noise_residual_mm(h.poses, b, a, other, sigma_mm))
            x, unit, margin = compare_residuals(fit.frame_residual_mm, other.frame_residual_mm, fit.rms_residual,
                                                other.rms_residual, tuple(np.sqrt(FLOOR_TRUST) * f for f in floor))
            # the margin measures the same excess the tree and its runner-up were chosen on
            noise_only = bool(fit.rms_residual <= NOISE_OK * floor[0] and other.rms_residual <= NOISE_OK * floor[1])
            conf, amb = (0.5, True) if noise_only else (_phi(x), bool(x < Z_AMBIGUOUS))
            runner = {"parent": b, "child": a, "residual_mm": float(other.rms_residual),
                      "margin_mm": margin, "margin_units": x,
                      "unit_mm": unit, "noise_only_mm": [_nan_none(f) for f in floor], "both_within_noise": noise_only}
            if amb:
                alt = [p for p in undirected if p != (u, v)] + [(b, a)]
                ambiguous.append({
                    "joint": [u, v], "residual_mm": float(fit.rms_residual), "alternative": [b, a],
                    "alternative_residual_mm": float(other.rms_residual), "margin_mm": runner["margin_mm"],
                    "margin_units": x,
                    "trees": {"chosen": [list(p) for p in orient(undirected, h.root)],
                              "alternative": orient(alt, h.root)},
                    "separating_motion": _separating_motion(u, v, a, b, h)})
        edges.append(Edge(u, v, float(fit.rms_residual), "obrien", runner, conf, amb, fit=fit))
    return edges, ambiguous


# ---------------------------------------------------------------------- one- and two-marker groups
def small_fit(poses, child_points: np.ndarray) -> SmallFit:
    """Fit a one- or two-marker group as a ball joint (sphere) and as a hinge (circle) in a posed segment's frame.

    Sphere: one centre for the group's markers, each with its own radius
    (:func:`identcheck.solve.gamage_lasenby.sphere_centre`); circle: each marker's own least-squares circle
    (:func:`identcheck.solve.minimal.circle_fit`), its residual the RMS of the radial and out-of-plane deviations.
    At most :data:`MAX_FIT_FRAMES` frames, evenly spread, are used.

    Parameters
    ----------
    poses : identcheck.geometry.poses.Poses
        The posed segment's poses.
    child_points : array, shape (n_frames, q, 3)
        The group (q = 1 or 2), mm, NaN = occluded.

    Returns
    -------
    SmallFit
    """
    local = poses.to_local(child_points)
    ok = np.isfinite(local).all(axis=(1, 2))
    n = int(ok.sum())
    if n < 10:
        return SmallFit(np.nan, np.nan, np.nan, np.nan, n, f"seen with this segment's pose in only {n} frame(s)")
    X = local[ok]
    travel = float(max(np.ptp(X[:, i], axis=0).max() for i in range(X.shape[1])))
    monotone = path_monotone(X[:, 0]) if X.shape[1] == 1 else float("nan")
    if travel < MIN_TRAVEL_MM:
        return SmallFit(np.nan, np.nan, travel, np.nan, n,
                        f"moves only {travel:.3g} mm in this segment's frame: nearly rigid with it, but beyond the "
                        f"rigidity tolerance, and too little motion to locate a joint", monotone=monotone)
    if len(X) > MAX_FIT_FRAMES:
        X = X[np.linspace(0, len(X) - 1, MAX_FIT_FRAMES).astype(int)]
    sphere = circ = reach_s = reach_c = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fit = sphere_centre(X)
            if np.linalg.norm(fit.centre) <= MAX_REACH_MM and np.max(fit.radii) <= MAX_REACH_MM:
                sphere, reach_s = float(fit.rms_residual_mm), float(np.linalg.norm(fit.centre))
        except (DegenerateError, np.linalg.LinAlgError):
            pass
        try:
            res, reach = [], 0.0
            for i in range(X.shape[1]):
                J, nrm, _ = circle_fit(X[:, i])
                J = J - ((J - X[:, i].mean(axis=0)) @ nrm) * nrm   # onto the mean plane (noisy arcs tilt it off)
                radial, along, radius = circle_deviations(X[:, i], J, nrm)
                res.append(np.concatenate([radial, along]))
                reach = max(reach, float(np.linalg.norm(J - (J @ nrm) * nrm)), radius)
            if reach <= MAX_REACH_MM:
                circ, reach_c = float(np.sqrt(np.mean(np.concatenate(res) ** 2))), reach
        except (DegenerateError, np.linalg.LinAlgError):
            pass
    if not (np.isfinite(sphere) or np.isfinite(circ)):
        return SmallFit(np.nan, np.nan, travel, np.nan, n,
                        f"moves {travel:.3g} mm in this segment's frame, but on no sphere or circle within "
                        f"{MAX_REACH_MM:g} mm of it")
    reach = reach_s if np.isfinite(sphere) else reach_c                   # (the fit residual_mm gives)
    factor = float(np.mean(np.sqrt(1.0 + pose_noise_factor(poses.local, np.median(X, axis=0)) ** 2)))
    return SmallFit(sphere, circ, travel, float(reach), n, noise_factor=factor, monotone=monotone)


def drift_reason(fits: dict) -> str:
    """Why a one-marker group is no joint's child, or '': it drifts (module docstring) in the frame of the segment
    where it moves least. `fits`: the group's :class:`SmallFit` in each posed segment's frame."""
    moving = [(f.travel_mm, s, f) for s, f in fits.items() if np.isfinite(f.travel_mm) and np.isfinite(f.monotone)]
    if not moving:
        return ""
    travel, s, f = min(moving, key=lambda x: x[0])
    if not is_drift(travel, f.monotone):
        return ""
    return (f"drifts one way through the trial in {s}'s frame, where it moves least ({travel:.3g} mm; its place "
            f"along its path ranks with time, |Spearman's rho| {f.monotone:.2f}): a marker sliding on the skin or "
            "coming loose, not a joint's motion, which goes and returns")


def _component(edges: list, without, start: str) -> set:
    """The segments reached from `start` through `edges` (undirected) when the edge `without` is left out."""
    return {start} | {v for _, v in orient([(e.parent, e.child) for e in edges if e is not without], start)}


def _through(fits: dict, used: list, upper: set, lower: set, accept_mm: float, travel_mm: float) -> list:
    """The ways to join the two sides of a cut tree through one small group: (worst residual, group, segment on
    `upper`'s side, segment on `lower`'s), best first (by the worse of the two fits, then the better). The group
    must fit a joint with a segment on each side within `accept_mm`, moving at least `travel_mm` in both their
    frames."""
    out = []
    for g, f in fits.items():
        if g in used:
            continue
        ok = {s for s, x in f.items() if x.residual_mm <= accept_mm and x.travel_mm >= travel_mm}
        for a in sorted(ok & upper):
            for b in sorted(ok & lower):
                r = sorted((f[a].residual_mm, f[b].residual_mm))
                out.append((r[1], r[0], g, a, b))
    return [(worst, g, a, b) for worst, _, g, a, b in sorted(out)]


def _oriented(edges: list, top: str) -> list:
    """The edges with parents before children, breadth first from `top` (:func:`orient`); an edge found the wrong way
    round is turned (an O'Brien fit through :meth:`~identcheck.estimate.obrien.JointFit.reversed`), as after a group
    put between two segments re-roots the part below it."""
    by_pair = {frozenset((e.parent, e.child)): e for e in edges}
    out = []
    for u, v in orient([(e.parent, e.child) for e in edges], top):
        e = by_pair[frozenset((u, v))]
        out.append(e if e.parent == u else
                   replace(e, parent=u, child=v, fit=e.fit.reversed() if e.fit is not None else None))
    return out


def _insert(edges: list, fits: dict, accept_mm: float, top: str) -> tuple[list, list, list, list, list]:
    """Put a small group between two parts of the posed tree whose direct joint it explains far better.

    A joint of the posed tree is replaced by two joints through a small group (:func:`_through`) when either

    - the joint is *poor*: its residual exceeds :data:`POOR_FACTOR` times the median of the other joints' (or the
      accepted residual `accept_mm`, if that is larger), and :data:`POOR_FLOOR_MM`, and the group fits a joint
      with a segment on each side of the cut the joint makes; or
    - the group fits a joint with a segment on each side, moving enough in both their frames
      (:data:`THROUGH_TRAVEL`), and its worst fit leaves less than 1 / :data:`THROUGH_RATIO` of the joint's
      residual: an upper arm carrying one marker between a trunk and a forearm, whose direct joint leaves 11 mm where
      both of the marker's spheres leave under 1.7 (subject01_walk1). Segments joined directly leave a small
      group a sphere in both frames only when their own joint hardly moves, and then their direct joint is as
      good.

    A poor joint with no such group is reported as poor. The group hangs from the segment on the root's side it
    fits best (with the other side's), possibly among segments that hardly move relative to each other: another
    segment outside the lower side that fits the group as well or better is reported (:func:`_inserted_doubt`).
    Returns (edges, the groups inserted, poor-joint reports, ambiguity reports, the joints replaced as
    (parent, child))."""
    current, used, poor, ambiguous, replaced = list(edges), [], [], [], []
    for e in sorted(edges, key=lambda e: -e.residual_mm):
        others = [o.residual_mm for o in edges if o is not e]
        median = float(np.median(others)) if others else 0.0
        is_poor = e.residual_mm > max(POOR_FACTOR * max(median, accept_mm), POOR_FLOOR_MM)
        upper = _component(current, e, e.parent)
        lower = _component(current, e, e.child)
        if is_poor:
            cands = _through(fits, used, upper, lower, accept_mm, 0.0)
        else:       # a group nearly rigid with one side is that side's, not a segment between
            travel = THROUGH_TRAVEL * max(accept_mm, MIN_TRAVEL_MM)
            cands = [c for c in _through(fits, used, upper, lower, accept_mm, travel)
                     if e.residual_mm > THROUGH_RATIO * c[0]]
        if not cands:
            if is_poor:
                poor.append({"joint": [e.parent, e.child], "residual_mm": e.residual_mm, "median_mm": median,
                             "note": f"the best joint between {e.parent} and {e.child} leaves {e.residual_mm:.3g} "
                                     f"mm, more than {POOR_FACTOR:g} x {max(median, accept_mm):.3g} mm (the other "
                                     "joints' median, or the rigidity tolerance): they are probably joined through "
                                     "a segment whose markers are too few to pose or were left out, or not joined "
                                     "at all"})
            continue
        worst, g, a, b = cands[0]
        unit = max(REL_AMBIGUOUS * worst, 1e-9)
        conf = _phi((e.residual_mm - worst) / unit)
        note = {"parent": e.parent, "child": e.child, "residual_mm": e.residual_mm, "margin_mm": e.residual_mm - worst,
                "margin_units": (e.residual_mm - worst) / unit, "unit_mm": unit, "replaced": True, "between": [a, b]}
        amb = _inserted_doubt(g, fits[g], a, lower, accept_mm)
        ambiguous += amb
        current.remove(e)
        current += [Edge(a, g, fits[g][a].residual_mm, "sphere_circle", note, conf, bool(amb), small=fits[g][a]),
                    Edge(g, b, fits[g][b].residual_mm, "sphere_circle", note, conf, False, small=fits[g][b])]
        used.append(g)
        replaced.append((e.parent, e.child))
    return _oriented(current, top), used, poor, ambiguous, replaced


def _inserted_doubt(g: str, fits: dict, parent: str, below: set, accept_mm: float) -> list:
    """An ambiguity report when a group inserted below `parent` (the segment on the root's side of the replaced
    joint that it fits best) fits a joint with another posed segment outside `below` (the child's side) within
    `accept_mm` and no more than :data:`Z_AMBIGUOUS` units (:data:`REL_AMBIGUOUS` of its residual with `parent`)
    worse: segments that hardly move relative to each other, or a wrong choice of the posed tree, carry the group's
    joint as well. Empty otherwise."""
    r = fits[parent].residual_mm
    unit = max(REL_AMBIGUOUS * r, 1e-9)
    others = sorted((f.residual_mm, s) for s, f in fits.items() if s != parent and s not in below
                    and np.isfinite(f.residual_mm) and f.residual_mm <= accept_mm)
    if not others or (others[0][0] - r) / unit >= Z_AMBIGUOUS:
        return []
    r2, s2 = others[0]
    return [{"joint": [parent, g], "residual_mm": float(r), "alternative": [s2, g],
             "alternative_residual_mm": float(r2), "margin_mm": float(r2 - r),
             "margin_units": float((r2 - r) / unit), "trees": None,
             "separating_motion": (f"the markers of {g} move about as much on a sphere or circle about a point of "
                                   f"{parent} as of {s2} (or more so about {s2}): record {parent} and {s2} moving "
                                   f"relative to each other while {g} moves")}]


def _loops(h: Hierarchy, edges: list, sigma_mm: float) -> list:
    """Pairs of posed segments the tree does not join whose O'Brien residual is no larger than the worst joint the
    tree keeps between posed segments, or within what marker noise alone would leave for a perfect joint there
    (O'Brien et al., section 5)."""
    kept = [e for e in edges if e.method == "obrien"]
    if not kept:
        return []
    worst = max(e.residual_mm for e in kept)
    joined = {frozenset((e.parent, e.child)) for e in kept}
    names, W = list(h.segments), h.residual_mm
    out = []
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            if i >= j or frozenset((a, b)) in joined or not np.isfinite(W[i, j]):
                continue
            why = "as well as a joint in it" if W[i, j] <= worst else ""
            if not why and W[i, j] <= LOOP_SEARCH * worst and np.isfinite(sigma_mm):
                fit = joint_location(h.poses[a], h.poses[b], names=(a, b))
                floor = noise_residual_mm(h.poses, a, b, fit, sigma_mm)
                why = f"within what noise alone leaves ({floor:.3g} mm)" if W[i, j] <= NOISE_OK * floor else ""
            if why:
                out.append({"segments": [a, b], "residual_mm": float(W[i, j]),
                            "note": f"not joined by the tree, yet fits a joint {why}: a closed chain (loop), or "
                                    "segments that hardly move relative to each other"})
    return out


def _place(small: dict, fits_all: dict, accept_mm: float, sigma_mm: float) -> tuple[list, list, list]:
    """Attach each small group to the posed segment it fits best: (edges, reports of unplaced groups,
    ambiguity reports)."""
    edges, unplaced, ambiguous = [], [], []
    for g in small:
        fits = fits_all[g]
        good = sorted((f.residual_mm, s) for s, f in fits.items() if np.isfinite(f.residual_mm))
        if not good:
            why = "; ".join(f"{s}: {f.reason}" for s, f in fits.items()) or "no segment with a pose to attach it to"
            unplaced.append((g, f"no joint with any segment with a pose ({why})"))
            continue
        r, s = good[0]
        if r > accept_mm:
            unplaced.append((g, f"its best fit, a joint with {s}, leaves {r:.3g} mm (sphere/circle residual), more "
                                f"than the {accept_mm:.3g} mm accepted for a joint in this trial"))
            continue
        runner, conf, amb = None, 1.0, False
        if len(good) > 1:
            r2, s2 = good[1]
            unit = max(REL_AMBIGUOUS * r, 1e-9)
            x = (r2 - r) / unit
            floor = (sigma_mm * fits[s].noise_factor, sigma_mm * fits[s2].noise_factor)
            noise_only = bool(np.isfinite(sigma_mm) and r <= NOISE_OK * floor[0] and r2 <= NOISE_OK * floor[1])
            conf, amb = (0.5, True) if noise_only else (_phi(x), bool(x < Z_AMBIGUOUS))
            runner = {"parent": s2, "child": g, "residual_mm": float(r2), "margin_mm": float(r2 - r),
                      "margin_units": float(x), "unit_mm": unit, "noise_only_mm": [_nan_none(f) for f in floor],
                      "both_within_noise": noise_only}
            if amb:
                ambiguous.append({
                    "joint": [s, g], "residual_mm": float(r), "alternative": [s2, g],
                    "alternative_residual_mm": float(r2), "margin_mm": float(r2 - r), "margin_units": float(x),
                    "trees": None,
                    "separating_motion": (f"the markers of {g} move about as much on a sphere or circle about a "
                                          f"point of {s} as of {s2}: record {g} moving relative to {s} while {s2} "
                                          f"stays still relative to {s} (a small group may also lie between them: "
                                          "add a third marker to it to fit it by poses)")})
        edges.append(Edge(s, g, float(r), "sphere_circle", runner, conf, amb, small=fits[s]))
    return edges, unplaced, ambiguous


# ---------------------------------------------------------------------- the tree
def _renamed(report: dict, number: dict) -> dict:
    """An ambiguity report with the provisional names of one-marker groups replaced by their final ones."""
    out = dict(report)
    for key in ("joint", "alternative"):
        out[key] = [number.get(x, x) for x in report[key]]
    for old, new in number.items():
        out["separating_motion"] = out["separating_motion"].replace(old, new)
    return out


def infer_tree(trial, grouping, root: str | None = None, sigma_mm: float = float("nan")) -> Tree:
    """The skeleton's tree from a trial and a grouping (module docstring).

    Parameters
    ----------
    trial : identcheck.trial.Trial
        The trial (recentred by the caller), mm.
    grouping : identcheck.infer.grouping.Grouping
    root : str, optional
        A segment with three or more markers, or one of its markers; by default the tree's centre.
    sigma_mm : float
        Marker noise, one coordinate, mm (:func:`identcheck.estimate.noise.noise_floor`): two joints that both fit
        within what it leaves (:data:`NOISE_OK`) are ambiguous, whatever their residuals' ratio. NaN: not used.

    Returns
    -------
    Tree

    Raises
    ------
    InputError
        No group with three markers (no segment has a pose), an unknown root or one without a pose, or segments
        that share too few frames to be joined.
    """
    points = {g: trial.select(ms).as_array() for g, ms in grouping.groups.items()}
    posed, small, no_pose, poses = [], {}, {}, {}
    for g, pts in points.items():
        if pts.shape[1] >= MIN_MARKERS:
            try:
                poses[g] = as_poses(pts, g)
                if int(poses[g].valid.sum()) >= MIN_FRAMES:
                    posed.append(g)
                    continue
                no_pose[g] = f"a pose in only {int(poses.pop(g).valid.sum())} frame(s)"
            except InputError as exc:
                no_pose[g] = "; ".join(exc.problems)
        else:
            small[g] = pts
    if not posed:
        raise InputError(["no rigid group of 3 or more markers with a pose" + (
            f" (groups: {', '.join(f'{g} = {list(ms)}' for g, ms in grouping.groups.items())})" if grouping.groups
            else "") + ": a segment pose needs 3 markers, and O'Brien's joint fit needs two posed segments; "
                       "give the grouping with --segments, or add markers"], source=trial.source)
    loose_names = {}                             # provisional names; placed ones are numbered on at the end
    for m in grouping.loose:
        loose_names[m] = f"~{m}"
        small[f"~{m}"] = points[f"~{m}"] = trial.select([m]).as_array()
    if root is not None:
        owner = {m: g for g, ms in grouping.groups.items() for m in ms}
        name = root if root in grouping.groups else owner.get(root)
        if name is None or name not in posed:
            what = ("is not a segment or a marker of the trial" if name is None else
                    f"is {'in ' if name != root else ''}segment {name!r}, which has no pose (fewer than "
                    f"{MIN_MARKERS} markers or frames)")
            raise InputError([f"--root {root!r} {what}; the root must be a segment with a pose: "
                              f"{', '.join(posed)}"], source=trial.source)
        root = name
    h, edges, ambiguous, loops = None, [], [], []
    if len(posed) >= 2:
        try:
            expected = (None if not np.isfinite(sigma_mm) else
                        lambda a, b, fit: np.sqrt(FLOOR_TRUST) * noise_residual_mm(poses, a, b, fit, sigma_mm))
            h = infer_hierarchy({g: poses[g] for g in posed}, root=root, expected=expected)
        except InputError as exc:
            raise exc.naming(trial.source) from None
        edges, ambiguous = _tree_edges(h, sigma_mm)
        top = h.root
        root_rule = h.root_rule
    else:
        top, root_rule = posed[0], "given" if root else "only segment with a pose"
    accept = grouping.tolerance.tolerance_mm
    fits = {g: {s: small_fit(poses[s], pts) for s in posed} for g, pts in small.items()}
    drifting = {g: why for g, f in fits.items() if (why := drift_reason(f))}
    fits = {g: f for g, f in fits.items() if g not in drifting}
    edges, inserted, poor, amb_inserted, replaced = _insert(edges, fits, accept, top)
    ambiguous = [a for a in ambiguous if tuple(a["joint"]) not in replaced]
    placed, unplaced, amb_small = _place([g for g in fits if g not in inserted], fits, accept, sigma_mm)
    unplaced += list(drifting.items())
    edges = _oriented(edges + placed, top)
    ambiguous += amb_small + amb_inserted
    if h is not None:
        loops = _loops(h, edges, sigma_mm)
    inv = {v: k for k, v in loose_names.items()}
    unassigned = {inv[g]: why for g, why in unplaced if g in inv}
    cannot = [{"segment": g, "markers": list(grouping.groups[g]), "reason": why} for g, why in unplaced
              if g not in inv]
    cannot += [{"segment": g, "markers": list(grouping.groups[g]), "reason": why} for g, why in no_pose.items()]
    in_tree = {top} | {e.child for e in edges}
    number = {g: f"seg{k}" for k, g in enumerate((g for g in small if g in inv and g in in_tree),
                                                  start=len(grouping.groups) + 1)}
    edges = [replace(e, parent=number.get(e.parent, e.parent), child=number.get(e.child, e.child),
                     runner_up=e.runner_up and {**e.runner_up,
                                                "parent": number.get(e.runner_up["parent"], e.runner_up["parent"]),
                                                "child": number.get(e.runner_up["child"], e.runner_up["child"])})
             for e in edges]
    ambiguous = [_renamed(a, number) for a in ambiguous]
    poor = [{**p, "joint": [number.get(x, x) for x in p["joint"]]} for p in poor]
    segments = {number.get(g, g): (tuple(grouping.groups[g]) if g in grouping.groups else (inv[g],))
                for g in points if g in in_tree}
    points = {number.get(g, g): p for g, p in points.items() if g in in_tree}
    return Tree(top, root_rule, tuple(edges), segments, tuple(ambiguous), tuple(loops), tuple(cannot), unassigned,
                hierarchy=h, points={g: points[g] for g in segments}, poor=tuple(poor))
