"""The rigid-joint model of a whole chain: its parameters (:class:`State`, with effect :class:`Terms`), its
predictions (:func:`forward`) and how a Gauss-Newton step moves it (:func:`apply_step`).

Every segment is rigid and every joint holds: the root has a free pose per frame, a spherical joint a free
relative rotation per frame, a revolute joint a hinge angle per frame; the constants are the markers'
positions on their segments, each joint's centre in both adjacent segments and each hinge's direction.

Effects add to this model through :class:`Terms`: marker offsets on their segment and joint-centre offsets in
the parent, each a fixed basis of per-frame functions times fitted 3-vectors (soft tissue, a slipped marker, a
translating joint), a hinge's second rotation about a fixed axis perpendicular to it, its angle a fixed
basis times fitted coefficients (a knee's varus/valgus or axial play), a hinge's centre moving along its fitted
axis (a screw: a fixed profile times a fitted scalar), and fields in the world times fitted scalars (a delay's
velocity, a distorted volume's basis fields, a ball joint's translation linear in its angles). Effects of the
recording (swapped labels, gross errors) also change the data or the weights.

Rotation updates are applied on the left in the world frame: a per-frame step ω turns the root about its
origin, or the child of a ball joint about the joint's centre, in the world.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from identcheck.geometry.kinematics import chain_poses
from identcheck.geometry.rotations import hinge_matrix, rotvec_matrix
from identcheck.skeleton import Skeleton

@dataclass
class Terms:
    """Linear effect terms: a per-frame basis times fitted 3-vectors.

    ``markers``: list of (column or columns of one segment, basis (F, K)): the marker's (or each of the
    markers') position on its segment moves by ``basis @ B`` (B (K, 3), segment frame, shared). ``centres``: list of
    (joint, basis (F, K)): the joint's centre in the parent moves by ``basis @ D``. ``rotations``: list of (hinge,
    basis (F, K), β₀): the hinge's relative rotation becomes ``Rot(a, θ) Exp(ψ u) rest`` with ψ = ``basis @ p[:K]``
    (p (K + 1, 1)) and u the unit vector at angle β = β₀ + p[K] in the plane perpendicular to the hinge axis a
    (:func:`tangents`): a second rotation about a fitted axis that turns with the child. ``screws``: list of (hinge,
    profile (F,)): the hinge's centre in the parent moves along its fitted axis a by a scalar times the profile (a
    translation linear in its angle, ``θ a``): it turns with the parent and follows the axis as they are fitted.
    ``world``: list of (columns (m,), field (F, m, 3)): those markers' predictions move by a scalar times the field (a
    delay's velocity, a distortion's basis field), in the world. Parameters are kept in that order: markers, centres,
    rotations, screws, world (the world's last: an effect that adds world terms finds them at the end).

    Why a screw is not a world field built from the round's parent rotations and axis: those rotations carry the
    noise of the frames they were fitted to, and a field frozen from them, fitted beside a term that turns with the
    fit (skin on the child's markers, linear in the same angle: along the axis it is the same motion), takes that
    noise up through their difference: on a rigid leg, a knee's ``θ a`` beside shank skin explained 1 957 and 2 834
    criterion units with one parameter (simulated, seeds 3 and 4), as a screw 0. Why it follows the axis: fixed in
    the parent's frame, it let the fit turn the axis 90° away and read it as a translation across the axis (a knee
    translating 9 mm: its centre then 170 mm off), and a direction fixed in a frame the gauge turns breaks the gauge
    (:mod:`identcheck.bundle.gauge`); along the axis it turns with it.
    """

    markers: list = field(default_factory=list)
    centres: list = field(default_factory=list)
    world: list = field(default_factory=list)
    rotations: list = field(default_factory=list)
    screws: list = field(default_factory=list)

    def size(self) -> int:
        return 3 * sum(b.shape[1] for _, b in self.markers + self.centres) \
            + sum(b.shape[1] + 1 for _, b, _ in self.rotations) + len(self.screws) + len(self.world)

    def redundant(self) -> int:
        """Directions of the terms' parameters that change no prediction: a hinge turning about two axes across it
        (two ``rotations``) spans the same plane whatever the two axes' angles, and each angle's change is taken back
        by mixing the two profiles (2 for each such hinge)."""
        hinges = [j for j, _, _ in self.rotations]
        return 2 * sum(hinges.count(j) >= 2 for j in set(hinges))

    def shapes(self) -> list:
        """Shape of each term's parameters, in ``State.term_params`` order."""
        return [(b.shape[1], 3) for _, b in self.markers + self.centres] \
            + [(b.shape[1] + 1, 1) for _, b, _ in self.rotations] + [(1,)] * (len(self.screws) + len(self.world))

    def ordered(self) -> list:
        """Every term in ``State.term_params`` order."""
        return self.markers + self.centres + self.rotations + self.screws + self.world

    def screws_start(self) -> int:
        """Index of the first screw's parameter in ``State.term_params``."""
        return len(self.markers) + len(self.centres) + len(self.rotations)

    def world_start(self) -> int:
        """Index of the first world field's parameter in ``State.term_params``."""
        return self.screws_start() + len(self.screws)

    def world_runs(self) -> list:
        """The world fields in runs of consecutive terms acting on the same markers, each run's fields stacked:
        [(first term index among ``world``, columns (m,), fields (F, m, 3, W))], built once per Terms and kept.

        A smooth distortion of the volume adds some fifty fields on every marker; taken one at a time they made
        the forward kinematics and the derivatives twelve times as slow as the rigid model's, and stacked they are
        one product each."""
        cached = self.__dict__.get("_world_runs")
        if cached is not None and cached[0] == len(self.world):
            return cached[1]
        runs, i = [], 0
        while i < len(self.world):
            cols = np.atleast_1d(self.world[i][0])
            end = i + 1
            while end < len(self.world) and np.array_equal(np.atleast_1d(self.world[end][0]), cols):
                end += 1
            runs.append((i, cols, np.stack([f for _, f in self.world[i:end]], axis=-1)))
            i = end
        self.__dict__["_world_runs"] = (len(self.world), runs)
        return runs

    def __add__(self, other: "Terms") -> "Terms":
        return Terms(markers=self.markers + other.markers, centres=self.centres + other.centres,
                     world=self.world + other.world, rotations=self.rotations + other.rotations,
                     screws=self.screws + other.screws)


@dataclass
class State:
    """Constants and per-frame motion of a fitted chain (world-from-segment convention)."""

    local: np.ndarray            # (M, 3) each marker on its segment
    c_parent: dict               # joint -> (3,)
    c_child: dict                # joint -> (3,)
    axis: dict                   # revolute joint -> (3,) unit, parent frame
    rest: dict                   # revolute joint -> (3, 3): R_rel = Rot(axis, θ) @ rest
    root_R: np.ndarray           # (F, 3, 3)
    root_t: np.ndarray           # (F, 3)
    rel_R: dict                  # spherical joint -> (F, 3, 3) child-from-parent relative rotation
    theta: dict                  # revolute joint -> (F,) radians
    term_params: list = field(default_factory=list)   # one array per term, in Terms.ordered() order (Terms.shapes)

    def copy(self) -> "State":
        return self.at_frames(slice(None))

    def at_frames(self, idx) -> "State":
        """A copy with the per-frame motion of the frames `idx` only (every frame: ``slice(None)``), the constants
        as they are."""
        cp = lambda d: {k: np.array(v) for k, v in d.items()}  # noqa: E731
        at = lambda d: {k: np.array(v[idx]) for k, v in d.items()}  # noqa: E731
        return State(self.local.copy(), cp(self.c_parent), cp(self.c_child), cp(self.axis), cp(self.rest),
                     np.array(self.root_R[idx]), np.array(self.root_t[idx]), at(self.rel_R), at(self.theta),
                     [p.copy() for p in self.term_params])


@dataclass
class Fit:
    """A fitted chain: the state, its predictions and the cost."""

    chain: Skeleton
    terms: Terms
    state: State
    pred: np.ndarray             # (F, M, 3)
    rss: float                   # Σ w |x̂ − y|², mm²
    n_samples: int               # visible (weight > 0) marker samples
    n_params: int                # free parameters net of the gauge: every unknown of a frame with samples but
    #                              those the tree's structure leaves free (Skeleton.frame_free); the covariance's
    #                              degrees of freedom count the ones its samples determine (uncertainty.frame_rank)
    iterations: int
    converged: bool
    seg_R: dict = field(default_factory=dict)
    seg_t: dict = field(default_factory=dict)

    @property
    def gap(self) -> float:
        """RMS 3-D distance between measured and predicted markers, mm (the contract's gap)."""
        return float(np.sqrt(self.rss / max(self.n_samples, 1)))


# ---------------------------------------------------------------------- kinematics
def second_axis(axis: np.ndarray, beta: float) -> np.ndarray:
    """The unit vector at angle β in the plane perpendicular to `axis` (from :func:`tangents`)."""
    b1, b2 = tangents(axis)
    return np.cos(beta) * b1 + np.sin(beta) * b2


def second_rotations(terms: Terms, s: State) -> dict:
    """Each hinge's second rotation vector v (F, 3), in the hinge's turned frame (``Rot(a, θ) Exp(v)``; in the world
    ``R_P Rot(a, θ) v``): the sum of ``ψ u`` over the joint's ``terms.rotations`` (two of them turn it about any axis
    across the hinge)."""
    n0 = len(terms.markers) + len(terms.centres)
    extra = {}
    for (j, basis, beta), p in zip(terms.rotations, s.term_params[n0:n0 + len(terms.rotations)]):
        extra[j] = extra.get(j, 0.0) + (basis @ p[:-1])[:, 0, None] * second_axis(s.axis[j], beta + p[-1, 0])
    return extra


def hinge_turns(chain: Skeleton, terms: Terms, s: State) -> dict:
    """Each revolute joint's ``Rot(a, θ) Exp(ψ u)`` (F, 3, 3), the second rotations of ``terms.rotations``
    included (:func:`second_rotations`): the relative rotation is this times the rest rotation."""
    extra = second_rotations(terms, s)
    turns = {j: hinge_matrix(s.axis[j], s.theta[j]) for j in chain.joints if chain.types[j] == "revolute"}
    return {j: turn @ rotvec_matrix(extra[j]) if j in extra else turn for j, turn in turns.items()}


def forward(chain: Skeleton, terms: Terms, s: State):
    """Segment rotations/translations and predicted markers (F, M, 3) of state `s`."""
    F = s.root_R.shape[0]
    coffs = {}
    for (j, basis), D in zip(terms.centres, s.term_params[len(terms.markers):]):
        coffs[j] = coffs.get(j, 0.0) + basis @ D
    for (j, profile), c in zip(terms.screws, s.term_params[terms.screws_start():]):
        coffs[j] = coffs.get(j, 0.0) + c[0] * np.outer(profile, s.axis[j])
    turns = hinge_turns(chain, terms, s)
    rel = {j: s.rel_R[j] if chain.types[j] == "spherical" else turns[j] @ s.rest[j] for j in chain.joints}
    cp = {j: s.c_parent[j] + coffs[j] if j in coffs else s.c_parent[j] for j in chain.joints}
    R, t, centre = chain_poses([(j, chain.parent[j], chain.child[j]) for j in chain.joints], chain.root,
                               s.root_R, s.root_t, rel, cp, s.c_child)
    local = np.broadcast_to(s.local, (F,) + s.local.shape).copy()
    for (col, basis), B in zip(terms.markers, s.term_params[:len(terms.markers)]):
        local[:, np.atleast_1d(col)] += (basis @ B)[:, None]
    pred = np.empty((F, chain.n_markers, 3))
    for seg in chain.segments:
        idx = chain.seg_markers[seg]
        pred[:, idx] = local[:, idx] @ np.swapaxes(R[seg], 1, 2) + t[seg][:, None]
    if terms.world:
        pred += world_motion(terms, s)
    return R, t, centre, pred


def world_motion(terms: Terms, s: State) -> np.ndarray | float:
    """What the world fields of `terms` add to the predicted markers (F, M, 3), or 0.0 when there are none: each
    field times its parameter."""
    runs = terms.world_runs()
    if not runs:
        return 0.0
    n0 = terms.world_start()
    out = 0.0
    for first, cols, fields in runs:
        coef = np.array([p[0] for p in s.term_params[n0 + first:n0 + first + fields.shape[-1]]])
        moved = np.zeros(fields.shape[:1] + (s.local.shape[0], 3))
        moved[:, cols] = fields @ coef
        out = out + moved
    return out


def cross3(a, b) -> np.ndarray:
    """The cross product of two 3-vectors (or stacks of them, last axis), written out: numpy's ``cross`` spends
    most of its time on argument handling at these sizes."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def tangents(a: np.ndarray):
    """Two unit vectors (b1, b2) that complete the unit vector `a` to the right-handed orthonormal basis
    (b1, b2, a): the plane a hinge axis tilts in."""
    b1 = cross3(a, np.array([1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0]))
    b1 /= np.sqrt(b1 @ b1)
    return b1, cross3(a, b1)


def turn_rate(chain: Skeleton, terms: Terms, s: State, joint: str, move, h: float = 1e-6):
    """The rotation vector (parent frame, (F, 3)) of ``d(turn)/dε · turnᵀ`` of the joint's
    :func:`hinge_turns` when ``move(state, ε)`` changes the state (central differences): where a second
    rotation's axis moves with the hinge axis or its own angle β, no closed form is worth its length."""
    def turn(eps):
        st = s.copy()
        move(st, eps)
        return hinge_turns(chain, terms, st)[joint]
    dT = (turn(h) - turn(-h)) / (2 * h)
    W = dT @ np.swapaxes(turn(0.0), 1, 2)
    return 0.5 * np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], axis=1)


def tilt_axis(joint: str, direction: np.ndarray):
    """``move`` for :func:`turn_rate`: the hinge axis tilted by ε towards `direction`, as :func:`apply_step` does."""
    def move(st, eps):
        a = st.axis[joint] + eps * direction
        st.axis[joint] = a / np.linalg.norm(a)
    return move


def turn_beta(index: int):
    """``move`` for :func:`turn_rate`: term parameter `index`'s β (its last row) moved by ε."""
    def move(st, eps):
        st.term_params[index] = st.term_params[index].copy()
        st.term_params[index][-1, 0] += eps
    return move


def apply_step(chain: Skeleton, terms: Terms, s: State, R, dq: np.ndarray, dc: np.ndarray) -> State:
    """The state moved by per-frame steps dq (F, k) and constant steps dc (P,)."""
    n = s.copy()
    n.root_R = rotvec_matrix(dq[:, :3]) @ s.root_R
    n.root_t = s.root_t + dq[:, 3:6]
    col = 6
    M = chain.n_markers
    n.local = s.local + dc[:3 * M].reshape(M, 3)
    c = 3 * M
    for j in chain.joints:
        P = chain.parent[j]
        if chain.types[j] == "spherical":
            wp = np.einsum("fji,fj->fi", R[P], dq[:, col:col + 3])
            n.rel_R[j] = rotvec_matrix(wp) @ s.rel_R[j]
            col += 3
        else:
            n.theta[j] = s.theta[j] + dq[:, col]
            col += 1
        n.c_parent[j] = s.c_parent[j] + dc[c:c + 3]
        n.c_child[j] = s.c_child[j] + dc[c + 3:c + 6]
        c += 6
        if chain.types[j] == "revolute":
            n.rest[j] = rotvec_matrix(dc[c:c + 3])[0] @ s.rest[j]
            b1, b2 = tangents(s.axis[j])
            a = s.axis[j] + dc[c + 3] * b1 + dc[c + 4] * b2
            n.axis[j] = a / np.linalg.norm(a)
            c += 5
    for i, p in enumerate(s.term_params):
        size = p.size
        n.term_params[i] = p + dc[c:c + size].reshape(p.shape)
        c += size
    return n


def n_const(chain: Skeleton, terms: Terms) -> int:
    """Number of constants: each marker's position, each joint's centres (and a hinge's rest rotation and
    axis), and the effect terms' parameters, in that order."""
    return 3 * chain.n_markers + sum(_joint_width(chain, j) for j in chain.joints) + terms.size()


def null_count(chain: Skeleton, terms: Terms | None = None) -> int:
    """Directions of the constants that change no prediction: the chain's gauge
    (:meth:`~identcheck.skeleton.Skeleton.gauge`) and its effect terms' redundant ones (:meth:`Terms.redundant`)."""
    return chain.gauge() + (terms.redundant() if terms is not None else 0)


def joint_offsets(chain) -> dict:
    """Column where each joint's constants start (centre in parent, centre in child, then for a hinge the
    rest rotation and the axis' two tangent directions), after the 3M marker coordinates."""
    offsets, c = {}, 3 * chain.n_markers
    for j in chain.joints:
        offsets[j] = c
        c += _joint_width(chain, j)
    return offsets


def _joint_width(chain, joint: str) -> int:
    """How many constants a joint has: its centre in parent and child, and a hinge's rest rotation and axis."""
    return 6 + (5 if chain.types[joint] == "revolute" else 0)
