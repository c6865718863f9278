"""``soft_tissue``: a marker moves on its segment as a smooth function of its segment's joints' angles.

Detector: each marker's residual in its own segment's frame, regressed on smooth functions of the
angles (smoothed in time, :func:`~identcheck.bundle.hypothesis.driving_angles`: the fitted angles carry the noise
of their frames, which terms built from them fit) of each joint its segment takes part in, and of each pair of
them together (:func:`drivers`); the variance explained, net of the parameters it costs, ranks the (marker,
joints) pairs. Augmentation: the marker's position on its segment becomes ``local + basis(angles) @ B`` with B
(K × 3) fitted with everything else. ``where`` names the joint (with two, ``joints`` names both and ``joint`` the
first).

Only the functions the criterion asks for are proposed and fitted (:func:`selected`: forward selection of
:mod:`identcheck.bundle.score_selection` over the functions, each with a free 3-vector, the choice charged), and
``where["functions"]`` names them (:func:`basis_names`): skin on a thigh moving with hip flexion needs one or two of
the hip's nine functions, not 27 parameters a marker (42 with the knee's angle too).

Skin also carries a whole marker cluster at once (a cluster on a plate, or the soft tissue under it): the
mean of a segment's markers' residuals regressed the same way proposes the cluster moving together, one
shared B for all its markers. A cluster moving on its segment is not a translating joint: it moves that
segment's markers only, while a joint that translates carries every segment below it.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import Terms
from identcheck.bundle.hypothesis import angle_basis, driving_angles, main_angle, segment_residuals
from identcheck.bundle.score_test import quadratic_form
from identcheck.bundle.score_selection import Selection, forward_selection
from identcheck.bundle.misfit import ModelledMotion
from identcheck.effects.base import Effect, Proposal, motion_rms_mm, seen_mean, term_offsets
from identcheck.effects.injection import Change, cannot, marker_column, diameter, normalised_angle, pick, rotate, rotations, unit_vectors


def explained(resid: np.ndarray, basis: np.ndarray, fields: list = ()) -> float:
    """Sum of squares of `resid` (F, 3) explained by `basis` (F, K) times free 3-vectors, plus a constant, over the
    finite rows; with `fields` (each (F, 3)), also by each field times a free scalar (a direction that turns with
    the frame, which a basis times a fixed 3-vector cannot hold: :mod:`identcheck.effects.joint_translation`)."""
    ok = np.all(np.isfinite(resid), axis=1)
    for f in fields:
        ok &= np.all(np.isfinite(f), axis=1)
    n, K = int(ok.sum()), basis.shape[1]
    if n <= K + len(fields) + 2:
        return 0.0
    y = resid[ok] - resid[ok].mean(axis=0)
    if not len(fields):                      # the three axes share one design: one small least squares
        X = np.column_stack([np.ones(n), basis[ok]])
        return float(np.sum((X @ np.linalg.lstsq(X, y, rcond=None)[0]) ** 2))
    eye = np.eye(3)
    X = np.hstack([np.kron(np.ones((n, 1)), eye)]                          # the constant, per axis
                  + [np.kron(basis[ok][:, [k]], eye) for k in range(K)]    # each basis function times a 3-vector
                  + [f[ok].reshape(-1, 1) for f in fields])                # each field times a scalar
    y = y.reshape(-1)
    return float(np.sum((X @ np.linalg.lstsq(X, y, rcond=None)[0]) ** 2))


def regression_moments(resid: np.ndarray, basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moments ``(N, A)`` of `resid` (F, 3) regressed on `basis` (F, K) times free 3-vectors plus a constant, over
    the finite rows, in the form :func:`~identcheck.bundle.score_selection.forward_selection` reads for functions whose
    three directions share one design: ``N = XᵀY`` (K, 3) and ``A = XᵀX`` (K, K), X the centred functions and Y the
    centred residual, so that ``trace(N_Sᵀ A_SS⁺ N_S)`` is the sum of squares the functions S explain (what
    :func:`explained` gives for S; the statistic of the 3|S| fields with ``A ⊗ I₃``, at a ninth of the cost). Both
    empty when the rows are too few for the whole basis."""
    ok = np.all(np.isfinite(resid), axis=1)
    K = basis.shape[1]
    if int(ok.sum()) <= K + 2:
        return np.zeros((0, 3)), np.zeros((0, 0))
    y = resid[ok] - resid[ok].mean(axis=0)
    X = basis[ok] - basis[ok].mean(axis=0)
    return X.T @ y, X.T @ X


def selected(ctx, resid: np.ndarray, basis: np.ndarray, weight: float = 1.0, choose: bool = True) -> Selection:
    """Which of `basis`'s functions (each with a free 3-vector) the criterion asks for to explain `resid` (F, 3): the
    forward selection on :func:`regression_moments`, each subset's gain ``ctx.bic_gain(weight · explained, its
    parameters + the choice's)`` (`weight`: how many markers share the residual, for a cluster's mean). Its ``units``
    are the chosen functions (indices into the basis's columns); an empty selection when the rows are too few.
    `choose` False: every function, at the gain of all of them (where the residual does not show the motion the
    refit will fit: :meth:`SoftTissue.propose`)."""
    n, G = regression_moments(resid, basis)
    if not len(n):
        return Selection((), (), float(ctx.bic_gain(0.0, 0)))
    gain = lambda stat, m: ctx.bic_gain(weight * stat, m)  # noqa: E731
    if not choose:
        every = tuple(range(basis.shape[1]))
        return Selection(every, every, float(gain(quadratic_form(n, G), 3 * len(every))))
    return forward_selection(n, G, [[k] for k in range(basis.shape[1])], gain, per_param=float(np.log(ctx.n_obs)))


def basis_names(chain, joints: tuple) -> list:
    """The names of the functions of :func:`~identcheck.bundle.hypothesis.angle_basis` of `joints`' angles stacked in
    that order (as :meth:`SoftTissue.propose` builds it), in its column order: each angle (a hinge's ``knee θ``, a
    ball joint's rotation-vector components ``hip ωx`` …), then the products of two (``hip ωx·knee θ``, squares
    ``knee θ²``); each angle scaled to [−1, 1] over the trial."""
    symbols = [f"{j} {a}" for j in joints for a in (["θ"] if chain.types[j] == "revolute" else ["ωx", "ωy", "ωz"])]
    i, k = np.triu_indices(len(symbols))
    return symbols + [f"{symbols[a]}²" if a == b else f"{symbols[a]}·{symbols[b]}" for a, b in zip(i, k)]


def same_motion_clusters(chain, joint: str) -> list:
    """The clusters moving as one (soft-tissue ``where``s) whose motion no data could tell from `joint`'s centre
    moving in its parent with the joint's angles (both effects' ``alike``):

    - the child's, where the child is a last segment (every marker below the joint is on it, two or more): a centre
      moving by D(θ) is the cluster moving by Rot(θ)ᵀ D(θ) on its segment, and only a marker further down could
      tell the two apart;
    - the parent's, where the parent is the root and every other marker is below the joint (two or more on the
      root): the root's pose moved by D(θ) with its cluster moved back by −D(θ) on it carries the centre, and with
      it everything below, by D(θ) while leaving the root's markers where they were (a hip pistoning in the pelvis
      was named as the pelvis's cluster moving with the hip, and nothing said the two were one)."""
    out = []
    child, parent = chain.child[joint], chain.parent[joint]
    below = set(chain.downstream[joint])
    cols = chain.seg_markers[child]
    if len(cols) >= 2 and below == set(cols):
        out.append({"markers": [chain.labels[c] for c in cols], "segment": child, "joint": joint, "together": True})
    cols = chain.seg_markers[parent]
    if parent == chain.root and len(cols) >= 2 and below | set(cols) == set(range(len(chain.labels))):
        out.append({"markers": [chain.labels[c] for c in cols], "segment": parent, "joint": joint, "together": True})
    return out


def drivers(chain) -> list:
    """Where skin can move and with which angles: (segment, joints) for each joint and each of its two segments,
    and, for a segment between joints (a thigh, below the hip and above the knee), each pair of its joints
    together. Skin over a segment moves with the angles of the muscles that cross it, and those span both of its
    joints: a thigh's cluster moving with hip flexion and knee flexion at once (a bulge with their product) was
    fitted by neither joint's angles alone, and a distortion of the whole volume explained more of it. Also each
    joint next to one of the segment's own (a shank's skin with the hip's angles, a pelvis's with the knee's): muscles
    that cross two joints move skin with the far joint too, and a shank marker moving with hip flexion had been
    named a distortion of the volume (held-out draw 46, trial 92)."""
    out = [(seg, (j,)) for j in chain.joints for seg in (chain.parent[j], chain.child[j])]
    for seg in chain.seg_markers:
        own = [j for j in chain.joints if seg in (chain.parent[j], chain.child[j])]
        out += [(seg, (a, b)) for k, a in enumerate(own) for b in own[k + 1:]]
        beside = {chain.parent[j] for j in own} | {chain.child[j] for j in own}
        out += [(seg, (j,)) for j in chain.joints
                if j not in own and (chain.parent[j] in beside or chain.child[j] in beside)]
    return out


class SoftTissue(Effect):
    name = "soft_tissue"
    max_proposals = 3

    def inject(self, sim, rng) -> Change:
        """One child-segment marker wobbles on its segment with the proximal joint angle a(t):
        d = u1 A1 a + u2 A2 (a^2 - mean a^2), in the segment frame."""
        model = sim.model
        options = [s for s in model.segments if s != model.root and model.segments[s].markers]
        if not options:
            raise cannot(self.name, "it needs a marker on a segment below a joint, and every marker "
                                         "of the model is on the root segment")
        seg = pick(rng, options)
        marker = pick(rng, model.segments[seg].markers)
        joint = model.parent_joint(seg).name
        a = normalised_angle(sim.truth.joints[joint], low=-1.0)
        u1, u2 = unit_vectors(rng, 2)
        a1, a2 = rng.uniform(5.0, 10.0), rng.uniform(2.0, 5.0)
        local = np.outer(a1 * a, u1) + np.outer(a2 * (a ** 2 - np.mean(a ** 2)), u2)
        clean = sim.clean.as_array()
        clean[:, marker_column(sim, marker)] += rotate(rotations(sim, seg), local)
        return Change(where={"markers": [marker], "segment": seg, "joint": joint},
                       params={"amplitude_mm": diameter(local),
                               "max_displacement_mm": float(np.linalg.norm(local, axis=1).max()),
                               "linear_mm": a1, "quadratic_mm": a2, "linear_direction": u1,
                               "quadratic_direction": u2, "displacement_local": local},
                       clean=clean)

    def propose(self, ctx, hyp) -> list:
        """Three kinds of place on each segment: one marker, the cluster moving as one (one shared motion), and every
        marker of the segment each moving its own way (skin under a cluster of separate markers); for each, the
        joints whose angles (:func:`drivers`) earn the most, with only the functions of them the criterion asks for
        (:func:`selected`; every marker its own for a segment's markers each moving their own way). On the root every
        function is fitted: the root's pose takes up its markers' common motion, which then shows on the markers
        below, so its markers' residuals do not show what their terms will fit, and a choice made from them fell
        short (the real walking2 trial's sparse model: the pelvis markers' skin with both hips' angles, chosen,
        scored 43 486 fitted against 71 158 with every function, and a knee's translation came first instead)."""
        seg_res = segment_residuals(hyp)
        angles = driving_angles(hyp, ctx.rate_hz)      # (smoothed: fitted angles carry the frames' noise)
        ch = hyp.chain
        best = {}

        def offer(where, gain, payload):  # noqa: E306 - keep the best joints for each place
            key = (where["segment"], tuple(where["markers"]), where.get("together", False))
            if gain > 0 and (key not in best or gain > best[key].strength):
                best[key] = Proposal(self.name, where, gain, payload)

        for seg, joints in drivers(ch):
            basis = angle_basis(np.column_stack([angles[j] for j in joints]))
            names = basis_names(ch, joints)
            cols = np.asarray(ch.seg_markers[seg])
            place = {"segment": seg, "joint": joints[0]} | ({"joints": list(joints)} if len(joints) > 1 else {})

            def chosen(sel):  # noqa: E306 - the payload and the named functions of one selection
                funcs = sorted(sel.units)
                return {"basis": basis[:, funcs], "choice_params": sel.choice_params}, [names[u] for u in funcs]
            choose = seg != ch.root
            own = [selected(ctx, seg_res[:, col], basis, choose=choose) for col in cols]
            for col, sel in zip(cols, own):
                payload, functions = chosen(sel)
                offer({"markers": [ch.labels[col]], **place, "functions": functions}, sel.gain,
                      {"col": int(col), "joint": joints[0], **payload})
            if len(cols) < 2:
                continue
            labels = [ch.labels[c] for c in cols]
            each = [chosen(sel) for sel in own]
            named = [f"{ch.labels[c]}: {', '.join(f)}" for c, (_, f) in zip(cols, each)]
            offer({"markers": labels, **place, "functions": named},
                  sum(sel.gain for sel in own),
                  {"col": cols, "each": True, "joint": joints[0], "bases": [p["basis"] for p, _ in each],
                   "basis": basis[:, :0], "choice_params": sum(p["choice_params"] for p, _ in each)})
            # the root's own pose takes up its cluster's common motion whole, which then shows on the
            # markers below its joints instead (in the root's frame, with the sign turned)
            # (for a joint a segment further, below the root's own joints: its cluster's motion shows there too)
            own_joints = [j for j in joints if seg in (ch.parent[j], ch.child[j])] or [
                j for j in ch.joints if ch.parent[j] == seg]
            seen = sorted(set().union(*(ch.downstream[j] for j in own_joints))) if seg == ch.root else cols
            mean = seen_mean(seg_res[:, seen] if seg != ch.root else np.einsum(
                "fji,fkj->fki", hyp.fit.seg_R[seg], hyp.residuals()[:, seen]), axis=1)
            sel = selected(ctx, mean, basis, weight=len(seen), choose=choose)
            payload, functions = chosen(sel)
            offer({"markers": labels, **place, "together": True, "functions": functions}, sel.gain,
                  {"col": cols, "joint": joints[0], **payload})
        return sorted(best.values(), key=lambda p: -p.strength)

    def alike(self, chain, where: dict) -> list:
        """A cluster moving as one with its joint's angles, where that is the joint's centre moving in the parent
        (:func:`same_motion_clusters`); not one moving with two joints' angles, which no one centre's motion is."""
        j = where.get("joint")
        if not where.get("together") or j is None or j not in chain.child or len(where.get("joints", [j])) > 1:
            return []
        if where.get("segment") not in [c["segment"] for c in same_motion_clusters(chain, j)]:
            return []
        from identcheck.effects.joint_translation import MODELLED     # (that module builds on this one)

        return [("joint_translation", {"joint": j, "modelled": MODELLED})]

    def apply(self, ctx, hyp, proposal):
        col, basis = proposal.payload["col"], proposal.payload["basis"]
        if proposal.payload.get("each"):
            terms = [(int(c), b) for c, b in zip(col, proposal.payload["bases"]) if b.shape[1]]
        else:
            terms = [(col, basis)] if basis.shape[1] else []
        return hyp.refit(terms=hyp.terms + Terms(markers=terms), effect=proposal,
                         extra_params=proposal.payload.get("choice_params", 0))

    def modelled_motion(self, proposal, hyp) -> list:
        """Each of the proposal's terms as the motion of its marker (or cluster) on its segment, RMS over the frames
        where one of its markers is seen."""
        mine = set(np.atleast_1d(proposal.payload["col"]).tolist())
        bases = proposal.payload.get("bases") or [proposal.payload["basis"]]
        out = []
        for cols, offsets in [found for b in bases for found in term_offsets(hyp, "markers", b)]:
            cols = np.atleast_1d(cols)
            if set(cols.tolist()) <= mine:
                seen = np.any(hyp.weights[:, cols] > 0, axis=1)
                out.append(ModelledMotion((proposal.where["segment"],), motion_rms_mm(offsets[seen])))
        return out

    def reading(self, chain, where: dict, rms_mm: float) -> list:
        """The markers at `where` moving on their segment(s) by `rms_mm`."""
        segment = where.get("segment")
        return [ModelledMotion((segment,), rms_mm)] if segment in chain.seg_markers else []

    def evidence(self, ctx, before, after, proposal) -> dict:
        col, j = np.atleast_1d(proposal.payload["col"]), proposal.payload["joint"]
        x, x_label = main_angle(before, j)

        each = bool(proposal.payload.get("each"))

        def moved(h):  # noqa: E306 - the marker's residual on its segment (the cluster's mean; its markers' RMS)
            with np.errstate(all="ignore"):
                r = segment_residuals(h)[:, col]
                if each:          # (a frame where every one of them is hidden: NaN, and no warning for it)
                    return np.sqrt(seen_mean(np.sum(r ** 2, axis=2), axis=1))
                return np.linalg.norm(seen_mean(r, axis=1), axis=1)
        who = (proposal.where["markers"][0] if len(col) == 1 else
               "its markers' RMS" if each else "the cluster's mean")
        return {"x": x, "x_label": x_label,
                "y": moved(before), "y_after": moved(after),
                "y_label": f"{who} residual on {proposal.where['segment']} (mm)",
                "kind": "scatter"}
