"""``marker_slip``: a marker shifts on its segment at one instant and stays there.

Detector: each marker's residual in its own segment's frame is scanned for the single change in mean
that explains most of its variance (a CUSUM split). Augmentation: a step in the marker's position on
its segment from that frame on (3 parameters, plus the frame).
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import Terms
from identcheck.bundle.hypothesis import segment_residuals
from identcheck.effects.base import Effect, Proposal
from identcheck.effects.injection import Change, cannot, marker_column, draw_frame, pick, rotations, unit_vectors

MIN_SIDE = 5     # frames on each side of a step


def best_step(resid: np.ndarray) -> tuple[int, float]:
    """(frame, explained sum of squares) of the best single mean shift of `resid` (F, 3), NaN rows skipped."""
    ok = np.flatnonzero(np.all(np.isfinite(resid), axis=1))
    n = len(ok)
    if n < 2 * MIN_SIDE:
        return -1, 0.0
    e = resid[ok]
    S = np.cumsum(e, axis=0)
    k = np.arange(1, n)
    left = S[:-1] / k[:, None]
    right = (S[-1] - S[:-1]) / (n - k)[:, None]
    stat = np.sum((left - right) ** 2, axis=1) * k * (n - k) / n
    stat[: MIN_SIDE - 1] = 0
    stat[n - MIN_SIDE:] = 0
    i = int(np.argmax(stat))
    return int(ok[i + 1]), float(stat[i])


class MarkerSlip(Effect):
    name = "marker_slip"
    max_proposals = 2

    def inject(self, sim, rng) -> Change:
        """One marker jumps on its segment at frame k (in [F/4, 3F/4]) by 6-15 mm and stays."""
        model, n = sim.model, sim.clean.n_frames
        if not model.markers:
            raise cannot(self.name, "the model has no marker")
        marker = pick(rng, model.markers)
        seg = model.marker_segment(marker)
        frame = draw_frame(rng, 0.25 * n, 0.75 * n, n)
        size = rng.uniform(6.0, 15.0)
        step = size * unit_vectors(rng, 1)[0]
        clean = sim.clean.as_array()
        clean[frame:, marker_column(sim, marker)] += rotations(sim, seg)[frame:] @ step
        return Change(where={"markers": [marker], "segment": seg, "frame": frame},
                       params={"step_mm": size, "step_local": step}, clean=clean)

    def propose(self, ctx, hyp) -> list:
        seg_res = segment_residuals(hyp)
        ch = hyp.chain
        out = []
        for col in range(ch.n_markers):
            frame, ss = best_step(seg_res[:, col])
            gain = ctx.bic_gain(ss, 4)
            if frame >= 0 and gain > 0:
                step = (np.arange(len(seg_res)) >= frame).astype(float)[:, None]
                out.append(Proposal(self.name, {"markers": [ch.labels[col]], "segment": ch.marker_seg[col],
                                                "frame": frame}, gain, {"col": col, "basis": step}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        term = (proposal.payload["col"], proposal.payload["basis"])
        return hyp.refit(terms=hyp.terms + Terms(markers=[term]), extra_params=1, effect=proposal)

    def evidence(self, ctx, before, after, proposal) -> dict:
        col = proposal.payload["col"]
        return {"x": np.arange(len(before.data)), "x_label": "frame",
                "y": segment_residuals(before)[:, col], "y_after": segment_residuals(after)[:, col],
                "y_label": f"{proposal.where['markers'][0]} residual on {proposal.where['segment']} (mm, x/y/z)",
                "mark": [proposal.where["frame"]], "kind": "series3"}
