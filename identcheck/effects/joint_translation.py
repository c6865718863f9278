"""``joint_translation``: the joint's centre (or hinge) moves in its parent as the joint turns.

Detector: the residuals of every marker below the joint, seen from the parent segment, regressed on
smooth functions of the joint's angles. Augmentation: the centre in the parent becomes
``c + basis(angles) @ D`` (D fitted with everything else), which carries the whole subtree.

The basis has the angles' products and cubes, no linear terms: a translation linear in a hinge's angle,
perpendicular to the axis, is to first order a rigid hinge about a shifted axis (and for a ball joint
the skew part of a linear translation is a shifted centre), so linear terms would trade off against
the joint's own parameters (their standard errors grow to several mm) rather than add information. A
knee rolling back (A sin θ, odd) is therefore seen through its cubic part, sin θ − θ, and its even
companions; the report says which part is modelled (``where["modelled"]``).
"""
from __future__ import annotations

import warnings

import numpy as np

from identcheck.bundle.model import Terms
from identcheck.bundle.hypothesis import angle_basis, joint_angles, main_angle
from identcheck.effects.base import Effect, Proposal
from identcheck.effects.injection import Change, cannot, normalised_angle, pick, rotate, rotations, subtree, subtree_columns, unit_vectors
from identcheck.effects.soft_tissue import explained


MODELLED = ("the centre's motion quadratic and cubic in the joint angles; a part linear in them cannot be told "
            "from a shifted centre or axis and stays in the joint's fitted position")


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
        ch, angles = hyp.chain, joint_angles(hyp)
        res = np.where((hyp.weights > 0)[..., None], hyp.residuals(), np.nan)
        out = []
        for j in ch.joints:
            idx = ch.downstream[j]
            seen_from_parent = np.einsum("fji,fkj->fki", hyp.fit.seg_R[ch.parent[j]], res[:, idx])
            basis = angle_basis(angles[j], linear=False, cubic=True)
            with warnings.catch_warnings():          # frames where every such marker is hidden
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(seen_from_parent, axis=1)
            gain = ctx.bic_gain(len(idx) * explained(mean, basis), 3 * basis.shape[1])
            out.append(Proposal(self.name, {"joint": j, "modelled": MODELLED}, float(gain), {"joint": j, "basis": basis}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        term = (proposal.payload["joint"], proposal.payload["basis"])
        return hyp.refit(terms=hyp.terms + Terms(centres=[term]), effect=proposal, max_iter=10)

    def evidence(self, ctx, before, after, proposal) -> dict:
        j = proposal.payload["joint"]
        ch = before.chain
        idx = ch.downstream[j]
        def moved(h):  # noqa: E306
            r = np.where((h.weights > 0)[..., None], h.residuals(), np.nan)[:, idx]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                return np.linalg.norm(np.nanmean(r, axis=1), axis=1)
        x, x_label = main_angle(before, j)
        return {"x": x, "x_label": x_label,
                "y": moved(before), "y_after": moved(after),
                "y_label": f"mean residual of the markers below {j} (mm)", "kind": "scatter"}
