"""Swapped marker labels, caught before a fit: a joint fitted through frames where two markers' labels are
exchanged is silently wrong, and real recordings do contain such spans (examples/real_diagnose_report.md).

Markers on one segment keep their distances apart. The model-free detector of ``diagnose``
(:func:`detect`, which ``diagnose``'s ``marker_swap`` effect also uses) compares, frame by frame, those distances as
labelled and as exchanged with their medians. A span that fits clearly better exchanged is judged
against the majority labelling, so the span is the minority. :func:`screen` leaves that span out for
the two markers, so the fit sees only the frames labelled like the rest of the trial, and it says so.
The noise scale is the distances' whole-trial scatter (skin motion included), so only exchanges far
beyond the segment's own deformation count. A wrong pair corrupts the distances of its partners too, so its span is exchanged back before the
next search (the strongest detection first), which keeps those echoes from being reported.
The input file is not touched.
"""
from __future__ import annotations

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.noise import noise_floor
from identcheck.skeleton import Skeleton
from identcheck.trial import Trial

MIN_RUN = 3          # frames
MAX_HOLE = 2         # frames of doubt (gaps, ties) bridged inside a run


def _partners(chain, col: int, exclude: set) -> np.ndarray:
    seg = chain.marker_seg[col]
    return np.array([k for k in chain.seg_markers[seg] if k not in exclude], dtype=int)


class _Distances:
    """Each marker's distances to the other markers of its segment (F, n) and their medians over frames, computed
    once per search and shared by every pair it is tested in (the medians are what make the search slow)."""

    def __init__(self, data: np.ndarray, chain):
        self.data, self.chain, self._own = data, chain, {}

    def to(self, a: int, ks: np.ndarray) -> np.ndarray:
        return np.linalg.norm(self.data[:, [a]] - self.data[:, ks], axis=2)

    def own(self, a: int, exclude: set):
        """(partner columns, their distances' medians (n,), per-frame squared misfit from them (F,)) of marker `a`,
        its partners being the other markers of its segment not in `exclude`."""
        ks = _partners(self.chain, a, exclude | {a})
        key = (a, tuple(ks))
        if key not in self._own:
            d = self.to(a, ks)
            med = np.nanmedian(d, axis=0) if len(ks) else np.zeros(0)
            self._own[key] = (ks, med, np.nansum((d - med) ** 2, axis=1))
        return self._own[key]


def swap_costs(data: np.ndarray, chain, i: int, j: int, dists: _Distances | None = None):
    """Per-frame misfit of the within-segment distances with labels i, j as given and exchanged (F,)."""
    dists = dists or _Distances(data, chain)
    Pi, Di, keep_i = dists.own(i, {j})
    Pj, Dj, keep_j = dists.own(j, {i})
    if len(Pi) + len(Pj) == 0:
        return None, None
    keep = keep_i + keep_j
    swap = np.nansum((dists.to(j, Pi) - Di) ** 2, axis=1) + np.nansum((dists.to(i, Pj) - Dj) ** 2, axis=1)
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
    dists = _Distances(data, chain)
    for i in range(chain.n_markers):
        for j in range(i + 1, chain.n_markers):
            keep, swap = swap_costs(data, chain, i, j, dists)
            if keep is None:
                continue
            n_terms = len(_partners(chain, i, {i, j})) + len(_partners(chain, j, {i, j}))
            clear = 2 * sig2 * n_terms * 9          # well beyond the distances' own noise
            better = (keep - swap > clear)
            if not np.any(better):
                continue
            doubt = ~np.isfinite(keep) | (np.abs(keep - swap) <= clear)
            a, b = longest_run(np.nan_to_num(better, nan=0).astype(bool), doubt)
            if a < 0 or b - a + 1 < MIN_RUN:
                continue
            gain = np.nansum((keep - swap)[a:b + 1]) / (2 * sig2) - 3 * pen
            if gain > 0:
                out.append({"cols": (i, j), "span": (int(a), int(b)), "gain": float(gain), "keep": keep, "swap": swap,
                            "clear": float(clear)})
    return sorted(out, key=lambda d: -d["gain"])


MAX_SWAPS = 5            # swaps looked for, strongest first, each exchanged back before the next search


def screen(model, trial) -> tuple:
    """(trial with each detected swap span set missing for its two markers, list of warnings: dicts with
    ``kind`` = "label_swap", ``markers``, ``frames`` (first, last; 0-based rows), ``file_frames`` (the same
    in the file's own numbering, as the capture software shows them) and ``message``)."""

    chain = Skeleton.from_model(model)
    present = set(trial.labels)
    if any(m not in present for m in chain.labels):
        return trial, []                 # missing markers are reported by the fit itself
    data = trial.select(chain.labels).as_array()
    segments = {s: model.segments[s].markers for s in model.segments}
    try:
        noise = noise_floor(data, chain.labels, segments)
    except InputError:
        return trial, []                 # no two markers share a segment: distances cannot tell
    # the scale is the distances' whole-trial scatter, which includes skin motion: a swap moves a distance
    # by tens of mm, skin motion by a few, and frame-to-frame noise alone (often 0.02 mm in filtered
    # recordings) would let a few mm of skin motion pass for a swap
    sigma = max(noise.sigma_mm, noise.sigma_scatter_mm)
    if not sigma > 0:
        return trial, []
    n_obs = int(np.all(np.isfinite(data), axis=2).sum())
    xyz = trial.as_array().copy()
    col = {m: i for i, m in enumerate(trial.labels)}
    warnings = []
    for _ in range(MAX_SWAPS):
        # a real swap fits well exchanged; an artefact on one marker (a bad gap edge) can merely fit better
        found = [d for d in detect(data, chain, sigma, n_obs)
                 if np.nanmedian(d["swap"][d["span"][0]:d["span"][1] + 1]) <= d["clear"]]
        if not found:
            break
        (i, j), (a, b) = found[0]["cols"], found[0]["span"]     # the strongest; others may be its echoes
        data[a:b + 1, [i, j]] = data[a:b + 1, [j, i]]              # exchanged back, to look for more
        mi, mj = chain.labels[i], chain.labels[j]
        xyz[a:b + 1, [col[mi], col[mj]]] = np.nan
        fa, fb = trial.frame_number(a), trial.frame_number(b)
        warnings.append({"kind": "label_swap", "markers": [mi, mj], "frames": [int(a), int(b)],
                         "file_frames": [fa, fb],
                         "message": f"{trial.source}: markers {mi} and {mj} look swapped in frames {fa}-{fb} of the file "
                                    f"(rows {a}-{b}; there, their "
                                    f"distances to the other markers of their segments fit clearly better exchanged than "
                                    f"as labelled in the rest of the trial); those frames are left out for these two "
                                    f"markers. Which labelling is right, only a reference (static) trial can tell: check "
                                    f"the labels."})
    if not warnings:
        return trial, []
    return trial.replace(xyz=xyz), warnings
