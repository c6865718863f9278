"""``joint_translation``: the joint's centre (or hinge) moves in its parent as the joint turns.

Detector: a score test of the translation's own marker displacements (every marker below the joint moved with the
centre), what a refit with them would gain to first order. The smooth functions are of the joint's angles smoothed
in time (:func:`~identcheck.bundle.hypothesis.driving_angles`). Augmentation: the centre in the parent becomes
``c + basis(angles) @ D`` (D fitted with everything else), which carries the whole subtree, plus the part of a
translation linear in the angles that a rigid joint cannot absorb.

A translation linear in the angles, ``M ω`` (ω the joint's rotation from its median pose), is to first order a
rigid joint about a shifted centre when M is skew-symmetric: moving the centre by δ in both segments adds
``(I − Rot ω) δ ≈ δ × ω``. So linear terms in every direction would trade off against the joint's own
parameters (their standard errors grow to several mm) rather than add information; the symmetric part of M
cannot be absorbed and is modelled: six fields ``S_p ω`` for a ball joint (a hip pistoning along its
abduction axis with abduction), one for a hinge (``θ a``: a screw along its axis; the part perpendicular to the
axis is a shifted axis). The centre's motion quadratic and cubic in the angles is modelled in every direction:
a knee rolling back (A sin θ, odd) shows through its cubic part, sin θ − θ, and its even companions. The report
says which parts are modelled (``where["modelled"]``), and which of the functions the data ask for
(``where["functions"]``): only those are fitted (:mod:`identcheck.bundle.score_selection`).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.bundle.model import Terms
from identcheck.bundle.score_test import modulated_score_moments
from identcheck.bundle.score_selection import forward_selection
from identcheck.bundle.hypothesis import angle_basis, driving_angles, main_angle
from identcheck.bundle.misfit import ModelledMotion
from identcheck.effects.base import Effect, Proposal, motion_rms_mm, seen_mean, term_offsets, scalar_coefficients
from identcheck.effects.injection import Change, cannot, normalised_angle, pick, rotate, rotations, subtree, subtree_columns, unit_vectors
from identcheck.effects.soft_tissue import same_motion_clusters


MODELLED = ("the centre's motion in those of the functions (`functions`) the data ask for, chosen from every product "
            "and cube of the joint angles and the part linear in them that no shifted centre or axis absorbs (along "
            "a hinge's axis; a ball joint's symmetric part); the rest of the linear part cannot be told from a "
            "shifted centre or axis and stays in the joint's fitted position")
_SYMMETRIC = [np.outer(np.eye(3)[i], np.eye(3)[k]) + np.outer(np.eye(3)[k], np.eye(3)[i])
              for i in range(3) for k in range(i, 3)]      # the six symmetric 3 x 3 matrices (up to scale)


def linear_names(joint_type: str, k: int) -> list:
    """How ``where["functions"]`` names the k linear fields (:func:`linear_fields`) of a joint of `joint_type`: a
    hinge's one ``θ along the axis``; a ball joint's ``ω, symmetric part 1``, … (combinations of the symmetric maps of
    its rotation vector this motion keeps apart from a centre shift, in :func:`linear_fields`' order)."""
    if joint_type == "revolute":
        return ["θ along the axis"] * k
    return [f"ω, symmetric part {i + 1}" for i in range(k)]


def function_names(joint_type: str, k: int) -> list:
    """The names of the k functions of :func:`~identcheck.bundle.hypothesis.angle_basis` (``linear=False,
    cubic=True``) for a joint of `joint_type`, in its order: a hinge's ``θ²``, ``θ³``; a ball joint's products of its
    rotation vector's parent-frame components ``ωx²``, ``ωx·ωy``, … then the cubes ``ωx³``, …; each angle scaled to
    [−1, 1] over the trial, centred."""
    symbols = ["θ"] if joint_type == "revolute" else ["ωx", "ωy", "ωz"]
    i, j = np.triu_indices(len(symbols))
    names = [symbols[a] + "²" if a == b else f"{symbols[a]}·{symbols[b]}" for a, b in zip(i, j)]
    names += [s + "³" for s in symbols]
    if len(names) != k:
        raise ValueError(f"{k} functions for a {joint_type} joint's {len(names)} names")
    return names


ABSORBED_SHARE = 0.25
"""A combination of a ball joint's symmetric fields is modelled only when at least this share of its sum of squares
(half its size) is left once the best centre shift is taken out of it: otherwise it trades off with the centre
(its standard error grows by more than 2x), and the translation would leave the joint undetermined."""


def linear_fields(hyp, joint: str, angles: np.ndarray) -> list:
    """The translations linear in a joint's angles that a shifted centre cannot absorb, each (F, 3) in the parent
    frame, centred over frames: ``θ a`` along a hinge's axis a; for a ball joint, the combinations of the six
    symmetric ``S ω`` (ω its rotation vector from the median pose, :func:`identcheck.bundle.hypothesis.joint_angles`)
    that this motion keeps apart from a centre shift. The six are independent of it only when the joint turns
    about every axis alike; in gait (flexion mostly) some of them are nearly a centre shift's ``(I − Rot ω) δ``, and
    fitting them would leave the centre undetermined (a hip pistoning in gait: marker distances' SE 10 mm).
    Kept: the combinations with at least :data:`ABSORBED_SHARE` of their size left after the best shift is
    subtracted (eigenvectors of the projection's Gram matrix in an orthonormal basis of the fields)."""
    a = angles - np.nanmean(angles, axis=0)
    if hyp.chain.types[joint] == "revolute":
        out = [a[:, :1] * hyp.fit.state.axis[joint][None, :]]
    else:
        out = _not_a_shift([a @ S.T for S in _SYMMETRIC], angles)
    return [f - np.nanmean(f, axis=0) for f in out]


def _not_a_shift(fields: list, omega: np.ndarray) -> list:
    """The combinations of `fields` (each (F, 3)) that a centre shift ``(I − Rot ω) δ`` does not absorb (see
    :func:`linear_fields`), as fields of the same shape."""
    ok = np.all(np.isfinite(omega), axis=1)
    if ok.sum() < 3:
        return fields
    X = np.stack([f[ok] - f[ok].mean(axis=0) for f in fields], axis=-1)                   # (n, 3, K)
    lever = np.eye(3)[None] - Rotation.from_rotvec(omega[ok]).as_matrix()             # (n, 3, 3): δ's columns
    lever = lever - lever.mean(axis=0)
    X, lever = X.reshape(-1, X.shape[-1]), lever.reshape(-1, 3)
    _, sv, Vt = np.linalg.svd(X, full_matrices=False)
    if not sv[0] > 0:
        return []                           # the joint did not turn: no linear translation to see
    B = Vt[sv > 1e-9 * sv[0]].T / sv[sv > 1e-9 * sv[0]]       # X @ B: orthonormal (dependent fields dropped)
    XB = X @ B
    P = XB - lever @ np.linalg.lstsq(lever, XB, rcond=None)[0]
    share, V = np.linalg.eigh(P.T @ P)                         # the share of each combination's sum of squares left
    full = np.stack(fields, axis=-1)                                                  # (F, 3, K)
    return [full @ (B @ v) for v in V[:, share >= ABSORBED_SHARE].T]


def in_world(hyp, joint: str, fields: list) -> list:
    """Fields given in `joint`'s parent frame (each (F, 3), NaN read as 0), turned into the world by the parent's
    fitted rotations: how a ball joint's linear fields are fitted (world terms). Frozen from the round's rotations,
    they could take up those rotations' noise beside a term that turns with the fit, as a hinge's had (see
    :class:`~identcheck.bundle.model.Terms`, ``screws``), but written in the parent's frame they would break the
    gauge of its frame (no constant of the joint turns them as a hinge's axis turns a screw); on a rigid leg (four
    seeds) thigh skin in the hip's angles then gained no more with the hip's six fields frozen than turning."""
    R = hyp.fit.seg_R[hyp.chain.parent[joint]]
    return [np.einsum("fij,fj->fi", R, np.nan_to_num(g)) for g in fields]


def carriers(hyp, joint: str) -> list:
    """The three marker displacements (each (F, M, 3)) of the joint's centre moved by a unit along each of its parent's
    axes, frame by frame: every marker below the joint moves with it, the others stay. Each of the translation's fields
    is one of them times a function of the frame (a basis function along that axis), or a sum of the three times the
    components of a field given in the parent's frame (:func:`linear_fields`)."""
    ch = hyp.chain
    idx, R = ch.downstream[joint], hyp.fit.seg_R[ch.parent[joint]]
    out = []
    for i in range(3):
        v = np.zeros(hyp.data.shape)
        v[:, idx] = R[:, None, :, i]
        out.append(v)
    return out


def translation_moments(hyp, joint: str, basis: np.ndarray, linear: list, residual: np.ndarray, proj
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The score test's moments ``(n, G)`` (:func:`~identcheck.bundle.score_test.score_moments`) of the translation's
    fields against `residual` (the fit's): each basis function (F, K) along each of the parent's axes (field
    ``3k + i``: function k, axis i), then each linear field (each (F, 3) in the parent frame, field ``3K + l``), NaN
    read as 0. From the three :func:`carriers` modulated by the functions
    (:func:`~identcheck.bundle.score_test.modulated_score_moments`), each linear field a sum of the carriers times its
    components: the 3K + L fields over every marker below the joint are never formed (a full body's ball joint: 33 of
    them, 50 MB; its detector's peak had been 220 MB above the round's)."""
    K, L = basis.shape[1], len(linear)
    functions = np.column_stack([np.nan_to_num(basis)] + [np.nan_to_num(g) for g in linear]) if K + L else basis
    width = functions.shape[1]                # the modulated fields: carrier i times function c at i·width + c
    T = np.zeros((3 * K + L, 3 * width))
    for k in range(K):
        for i in range(3):
            T[3 * k + i, i * width + k] = 1.0
    for m in range(L):
        for i in range(3):
            T[3 * K + m, i * width + K + 3 * m + i] = 1.0
    ((n, G),) = modulated_score_moments(hyp.fit, hyp.weights, residual, carriers(hyp, joint), [functions], proj)
    return T @ n, T @ G @ T.T


class JointTranslation(Effect):
    name = "joint_translation"
    max_proposals = 3

    def inject(self, sim, rng) -> Change:
        """A joint centre moves in its parent frame along v by A (2a(t) − 1)², a the joint angle scaled
        to [0, 1]: at rest mid-range, A away at either end of the range; the child segment and everything
        below it follow. The profile is even on purpose: a translation linear in a hinge's angle,
        perpendicular to the axis, is to first order a rigid hinge about a shifted axis
        ((I − Rot θ)Δc ≈ θ Δc × a), so data cannot tell that part from a rigid joint elsewhere."""
        model = sim.model
        options = [j for j in model.joint_order if subtree_columns(sim, model.joints[j].child)]
        if not options:
            raise cannot(self.name, "no joint has a marker on its child segment or below it")
        joint = pick(rng, options)
        a = normalised_angle(sim.truth.joints[joint], low=0.0)
        direction = unit_vectors(rng, 1)[0]
        size = rng.uniform(8.0, 15.0)
        delta = np.outer(size * (2 * a - 1) ** 2, direction)
        clean = sim.clean.as_array()
        cols = subtree_columns(sim, model.joints[joint].child)
        clean[:, cols] += rotate(rotations(sim, model.joints[joint].parent), delta)[:, None]
        return Change(where={"joint": joint},
                       params={"amplitude_mm": size, "direction_parent": direction, "translation_parent": delta,
                               "moved_segments": subtree(model, model.joints[joint].child)},
                       clean=clean)

    def propose(self, ctx, hyp) -> list:
        """Each joint's translation, its strength what the refit with it would gain to first order (a score test
        over the translation's own displacement fields, :func:`translation_moments`, net of its parameters). The
        markers' mean residual below the joint, regressed on the same functions, read a knee rolling back 10.7 mm in
        gait as 25 where the refit gained 247: a rigid refit takes up most of a smooth translation in the joint's
        angle and the other segments' poses, and what is left shows on every marker.

        Only the functions the criterion asks for are proposed (:func:`~identcheck.bundle.score_selection.
        forward_selection` over the functions, each in three directions, and the linear fields, each its own), and
        ``where["functions"]`` names them (:func:`function_names`, :func:`linear_names`): a hip pistoning with its
        flexion needs one function, not the 31 parameters of all of them (see the selection module)."""
        ch, angles = hyp.chain, driving_angles(hyp, ctx.rate_hz)
        out, residual = [], hyp.residuals()
        for j in ch.joints:
            basis = angle_basis(angles[j], linear=False, cubic=True)
            lin = linear_fields(hyp, j, angles[j])
            n, G = translation_moments(hyp, j, basis, lin, residual, hyp.projection)
            k = basis.shape[1]
            units = [[3 * f, 3 * f + 1, 3 * f + 2] for f in range(k)] + [[3 * k + i] for i in range(len(lin))]
            chosen = forward_selection(n, G, units, lambda stat, m: ctx.bic_gain(ctx.smooth_share * stat, m),
                                       per_param=np.log(ctx.n_obs))
            functions = sorted(u for u in chosen.units if u < k)
            linear = [lin[u - k] for u in sorted(chosen.units) if u >= k]
            names = function_names(ch.types[j], k) + linear_names(ch.types[j], len(lin))
            where = {"joint": j, "modelled": MODELLED, "functions": [names[u] for u in sorted(chosen.units)]}
            out.append(Proposal(self.name, where, chosen.gain,
                                {"joint": j, "basis": basis[:, functions], "linear": linear,
                                 "choice_params": chosen.choice_params, "proposed_for": ch.types[j]}))
        return sorted(out, key=lambda p: -p.strength)

    def alike(self, chain, where: dict) -> list:
        """The clusters moving as one that are the same motion
        (:func:`identcheck.effects.soft_tissue.same_motion_clusters`: a last segment's below the joint, the root's
        above it)."""
        return [("soft_tissue", c) for c in same_motion_clusters(chain, where["joint"])]

    def apply(self, ctx, hyp, proposal):
        """The centre's terms: the chosen functions as a centre term; the part linear in the angles, a hinge's
        ``θ a`` as a screw along its fitted axis, a ball joint's fields as world terms (:func:`in_world`), also where
        a ball joint's proposal is fitted again after the joint was declared a hinge again (a search going back
        over its steps): its fields are not along the axis."""
        j = proposal.payload["joint"]
        ch = hyp.chain
        idx = ch.downstream[j]
        linear = proposal.payload.get("linear", [])
        hinge = ch.types[j] == "revolute" and proposal.payload.get("proposed_for", "revolute") == "revolute"
        screws = [np.nan_to_num(g) @ hyp.fit.state.axis[j] for g in linear] if hinge else []
        world = [] if screws else [(idx, np.broadcast_to(g[:, None, :], (len(g), len(idx), 3)).copy())
                                   for g in in_world(hyp, j, linear)]
        proposal.payload["world_fields"] = [f for _, f in world]      # how modelled_motion finds their terms
        proposal.payload["screws"] = screws
        basis = proposal.payload["basis"]
        terms = Terms(centres=[(j, basis)] if basis.shape[1] else [],   # the linear part alone: no centre term
                      screws=[(j, profile) for profile in screws], world=world)
        return hyp.refit(terms=hyp.terms + terms, effect=proposal, max_iter=10,
                         extra_params=proposal.payload.get("choice_params", 0))

    def modelled_motion(self, proposal, hyp) -> list:
        """The joint's centre moving in its parent as fitted, RMS about its mean over the frames: its term quadratic
        and cubic in the angles plus the part linear in them (a hinge's screw along its fitted axis; a ball joint's
        fields given in the parent's frame, fitted as world terms); the distances to a centre fixed in both segments
        are then a convention of the pose they are taken at."""
        j = proposal.payload["joint"]
        ch = hyp.chain
        linear = [np.nan_to_num(g) for g in proposal.payload.get("linear", [])]
        basis = proposal.payload["basis"]
        found = term_offsets(hyp, "centres", basis) if basis.shape[1] else []
        coefficients = scalar_coefficients(hyp, proposal.payload.get("world_fields", []))
        screws = proposal.payload.get("screws", [])
        along = scalar_coefficients(hyp, screws, kind="screws")
        if not found and not coefficients and not along:
            return []                       # the proposal's terms are not in `hyp`
        offsets = (found[0][1] if found else 0.0) + sum((c * linear[k] for k, c in coefficients), 0.0) \
            + sum((c * np.outer(screws[k], hyp.fit.state.axis[j]) for k, c in along), 0.0)
        return [ModelledMotion((ch.parent[j], ch.child[j]), motion_rms_mm(offsets), joint=j)]

    def reading(self, chain, where: dict, rms_mm: float) -> list:
        """The centre of the joint at `where` moving in its parent by `rms_mm`."""
        j = where.get("joint")
        return [ModelledMotion((chain.parent[j], chain.child[j]), rms_mm, joint=j)] if j in chain.parent else []

    def evidence(self, ctx, before, after, proposal) -> dict:
        j = proposal.payload["joint"]
        ch = before.chain
        idx = ch.downstream[j]
        def moved(h):  # noqa: E306
            r = np.where((h.weights > 0)[..., None], h.residuals(), np.nan)[:, idx]
            return np.linalg.norm(seen_mean(r, axis=1), axis=1)
        x, x_label = main_angle(before, j)
        return {"x": x, "x_label": x_label,
                "y": moved(before), "y_after": moved(after),
                "y_label": f"mean residual of the markers below {j} (mm)", "kind": "scatter"}
