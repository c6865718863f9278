"""``marker_swap``: two markers' labels exchanged over a span of frames.

Detector (needs no joint model): markers on one segment keep their distances apart, so for every pair
of labels and every frame the distances to each one's segment partners are compared with their
medians as labelled and as exchanged; the longest run of frames that fits clearly better exchanged
is the span. Augmentation: the two columns are exchanged back over the span (the pair and the two
ends count as three parameters).
"""
from __future__ import annotations

import numpy as np

from ..chain import initial_state
from .base import Effect, Proposal

MIN_RUN = 3          # frames
MAX_HOLE = 2         # frames of doubt (gaps, ties) bridged inside a run


def _partners(chain, col: int, exclude: set) -> np.ndarray:
    seg = chain.marker_seg[col]
    return np.array([k for k in chain.seg_markers[seg] if k not in exclude], dtype=int)


def swap_costs(data: np.ndarray, chain, i: int, j: int):
    """Per-frame misfit of the within-segment distances with labels i, j as given and exchanged (F,)."""
    Pi, Pj = _partners(chain, i, {i, j}), _partners(chain, j, {i, j})
    if len(Pi) + len(Pj) == 0:
        return None, None
    def dist(a, ks):  # noqa: E306
        return np.linalg.norm(data[:, [a]] - data[:, ks], axis=2)
    Di, Dj = np.nanmedian(dist(i, Pi), axis=0), np.nanmedian(dist(j, Pj), axis=0)
    keep = np.nansum((dist(i, Pi) - Di) ** 2, axis=1) + np.nansum((dist(j, Pj) - Dj) ** 2, axis=1)
    swap = np.nansum((dist(j, Pi) - Di) ** 2, axis=1) + np.nansum((dist(i, Pj) - Dj) ** 2, axis=1)
    both = np.all(np.isfinite(data[:, [i, j]]), axis=(1, 2))
    keep[~both], swap[~both] = np.nan, np.nan
    return keep, swap


def longest_run(flag: np.ndarray, doubt: np.ndarray) -> tuple[int, int]:
    """First and last frame of the longest run of `flag`, bridging holes of at most MAX_HOLE `doubt`
    frames; (-1, -1) if none."""
    best, start, last_true, holes = (-1, -1), None, None, 0
    for f in range(len(flag) + 1):
        if f < len(flag) and flag[f]:
            start = f if start is None else start
            last_true, holes = f, 0
        elif start is not None and f < len(flag) and doubt[f] and holes < MAX_HOLE:
            holes += 1
        else:
            if start is not None and (best[0] < 0 or last_true - start > best[1] - best[0]):
                best = (start, last_true)
            start, holes = None, 0
    return best


def detect(data: np.ndarray, chain, sigma_mm: float, n_obs: int) -> list:
    """Label swaps the within-segment distances show, strongest first: dicts with the two columns, the
    frame span (first, last), the evidence ``gain`` (log-likelihood gain net of a BIC penalty for 3
    parameters), the per-frame misfits as labelled (``keep``) and exchanged (``swap``), mm², and the
    margin ``clear`` a frame's improvement had to exceed."""
    sig2, pen = sigma_mm ** 2, np.log(max(n_obs, 2))
    out = []
    for i in range(chain.n_markers):
        for j in range(i + 1, chain.n_markers):
            keep, swap = swap_costs(data, chain, i, j)
            if keep is None:
                continue
            n_terms = len(_partners(chain, i, {i, j})) + len(_partners(chain, j, {i, j}))
            clear = 2 * sig2 * n_terms * 9          # well beyond the distances' own noise
            better = (keep - swap > clear)
            doubt = ~np.isfinite(keep) | (np.abs(keep - swap) <= clear)
            a, b = longest_run(np.nan_to_num(better, nan=0).astype(bool), doubt)
            if a < 0 or b - a + 1 < MIN_RUN:
                continue
            gain = np.nansum((keep - swap)[a:b + 1]) / (2 * sig2) - 3 * pen
            if gain > 0:
                out.append({"cols": (i, j), "span": (int(a), int(b)), "gain": float(gain), "keep": keep, "swap": swap,
                            "clear": float(clear)})
    return sorted(out, key=lambda d: -d["gain"])


class MarkerSwap(Effect):
    name = "marker_swap"
    max_proposals = 2

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        return [Proposal(self.name, {"markers": [ch.labels[d["cols"][0]], ch.labels[d["cols"][1]]],
                                     "frames": list(d["span"])},
                         d["gain"], {"cols": d["cols"], "span": d["span"], "keep": d["keep"], "swap": d["swap"]})
                for d in detect(hyp.data, ch, ctx.noise.sigma_mm, ctx.n_obs)]

    def apply(self, ctx, hyp, proposal):
        (i, j), (a, b) = proposal.payload["cols"], proposal.payload["span"]
        data, w = hyp.data.copy(), hyp.weights.copy()
        data[a:b + 1, [i, j]] = data[a:b + 1, [j, i]]
        w[a:b + 1, [i, j]] = w[a:b + 1, [j, i]]
        fresh = initial_state(hyp.chain, data)       # the swapped frames pulled the old fit far off
        fresh.term_params = hyp.fit.state.term_params
        return hyp.refit(data=data, weights=w, state=fresh, extra_params=3, effect=proposal, max_iter=15)

    def evidence(self, ctx, before, after, proposal) -> dict:
        keep, swap = proposal.payload["keep"], proposal.payload["swap"]
        return {"x": np.arange(len(keep)), "x_label": "frame", "y": np.sqrt(np.maximum(keep, 0)),
                "y_after": np.sqrt(np.maximum(swap, 0)),
                "y_label": "within-segment distance misfit (mm): as labelled / exchanged",
                "span": list(proposal.payload["span"]), "kind": "series"}
