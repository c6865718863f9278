"""The whole rigid-joint model fitted to a trial at once: the simulation that ``diagnose`` compares
with the measured markers, and the maximum-likelihood fit ``fit`` reports.

The model (:mod:`identcheck.bundle.model`) predicts every marker by forward kinematics; the sum of squared
3-D marker errors is minimised over every per-frame unknown and every constant together by
Levenberg-Marquardt, with the per-frame unknowns eliminated by the Schur complement (bundle adjustment) and
the normal equations built block by block (:mod:`identcheck.bundle.normal`), so a 1500-frame trial costs a
few small dense solves.
"""
from __future__ import annotations

import time

from dataclasses import replace

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial.transform import Rotation

from identcheck.bundle.jacobian import jacobian_blocks
from identcheck.bundle.model import Fit, State, Terms, apply_step, forward, n_const, null_count, tangents
from identcheck.bundle.normal import eliminate_frames, frames_eliminated, normal_equations
from identcheck.errors import DegenerateError, InputError
from identcheck.estimate.obrien import joint_location
from identcheck.geometry.poses import Poses, refine_local
from identcheck.geometry.rotations import hinge_matrix, skew
from identcheck.skeleton import Skeleton

MAX_ITER = 60
REL_TOL = 1e-8        # stop when the cost falls by less than this fraction
FAST_RATE = 0.1
"""Where each accepted step lowers the cost by at most this fraction of the step before (the iteration converges
geometrically, at rate ρ ≤ FAST_RATE), the decrease still to come is at most ``drop·ρ/(1 − ρ)``: the fit stops
when that is below ``REL_TOL`` of the cost, one normal-equation build before the step that would only confirm it
(on the bundled leg: 4 iterations instead of 5, the cost within 1e-10 of its minimum), and it does not try to
extend such a step (:func:`_extend` is for the crawl, where successive steps barely shrink). Only a step taken at
the damping the iteration started with counts: one accepted after the damping was raised is short by choice."""
CONSTANT_RIDGE = 0.0
"""Ridge on the constants' reduced normal matrix, relative to its mean diagonal: none. The reduced system is solved
by least squares, whose cutoff already leaves the gauge's exact null directions alone. At 1e-9 it held back every
step along a weakly determined direction, and a minimal leg's fit crawled: 200-340 Gauss-Newton iterations a start,
each accepted undamped, against 62-75 without it, to a cost as low or lower (held-out minimal trials: 52 -> 30 and
47 -> 14 CPU s, the same verdicts). At 1e-12 it lifted the gauge directions above that cutoff, and roundoff in the
gradient moved the fit along them."""


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
        far = apply_step(chain, terms, s, R, 2 * alpha * dq, 2 * alpha * dc)
        R2, t2, c2, p2 = forward(chain, terms, far)
        cost = _cost(p2, y, w) + pen(far)
        if not cost < best[-1]:
            break
        best, alpha = (far, R2, t2, c2, p2, cost), 2 * alpha
    return best


def fit_chain(chain: Skeleton, data, state: State, terms: Terms | None = None, weights=None,
              max_iter: int = MAX_ITER, tol: float = REL_TOL, penalty=None, on_iteration=None,
              deadline: float | None = None, fast_tol: float | None = None) -> Fit:
    """Levenberg-Marquardt over every per-frame unknown and every constant, from `state`.

    Parameters
    ----------
    chain : Skeleton
    data : array (F, M, 3)
        Measured markers in the chain's column order, mm, NaN where occluded.
    state : State
        Starting point (:func:`initial_state`, or an earlier fit's state).
    terms : Terms, optional
        Effect terms; ``state.term_params`` holds one array per term, shaped as ``terms.shapes()`` (new terms start
        at zero).
    weights : array (F, M), optional
        Per-sample weights (0 drops a sample: gaps, gross errors).
    penalty : callable, optional
        ``penalty(state) -> (r (c,), D (c, P))``: extra residuals on the constants alone with their
        Jacobian, added to the cost (a constraint held by a stiff spring: the profile likelihood). The
        returned fit's ``rss`` is the data's alone.
    on_iteration : callable, optional
        Called as ``on_iteration(iteration, cost)`` after each iteration: a long fit's progress.
    deadline : float, optional
        A ``time.monotonic()`` value after which no new iteration starts (the fit is returned not converged).
    tol, fast_tol : float
        Stop when an iteration lowers the cost by at most ``tol`` times the cost, or when the drops shrink
        fast (each at most :data:`FAST_RATE` of the one before) and what they promise to remove is at most
        ``fast_tol`` (default ``tol``) times the cost; either only where :func:`small_drop_ends` allows (the step's
        model held, or promised nothing). An iteration no damping up to :data:`STALL_DAMPING` lowers the cost in ends
        the fit, converged only when its least damped step promised at most the larger of the two tolerances
        (:func:`stalled_at_minimum`).
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
    lam, it, converged, last_drop = LAM_START, 0, False, None
    frame_has = w.sum(axis=1) > 0
    for it in range(1, max_iter + 1):
        # the last iteration's blocks are let go before the next are built (B alone: 93 MB for 42 markers)
        A = B = Ad = back = None
        A, B, C, g, h = _normal(chain, terms, s, R, centre, pred, y, w)
        if penalty:
            r_p, D = penalty(s)
            C, h = C + D.T @ D, h + D.T @ r_p
        k = A.shape[1]
        scaleA = np.trace(A, axis1=1, axis2=2)[:, None] / k + 1e-12
        improved, promise, attempt = False, np.inf, 0
        rate_tol = tol if fast_tol is None else fast_tol
        stop_tol = max(tol, rate_tol)
        while attempt < MIN_ATTEMPTS or (lam <= STALL_DAMPING and not stalled_at_minimum(promise, cost, stop_tol)):
            damp_q = lam * np.diagonal(A, axis1=1, axis2=2) + 1e-9 * scaleA                  # (F, k)
            damp_c = lam * np.diag(C) + CONSTANT_RIDGE * (np.trace(C) / max(len(C), 1))      # (P,)
            Ad = A + damp_q[..., None] * np.eye(k)
            S, reduced, back = eliminate_frames(Ad, B, C + np.diag(damp_c), g, h)
            dc = _solve_constants(S, -reduced)
            dq = -back(dc)
            dq[~frame_has] = 0.0
            trial = apply_step(chain, terms, s, R, dq, dc)
            R2, t2, c2, p2 = forward(chain, terms, trial)
            new = _cost(p2, y, w) + pen(trial)
            if attempt == 0:
                promise = promised_drop(g, h, dq, dc, damp_q, damp_c)
            if new <= cost:
                improved = True
                drop = cost - new
                promised = promised_drop(g, h, dq, dc, damp_q, damp_c)
                lam = max(lam * damping_factor(drop, promised), LAM_MIN)
                rate = drop / last_drop if last_drop else 1.0
                fast = rate <= FAST_RATE and attempt == 0     # a drop made small by raised damping says nothing
                # a small drop ends the fit only where the least damped step's model held or promised no more
                done = small_drop_ends(drop, promised, promise, cost, stop_tol, attempt == 0) and (
                    drop <= tol * max(cost, 1e-300)
                    or (fast and drop * rate / (1 - rate) <= rate_tol * max(new, 1e-300)))
                if not done and not fast:
                    trial, R2, t2, c2, p2, new = _extend(chain, terms, s, R, dq, dc, y, w, pen,
                                                         (trial, R2, t2, c2, p2, new))
                last_drop = cost - new
                s, R, t, centre, pred, cost = trial, R2, t2, c2, p2, new
                break
            lam *= 4
            attempt += 1
        if on_iteration:
            on_iteration(it, cost)
        if not improved:
            # no damping found a lower cost: a minimum when the least damped step promised no more than the
            # tolerance, else a stall (a valley Gauss-Newton's model does not hold in), which is not convergence
            converged = stalled_at_minimum(promise, cost, stop_tol)
            break
        if done:
            converged = True
            break
        if deadline is not None and time.monotonic() > deadline:
            break
    n_samples = int((w > 0).sum())
    n_params = (int(frame_has.sum()) * (chain.frame_dof() - chain.frame_free()) + n_const(chain, terms)
                - null_count(chain, terms))
    rss = _cost(pred, y, w) if penalty else cost
    return Fit(chain, terms, s, pred, rss, n_samples, n_params, it, converged, R, t)


LAM_START, LAM_MIN = 1e-3, 1e-12     # the damping a fit starts with, and the least it is ever lowered to
MIN_ATTEMPTS = 12
STALL_DAMPING = 1e3
"""An iteration raises its damping fourfold per rejected step, at least :data:`MIN_ATTEMPTS` times and on until it
exceeds :data:`STALL_DAMPING` (steps a thousandth of Gauss-Newton's along each scaled coordinate); a fit no damping
up to there lowers is stalled. Why not only twelve attempts: after a run of good steps the damping can sit near
:data:`LAM_MIN`, twelve quadruplings then end near 2e-5, and the fit stopped there as stalled. A real walking trial's
sparse leg (151 frames) stopped so at 3733 mm², 12 iterations in, where the same fit with its damping reset went on to
2230 mm² in 24 more: ``diagnose`` had judged its gap, and named an effect, from the stalled fit."""
GOOD_STEP, POOR_STEP = 0.75, 0.25


def promised_drop(g, h, dq, dc, damp_q, damp_c) -> float:
    """What the Gauss-Newton model promises a damped step (dq, dc) lowers the cost by: ``−gᵀδ + δᵀDδ`` with the
    gradients (g per frame, h of the constants) as the normal equations give them (half the cost's gradient) and D the
    damping added to the diagonal (``(N + D)δ = −[g; h]`` makes ``−2gᵀδ − δᵀNδ`` equal to it)."""
    return float(-(np.sum(g * dq) + h @ dc) + np.sum(damp_q * dq * dq) + damp_c @ (dc * dc))


def small_drop_ends(drop: float, promised: float, least_damped: float, cost: float, tol: float,
                    first: bool) -> bool:
    """Whether a small drop of the cost may end the fit: where the accepted step was the iteration's first, least
    damped one (`first`) and lowered the cost by more than :data:`POOR_STEP` of what its Gauss-Newton model promised
    (`promised`, :func:`promised_drop`), or where the least damped step's model promised at most `tol` times the
    cost (`least_damped`: what is left is then below what the fit was asked to resolve, as in
    :func:`stalled_at_minimum`).

    A step that delivers a sliver of a larger promise has met the valley's curvature, not its floor: a real walking
    trial's sparse leg, 4 iterations in, lowered the cost by 0.49 mm² of a promised 123 after a drop of 203; read as
    fast convergence, the fit stopped at 4489 mm² and was called converged, where going on reached 2526 mm². A step
    accepted only after the damping was raised says nothing either, whatever share of its own (damped, so small)
    promise it kept: on the same leg one such step, 2.3e-7 mm² of a damped promise of 2.4e-3 where the least damped
    step had promised 6.9e-3, had ended another start 0.008 χ² above its minimum."""
    return (first and drop > POOR_STEP * promised) or stalled_at_minimum(least_damped, cost, tol)


def stalled_at_minimum(promise: float, cost: float, tol: float) -> bool:
    """Whether an iteration in which no damping lowered the cost ends at a minimum: when the least damped step
    promised to lower the cost (:func:`promised_drop`) by at most `tol` times it, what is left is below what the fit
    was asked to resolve (a step that large is lost in the rounding of the cost); a larger promise the steps could
    not deliver is a stall, and a stalled fit is not a converged one (a refit of the profile likelihood stopped
    there would overstate Δχ² and close its interval too soon)."""
    return promise <= tol * max(cost, 1e-300)


def damping_factor(drop: float, promised: float) -> float:
    """What an accepted step's damping is multiplied by for the next, by how much of the promised drop it delivered
    (ρ, Fletcher's rule): a tenth when ρ > :data:`GOOD_STEP` (the model holds: step further), twice when ρ <
    :data:`POOR_STEP` (it barely holds), unchanged between.

    Why not a tenth after every accepted step: on a gait trial with skin terms (walking2's diagnosis) the steps
    delivered 30-60 % of their promise at a damping near 2e-4, a tenth of it overshot, and half of all attempts were
    rejected, each costing a whole elimination of the frames. Nielsen's smooth rule (``max(1/3, 1 − (2ρ − 1)³)``)
    ended those rejections too but slowed fits whose steps deliver 80-90 %, which it barely undamps (a minimal
    leg's `fit`: 15 % more time)."""
    rho = drop / promised if promised > 0 else 1.0
    return 0.1 if rho > GOOD_STEP else 2.0 if rho < POOR_STEP else 1.0


def _solve_constants(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The constants' step from the damped Schur complement `S` (P, P): by its Cholesky factor, and by least squares
    only when it has none (a direction no sample and no damping holds).

    The damping makes S positive definite whenever every constant touches a sample, so the factor almost always
    exists; least squares (an SVD) costs 2.4-6 times as much at P = 200-660, and took 34 of ``diagnose``'s 261 s
    (under the profiler) on a gait trial with skin terms (P = 450-775)."""
    try:
        return cho_solve(cho_factor(S, lower=True, check_finite=False), rhs, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(S, rhs, rcond=None)[0]


def _normal(chain, terms, s, R, centre, pred, y, w):
    """Gauss-Newton normal-equation blocks: per-frame A (F,k,k), coupling B (F,k,P), constants C (P,P),
    gradients g (F,k) and h (P,)."""
    lay, blocks = jacobian_blocks(chain, terms, s, R, centre, pred, lazy=True)     # formed one at a time, once
    return normal_equations(lay, blocks, np.where(w[..., None] > 0, pred - y, 0.0), w)


def information(fit: "Fit", data, weights=None) -> np.ndarray:
    """The constants' information matrix with the per-frame unknowns profiled out (Schur complement
    of the Gauss-Newton normal matrix at the solution), (P, P); σ² times its pseudo-inverse is the
    constants' covariance, and its null space beyond the gauge is what the data leave undetermined."""
    return information_at(fit.chain, fit.terms, fit.state, _prepare(data, weights)[1])


def information_at(chain, terms, state, w: np.ndarray) -> np.ndarray:
    """:func:`information` at any `state` with sample weights w (F, M): it depends on where the model is, not on
    the residual."""
    R, _t, centre, pred = forward(chain, terms, state)
    lay, blocks = jacobian_blocks(chain, terms, state, R, centre, pred)
    return frames_eliminated(lay, blocks, w)[0]



# ---------------------------------------------------------------------- starting point
def fill_gaps(valid: np.ndarray, arr: np.ndarray) -> np.ndarray:
    """Copy each invalid frame's value from the nearest valid frame (pose continuity)."""
    idx = np.flatnonzero(valid)
    near = idx[np.clip(np.searchsorted(idx, np.arange(len(valid))), 0, len(idx) - 1)]
    prev = idx[np.clip(np.searchsorted(idx, np.arange(len(valid))) - 1, 0, len(idx) - 1)]
    pick = np.where(np.abs(prev - np.arange(len(valid))) < np.abs(near - np.arange(len(valid))), prev, near)
    return arr[pick]


def filled_poses(pts: np.ndarray, local: np.ndarray, poses: Poses, n_markers: int | None = None) -> Poses:
    """`poses` of the points `pts` (F, m, 3; body-fixed `local` (m, 3)) with every frame they leave unposed filled:
    the nearest posed frame's pose (:func:`fill_gaps`), then moved onto the points seen in that frame: turned so
    that the line through the two of them farthest apart on the segment has its measured direction (the smallest
    such turn, about their midpoint), and shifted so that their centroid lands on theirs. ``local`` of the result
    keeps the first `n_markers` rows (default all).

    Why: a segment seen by one or two markers for a while (a gap at the end of a walking trial) had been held at the
    last posed frame while the subject walked on, and its seen markers started the whole-tree fit up to 1.7 m from
    their predictions (both legs of the real walking2 trial: the first fit took 54 iterations, 13 from this start)."""
    R, t = fill_gaps(poses.valid, poses.R).copy(), fill_gaps(poses.valid, poses.t).copy()
    seen = np.all(np.isfinite(pts), axis=2) & ~poses.valid[:, None]
    for f in np.flatnonzero(seen.any(axis=1)):
        cols = np.flatnonzero(seen[f])
        x, lo = pts[f, cols], local[cols]
        if len(cols) >= 2:
            d = np.linalg.norm(lo[:, None] - lo[None], axis=2)
            a, b = np.unravel_index(int(np.argmax(d)), d.shape)
            u, v = R[f] @ (lo[b] - lo[a]), x[b] - x[a]
            if np.linalg.norm(u) > 0 and np.linalg.norm(v) > 0:
                R[f] = _turn_onto(u / np.linalg.norm(u), v / np.linalg.norm(v)) @ R[f]
        t[f] = x.mean(axis=0) - R[f] @ lo.mean(axis=0)
    keep = len(local) if n_markers is None else n_markers
    return Poses(R=R, t=t, valid=poses.valid, local=local[:keep], rms=poses.rms)


def _turn_onto(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the unit vector `u` to the unit vector `v` (the identity when they are opposite:
    no turn is the smallest then, and a start need not be exact)."""
    w, c = np.cross(u, v), float(u @ v)
    if c <= -1.0 + 1e-9:
        return np.eye(3)
    K = skew(w)
    return np.eye(3) + K + K @ K / (1.0 + c)


def segment_frames(chain: Skeleton, data, only=None) -> dict:
    """Rigid poses of every segment (three or more markers each; of the segments `only`, when given), gaps filled
    from the nearest frame."""
    out, problems = {}, []
    for seg in (chain.segments if only is None else only):
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
        out[seg] = filled_poses(pts, local, poses)
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


FAR_CENTRE_MM = 500.0
"""A joint centre started farther than this from both of its segments' markers is no start: the whole-chain fit
creeps from it for hundreds of iterations (a clean held-out overground gait trial: O'Brien's hip and knee 850 mm
from the pelvis markers, rigid fit stuck at 0.76 mm rms against 0.24 mm from a start between the segments)."""


def _between_if_far(s: State, joint: str, P: Poses, C: Poses, axis_parent) -> None:
    """Start `joint` half-way between its two segments' markers when O'Brien's least-squares centre (weakly
    determined when the joint turns little: gait's hip) lies more than :data:`FAR_CENTRE_MM` from both (a hinge:
    its axis line); a hinge keeps its axis direction and starts at the axis point nearest that midpoint."""
    def world(poses, local):
        return poses.to_world(local[None])[:, 0]

    centre = world(P, s.c_parent[joint])
    a_world = None if axis_parent is None else np.einsum("fij,j->fi", P.R, axis_parent / np.linalg.norm(axis_parent))
    near = []
    for X in (P, C):
        off = world(X, X.local.mean(axis=0)) - centre
        if a_world is not None:                        # a hinge's point may sit anywhere on its axis: the line counts
            off = off - np.einsum("fi,fi->f", off, a_world)[:, None] * a_world
        near.append(np.nanmedian(np.linalg.norm(off, axis=1)))
    if not min(near) > FAR_CENTRE_MM:
        return
    mid = (world(P, P.local.mean(axis=0)) + world(C, C.local.mean(axis=0))) / 2
    cp = P.body_fixed(mid, robust=True)
    if axis_parent is not None:                        # onto the hinge axis through O'Brien's point
        a = axis_parent / np.linalg.norm(axis_parent)
        cp = s.c_parent[joint] + a * float(a @ (cp - s.c_parent[joint]))
    mid = world(P, cp)
    s.c_parent[joint] = cp
    s.c_child[joint] = C.body_fixed(mid, robust=True)


def centred_frame(frame: Poses) -> Poses:
    """The same poses with the body frame's origin moved to the centroid of its body-fixed points.

    Why: the shape averaging puts a segment's body frame where the world was in its reference frame, so on an
    overground walk recentred about its mean the body-fixed coordinates lie metres from their origin (11 m on a
    held-out gait trial). The fit is the same whatever the origin, but a pose's rotation then swings the markers
    about a point metres away: a step's second-order error grows with that lever arm, Gauss-Newton crawls (on a
    clean 1941-frame gait trial the rigid fit was still 518 σ² above its minimum after 40 iterations, which it
    reached 196 iterations later), and the root's translation wanders with the rotation's gauge."""
    origin = frame.local.mean(axis=0)
    return replace(frame, local=frame.local - origin, t=frame.t + np.einsum("fij,j->fi", frame.R, origin))


def initial_state(chain: Skeleton, data, frames: dict | None = None) -> State:
    """Starting point: SVD poses of every segment (:func:`centred_frame`), O'Brien joint centres (half-way between
    the segments when O'Brien's is far from both: :func:`_between_if_far`), declared hinges' axes."""
    data = np.asarray(data, dtype=float)
    frames = {seg: centred_frame(f) for seg, f in (frames or segment_frames(chain, data)).items()}
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
        _between_if_far(s, j, P, C, fit.axis_parent if rev else None)
        rel = np.einsum("fji,fjk->fik", P.R, C.R)
        if rev:
            if fit.axis_parent is None:
                both = int(np.sum(P.valid & C.valid))
                seen = f" in the {both} of {len(P.valid)} frames that pose both" if both < len(P.valid) else ""
                raise DegenerateError(f"joint {j!r}: {chain.child[j]!r} does not move relative to "
                                      f"{chain.parent[j]!r}{seen} ({fit.reason}); a static trial leaves the hinge "
                                      "undefined, so there is no model to compare with. Record the joint's functional "
                                      "movement.", segment=chain.child[j])
            s.axis[j] = fit.axis_parent / np.linalg.norm(fit.axis_parent)
            s.rest[j], s.theta[j] = _rest_and_theta(rel, s.axis[j], fit.axis_child / np.linalg.norm(fit.axis_child))
        else:
            s.rel_R[j] = rel
    return _root_on_seen_markers(chain, data, s, frames[chain.root].valid)


def _root_on_seen_markers(chain: Skeleton, data: np.ndarray, s: State, posed: np.ndarray) -> State:
    """`s` with the root moved, in each frame its own markers leave unposed, by the mean distance from the
    markers seen there (on other segments) to their predictions: the root's pose is the nearest posed frame's
    there, and a subject who walked on since (the end of the real walking2 trial, its pelvis unseen and a thigh
    marker seen) had started the fit 1.7 m off. Translation alone: the segments below keep the rotations their own
    markers gave them."""
    if posed.all():
        return s
    pred = forward(chain, Terms(), s)[3]
    seen = np.all(np.isfinite(data), axis=2)
    fix = ~posed & seen.any(axis=1)
    if fix.any():
        off = np.where(seen[fix][..., None], data[fix] - pred[fix], 0.0).sum(axis=1)
        s.root_t[fix] += off / seen[fix].sum(axis=1)[:, None]
    return s


def convert_joint(chain: Skeleton, state: State, joint: str, to: str) -> tuple[Skeleton, State]:
    """The same fitted chain with `joint` re-declared as type `to` (hinge → ball keeps its motion)."""
    types = dict(chain.types)
    types[joint] = to
    new = replace(chain, types=types)
    s = state.copy()
    if to == "spherical" and chain.types[joint] == "revolute":
        s.rel_R[joint] = hinge_matrix(s.axis[joint], s.theta[joint]) @ s.rest[joint]
        del s.axis[joint], s.rest[joint], s.theta[joint]
    elif to != chain.types[joint]:
        raise ValueError(f"cannot convert {chain.types[joint]} joint {joint!r} to {to}")
    return new, s
