"""``extra_dof``: a joint declared a hinge also turns about another axis.

Detector: a hinge whose downstream markers carry residual the hinge cannot absorb (ranked by that
residual). Augmentation: the joint re-declared as the next type up, a ball joint, keeping its fitted
motion as the starting point (two more angles per frame; the selection makes them earn it, and the
joint must stay identifiable as a ball).
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import convert_joint, initial_state
from identcheck.effects.base import Effect, Proposal

NEXT_TYPE = {"revolute": "spherical"}


def off_axis_deg(h, joint: str) -> np.ndarray:
    """Angle between the hinge direction as carried by the parent and by the child, per frame (deg),
    from the segments' own rigid poses: zero for a true hinge."""
    from identcheck.estimate.obrien import joint_location
    from identcheck.bundle.chain import segment_frames
    frames = segment_frames(h.chain, h.data)
    P, C = frames[h.chain.parent[joint]], frames[h.chain.child[joint]]
    fit = joint_location(P, C, hinge=True)
    a = np.einsum("fij,j->fi", P.R, fit.axis_parent)
    b = np.einsum("fij,j->fi", C.R, fit.axis_child)
    return np.rad2deg(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))


class ExtraDof(Effect):
    name = "extra_dof"
    max_proposals = 2

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        res = np.where((hyp.weights > 0)[..., None], hyp.residuals(), 0.0)
        out = []
        for j in ch.joints:
            if ch.types[j] not in NEXT_TYPE:
                continue
            rss = float(np.sum(res[:, ch.downstream[j]] ** 2)) / ctx.noise.sigma_mm ** 2
            out.append(Proposal(self.name, {"joint": j, "declared": ch.types[j], "needs": NEXT_TYPE[ch.types[j]]},
                                rss, {"joint": j}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        j = proposal.payload["joint"]
        chain, _ = convert_joint(hyp.chain, hyp.fit.state, j, NEXT_TYPE[hyp.chain.types[j]])
        # a fresh start: the hinge fit bent every constant to absorb the missing rotation
        state = initial_state(chain, hyp.data)
        return hyp.refit(chain=chain, state=state, effect=proposal, max_iter=12)

    def evidence(self, ctx, before, after, proposal) -> dict:
        j = proposal.payload["joint"]
        off = off_axis_deg(before, j)
        return {"x": np.arange(len(off)), "x_label": "frame", "y": off,
                "y_label": f"{j}: hinge direction from thigh vs from shank (deg)".replace(
                    "thigh", before.chain.parent[j]).replace("shank", before.chain.child[j]), "kind": "series"}
