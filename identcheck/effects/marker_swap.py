"""``marker_swap``: two markers' labels exchanged over a span of frames.

Detector (needs no joint model): markers on one segment keep their distances apart, so for every pair
of labels and every frame the distances to each one's segment partners are compared with their
medians as labelled and as exchanged; the longest run of frames that fits clearly better exchanged
is the span. Two markers whose distances to the rest are alike (the base of an isosceles triangle, a
mirror-symmetric pair) exchange without changing any distance: the segment then turns by a half turn at both
ends of the span, which its pose shows (:func:`identcheck.estimate.labels.flips`). Two markers alone on a segment
have one distance and no pose of their own, and a swap that begins or ends in a gap shows its distances on one side
only: their positions continuing from each other's at the span's ends show it
(:func:`identcheck.estimate.labels.exchanges`). An exchange that turns its segment over across the span's ends
(by more than a quarter turn, and more than the labels as given do) is not proposed: it poses the segment as its own
mirror image, which its distances cannot tell (:func:`identcheck.estimate.labels.exchange_turns_over`).
Augmentation: the two columns are exchanged back over the span (the pair and the two ends count as three
parameters).
"""
from __future__ import annotations

import math

import numpy as np

from identcheck.effects.base import Effect, Proposal
from identcheck.effects.injection import Change, cannot, draw_frame
from identcheck.estimate.labels import detect, exchange_turns_over, exchanges, fits_exchanged, flips


def _unexplained(ctx, hyp, span) -> float:
    """A flip's strength (:func:`identcheck.estimate.labels.flips`, which reads no distances): the criterion's
    gain if the exchange explained every residual of the span beyond the noise, for its three parameters."""
    a, b = span
    w = hyp.weights[a:b + 1] > 0
    r = np.where(w[..., None], hyp.residuals()[a:b + 1], 0.0)
    excess = float(np.sum(r ** 2)) - 3 * int(w.sum()) * ctx.noise.sigma_mm ** 2
    return ctx.bic_gain(max(excess, 0.0), 3)


class MarkerSwap(Effect):
    name = "marker_swap"
    nested = False          # it changes the data (see Effect.nested)
    max_proposals = 2

    def inject(self, sim, rng) -> Change:
        """Two markers at least 40 mm apart (on average) exchange labels for 10-30 % of the frames,
        inside [5 %, 95 %] of the trial."""
        x, n = sim.clean.xyz, sim.clean.n_frames
        apart = np.array([np.linalg.norm(x - x[:, [i]], axis=2).mean(axis=0) for i in range(x.shape[1])])
        first, second = np.nonzero(np.triu(apart >= 40.0, k=1))
        if not len(first):
            raise cannot(self.name, "it needs two markers at least 40 mm apart on average")
        k = int(rng.integers(len(first)))
        cols = [int(first[k]), int(second[k])]
        span = int(rng.integers(max(1, math.ceil(0.1 * n)), max(1, math.floor(0.3 * n)) + 1))
        start = draw_frame(rng, 0.05 * n, 0.95 * n - span + 1, n - span + 1)
        rows = slice(start, start + span)
        trial, gaps = sim.trial.as_array(), np.array(sim.gaps, dtype=bool)
        trial[rows, cols] = trial[rows][:, cols[::-1]]
        gaps[rows, cols] = gaps[rows][:, cols[::-1]]
        labels = sim.trial.labels
        return Change(where={"markers": [labels[cols[0]], labels[cols[1]]], "frames": [start, start + span - 1]},
                       params={"mean_distance_mm": float(apart[cols[0], cols[1]])}, trial=trial, gaps=gaps)

    always_fit = True

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        found = [{**d, "shown": fits_exchanged(d)} for d in detect(hyp.data, ch, ctx.noise.sigma_mm, ctx.n_obs)]
        seen = {(d["cols"], d["span"]) for d in found}
        for d in flips(hyp.data, ch) + exchanges(hyp.data, ch):
            if (d["cols"], d["span"]) not in seen:
                seen.add((d["cols"], d["span"]))
                found.append({**d, "gain": _unexplained(ctx, hyp, d["span"]), "shown": True})
        # an exchange that turns its segment over is no swap (its distances cannot tell it from the mirror image)
        found = [d for d in found if not exchange_turns_over(hyp.data, ch, d["cols"], d["span"], hyp.fit.state.local)]
        out = [Proposal(self.name, {"markers": [ch.labels[d["cols"][0]], ch.labels[d["cols"][1]]],
                                    "frames": list(d["span"])},
                        d["gain"], {"cols": d["cols"], "span": d["span"], "keep": d["keep"], "swap": d["swap"],
                                    "steps": d.get("steps", False), "shown": d["shown"]})
               for d in found]
        return sorted(out, key=lambda p: -p.strength)

    def read_without_joints(self, proposal) -> bool:
        """A swap whose exchanged distances fit (what ``fit``'s label screen leaves out), or one read from a flip of
        the segment's pose or from the trajectories going on under each other's label: the labels are wrong whatever
        the joints do. (A thigh skin model with both joints' angles absorbed part of a pelvis swap beside a shank
        delay and was adopted first; the swap was then never named.)"""
        return bool(proposal.payload.get("shown"))

    def apply(self, ctx, hyp, proposal):
        (i, j), (a, b) = proposal.payload["cols"], proposal.payload["span"]
        data, w = hyp.data.copy(), hyp.weights.copy()
        data[a:b + 1, [i, j]] = data[a:b + 1, [j, i]]
        w[a:b + 1, [i, j]] = w[a:b + 1, [j, i]]
        # the swapped frames may have pulled the old fit far off, and a fresh start may find another minimum
        return hyp.refit_corrected(ctx, data, w, max_iter=15, extra_params=3, effect=proposal)

    def evidence(self, ctx, before, after, proposal) -> dict:
        keep, swap = proposal.payload["keep"], proposal.payload["swap"]
        return {"x": np.arange(len(keep)), "x_label": "frame", "y": np.sqrt(np.maximum(keep, 0)),
                "y_after": np.sqrt(np.maximum(swap, 0)),
                "y_label": ("step from the frame before (mm): as labelled / exchanged" if proposal.payload.get("steps")
                            else "within-segment distance misfit (mm): as labelled / exchanged"),
                "span": list(proposal.payload["span"]), "kind": "series"}
