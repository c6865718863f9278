"""``soft_tissue``: a marker moves on its segment as a smooth function of an adjacent joint's angles.

Detector: each marker's residual in its own segment's frame, regressed on smooth functions of the
angles of each joint its segment takes part in; the variance explained, net of the parameters it
costs, ranks the (marker, joint) pairs. Augmentation: the marker's position on its segment becomes
``local + basis(angles) @ B`` with B (2n × 3) fitted with everything else.

Skin also carries a whole marker cluster at once (a cluster on a plate, or the soft tissue under it): the
mean of a segment's markers' residuals regressed the same way proposes the cluster moving together, one
shared B for all its markers. A cluster moving on its segment is not a translating joint: it moves that
segment's markers only, while a joint that translates carries every segment below it.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import Terms
from identcheck.bundle.hypothesis import angle_basis, joint_angles, main_angle, segment_residuals
from identcheck.effects.base import Effect, Proposal, seen_mean
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
        seg_res = segment_residuals(hyp)
        angles = joint_angles(hyp)
        ch = hyp.chain
        out = []
        for j in ch.joints:
            basis = angle_basis(angles[j])
            for seg in (ch.parent[j], ch.child[j]):
                cols = np.asarray(ch.seg_markers[seg])
                if len(cols) >= 2:
                    # the root's own pose takes up its cluster's common motion whole, which then shows on the
                    # markers below the joint instead (in the root's frame, with the sign turned)
                    seen = ch.downstream[j] if seg == ch.root else cols
                    mean = seen_mean(seg_res[:, seen] if seg != ch.root else np.einsum(
                        "fji,fkj->fki", hyp.fit.seg_R[seg], hyp.residuals()[:, seen]), axis=1)
                    gain = ctx.bic_gain(len(seen) * explained(mean, basis), 3 * basis.shape[1])
                    if gain > 0:
                        out.append(Proposal(self.name, {"markers": [ch.labels[c] for c in cols], "segment": seg,
                                                        "joint": j, "together": True},
                                            gain, {"col": cols, "basis": basis, "joint": j}))
                for col in ch.seg_markers[seg]:
                    gain = ctx.bic_gain(explained(seg_res[:, col], basis), 3 * basis.shape[1])
                    if gain > 0:
                        out.append(Proposal(self.name, {"markers": [ch.labels[col]], "segment": seg, "joint": j},
                                            gain, {"col": int(col), "basis": basis, "joint": j}))
        return sorted(out, key=lambda p: -p.strength)

    def alike(self, chain, where: dict) -> list:
        """A cluster moving as one with its joint's angles, where that is the joint's centre moving in the parent
        (:func:`same_motion_clusters`)."""
        j = where.get("joint")
        if not where.get("together") or j is None or j not in chain.child:
            return []
        if where.get("segment") not in [c["segment"] for c in same_motion_clusters(chain, j)]:
            return []
        from identcheck.effects.joint_translation import MODELLED     # (that module builds on this one)

        return [("joint_translation", {"joint": j, "modelled": MODELLED})]

    def apply(self, ctx, hyp, proposal):
        term = (proposal.payload["col"], proposal.payload["basis"])
        return hyp.refit(terms=hyp.terms + Terms(markers=[term]), effect=proposal)

    def evidence(self, ctx, before, after, proposal) -> dict:
        col, j = np.atleast_1d(proposal.payload["col"]), proposal.payload["joint"]
        x, x_label = main_angle(before, j)

        def moved(h):  # noqa: E306 - the marker's (the cluster's mean) residual on its segment
            with np.errstate(all="ignore"):
                return np.linalg.norm(seen_mean(segment_residuals(h)[:, col], axis=1), axis=1)
        who = proposal.where["markers"][0] if len(col) == 1 else "the cluster's mean"
        return {"x": x, "x_label": x_label,
                "y": moved(before), "y_after": moved(after),
                "y_label": f"{who} residual on {proposal.where['segment']} (mm)",
                "kind": "scatter"}
