"""``soft_tissue``: a marker moves on its segment as a smooth function of an adjacent joint's angles.

Detector: each marker's residual in its own segment's frame, regressed on smooth functions of the
angles of each joint its segment takes part in; the variance explained, net of the parameters it
costs, ranks the (marker, joint) pairs. Augmentation: the marker's position on its segment becomes
``local + basis(angles) @ B`` with B (2n × 3) fitted with everything else.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import Terms
from identcheck.bundle.hypothesis import angle_basis, joint_angles, segment_residuals
from identcheck.effects.base import Effect, Proposal


def explained(resid: np.ndarray, basis: np.ndarray) -> float:
    """Sum of squares of `resid` (F, 3) explained by `basis` (F, K) plus a constant, over finite rows."""
    ok = np.all(np.isfinite(resid), axis=1)
    if ok.sum() <= basis.shape[1] + 2:
        return 0.0
    X = np.column_stack([np.ones(ok.sum()), basis[ok]])
    y = resid[ok] - resid[ok].mean(axis=0)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    return float(np.sum((X @ coef) ** 2))


class SoftTissue(Effect):
    name = "soft_tissue"
    max_proposals = 2

    def propose(self, ctx, hyp) -> list:
        seg_res = segment_residuals(hyp)
        angles = joint_angles(hyp)
        ch = hyp.chain
        out = []
        for j in ch.joints:
            basis = angle_basis(angles[j])
            for seg in (ch.parent[j], ch.child[j]):
                for col in ch.seg_markers[seg]:
                    gain = ctx.bic_gain(explained(seg_res[:, col], basis), 3 * basis.shape[1])
                    if gain > 0:
                        out.append(Proposal(self.name, {"markers": [ch.labels[col]], "segment": seg, "joint": j},
                                            gain, {"col": int(col), "basis": basis, "joint": j}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        term = (proposal.payload["col"], proposal.payload["basis"])
        return hyp.refit(terms=hyp.terms + Terms(markers=[term]), effect=proposal)

    def evidence(self, ctx, before, after, proposal) -> dict:
        col, j = proposal.payload["col"], proposal.payload["joint"]
        ang = np.rad2deg(joint_angles(before)[j])
        return {"x": ang[:, 0], "x_label": f"{j} angle (deg)",
                "y": np.linalg.norm(segment_residuals(before)[:, col], axis=1),
                "y_after": np.linalg.norm(segment_residuals(after)[:, col], axis=1),
                "y_label": f"{proposal.where['markers'][0]} residual on {proposal.where['segment']} (mm)",
                "kind": "scatter"}
