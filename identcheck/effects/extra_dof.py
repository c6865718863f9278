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
from identcheck.simulate.rigid import smooth_profile
from identcheck.effects.injection import Change, cannot, extra_rotation_world, pick, rotations, subtree, subtree_columns, unit

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

    def inject(self, sim, rng) -> Change:
        """A hinge also turns about an axis b perpendicular to its own (in the parent frame), by a
        smooth angle of 12-25 deg peak to peak; the child subtree turns about the joint centre."""
        model = sim.model
        hinges = [j for j in model.joint_order if model.joints[j].type == "revolute"]
        if not hinges:
            raise cannot(self.name, "it adds a second rotation to a revolute joint, and the model has none")
        options = [j for j in hinges if subtree_columns(sim, model.joints[j].child)]
        if not options:
            raise cannot(self.name, "no revolute joint has a marker on its child segment or below it")
        joint = pick(rng, options)
        hinge = sim.truth.joints[joint].axis_parent
        b = rng.normal(size=3)
        b = unit(b - (b @ hinge) * hinge)
        rom = rng.uniform(12.0, 25.0)
        psi = rom * smooth_profile(rng, sim.clean.times, 1)[:, 0]
        turn = extra_rotation_world(rotations(sim, model.joints[joint].parent), b, psi)
        pivot = sim.truth.centre_world(joint)[:, None]
        clean = sim.clean.as_array()
        cols = subtree_columns(sim, model.joints[joint].child)
        clean[:, cols] = pivot + np.einsum("fij,fmj->fmi", turn, clean[:, cols] - pivot)
        return Change(where={"joint": joint},
                       params={"extra_rom_deg": rom, "axis_parent": b, "angle_deg": psi,
                               "moved_segments": subtree(model, model.joints[joint].child)},
                       clean=clean)

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
