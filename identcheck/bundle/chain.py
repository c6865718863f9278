"""The whole rigid-joint model fitted to a trial at once: the simulation that ``diagnose`` compares
with the measured markers.

Every segment is rigid and every joint holds: the root has a free pose per frame, a spherical joint
a free relative rotation per frame, a revolute joint a hinge angle per frame; the constants are the
markers' positions on their segments, each joint's centre in both adjacent segments and each hinge's
direction. Markers are predicted by forward kinematics and the sum of squared 3-D marker errors is
minimised over everything together by Levenberg-Marquardt, with the per-frame unknowns eliminated by
the Schur complement (bundle adjustment), so a 1500-frame trial costs a few small dense solves.

Effects add to this model through :class:`Terms`: marker offsets on their segment and joint-centre
offsets in the parent, each a fixed basis of per-frame functions times fitted 3-vectors (soft tissue,
a slipped marker, a translating joint), and a hinge's second rotation about a fixed axis perpendicular
to it, its angle a fixed basis times fitted coefficients (a knee's varus/valgus or axial play). Effects of the recording (swapped labels, a delay, a distorted
volume, gross errors) change the data or the weights instead.

Rotation updates are applied on the left in the world frame, so the Jacobian of every marker with
respect to a rotation ω about a point c is ``ω × (x − c)``: about the root origin, or about the
joint's centre for every marker downstream of the joint.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.geometry.kinematics import chain_poses
from identcheck.geometry.rotations import hinge_matrix, rotvec_matrix
from identcheck.skeleton import Skeleton
from identcheck.estimate.obrien import joint_location
from identcheck.geometry.poses import Poses, refine_local

MAX_ITER = 60
REL_TOL = 1e-8        # stop when the cost falls by less than this fraction


@dataclass
class Terms:
    """Linear effect terms: a per-frame basis times fitted 3-vectors.

    ``markers``: list of (column or columns of one segment, basis (F, K)): the marker's (or each of the
    markers') position on its segment moves by ``basis @ B`` (B (K, 3), segment frame, shared). ``centres``: list of (joint, basis (F, K)): the joint's
    centre in the parent moves by ``basis @ D``. ``rotations``: list of (hinge, basis (F, K), β₀): the
    hinge's relative rotation becomes ``Rot(a, θ) Exp(ψ u) rest`` with ψ = ``basis @ p[:K]`` (p (K + 1, 1))
    and u the unit vector at angle β = β₀ + p[K] in the plane perpendicular to the hinge axis a
    (:func:`tangents`): a second rotation about a fitted axis that turns with the child. ``world``: list of (columns (m,), field (F, m, 3)):
    those markers' predictions move by a scalar times the field (a delay's velocity, a distortion's
    basis field), in the world. Parameters are kept in that order: markers, centres, rotations, world.
    """

    markers: list = field(default_factory=list)
    centres: list = field(default_factory=list)
    world: list = field(default_factory=list)
    rotations: list = field(default_factory=list)

    def size(self) -> int:
        return 3 * sum(b.shape[1] for _, b in self.markers + self.centres) \
            + sum(b.shape[1] + 1 for _, b, _ in self.rotations) + len(self.world)

    def shapes(self) -> list:
        """Shape of each term's parameters, in ``State.term_params`` order."""
        return [(b.shape[1], 3) for _, b in self.markers + self.centres] \
            + [(b.shape[1] + 1, 1) for _, b, _ in self.rotations] + [(1,)] * len(self.world)

    def ordered(self) -> list:
        """Every term in ``State.term_params`` order."""
        return self.markers + self.centres + self.rotations + self.world

    def __add__(self, other: "Terms") -> "Terms":
        return Terms(self.markers + other.markers, self.centres + other.centres, self.world + other.world,
                     self.rotations + other.rotations)


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
    term_params: list = field(default_factory=list)   # one (K, 3) per term, markers then centres

    def copy(self) -> "State":
        cp = lambda d: {k: np.array(v) for k, v in d.items()}  # noqa: E731
        return State(self.local.copy(), cp(self.c_parent), cp(self.c_child), cp(self.axis), cp(self.rest),
                     self.root_R.copy(), self.root_t.copy(), cp(self.rel_R), cp(self.theta),
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
    n_params: int                # free parameters net of the gauge
    iterations: int
    converged: bool
    seg_R: dict = field(default_factory=dict)
    seg_t: dict = field(default_factory=dict)

    @property
    def gap(self) -> float:
        """RMS 3-D distance between measured and predicted markers, mm (the contract's gap)."""
        return float(np.sqrt(self.rss / max(self.n_samples, 1)))


# ---------------------------------------------------------------------- kinematics
def _rot(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    return hinge_matrix(axis, theta)


def _exp(w: np.ndarray) -> np.ndarray:
    return rotvec_matrix(w)


def second_axis(axis: np.ndarray, beta: float) -> np.ndarray:
    """The unit vector at angle β in the plane perpendicular to `axis` (from :func:`tangents`)."""
    b1, b2 = tangents(axis)
    return np.cos(beta) * b1 + np.sin(beta) * b2


def _hinge_turns(chain: Skeleton, terms: Terms, s: State) -> dict:
    """Each revolute joint's ``Rot(a, θ) Exp(ψ u)`` (F, 3, 3), the second rotations of ``terms.rotations``
    included: the relative rotation is this times the rest rotation."""
    n0 = len(terms.markers) + len(terms.centres)
    extra = {}
    for (j, basis, beta), p in zip(terms.rotations, s.term_params[n0:n0 + len(terms.rotations)]):
        extra[j] = extra.get(j, 0.0) + (basis @ p[:-1])[:, 0, None] * second_axis(s.axis[j], beta + p[-1, 0])
    return {j: _rot(s.axis[j], s.theta[j]) @ _exp(extra[j]) if j in extra else _rot(s.axis[j], s.theta[j])
            for j in chain.joints if chain.types[j] == "revolute"}


def forward(chain: Skeleton, terms: Terms, s: State):
    """Segment rotations/translations and predicted markers (F, M, 3) of state `s`."""
    F = s.root_R.shape[0]
    coffs = {}
    for (j, basis), D in zip(terms.centres, s.term_params[len(terms.markers):]):
        coffs[j] = coffs.get(j, 0.0) + basis @ D
    turns = _hinge_turns(chain, terms, s)
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
        pred[:, idx] = np.einsum("fij,fkj->fki", R[seg], local[:, idx]) + t[seg][:, None]
    n0 = len(terms.markers) + len(terms.centres) + len(terms.rotations)
    for (cols, fld), p in zip(terms.world, s.term_params[n0:]):
        pred[:, cols] += p[0] * fld
    return R, t, centre, pred


def tangents(a: np.ndarray):
    b1 = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(a, b1)


def _turn_rate(chain: Skeleton, terms: Terms, s: State, joint: str, move, h: float = 1e-6):
    """The rotation vector (parent frame, (F, 3)) of ``d(turn)/dε · turnᵀ`` of the joint's
    :func:`_hinge_turns` when ``move(state, ε)`` changes the state (central differences): where a second
    rotation's axis moves with the hinge axis or its own angle β, no closed form is worth its length."""
    def turn(eps):
        st = s.copy()
        move(st, eps)
        return _hinge_turns(chain, terms, st)[joint]
    dT = (turn(h) - turn(-h)) / (2 * h)
    W = dT @ np.swapaxes(turn(0.0), 1, 2)
    return 0.5 * np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], axis=1)


def _tilt_axis(joint: str, direction: np.ndarray):
    """``move`` for :func:`_turn_rate`: the hinge axis tilted by ε towards `direction`, as :func:`_apply` does."""
    def move(st, eps):
        a = st.axis[joint] + eps * direction
        st.axis[joint] = a / np.linalg.norm(a)
    return move


def _turn_beta(index: int):
    """``move`` for :func:`_turn_rate`: term parameter `index`'s β (its last row) moved by ε."""
    def move(st, eps):
        st.term_params[index] = st.term_params[index].copy()
        st.term_params[index][-1, 0] += eps
    return move


def _jacobians(chain: Skeleton, terms: Terms, s: State, R, t, centre, pred):
    """Per-frame Jacobian (F, M, 3, k) and constants' Jacobian (F, M, 3, P) of the predictions."""
    F, M = pred.shape[:2]
    k = chain.frame_dof()
    J = np.zeros((F, M, 3, k))
    eye = np.eye(3)
    n0 = len(terms.markers) + len(terms.centres) + len(terms.rotations)
    if terms.world:                                   # lever arms are the rigid bodies' points, not the fields'
        pred = pred.copy()
        for (cols, fld), p in zip(terms.world, s.term_params[n0:]):
            pred[:, cols] -= p[0] * fld
    d = pred - s.root_t[:, None]
    for a in range(3):
        J[..., a] = np.cross(eye[a], d)
    J[..., 3:6] = eye
    col = 6
    n_const = 3 * M + sum(6 + (5 if chain.types[j] == "revolute" else 0) for j in chain.joints) + terms.size()
    G = np.zeros((F, M, 3, n_const))
    turns = _hinge_turns(chain, terms, s) if terms.rotations else {}
    for seg in chain.segments:
        for i in chain.seg_markers[seg]:
            G[:, i, :, 3 * i:3 * i + 3] = R[seg]
    c = 3 * M
    for j in chain.joints:
        P, C, idx = chain.parent[j], chain.child[j], chain.downstream[j]
        dx = pred[:, idx] - centre[j][:, None]
        if chain.types[j] == "spherical":
            for a in range(3):
                J[..., col + a][:, idx] = np.cross(eye[a], dx)
            col += 3
        else:
            aw = R[P] @ s.axis[j]
            J[..., col][:, idx] = np.cross(aw[:, None], dx)
            col += 1
        G[:, idx, :, c:c + 3] = R[P][:, None]
        G[:, idx, :, c + 3:c + 6] = -R[C][:, None]
        c += 6
        if chain.types[j] == "revolute":
            th = s.theta[j]
            rot = turns.get(j, None)
            rot = _rot(s.axis[j], th) if rot is None else rot
            for a in range(3):                              # rest rotation, pre-multiplied by Rot(a, θ) Exp(ψu)
                w = np.einsum("fij,fj->fi", R[P], rot[:, :, a])
                G[..., c + a][:, idx] = np.cross(w[:, None], dx)
            ax = s.axis[j]
            for a, b in enumerate(tangents(ax)):           # axis direction, tangent plane
                if any(r[0] == j for r in terms.rotations):
                    wp = _turn_rate(chain, terms, s, j, _tilt_axis(j, b))  # the second axis moves with it
                else:
                    wp = np.sin(th)[:, None] * b + (1 - np.cos(th))[:, None] * np.cross(ax, b)
                w = np.einsum("fij,fj->fi", R[P], wp)
                G[..., c + 3 + a][:, idx] = np.cross(w[:, None], dx)
            c += 5
    for (i, basis) in terms.markers:
        cols = np.atleast_1d(i)
        seg = chain.marker_seg[int(cols[0])]
        for kk in range(basis.shape[1]):
            G[:, cols, :, c:c + 3] = (R[seg] * basis[:, kk, None, None])[:, None]
            c += 3
    for (j, basis) in terms.centres:
        idx = chain.downstream[j]
        for kk in range(basis.shape[1]):
            G[:, idx, :, c:c + 3] = (R[chain.parent[j]] * basis[:, kk, None, None])[:, None]
            c += 3
    n_mc = len(terms.markers) + len(terms.centres)
    for r, (j, basis, beta) in enumerate(terms.rotations):  # d/dψ: about R_P Rot(a, θ) u, through the centre
        idx = chain.downstream[j]
        dx = pred[:, idx] - centre[j][:, None]
        u = second_axis(s.axis[j], beta + s.term_params[n_mc + r][-1, 0])
        w = np.einsum("fij,fjk,k->fi", R[chain.parent[j]], _rot(s.axis[j], s.theta[j]), u)
        turn = np.cross(w[:, None], dx)
        for kk in range(basis.shape[1]):
            G[..., c][:, idx] = turn * basis[:, kk, None, None]
            c += 1
        w = np.einsum("fij,fj->fi", R[chain.parent[j]], _turn_rate(chain, terms, s, j, _turn_beta(n_mc + r)))
        G[..., c][:, idx] = np.cross(w[:, None], dx)
        c += 1
    for (cols, fld) in terms.world:
        G[..., c][:, cols] = fld
        c += 1
    return J, G


def _apply(chain: Skeleton, terms: Terms, s: State, R, dq: np.ndarray, dc: np.ndarray) -> State:
    """The state moved by per-frame steps dq (F, k) and constant steps dc (P,)."""
    n = s.copy()
    n.root_R = _exp(dq[:, :3]) @ s.root_R
    n.root_t = s.root_t + dq[:, 3:6]
    col = 6
    M = chain.n_markers
    n.local = s.local + dc[:3 * M].reshape(M, 3)
    c = 3 * M
    for j in chain.joints:
        P = chain.parent[j]
        if chain.types[j] == "spherical":
            wp = np.einsum("fji,fj->fi", R[P], dq[:, col:col + 3])
            n.rel_R[j] = _exp(wp) @ s.rel_R[j]
            col += 3
        else:
            n.theta[j] = s.theta[j] + dq[:, col]
            col += 1
        n.c_parent[j] = s.c_parent[j] + dc[c:c + 3]
        n.c_child[j] = s.c_child[j] + dc[c + 3:c + 6]
        c += 6
        if chain.types[j] == "revolute":
            n.rest[j] = _exp(dc[c:c + 3])[0] @ s.rest[j]
            b1, b2 = tangents(s.axis[j])
            a = s.axis[j] + dc[c + 3] * b1 + dc[c + 4] * b2
            n.axis[j] = a / np.linalg.norm(a)
            c += 5
    for i, p in enumerate(s.term_params):
        size = p.size
        n.term_params[i] = p + dc[c:c + size].reshape(p.shape)
        c += size
    return n


def _cost(pred, data, w) -> float:
    r = np.where(w[..., None] > 0, pred - data, 0.0)
    return float(np.sum(w[..., None] * r * r))


# ---------------------------------------------------------------------- fitting
def _prepare(data: np.ndarray, weights: np.ndarray | None):
    data = np.asarray(data, dtype=float)
    seen = np.all(np.isfinite(data), axis=2)
    w = seen.astype(float) if weights is None else np.where(seen, np.asarray(weights, dtype=float), 0.0)
    return np.where(seen[..., None], data, 0.0), w


def _extend(chain: Skeleton, terms: Terms, s: State, R, dq, dc, y, w, pen, taken):
    """The accepted step (dq, dc) from `s` doubled while that lowers the cost (at most 2¹³ times the step).

    Gauss-Newton crawls along a curved valley: where a segment is posed by two markers and the joint
    below it, the neglected second-order term is as large as the valley's information, and successive
    steps point the same way, each a fraction of the way. Measured on a held-out 2+2 gait trial: 600
    iterations left the fit unconverged and its hip 7 mm off; doubling along the step converged it in
    176. Only a lower cost is taken, so the iteration stays a descent. `taken` is the accepted
    (state, R, t, centre, pred, cost); the best of it and its extensions is returned."""
    best, alpha = taken, 1.0
    while alpha < 2.0 ** 13:
        far = _apply(chain, terms, s, R, 2 * alpha * dq, 2 * alpha * dc)
        R2, t2, c2, p2 = forward(chain, terms, far)
        cost = _cost(p2, y, w) + pen(far)
        if not cost < best[-1]:
            break
        best, alpha = (far, R2, t2, c2, p2, cost), 2 * alpha
    return best


def fit_chain(chain: Skeleton, data, state: State, terms: Terms | None = None, weights=None,
              max_iter: int = MAX_ITER, tol: float = REL_TOL, penalty=None) -> Fit:
    """Levenberg-Marquardt over every per-frame unknown and every constant, from `state`.

    Parameters
    ----------
    chain : Skeleton
    data : array (F, M, 3)
        Measured markers in the chain's column order, mm, NaN where occluded.
    state : State
        Starting point (:func:`initial_state`, or an earlier fit's state).
    terms : Terms, optional
        Effect terms; ``state.term_params`` must hold one (K, 3) array per term (zeros to start).
    weights : array (F, M), optional
        Per-sample weights (0 drops a sample: gaps, gross errors).
    penalty : callable, optional
        ``penalty(state) -> (r (c,), D (c, P))``: extra residuals on the constants alone with their
        Jacobian, added to the cost (a constraint held by a stiff spring: the profile likelihood). The
        returned fit's ``rss`` is the data's alone.
    """
    terms = terms or Terms()
    y, w = _prepare(data, weights)
    s = state.copy()
    shapes = terms.shapes()
    if [p.shape for p in s.term_params] != shapes:    # new terms start at zero, kept ones keep their values
        old = s.term_params
        s.term_params = [old[i] if i < len(old) and old[i].shape == sh else np.zeros(sh)
                         for i, sh in enumerate(shapes)]
    pen = (lambda st: float(np.sum(penalty(st)[0] ** 2))) if penalty else (lambda st: 0.0)
    R, t, centre, pred = forward(chain, terms, s)
    cost = _cost(pred, y, w) + pen(s)
    lam, it, converged = 1e-3, 0, False
    frame_has = w.sum(axis=1) > 0
    for it in range(1, max_iter + 1):
        A, B, C, g, h = _normal(chain, terms, s, R, t, centre, pred, y, w)
        if penalty:
            r_p, D = penalty(s)
            C, h = C + D.T @ D, h + D.T @ r_p
        k = A.shape[1]
        scaleA = np.trace(A, axis1=1, axis2=2)[:, None] / k + 1e-12
        improved = False
        for _ in range(12):
            Ad = A + lam * (A * np.eye(k)) + 1e-9 * scaleA[..., None] * np.eye(k)
            sol = np.linalg.inv(Ad) @ np.concatenate([B, g[..., None]], axis=2)  # batched k×k: inv + matmul
                                                                                   # beats solve 3x here
            Ainv_B, Ainv_g = sol[..., :-1], sol[..., -1]
            Cd = C + lam * np.diag(np.diag(C)) + 1e-9 * (np.trace(C) / max(len(C), 1)) * np.eye(len(C))
            B2 = B.reshape(-1, B.shape[-1])
            S = Cd - B2.T @ Ainv_B.reshape(B2.shape)
            rhs = -h + B2.T @ Ainv_g.reshape(-1)
            dc = np.linalg.lstsq(S, rhs, rcond=None)[0]
            dq = -(Ainv_g + Ainv_B @ dc)
            dq[~frame_has] = 0.0
            trial = _apply(chain, terms, s, R, dq, dc)
            R2, t2, c2, p2 = forward(chain, terms, trial)
            new = _cost(p2, y, w) + pen(trial)
            if new <= cost:
                improved = True
                done = cost - new <= tol * max(cost, 1e-300)
                if not done:
                    trial, R2, t2, c2, p2, new = _extend(chain, terms, s, R, dq, dc, y, w, pen,
                                                         (trial, R2, t2, c2, p2, new))
                s, R, t, centre, pred, cost = trial, R2, t2, c2, p2, new
                lam = max(lam / 10, 1e-12)
                break
            lam *= 4
        if not improved or done:
            converged = True
            break
    n_samples = int((w > 0).sum())
    n_params = int(frame_has.sum()) * chain.frame_dof() + _n_const(chain, terms) - chain.gauge()
    rss = _cost(pred, y, w) if penalty else cost
    return Fit(chain, terms, s, pred, rss, n_samples, n_params, it, converged, R, t)


def normal_products(J: np.ndarray, G: np.ndarray, r: np.ndarray, w: np.ndarray, per_frame: bool = False):
    """Weighted Gauss-Newton products from the Jacobians J (F,M,3,k), G (F,M,3,P) and residuals r (F,M,3):
    A = JᵀJ per frame (F,k,k), B = JᵀG per frame (F,k,P), C = Σ_f G_fᵀG_f (P,P), g = Jᵀr per frame (F,k),
    and h = Σ_f G_fᵀr_f (P,), or per frame (F,P) when `per_frame` (the scores' first term).

    Dense on purpose: taken segment by segment over each one's own constant columns (a marker touches 12-26
    of walking2's 82) the products measured 10 % slower at these sizes, the gathers costing more than the
    skipped zeros; building G (:func:`_jacobians`) costs several times the products either way."""
    F, k, P = J.shape[0], J.shape[-1], G.shape[-1]
    if np.all(w == 1.0):                 # every sample seen at unit weight (most trials): no weighted copies
        Jw, Gw, rw = J.reshape(F, -1, k), G.reshape(F, -1, P), r.reshape(F, -1)
    else:
        sw = np.sqrt(w)[..., None]
        Jw = (J * sw[..., None]).reshape(F, -1, k)
        Gw = (G * sw[..., None]).reshape(F, -1, P)
        rw = (r * sw).reshape(F, -1)
    Jt = Jw.transpose(0, 2, 1)
    G2 = Gw.reshape(-1, P)
    h = np.einsum("fmp,fm->fp", Gw, rw) if per_frame else G2.T @ rw.reshape(-1)
    return Jt @ Jw, Jt @ Gw, G2.T @ G2, (Jt @ rw[..., None])[..., 0], h


def _normal(chain, terms, s, R, t, centre, pred, y, w):
    """Gauss-Newton normal-equation blocks: per-frame A (F,k,k), coupling B (F,k,P), constants C (P,P),
    gradients g (F,k) and h (P,)."""
    J, G = _jacobians(chain, terms, s, R, t, centre, pred)
    return normal_products(J, G, np.where(w[..., None] > 0, pred - y, 0.0), w)


def information(fit: "Fit", data, weights=None) -> np.ndarray:
    """The constants' information matrix with the per-frame unknowns profiled out (Schur complement
    of the Gauss-Newton normal matrix at the solution), (P, P); σ² times its pseudo-inverse is the
    constants' covariance, and its null space beyond the gauge is what the data leave undetermined."""
    y, w = _prepare(data, weights)
    s = fit.state
    R, t, centre, pred = forward(fit.chain, fit.terms, s)
    A, B, C, _, _ = _normal(fit.chain, fit.terms, s, R, t, centre, pred, y, w)
    k = A.shape[1]
    scale = np.trace(A, axis1=1, axis2=2)[:, None, None] / k
    ridge = 1e-12 * np.maximum(scale, np.median(scale) + 1e-300)      # frames without markers stay finite
    Ainv_B = np.linalg.solve(A + ridge * np.eye(k), B)
    B2 = B.reshape(-1, B.shape[-1])
    S = C - B2.T @ Ainv_B.reshape(B2.shape)
    return 0.5 * (S + S.T)


def _n_const(chain: Skeleton, terms: Terms) -> int:
    return 3 * chain.n_markers + sum(6 + (5 if chain.types[j] == "revolute" else 0) for j in chain.joints) \
        + terms.size()


# ---------------------------------------------------------------------- starting point
def fill_gaps(valid: np.ndarray, arr: np.ndarray) -> np.ndarray:
    """Copy each invalid frame's value from the nearest valid frame (pose continuity)."""
    idx = np.flatnonzero(valid)
    near = idx[np.clip(np.searchsorted(idx, np.arange(len(valid))), 0, len(idx) - 1)]
    prev = idx[np.clip(np.searchsorted(idx, np.arange(len(valid))) - 1, 0, len(idx) - 1)]
    pick = np.where(np.abs(prev - np.arange(len(valid))) < np.abs(near - np.arange(len(valid))), prev, near)
    return arr[pick]


def segment_frames(chain: Skeleton, data) -> dict:
    """Rigid poses of every segment (three or more markers each), gaps filled from the nearest frame."""
    out, problems = {}, []
    for seg in chain.segments:
        idx = chain.seg_markers[seg]
        if len(idx) < 3:
            problems.append(f"segment {seg!r} has {len(idx)} marker(s): diagnose needs three or more on every "
                            "segment to check it is rigid")
            continue
        pts = data[:, idx]
        try:
            local, poses = refine_local(pts)
        except ValueError as exc:
            problems.append(f"segment {seg!r}: {exc}")
            continue
        if poses.valid.sum() < 3:
            problems.append(f"segment {seg!r}: fewer than 3 frames show three of its markers")
            continue
        out[seg] = Poses(R=fill_gaps(poses.valid, poses.R), t=fill_gaps(poses.valid, poses.t),
                         valid=poses.valid, local=local, rms=poses.rms)
    if problems:
        raise InputError(problems)
    return out


def _rest_and_theta(rel: np.ndarray, a_p: np.ndarray, a_c: np.ndarray):
    """A rest rotation with rest @ a_c = a_p and the hinge angles that best give `rel` (F, 3, 3)."""
    ref = rel[len(rel) // 2]
    v = ref @ a_c
    fix = Rotation.align_vectors([a_p], [v])[0].as_matrix()
    rest = fix @ ref
    u = tangents(a_p)[0]
    moved = np.einsum("fij,j->fi", rel @ rest.T, u)
    theta = np.arctan2(np.cross(u, moved) @ a_p, moved @ u)
    return rest, theta


def initial_state(chain: Skeleton, data, frames: dict | None = None) -> State:
    """Starting point: SVD poses of every segment, O'Brien joint centres, declared hinges' axes."""
    data = np.asarray(data, dtype=float)
    frames = frames or segment_frames(chain, data)
    local = np.zeros((chain.n_markers, 3))
    for seg in chain.segments:
        local[chain.seg_markers[seg]] = frames[seg].local
    root = frames[chain.root]
    s = State(local, {}, {}, {}, {}, root.R.copy(), root.t.copy(), {}, {})
    for j in chain.joints:
        P, C = frames[chain.parent[j]], frames[chain.child[j]]
        rev = chain.types[j] == "revolute"
        fit = joint_location(P, C, names=(chain.parent[j], chain.child[j]), hinge=rev)
        s.c_parent[j], s.c_child[j] = fit.centre_parent.copy(), fit.centre_child.copy()
        rel = np.einsum("fji,fjk->fik", P.R, C.R)
        if rev:
            if fit.axis_parent is None:
                raise InputError([f"joint {j!r}: {chain.child[j]!r} does not move relative to {chain.parent[j]!r} "
                                  f"({fit.reason}); a static trial leaves the hinge undefined, so there is no model "
                                  "to compare with. Record the joint's functional movement."])
            s.axis[j] = fit.axis_parent / np.linalg.norm(fit.axis_parent)
            s.rest[j], s.theta[j] = _rest_and_theta(rel, s.axis[j], fit.axis_child / np.linalg.norm(fit.axis_child))
        else:
            s.rel_R[j] = rel
    return s


def convert_joint(chain: Skeleton, state: State, joint: str, to: str) -> tuple[Skeleton, State]:
    """The same fitted chain with `joint` re-declared as type `to` (hinge → ball keeps its motion)."""
    types = dict(chain.types)
    types[joint] = to
    new = replace(chain, types=types)
    s = state.copy()
    if to == "spherical" and chain.types[joint] == "revolute":
        s.rel_R[joint] = _rot(s.axis[joint], s.theta[joint]) @ s.rest[joint]
        del s.axis[joint], s.rest[joint], s.theta[joint]
    elif to != chain.types[joint]:
        raise ValueError(f"cannot convert {chain.types[joint]} joint {joint!r} to {to}")
    return new, s
