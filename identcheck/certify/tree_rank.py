"""Local identifiability of every joint of a whole skeleton at once, from the exact rank of its Jacobian.

The per-joint table reasons about two links with the rest of the body out of sight. A marker plan
is a tree: the root's free pose, every joint's angles in every frame, and constant parameters —
each marker's position on its segment, each joint's centre in its parent, each hinge's direction.
J is the Jacobian of all marker coordinates over N frames with respect to all of these. A
gauge-invariant quantity f of the constants (a marker's distance to a joint centre or hinge axis,
a marker's offset along a hinge relative to another's) is locally identifiable iff ∇f lies in the
row space of J restricted to the constants (:mod:`identcheck.certify.jacobian` explains why; this module
is the same idea for a whole tree).

Parametrisation (the gauge is free, so any generic one works). The child of joint j has its origin
at the joint (a point of the hinge for a revolute joint) and the orientation of its parent turned
by the joint: R_C = R_P Q_j, t_C = R_P c_j + t_P, with Q_j a free rotation (spherical) or
Rot(a_j, θ) (revolute, a_j a unit direction in the parent). A marker of segment s sits at
x = R_s m + t_s. In frame i the columns are the per-frame variables (root rotation and
translation, each joint's rotation) and the constants (m, c_j, the two tangent directions of a_j).

How it is computed. W = {λ C : λ V = 0} for the stacked rows [V | C] of all frames (V the per-frame
columns). W does not depend on how the per-frame unknowns are parametrised, so the equations are
written with every segment's pose as an unknown and each joint's constraint as rows
(:mod:`identcheck.certify.tree_equations`): every row then touches one segment or one joint, and the
unknowns are eliminated leaf to root and back (:mod:`identcheck.certify.tree_elimination`), each
subtree summarised by what it fixes on its parent's poses. A joint's quantities involve only its own
constants, its segments' markers and neighbouring centres (L_j), so each is judged against
W ∩ span(L_j); dim W = rank [V | C] − rank V. The cost is linear in the number of segments (a
200-segment chain in seconds), where one dense matrix per frame grew as the cube of the chain. W only
grows with N; frames are added until a new generic frame changes neither dim W nor any verdict (the
stopping rule of :mod:`identcheck.certify.jacobian`).

What a joint is judged by. Its own parameters — its centre (and axis) in each of its two segments —
relative to what the data determine in that segment: its distances to the segment's markers, or, on
a segment without markers, to the centres of the segment's other ball joints. Such a segment has no
frame of its own: its determined content is the configuration of the centres placed relative to
each other (:func:`anchored_centres`). A joint is locally identifiable iff the null space of J,
beyond the gauge, moves none of those distances (each ∇f in W). A neighbour's centre that the data
do not place on the segment (a neck whose head carries no marker) is not judged against: that
distance is the neighbour's undetermined quantity, and it is reported with it
(:attr:`JointRank.set_aside`), not charged to the shoulders and hips (:func:`judged_points`).

Exactness. Every rank is exact, in one of two fields (python-flint matrices): ``"GFp"``, the
integers modulo a prime p drawn uniformly among the 61-bit primes, with the point uniform on
GF(p)^n (the default: fast), or ``"QQ"``, exact rationals, the point's coordinates uniform on a set
S of 2^40 rationals (slower; a cross-check). A rank at one point is never above the generic rank
over QQ, and equals it unless one non-zero integer polynomial of degree ≤ D (:func:`degree_bound`)
vanishes there (probability ≤ D/|S| over QQ) or — over GF(p) — p divides all its coefficients
or the point is a root mod p; :func:`failure_bound` turns this into the probability, stated with
every verdict, that any verdict is wrong.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property

from identcheck.errors import InputError
from identcheck.progress import Progress
from identcheck.exact.linalg import PRIME_BITS, Field
from identcheck.certify.tree_elimination import TreeElimination
from identcheck.certify.tree_equations import (centre_keys, frame_pose, frozen_keys, joint_rows, marker_keys, marker_rows,
                                               tangent_keys)
from identcheck.exact.algebra import axis_rotation, dot as _dot, half_angle, quaternion_rotation, scale as _scale, sub as _sub

SET_BITS = 40
MAX_FRAMES = 60
TYPES = ("spherical", "revolute")
VARS_PER_JOINT = {"spherical": 3, "revolute": 1}


# -- fields: identcheck.exact.linalg.Field (QQ or GF(p)) ------------------------------------------
class _Draw:
    """Random elements of a field: uniform on GF(p), or on S = {k / 2^20 : |k| < 2^39} ⊂ QQ."""

    def __init__(self, F: Field, rng: random.Random):
        self.F, self.rng = F, rng

    def scalar(self):
        if self.F.p is not None:                       # uniform on GF(p)
            return self.F(self.rng.randrange(self.F.p))
        k = self.rng.randrange(-(1 << (SET_BITS - 1)), 1 << (SET_BITS - 1))
        return self.F(Fraction(k, 1 << 20))

    def vector(self):
        return [self.scalar() for _ in range(3)]

    def rotation(self):
        """A rational rotation from a random quaternion (w, x, y, z) ≠ 0."""
        while True:
            q = [self.scalar() for _ in range(4)]
            if sum(v * v for v in q) != 0:
                return quaternion_rotation(*q)

    def angle(self):
        """(cos θ, sin θ) from a random half-angle tangent t with 1 + t² ≠ 0."""
        while True:
            t = self.scalar()
            if 1 + t * t != 0:
                return half_angle(t)


# -- the tree ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TreeSpec:
    """A skeleton as the engine needs it: segments with marker counts, joints (name, type, parent, child)."""

    root: str
    markers: dict                  # segment -> tuple of marker names
    joints: tuple                  # ((name, type, parent, child), ...) parents before children
    frozen: frozenset = frozenset()   # joints held at one fixed angle in every frame (motion not exercised)
    known: frozenset = frozenset()    # segments whose pose in every frame is given, not unknown (a window of a
    #                                   larger tree told everything beyond it: identcheck.plan.windows)

    @classmethod
    def from_model(cls, model) -> "TreeSpec":
        """From an :class:`identcheck.io.model.Model`; an unsupported joint type is an InputError."""
        markers = {s: tuple(seg.markers) for s, seg in model.segments.items()}
        joints = tuple((n, model.joints[n].type, model.joints[n].parent, model.joints[n].child)
                       for n in model.joint_order)
        for n, t, _, _ in joints:
            if t not in TYPES:
                raise InputError([f"joint {n!r}: type {t!r} is not supported by the whole-tree analysis "
                                  f"(supported: {', '.join(TYPES)})"])
        return cls(model.root, markers, joints)

    def without(self, marker: str) -> "TreeSpec":
        return TreeSpec(self.root, {s: tuple(m for m in ms if m != marker) for s, ms in self.markers.items()},
                        self.joints, self.frozen, self.known)

    def freezing(self, names) -> "TreeSpec":
        return TreeSpec(self.root, self.markers, self.joints, frozenset(names), self.known)

    @cached_property
    def children(self) -> dict:
        out = {s: [] for s in self.markers}
        for j in self.joints:
            out[j[2]].append(j)
        return out

    @cached_property
    def parent_joint(self) -> dict:
        return {j[3]: j for j in self.joints}


@dataclass
class _Columns:
    """Indices of the constant columns (markers, joint centres, hinge tangents)."""

    marker: dict = field(default_factory=dict)     # marker -> first of 3 columns
    centre: dict = field(default_factory=dict)     # joint -> first of 3 columns
    tangent: dict = field(default_factory=dict)    # joint -> first of 2 columns
    frozen: dict = field(default_factory=dict)     # frozen joint -> columns of its constant angle(s)
    n: int = 0

    def take(self, k: int) -> int:
        self.n += k
        return self.n - k


def constant_columns(spec: TreeSpec) -> _Columns:
    """The constants' column indices, the layout the gradients of :func:`quantities` are written in: each
    marker's position (3), each joint's centre (3), each hinge's two axis tangents, each frozen joint's
    angle(s)."""
    cols = _Columns()
    for s, ms in spec.markers.items():
        for m in ms:
            cols.marker[m] = cols.take(3)
    for name, kind, _, _ in spec.joints:
        cols.centre[name] = cols.take(3)
        if kind == "revolute":
            cols.tangent[name] = cols.take(2)
        if name in spec.frozen:
            cols.frozen[name] = cols.take(VARS_PER_JOINT[kind])
    return cols


@dataclass
class _Constants:
    m: dict            # marker -> local position
    c: dict            # joint -> centre in the parent
    a: dict            # revolute joint -> (a, u, v) unit direction and tangents in the parent


class TreeJacobian:
    """The whole-tree equations at one random point over the frames drawn so far, and what they determine
    about each joint's constants (see the module docstring; the equations are
    :mod:`identcheck.certify.tree_equations`, eliminated by :mod:`identcheck.certify.tree_elimination`)."""

    def __init__(self, spec: TreeSpec, field_kind: str = "GFp", seed: int = 0, share: bool = True):
        self.spec = spec
        self._stream = f"identcheck.tree_rank/{seed}/{field_kind}"
        self._shared = self._stream if share else None     # eliminations shared through the memo under this key
        self.F = Field(field_kind, random.Random(self._stream))
        self.cols = cols = constant_columns(spec)
        self.col_key = [None] * cols.n          # constant column index -> its key in the equations
        for m, i in cols.marker.items():
            self.col_key[i:i + 3] = marker_keys(m)
        for n, i in cols.centre.items():
            self.col_key[i:i + 3] = centre_keys(n)
        for n, i in cols.tangent.items():
            self.col_key[i:i + 2] = tangent_keys(n)
        for n, kind, _, _ in spec.joints:
            if n in cols.frozen:
                i, width = cols.frozen[n], VARS_PER_JOINT[kind]
                self.col_key[i:i + width] = frozen_keys(n, width)
        axes = {}
        for name, kind, _, _ in spec.joints:
            if kind == "revolute":
                R = self.draw("axis", name).rotation()
                axes[name] = ([R[i][2] for i in range(3)], [R[i][0] for i in range(3)], [R[i][1] for i in range(3)])
        self.k = _Constants(m={m: self.draw("marker", m).vector() for ms in spec.markers.values() for m in ms},
                            c={j[0]: self.draw("centre", j[0]).vector() for j in spec.joints}, a=axes)
        self.frozen_angles = {name: self._joint_rotation(name, kind) for name, kind, _, _ in spec.joints
                              if name in spec.frozen}
        self.frames = 0
        self._frames: list = []            # per frame: (marker rows by segment, joint rows by joint, rank V_f)
        self._states: dict = {}

    def draw(self, *item) -> _Draw:
        """The random source of one item (a marker's position, a joint's centre or axis, a frame's root pose
        or joint turn): each item has its own stream, so plans that share an item draw it alike."""
        return _Draw(self.F, random.Random("/".join([self._stream, *map(str, item)])))

    def _joint_rotation(self, name, kind):
        d = self.draw("frozen", name)
        if kind == "spherical":
            return (d.rotation(), None)
        c, s = d.angle()
        return (axis_rotation(self.k.a[name][0], c, s), (c, s))

    @property
    def n_frame_unknowns(self) -> int:
        """Per-frame unknowns of the equations: each segment's pose (6) and each moving hinge's angle."""
        hinges = sum(1 for n, kind, _, _ in self.spec.joints if kind == "revolute" and n not in self.spec.frozen)
        return 6 * (len(self.spec.markers) - len(self.spec.known)) + hinges

    def add_frame(self, count: int = 1) -> None:
        """Add ``count`` generic frames: their equations, marker by marker and joint by joint, and the rank
        of their per-frame columns (frames share no per-frame column, so rank V is a sum over frames)."""
        spec = self.spec
        for _ in range(count):
            f = self.frames
            pose, turns = frame_pose(spec, self.k, lambda *item: self.draw("frame", f, *item), self.frozen_angles)
            mrows = {s: [row for m in ms for row in marker_rows(s, f, pose[s][0], self.k.m[m], marker_keys(m))]
                     for s, ms in spec.markers.items()}
            jrows = {j[0]: joint_rows(j, f, pose[j[2]][0], turns[j[0]], self.k, j[0] in spec.frozen)
                     for j in spec.joints}
            if spec.known:
                mrows = {s: _given_poses(rows, spec.known) for s, rows in mrows.items()}
                jrows = {n: _given_poses(rows, spec.known) for n, rows in jrows.items()}
            rank_v = TreeElimination(self.F, spec, [f], mrows, jrows, stream=self._shared).rank_per_frame()
            self._frames.append((mrows, jrows, rank_v))
            self.frames += 1

    def at(self, frames: int) -> "FrameState":
        """What the first ``frames`` frames determine (computed once per frame count)."""
        if frames not in self._states:
            self._states[frames] = FrameState(self, frames)
        return self._states[frames]


def _given_poses(rows: list, known: frozenset) -> list:
    """``rows`` with the pose columns of the segments in ``known`` left out: those poses are given, not unknown."""
    return [{key: v for key, v in row.items() if not (key[0] in ("w", "t") and key[1] in known)} for row in rows]


class FrameState:
    """W after the first ``frames`` frames of a :class:`TreeJacobian`: dim W, and membership in W of
    gradients supported on one joint's constants (against W ∩ span(L_j))."""

    def __init__(self, tj: TreeJacobian, frames: int):
        self.tj, self.frames = tj, frames
        self._elimination = None
        self._subspaces: dict = {}

    @property
    def elimination(self) -> TreeElimination:
        if self._elimination is None:
            tj, spec = self.tj, self.tj.spec
            used = tj._frames[:self.frames]
            marker_rows_ = {s: [r for m, _, _ in used for r in m[s]] for s in spec.markers}
            joint_rows_ = {n: [r for _, j, _ in used for r in j[n]] for n, _, _, _ in spec.joints}
            marker_cols = {s: [k for m in ms for k in marker_keys(m)] for s, ms in spec.markers.items()}
            centre_cols = {n: centre_keys(n) for n, _, _, _ in spec.joints}
            joint_cols = {n: centre_cols[n] + (tangent_keys(n) if kind == "revolute" else [])
                          for n, kind, _, _ in spec.joints}
            e = TreeElimination(tj.F, spec, range(self.frames), marker_rows_, joint_rows_,
                                marker_cols, centre_cols, joint_cols, stream=tj._shared)
            e.upward()
            self._elimination = e
        return self._elimination

    def dim_w(self) -> int:
        """dim W = rank [V | C] − rank V: the constants' combinations the data determine, whole tree."""
        return self.elimination.rank_full - sum(r for _, _, r in self.tj._frames[:self.frames])

    def in_joint_span(self, joint: str, grads: list) -> list:
        """For each gradient ({constant column: value}, supported on the joint's constants, its segments'
        markers and the centres it may be judged against), is it in W?"""
        if not grads:
            return []
        if joint not in self._subspaces:
            e = self.elimination
            if not e.downward_done:
                e.downward()
            W = e.joint_subspace(next(j for j in self.tj.spec.joints if j[0] == joint))
            pivots = [next(key for key in W.keys if key in r) for r in W.rows]
            self._subspaces[joint] = (set(W.keys), list(zip(pivots, W.rows)))
        keys, basis = self._subspaces[joint]
        out = []
        for grad in grads:
            g = {}
            for i, v in grad.items():
                if v != 0:
                    key = self.tj.col_key[i]
                    g[key] = g.get(key, 0) + v
            if any(key not in keys for key in g):
                raise ValueError(f"gradient outside joint {joint!r}'s constants")
            for piv, row in basis:                  # reduced echelon rows: one subtraction per pivot
                v = g.get(piv)
                if v is not None and v != 0:
                    for key, x in row.items():
                        g[key] = g.get(key, 0) - v * x
            out.append(not any(v != 0 for v in g.values()))
        return out


# -- what is asked: gauge-invariant quantities of each joint ------------------------------------------
@dataclass(frozen=True)
class Point:
    """A point fixed in a segment that a joint is measured against: a marker, or another joint's centre."""

    name: str
    segment: str
    kind: str           # "marker" | "centre"


def adjacent_points(spec: TreeSpec, joint: str) -> tuple:
    """(parent-side points, child-side points) a joint's parameters are measured against: the markers
    of each adjacent segment; for a segment without markers, the centres of its other spherical
    joints (so a markerless shank still relates the knee to the ankle)."""
    name, kind, par, chi = next(j for j in spec.joints if j[0] == joint)
    sides = []
    for seg in (par, chi):
        pts = [Point(m, seg, "marker") for m in spec.markers[seg]]
        if not pts:
            others = [j for j in spec.children[seg] if j[0] != joint]
            pj = spec.parent_joint.get(seg)
            if pj is not None and pj[0] != joint:
                others.append(pj)
            pts = [Point(o[0], seg, "centre") for o in others if o[1] == "spherical"]
        sides.append(tuple(pts))
    return tuple(sides)


class _Quantity:
    """A gauge-invariant quantity of one joint and its gradient on the constants (column -> value), with the
    point it measures the joint against (``None`` for an axial offset, which involves two)."""

    def __init__(self, label: str, grad: dict, point: Point | None = None):
        self.label, self.grad, self.point = label, grad, point


def _point_local(tj: "TreeJacobian", pt: Point, seg: str):
    """(coordinates in ``seg``'s frame, {column: d coords / d column} as 3-vectors per column)."""
    spec, k, F = tj.spec, tj.k, tj.F
    if pt.kind == "marker":
        i = tj.cols.marker[pt.name]
        return k.m[pt.name], {i + a: a for a in range(3)}
    j = next(j for j in spec.joints if j[0] == pt.name)
    if j[2] == seg:              # a child joint of seg: its centre in seg's frame is c_j
        i = tj.cols.centre[pt.name]
        return k.c[pt.name], {i + a: a for a in range(3)}
    return [F(0), F(0), F(0)], {}  # seg's own parent joint: its centre is seg's origin


def quantities(tj: "TreeJacobian", joint: str, points: tuple | None = None) -> list:
    """Squared distances of the adjacent points to the centre (spherical) or to the hinge, and the
    hinge's axial offsets between the adjacent points (revolute). ``points``: (parent-side, child-side)
    points to measure against instead of all of :func:`adjacent_points`."""
    spec, k, F = tj.spec, tj.k, tj.F
    name, kind, par, chi = next(j for j in spec.joints if j[0] == joint)
    parent_pts, child_pts = points if points is not None else adjacent_points(spec, joint)
    ci = tj.cols.centre[name]
    out, axial = [], []
    for side, pts in ((par, parent_pts), (chi, child_pts)):
        for pt in pts:
            y, dy = _point_local(tj, pt, side)
            w = _sub(y, k.c[name]) if side == par else y     # from the centre / a point of the hinge
            grad: dict = {}

            def put(col, val):
                grad[col] = grad.get(col, F(0)) + val

            if kind == "spherical":
                for col, a in dy.items():
                    put(col, 2 * w[a])
                if side == par:
                    for a in range(3):
                        put(ci + a, -2 * w[a])
                out.append(_Quantity(f"|{pt.name} - centre|^2", grad, pt))
                continue
            a_, u_, v_ = k.a[name]
            h = _dot(w, a_)
            perp = _sub(w, _scale(h, a_))
            for col, a in dy.items():
                put(col, 2 * perp[a])
            if side == par:
                for a in range(3):
                    put(ci + a, -2 * perp[a])
            ti = tj.cols.tangent[name]
            put(ti, -2 * h * _dot(w, u_))
            put(ti + 1, -2 * h * _dot(w, v_))
            out.append(_Quantity(f"dist({pt.name}, hinge)^2", grad, pt))
            hg: dict = {}
            for col, a in dy.items():
                hg[col] = hg.get(col, F(0)) + a_[a]
            if side == par:
                for a in range(3):
                    hg[ci + a] = hg.get(ci + a, F(0)) - a_[a]
            hg[ti] = hg.get(ti, F(0)) + _dot(w, u_)
            hg[ti + 1] = hg.get(ti + 1, F(0)) + _dot(w, v_)
            axial.append((pt.name, hg))
    for (n0, g0), (n1, g1) in zip(axial, axial[1:]):
        g = dict(g1)
        for col, val in g0.items():
            g[col] = g.get(col, F(0)) - val
        out.append(_Quantity(f"axial({n1}) - axial({n0})", g))
    return out


# -- what a joint is judged against on a segment without markers ----------------------------------------
def _centre_joints(spec: TreeSpec, seg: str) -> list:
    """Names of the spherical joints attached to ``seg`` (its parent joint and its child joints)."""
    attached = list(spec.children[seg]) + ([spec.parent_joint[seg]] if seg in spec.parent_joint else [])
    return [j[0] for j in attached if j[1] == "spherical"]


def anchored_centres(spec: TreeSpec, asked: dict, undetermined: dict) -> dict:
    """segment without markers -> the ball-joint centres on it that the data place relative to another
    of them: a centre is anchored when some distance from it to another centre of the segment is
    determined (in W).

    A segment without markers has no frame of its own; its determined content is the configuration of
    its anchored centres. A centre whose distances to all the others stay undetermined (a neck whose
    head carries no marker) is not part of it, and its distances are that joint's undetermined
    quantities, not its neighbours'. ``asked``: joint -> its :class:`_Quantity` list over all
    :func:`adjacent_points`; ``undetermined``: joint -> the labels of those not in W."""
    out = {}
    for seg, ms in spec.markers.items():
        if ms:
            continue
        out[seg] = {a for a in _centre_joints(spec, seg)
                    if any(q.point is not None and q.point.segment == seg and q.point.kind == "centre"
                           and q.label not in undetermined[a] for q in asked[a])}
    return out


def judged_points(spec: TreeSpec, joint: str, anchored: dict) -> tuple:
    """((parent-side, child-side) points ``joint`` is judged against, [points set aside]).

    On a segment with markers: its markers. On one without: the anchored centres of its other ball
    joints (:func:`anchored_centres`); all of them when none is anchored (then nothing on the segment
    is determined, and the joint is judged against everything there, as its neighbours are). A point
    set aside is another joint's centre that the data leave undetermined on the segment: it belongs to
    that joint's verdict, not to this one's."""
    sides, aside = [], []
    for pts in adjacent_points(spec, joint):
        seg_anchored = anchored.get(pts[0].segment, set()) if pts else set()
        keep = [p for p in pts if p.kind == "marker" or p.name in seg_anchored]
        if not keep:
            keep = list(pts)
        aside += [p for p in pts if p not in keep]
        sides.append(tuple(keep))
    return tuple(sides), aside


# -- the analysis ------------------------------------------------------------------------------------
@dataclass
class JointRank:
    """The whole-tree verdict for one joint."""

    local: bool
    min_frames: int | None            # fewest generic frames after which it is locally identifiable
    quantities: list                  # labels of the gauge-invariant quantities asked about
    undetermined: list                # labels not in W (empty when local)
    points: tuple = ((), ())          # (parent-side, child-side) Points the quantities measure against
    set_aside: list = field(default_factory=list)   # [{"joint", "segment", "quantity"}]: its quantities
    #     measured against another joint's centre that the data leave undetermined on a segment without
    #     markers (``quantity``, this joint's label) — they belong to that joint (``joint``), not to this one


@dataclass
class TreeRank:
    """Whole-tree verdicts, with what the certificate rests on."""

    joints: dict                      # name -> JointRank
    frames: int                       # frames used (the scan stopped: one more changed nothing)
    dim_w: int                        # dim W: constants combinations the data determine
    n_constants: int
    field: str
    prime: int | None
    degree_bound: int
    failure_bound: float              # probability the verdicts are wrong (QQ) / guidance only (GFp)


def _rows_per_frame(spec: TreeSpec) -> list:
    """(rows, segment) per frame of the equations (:mod:`identcheck.certify.tree_equations`): three per
    marker on its segment; three per ball joint and six per hinge or frozen joint, counted at the child
    (their entries — R_P, R_P c_j, R_P a_j, R_P g — are products of the rotations above the child)."""
    out = [(3 * len(ms), s) for s, ms in spec.markers.items()]
    out += [(3 if kind == "spherical" and name not in spec.frozen else 6, chi) for name, kind, _, chi in spec.joints]
    return out


def degree_bound(spec: TreeSpec, frames: int) -> int:
    """D: a bound on the degree, in the drawn coordinates, of the minors the verdicts rest on.

    Entries of a row are, after clearing denominators, polynomials in the drawn coordinates: each
    rotation on the chain from the root contributes degree ≤ 2 to numerator and denominator
    (quaternion / |q|² or half-angle over 1 + t²), a joint at most two rotations (a hinge: its axis'
    rotation and its angle; an axis' tilt rate g is a product of two such), the constants degree 1; a
    row below d joints therefore has degree ≤ 4(2d + 2) + 2 once its denominators are cleared, and a
    minor built from ≤ R rows (plus one gradient row) has degree ≤ the sum over its rows, bounded by the
    sum over all rows (:func:`_rows_per_frame`).
    """
    depth = {spec.root: 0}
    for _, _, par, chi in spec.joints:
        depth[chi] = depth[par] + 2
    per_frame = sum(n * (4 * (depth[s] + 2) + 2) for n, s in _rows_per_frame(spec))
    grad_row = 8
    return per_frame * frames + grad_row


def content_bits(spec: TreeSpec, frames: int, ncols: int) -> int:
    """L: a bound on log2 of the largest coefficient (over Z) of a minor the verdicts rest on.

    A minor's coefficient 1-norm is at most the product over its rows of the row's summed entry
    1-norms (expand the determinant). An entry, denominators cleared, is a sum of ≤ 3 products per
    joint on the chain of quaternion / half-angle numerators and constants, each of 1-norm ≤ 4:
    ≤ 2^(8 (d + 3)) for a chain of d joints is generous. So L ≤ Σ_rows (log2 ncols + 8 (d + 3)).
    """
    depth = {spec.root: 0}
    for _, _, par, chi in spec.joints:
        depth[chi] = depth[par] + 1
    per_frame = sum(n * (math.ceil(math.log2(max(ncols, 2))) + 8 * (depth[s] + 3)) for n, s in _rows_per_frame(spec))
    return per_frame * frames + 64


def failure_bound(spec: TreeSpec, frames: int, n_claims: int, prime: int | None, ncols: int) -> float:
    """Probability that any of ``n_claims`` verdicts is wrong (the rank at the drawn point is not generic).

    QQ: Schwartz–Zippel, D/|S| per claim. GF(p), p uniform among the primes of [2^60, 2^61): the
    critical minor P ∈ Z[x] is non-zero; it vanishes identically mod p only if p divides all its
    coefficients — at most L/60 primes of that size divide one non-zero coefficient (< 2^L), out of
    more than 2^60 / (2 ln 2^61) primes there — else it vanishes at the uniform point of GF(p)^n
    with probability ≤ D/p. Union bound over the claims.
    """
    D = degree_bound(spec, frames)
    if prime is None:
        per = D / 2.0 ** SET_BITS
    else:
        n_primes = 2.0 ** (PRIME_BITS - 1) / (2 * PRIME_BITS * math.log(2))
        per = D / prime + (content_bits(spec, frames, ncols) / (PRIME_BITS - 1)) / n_primes
    return min(1.0, n_claims * per)


def _not_in_w(state: FrameState, asked: dict) -> dict:
    """joint -> labels of its quantities whose gradients are not in W (each joint against W ∩ span(L_j))."""
    out = {}
    for n, ql in asked.items():
        found = state.in_joint_span(n, [q.grad for q in ql])
        out[n] = [q.label for q, ok in zip(ql, found) if not ok]
    return out


def _judge(state: FrameState, asked: dict) -> tuple:
    """(joint -> (points, set aside), joint -> its judged quantities, joint -> judged labels not in W) at
    the state's W: every quantity over :func:`adjacent_points` is decided first, which fixes the anchored
    centres; joints whose points then change are asked again, against :func:`judged_points`."""
    spec = state.tj.spec
    undetermined = _not_in_w(state, asked)
    anchored = anchored_centres(spec, asked, undetermined)
    points = {n: judged_points(spec, n, anchored) for n in asked}
    redo = {n: quantities(state.tj, n, pts) for n, (pts, aside) in points.items() if aside}
    again = _not_in_w(state, redo)
    judged = {n: redo.get(n, asked[n]) for n in asked}
    return points, judged, {n: again.get(n, undetermined[n]) for n in asked}


def _local(judged: dict, verdict: dict) -> set:
    return {n for n, qlist in judged.items() if qlist and not verdict[n]}


def analyse(spec: TreeSpec, field_kind: str = "GFp", seed: int = 0, max_frames: int = MAX_FRAMES,
            warm_frames: int = 0, search_min_frames: bool = True, share: bool = True, progress=None) -> TreeRank:
    """Scan frames until one more generic frame changes neither dim W nor any joint's verdict.

    A joint is locally identifiable when every quantity it is judged by is in W: its distances to the
    markers of its segments, and on a segment without markers to the anchored centres of the segment's
    other ball joints (:func:`judged_points`). An undetermined neighbour (a neck whose head carries no
    marker) is then the neighbour's undetermined quantity, reported in ``set_aside``, not this joint's.

    The frames are nested, so W only grows: when one more frame leaves dim W unchanged, W and every
    verdict are unchanged, and the scan stops there (only dim W is computed while scanning). A joint's
    ``min_frames`` is the fewest frames from which on it is locally identifiable, found by judging again
    at fewer frames, from the stop downwards, while some joint is still local there.

    ``warm_frames``: take that many frames at once before scanning one by one (faster when a similar
    plan's count is known; the verdicts are the same, but ``min_frames`` is then at least that count).
    ``search_min_frames=False``: do not judge again below the stop (the variants a plan's analyses rank
    use only the verdicts); a local joint's ``min_frames`` is then an upper bound: the fewest frames seen to
    give the final W (the stop, or one less when the last frame changed nothing). ``share=False``: keep
    this rank's eliminations out of the memo other ranks of the same skeleton's variants reuse (a small
    window's are cheaper to redo than to look up). ``progress``: called with a line at most once a second."""
    line = Progress(progress, first_after_s=1.0)
    tj = TreeJacobian(spec, field_kind, seed, share)
    asked = {j[0]: quantities(tj, j[0]) for j in spec.joints}
    dims = {}
    stable = False
    while tj.frames < max_frames:
        tj.add_frame(max(1, warm_frames - tj.frames))
        dims[tj.frames] = tj.at(tj.frames).dim_w()
        line(lambda: f"whole-tree rank: {tj.frames} frames, {dims[tj.frames]} combinations of constants determined")
        if dims.get(tj.frames - 1) == dims[tj.frames]:
            stable = True
            break
    final, start = tj.frames, min(dims)
    points, judged, verdict = _judge(tj.at(final), asked)
    local = _local(judged, verdict)
    first = {n: final for n in local}
    frames = final - 1
    if stable and frames >= start:            # same W one frame earlier: same verdicts
        first = {n: frames for n in local}
        frames -= 1
    while search_min_frames and frames >= start and any(first[n] == frames + 1 for n in local):
        line(lambda: f"whole-tree rank: the fewest frames each joint needs, judging at {frames}")
        still = _local(*_judge(tj.at(frames), asked)[1:])
        for n in local:
            if first[n] == frames + 1 and n in still:
                first[n] = frames
        frames -= 1
    joints = {n: JointRank(local=n in local, min_frames=first.get(n),
                           quantities=[q.label for q in judged[n]], undetermined=verdict[n],
                           points=points[n][0],
                           set_aside=[{"joint": q.point.name, "segment": q.point.segment, "quantity": q.label}
                                      for q in asked[n] if q.point in points[n][1]])
              for n in asked}
    D = degree_bound(spec, final)
    n_claims = sum(len(q) for q in asked.values()) + sum(len(q) for n, q in judged.items() if points[n][1]) + 1
    fail = failure_bound(spec, final, n_claims, tj.F.p, tj.n_frame_unknowns * final + tj.cols.n)
    return TreeRank(joints=joints, frames=final, dim_w=dims[final], n_constants=tj.cols.n, field=field_kind,
                    prime=tj.F.p, degree_bound=D, failure_bound=fail)
