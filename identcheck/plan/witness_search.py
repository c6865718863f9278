"""Whole-tree counterexamples: a second skeleton that puts every marker of a trial where it was measured
while one joint's gauge-invariant quantities differ — the evidence behind a plan's "not identifiable".

The exact rank of :mod:`identcheck.certify.tree_rank` says *that* a joint's quantities are undetermined;
a witness shows it on data. Given a trial (every marker in every frame) and the skeleton that
produced it, :func:`construct` searches the whole tree — every constant and every frame's pose
and angles — for another skeleton that reproduces the trial:

- ``"family"``: when the joint is not locally identifiable, the data leave a curve of skeletons
  through the true one. Gauss-Newton on [markers; one undetermined quantity] walks along it until
  that quantity has moved by ``change`` (a fraction of its value).
- ``"isolated"``: when the joint is locally identifiable with several candidates (revolute (2,1):
  ERRATA E1, E2), the others are isolated points. Gauss-Newton starts from each of the closed form's
  other joints, the rest of the tree re-posed around it, and keeps a solution whose quantities differ.

Either way the alternative is then *verified*, nothing taken from the search: at 50 digits its
markers are refined (the residual evaluated in mpmath, the correction from the float Jacobian's
pseudo-inverse) until every marker of every frame is reproduced to ``TOL_VERIFIED`` mm, and the
same constants must also reproduce frames the search never saw (held-out frames: only their poses
and angles are solved for), so the alternative explains the motion, not just the frames it was
built on (when its frames' poses cannot absorb every marker coordinate: ``held_out_informative``).
The joint constraints hold exactly for every parameter value (:mod:`identcheck.plan.tree_kinematics`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import mpmath
import numpy as np

from identcheck.plan import tree_kinematics as K
from identcheck.certify.tree_rank import TreeSpec

TOL_VERIFIED = 1e-30       # mm: every marker of every frame, construction and held-out, at 50 digits
TOL_FLOAT = 1e-8           # mm: the float search must get this close before the refinement takes over
MIN_CHANGE = 1e-3          # relative change of some quantity for the alternative to count as different
RCOND = 1e-10
AXIS_HANDLE_MM = 100.0     # the second point of a hinge taken as a virtual marker
FAMILY_FLOOR = 100.0       # a quantity near 0 (an axial offset) is moved by change × this (mm or mm²)
STALL = 6                  # Gauss-Newton gives up when the residual has not halved in this many steps


def _axis_sign(true: dict, alt: dict) -> float:
    """−1 when the alternative's axial offsets are closer to the truth's with the hinge direction flipped."""
    ax = [k for k in true if k.startswith("axial")]
    plus = sum((alt[k] - true[k]) ** 2 for k in ax)
    minus = sum((alt[k] + true[k]) ** 2 for k in ax)
    return -1.0 if ax and minus < plus else 1.0


def relative_changes(true: dict, alt: dict) -> dict:
    """label -> |alt − true| / max(|true|, 1). A hinge's direction has no sign, so its axial offsets are
    compared after the sign that brings them closest (flipping the axis flips them all)."""
    ax = [k for k in true if k.startswith("axial")]
    sign = _axis_sign(true, alt)
    return {k: abs((sign if k in ax else 1.0) * alt[k] - v) / max(abs(v), 1.0) for k, v in true.items()}


@dataclass
class Witness:
    """An alternative skeleton for a trial, with what its verification found."""

    joint: str
    method: str                     # "family" | "isolated"
    quantities_true: dict           # label -> value (float)
    quantities_alt: dict
    residual_mm: float              # max marker error over the construction frames, at 50 digits
    held_out_residual_mm: float     # max marker error over the held-out frames, at 50 digits
    n_frames: int
    n_held_out: int
    x: np.ndarray = field(repr=False, default=None)     # the alternative (mpf), constants then frames
    held_out_informative: bool = False   # could the held-out frames have failed? (False: their poses absorb
    #                                      every marker coordinate, so they test nothing)

    @property
    def change(self) -> tuple:
        """(label, relative change) of the quantity that moved most."""
        rel = relative_changes(self.quantities_true, self.quantities_alt)
        k = max(rel, key=rel.get)
        return k, rel[k]

    @property
    def verified(self) -> bool:
        return (self.residual_mm <= TOL_VERIFIED and self.held_out_residual_mm <= TOL_VERIFIED
                and self.change[1] >= MIN_CHANGE)

    def to_dict(self) -> dict:
        label, rel = self.change
        alt = self.quantities_alt[label]
        flipped = label.startswith("axial") and _axis_sign(self.quantities_true, self.quantities_alt) < 0
        return {"joint": self.joint, "method": self.method, "verified": bool(self.verified),
                "quantity": label, "true": self.quantities_true[label], "alternative": -alt if flipped else alt,
                "hinge_direction_flipped": bool(flipped), "held_out_informative": bool(self.held_out_informative),
                "relative_change": rel, "max_marker_error_mm": self.residual_mm,
                "held_out_max_marker_error_mm": self.held_out_residual_mm,
                "frames": self.n_frames, "held_out_frames": self.n_held_out,
                "precision_digits": K.DPS}


# -- float Gauss-Newton -----------------------------------------------------------------------------------
def jacobian(L: K.Layout, x: np.ndarray, F: int, frames_only: bool = False) -> np.ndarray:
    """d positions / d x by central differences, using that a frame's variables move only that frame:
    one evaluation per constant and one per frame variable (all frames at once)."""
    n_c, per = L.n_const, L.per_frame
    rows = F * len(L.markers) * 3
    J = np.zeros((rows, L.size(F)))

    def diff(dx):
        return (K.positions(L, x + dx, F) - K.positions(L, x - dx, F)).reshape(F, -1)

    if not frames_only:
        for k in range(n_c):
            h = 1e-6 * max(1.0, abs(x[k]))
            dx = np.zeros_like(x); dx[k] = h
            J[:, k] = diff(dx).ravel() / (2 * h)
    per_rows = len(L.markers) * 3
    for k in range(per):
        idx = n_c + np.arange(F) * per + k
        h = 1e-6 * np.maximum(1.0, np.abs(x[idx]))
        dx = np.zeros_like(x); dx[idx] = h
        d = diff(dx) / (2 * h[:, None])
        for i in range(F):
            J[i * per_rows:(i + 1) * per_rows, idx[i]] = d[i]
    return J[:, n_c:] if frames_only else J


def trial(L: K.Layout, x: np.ndarray, F: int) -> np.ndarray:
    """The markers of skeleton ``x`` at 50 digits, (F, M, 3) of mpf: a trial that the rigid model
    reproduces exactly (float data would not: rounding breaks rigidity at 1e-14 mm)."""
    with mpmath.workdps(K.DPS):
        return K.positions(L, K.to_mp(x), F)


def _residual(L, x, F, data):
    return (K.positions(L, x, F) - data).ravel()


def past(deadline: float | None) -> bool:
    """Whether ``time.monotonic()`` is beyond `deadline` (never, without one)."""
    return deadline is not None and time.monotonic() > deadline


def gauss_newton(L: K.Layout, x, F: int, data, extra=None, max_iter: int = 40, frames_only: bool = False,
                 deadline: float | None = None):
    """Minimum-norm Gauss-Newton to a zero residual, halving a step that would raise the residual;
    ``extra(x) -> (value, gradient)`` adds one equation, as one more least-squares row (met exactly when
    the system is consistent, as along a family of exact solutions); no iteration begins past `deadline`
    (``time.monotonic()``).
    Returns (x, max |marker error|)."""
    x = x.copy()
    data = np.asarray(data, dtype=float)
    cols = slice(L.n_const, None) if frames_only else slice(None)

    def cost(z):
        r = _residual(L, z, F, data)
        e = 0.0 if extra is None else extra(z)[0] / max(np.linalg.norm(extra(z)[1]), 1e-12)
        return float(r @ r + e * e), r

    c, r = cost(x)
    history = [np.abs(r).max(initial=0.0)]
    for _ in range(max_iter):
        if past(deadline):
            break
        J = jacobian(L, x, F, frames_only)
        rows, rhs = [J], [-r]
        if extra is not None:
            val, grad = extra(x)
            w = 1.0 / max(np.linalg.norm(grad), 1e-12)
            g = np.zeros(J.shape[1])
            g[:len(grad)] = grad                 # the quantities depend on the constants only
            rows.append(w * g[None])
            rhs.append([-w * val])
        dx = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=RCOND)[0]
        for _ in range(8):                       # backtrack: never accept a worse skeleton (a continuation
            trial_x = x.copy()                   # step along a family may need a worse one first)
            trial_x[cols] += dx
            c2, r2 = cost(trial_x)
            if c2 <= c or c2 < 1e-24 or extra is not None:
                break
            dx = dx / 2
        else:
            break                                # no descent along the step: a local minimum
        small = np.abs(dx).max() < 1e-12 * max(1.0, np.abs(x).max())
        x, c, r = trial_x, c2, r2
        history.append(np.abs(r).max(initial=0.0))
        if small or (len(history) > STALL and history[-1] > 0.5 * history[-1 - STALL] and history[-1] > TOL_FLOAT):
            break                                # converged, or stalled in a wrong basin
    return x, float(np.abs(r).max(initial=0.0))


# -- 50-digit refinement ---------------------------------------------------------------------------------
def refine(L: K.Layout, x: np.ndarray, F: int, data, frames_only: bool = False, iterations: int = 8,
           const_mp=None):
    """Refine ``x`` (float) at 50 digits: mpmath residual, float pseudo-inverse correction. Returns
    (x as mpf, max |marker error| in mm at 50 digits). ``frames_only``: the constants stay fixed, at
    ``const_mp`` (mpf) when given."""
    with mpmath.workdps(K.DPS):
        J = jacobian(L, x, F, frames_only)
        pinv = np.linalg.pinv(J, rcond=RCOND)
        xm = K.to_mp(x)
        if const_mp is not None:
            xm[:L.n_const] = const_mp
        for _ in range(iterations):
            r = (K.positions(L, xm, F) - data).ravel()
            if max((abs(v) for v in r), default=mpmath.mpf(0)) < mpmath.mpf(TOL_VERIFIED) * 1e-5:
                break
            dx = K.to_mp(pinv @ r.astype(float))
            if frames_only:
                xm[L.n_const:] -= dx
            else:
                xm -= dx
        r = (K.positions(L, xm, F) - data).ravel()
        return xm, float(max((abs(v) for v in r), default=mpmath.mpf(0)))


# -- the construction ------------------------------------------------------------------------------------
def _quantity_fn(L, label, joint):
    def f(x):
        return K.joint_quantities(L, x[:L.n_const], joint)[label]

    def with_grad(x, target):
        g = np.zeros(L.n_const)
        for k in range(L.n_const):
            h = 1e-6 * max(1.0, abs(x[k]))
            xp, xm = x.copy(), x.copy()
            xp[k] += h; xm[k] -= h
            g[k] = (f(xp) - f(xm)) / (2 * h)
        return f(x) - target, g
    return f, with_grad


def _along_family(L, x0, F, data, joint, label, change, stages=4, deadline=None):
    f, with_grad = _quantity_fn(L, label, joint)
    v0 = f(x0)
    x = x0
    for s in range(1, stages + 1):
        target = v0 + change * s / stages * max(abs(v0), FAMILY_FLOOR)
        x, err = gauss_newton(L, x, F, data, extra=lambda z: with_grad(z, target), max_iter=15, deadline=deadline)
    x, err = gauss_newton(L, x, F, data, max_iter=10, deadline=deadline)
    return x, err


def _differs(L, x, x0, joint) -> bool:
    qa, qt = K.joint_quantities(L, x[:L.n_const], joint), K.joint_quantities(L, x0[:L.n_const], joint)
    return any(v >= MIN_CHANGE for v in relative_changes(_floats(qt), _floats(qa)).values())


def _points(L: K.Layout, const, seg: str, names=None) -> list:
    """Known points of a segment in its own frame: the named ones (markers, ``J.centre``, ``J.axis[0|1]`` as
    the propagation names them), or by default its markers and the centres of its ball joints."""
    if names is None:
        names = list(L.spec.markers[seg]) + [f"{n}.centre" for n, k, p, c in L.spec.joints
                                             if k == "spherical" and seg in (p, c)]
    out = []
    for label in names:
        if f"m:{label}" in L.const:
            out.append(np.array(const[L.const["m:" + label]], dtype=float))
            continue
        joint, _, what = label.partition(".")
        _, kind, par, chi = next(j for j in L.spec.joints if j[0] == joint)
        centre = np.array(const[L.const[("c:" if seg == par else "e:") + joint]], dtype=float)
        if what == "axis[1]":
            a = np.array(const[L.const["a:" + joint]], dtype=float)
            a /= np.linalg.norm(a)
            if seg == chi:
                a = K.quat_matrix(np.array(const[L.const["rest:" + joint]], dtype=float)).T @ a
            centre = centre + AXIS_HANDLE_MM * a
        out.append(centre)
    return out


def _twin_starts(L: K.Layout, x0: np.ndarray, F: int, joint: str, case_points: dict | None = None) -> list:
    """Starting skeletons at the other joints of Pham's revolute (2,1) (ERRATA E1, E2), when one side of the
    hinge carries exactly two known points A1, A2 and the other at least one, B: the closed form's other
    solutions (d, r, α, l, ρ) in the frame of A1A2; the two-point segment rolled about A1A2 per frame (a roll
    its points cannot see), the other turned about the new hinge to put B back; the rest of the tree keeps
    its world poses (joints on the moved segments are re-expressed at frame 0). ``case_points``: joint ->
    (parent point names, child point names) the propagation settled it with (default: markers and ball
    centres)."""
    from identcheck.estimate import revolute21 as revolute21_fit
    from identcheck.geometry.frames import pair_frame

    name, kind, par, chi = next(j for j in L.spec.joints if j[0] == joint)
    if kind != "revolute":
        return []
    const, frames = L.split(x0, F)
    names = (case_points or {}).get(joint, (None, None))
    pts = {par: _points(L, const, par, names[0]), chi: _points(L, const, chi, names[1])}
    two = par if len(pts[par]) == 2 and pts[chi] else (chi if len(pts[chi]) == 2 and pts[par] else None)
    if two is None:
        return []
    one = chi if two == par else par
    Rw, tw = K.tree_poses(L, const, frames)
    a1, a2 = pts[two]
    cols, _ = pair_frame(a1[None, None], a2[None, None], a1[None, None] + np.eye(3)[None])
    E = cols[0]                                                 # columns: the A1A2 frame's axes, in `two`
    b_world = Rw[one] @ pts[one][0] + tw[one]
    local = (np.einsum("fji,fj->fi", Rw[two], b_world - tw[two]) - a1) @ E
    out = []
    for params, rms, _ in revolute21_fit.fit(local):
        if rms > 1e-6 * np.sqrt(np.mean(local ** 2)):
            continue
        d, r, alpha, _, _ = params
        roll = revolute21_fit.thetas(params, local)
        beta = revolute21_fit._nearest_beta(params, np.hypot(local[:, 0], local[:, 1]), local[:, 2])
        roll_two = E @ axis_rotation_z(roll) @ E.T                  # roll about A1A2, in `two`'s frame
        hinge_pt, hinge_dir = a1 + E @ np.array([r, 0.0, d]), E @ np.array([0.0, -np.sin(alpha), np.cos(alpha)])
        R2, t2 = dict(Rw), dict(tw)
        R2[two] = Rw[two] @ roll_two
        t2[two] = tw[two] + np.einsum("fij,fj->fi", Rw[two], a1 - roll_two @ a1)
        turn = K.axis_rotation(hinge_dir, beta)                      # `one` = `two` turned about the hinge
        R2[one] = R2[two] @ turn
        t2[one] = np.einsum("fij,fj->fi", R2[two], hinge_pt - turn @ hinge_pt) + t2[two]
        local_m, cp, cc, ax = K.constants(L, const)
        for seg in (two, one):                                       # re-express what they carry, at frame 0
            for m in L.spec.markers[seg]:
                local_m[m] = _reexpress(Rw, tw, R2, t2, seg, local_m[m])
            for k, _, pk, ck in L.spec.joints:
                if k != name and seg in (pk, ck):
                    store = cp if seg == pk else cc
                    store[k] = _reexpress(Rw, tw, R2, t2, seg, store[k])
        cp[name], cc[name], ax[name] = hinge_pt, hinge_pt, hinge_dir
        x = K.from_poses(L, R2, t2, local_m, cp, cc, ax)
        if _differs(L, x, x0, joint):                                # not the truth (or its mirror view)
            out.append(x)
    return out


def axis_rotation_z(angle: np.ndarray) -> np.ndarray:
    """Rotations about z by ``angle`` (F,): (F, 3, 3)."""
    return K.axis_rotation(np.array([0.0, 0.0, 1.0]), angle)


def _reexpress(Rw, tw, R2, t2, seg, v):
    """A point fixed in ``seg`` re-expressed in its new frame, at frame 0."""
    return np.linalg.solve(R2[seg][0], Rw[seg][0] @ v + tw[seg][0] - t2[seg][0])


RANDOM_SPREAD = 0.3
"""A random start moves every constant of the true skeleton by this fraction of the skeleton's size (the RMS of
its marker and centre offsets), in a random direction, the poses kept: a start far from the truth but still
inside the motion's range."""


def random_starts(L: K.Layout, x0: np.ndarray, n: int, seed: int = 0) -> list:
    """``n`` skeletons with every constant of ``x0`` moved at random by :data:`RANDOM_SPREAD` of its size
    (quaternions and hinge directions too, renormalised when used), each frame's poses and angles kept."""
    rng = np.random.default_rng(seed)
    const = x0[:L.n_const]
    size = float(np.sqrt(np.mean(const ** 2))) if L.n_const else 1.0
    out = []
    for _ in range(n):
        x = x0.copy()
        x[:L.n_const] += RANDOM_SPREAD * size * rng.standard_normal(L.n_const)
        out.append(x)
    return out


def construct(spec: TreeSpec, truth_x: np.ndarray, n_frames: int, joint: str, method: str,
              undetermined: list | None = None, held_out_truth: np.ndarray | None = None, n_held_out: int = 0,
              change: float = 0.05, via: tuple = (),
              case_points: dict | None = None, judged: tuple = (), n_random: int = 0, seed: int = 0,
              memo: dict | None = None, deadline: float | None = None) -> "Search":
    """Search for and verify an alternative skeleton with ``joint``'s quantities changed that reproduces
    the trial of the true skeleton ``truth_x`` (its vector over ``n_frames`` frames). The trial is the
    truth's markers evaluated at 50 digits (the truth's float parameters taken as exact), so truth and
    alternative are held to the same data. The truth's vector over ``n_held_out`` further frames,
    ``held_out_truth``, gives frames the alternative's constants must also reproduce. ``via``: for an
    ``"isolated"`` search, further joints whose other candidates may carry this one's (a joint that uses
    their virtual markers inherits them, or that share its unknown motion); ``n_random``: an ``"isolated"``
    search also starts from this many random skeletons (:func:`random_starts`, ``seed``), for a joint no table
    case settles; ``memo``: a dict shared by searches on the same trial, ``judged`` and ``case_points``, so each
    start is descended once; ``case_points``: the points the propagation settled each with;
    ``judged``: the points the whole-tree verdict judged each joint against (:class:`~identcheck.plan.
    tree_kinematics.Layout`), so an alternative counts as different only by the joint's own quantities.

    No start is descended, and no Gauss-Newton iteration begins, past `deadline` (``time.monotonic()``); the search
    then says so (``out_of_time``).

    Returns a :class:`Search`: the first verified witness, else the best unverified attempt (``verified``
    False), else none — which is not a proof that nothing exists."""
    L = K.Layout(spec, judged)
    F = n_frames
    data = trial(L, truth_x, F)
    held_out = trial(L, held_out_truth, n_held_out) if n_held_out else None
    best, misses, back, cut = None, [], 0, past(deadline)
    for cand, err in _candidates(L, truth_x, F, data, joint, method, undetermined, change, via, case_points,
                                 n_random, seed, memo, deadline):
        if past(deadline):           # (a run the deadline cut short is no finding)
            cut = True
            break
        if err is None:
            back += 1
            continue
        if err >= TOL_FLOAT:
            misses.append(err)
            continue
        w = _verify(L, cand, truth_x, F, data, joint, method, held_out, held_out_truth, n_held_out)
        if w.verified:
            return Search(w, back + len(misses) + 1, back, min(misses, default=None))
        if best is None or w.held_out_residual_mm < best.held_out_residual_mm:
            best = w
    cut = cut or past(deadline)      # (the starts may have stopped at it without a finding to break on)
    return Search(best, back + len(misses) + (best is not None), back, min(misses, default=None), cut)


@dataclass
class Search:
    """What :func:`construct` found: the witness (``None`` if no start converged; check ``verified``: one
    that converged but failed at 50 digits or on the held-out frames is kept), how many starts it tried,
    how many of them led back to the truth, and the smallest max marker error at which others stalled (mm)."""

    witness: Witness | None
    attempts: int
    back_to_truth: int
    closest_miss_mm: float | None
    out_of_time: bool = False


def _candidates(L, truth_x, F, data, joint, method, undetermined, change, via=(), case_points=None, n_random=0,
                seed=0, memo=None, deadline=None):
    """(skeleton, max marker error) after Gauss-Newton from each start, most promising first (a generator):
    an error below ``TOL_FLOAT`` is a candidate alternative, None a start that led back to the truth."""
    def done(cand, err):        # err None: it converged back to the truth
        return cand, (err if err >= TOL_FLOAT or _differs(L, cand, truth_x, joint) else None)

    if method == "family":
        for label in (undetermined or []):
            for ch in (change, -change, change / 5, -change / 5):
                if past(deadline):
                    return
                yield done(*_along_family(L, truth_x, F, data, joint, label, ch, deadline=deadline))
        return
    if method != "isolated":
        raise ValueError(f"unknown method {method!r}")
    def descend(key, make):         # Gauss-Newton from each start once, whichever joint's search asks first
        if memo is None or key not in memo:
            runs = []
            for start in make():
                if past(deadline):
                    return runs                          # cut short: not kept for the next search
                runs.append(gauss_newton(L, start, F, data, deadline=deadline))
            if past(deadline) or memo is None:
                return runs
            memo[key] = runs
        return memo[key]

    for j in (joint, *via):
        for cand, err in descend(("twins", j), lambda: _twin_starts(L, truth_x, F, j, case_points)):
            yield done(cand, err)
    for cand, err in descend(("random", n_random, seed), lambda: random_starts(L, truth_x, n_random, seed)):
        yield done(cand, err)


def _verify(L, x, truth_x, F, data, joint, method, held_out, held_out_truth, H) -> Witness:
    xm, err = refine(L, x, F, data)
    held_err, informative = 0.0, False
    if H:
        xh = _held_out_start(L, x, F, held_out_truth, truth_x, H)
        xh, _ = gauss_newton(L, xh, H, held_out, frames_only=True)
        _, held_err = refine(L, xh, H, held_out, frames_only=True, const_mp=xm[:L.n_const])
        Jh = jacobian(L, xh, H, frames_only=True)
        informative = bool(Jh.shape[0]) and bool(np.linalg.matrix_rank(Jh, tol=1e-9 * max(np.abs(Jh).max(), 1.0)) < Jh.shape[0])
    const = np.array([float(v) for v in xm[:L.n_const]])
    return Witness(joint, method, _floats(K.joint_quantities(L, truth_x[:L.n_const], joint)),
                   _floats(K.joint_quantities(L, const, joint)), err, held_err, F, H, xm, informative)


def _held_out_start(L, x_alt, F, held_truth, truth_x, H):
    """Held-out frames start from the alternative's pose in the construction frame whose true pose is
    nearest (the alternative differs from the truth by a smooth change of the poses)."""
    _, fa = L.split(x_alt, F)
    _, ft = L.split(truth_x, F)
    _, fh = L.split(held_truth, H)
    nearest = np.argmin(((fh[:, None, :] - ft[None, :, :]) ** 2).sum(axis=2), axis=1)
    start = fa[nearest] + (fh - ft[nearest])
    return np.concatenate([x_alt[:L.n_const], start.ravel()])


def _floats(d: dict) -> dict:
    return {k: float(v) for k, v in d.items()}
