"""What one more marker would buy (``plan --noise-mm``): each segment given one added marker, the practical intervals
that capture would give, ranked by the millimetres it saves.

The prediction of :mod:`identcheck.fit.predict` linearises the whole-tree fit at the noise-free simulated capture.
There the fitted skeleton reproduces every marker, so a marker added to a segment needs no new fit: its position
in the segment's frame is a new constant, its trajectory follows from the segment's fitted poses, and the
information of the enlarged plan at that same truth gives every joint's predicted standard errors with it. The
added marker sits where a skin marker would: off the segment's long axis, :data:`OFFSET_MM` from the middle of what
the segment already carries (its markers and joint centres), along the direction those points spread least.

A joint's interval is its widest marker distance's 95 % half-width (``fit``'s practical rule), a distance the
motion leaves free counting as :data:`CAP_MM`; a suggestion's ``mm_saved`` is the sum over the joints of how much it
narrows them, each capped at :data:`CAP_MM` (so one joint that goes from free to determined counts as much as a
wide interval that closes). Only the information is recomputed: rivals the added marker might now reject are not
searched again, and the structural verdicts of the enlarged plan are ``plan``'s own (its ``suggestions``).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from identcheck.bundle.chain import information
from identcheck.bundle.model import Fit, forward
from identcheck.bundle.practical import TOLERANCE_MM, Z95
from identcheck.bundle.uncertainty import chain_inverse, distance_gradients, moves_along_free
from identcheck.skeleton import Skeleton

OFFSET_MM = 60.0
CAP_MM = 100.0
ADDED = "+{segment}"
"""Name of the marker added to a segment (with more ``+`` in front while a marker of the model has that name)."""


def added_point(chain: Skeleton, state, segment: str) -> np.ndarray:
    """Where the added marker sits in ``segment``'s frame (see the module docstring)."""
    pts = [state.local[i] for i in chain.seg_markers[segment]]
    pts += [state.c_parent[j] for j in chain.joints if chain.parent[j] == segment]
    pts += [state.c_child[j] for j in chain.joints if chain.child[j] == segment]
    P = np.array(pts, dtype=float).reshape(-1, 3)
    centre = P.mean(axis=0)
    normal = np.linalg.svd(P - centre)[2][-1] if len(P) >= 2 else np.array([1.0, 0.0, 0.0])
    return centre + OFFSET_MM * normal


def standard_errors(chain: Skeleton, state, S: np.ndarray, noise_mm: float) -> dict:
    """joint -> marker -> predicted standard error of its distance, mm, from the information ``S`` (per unit noise
    variance); ``inf`` for a distance the information leaves free."""
    Sinv, undetermined, null = chain_inverse(chain, state, S)
    return {j: {m: (np.inf if moves_along_free(g, null, undetermined)
                    else noise_mm * float(np.sqrt(max(g @ Sinv @ g, 0.0)))) for m, (_, g) in by.items()}
            for j, by in distance_gradients(chain, state, len(S)).items()}


def half_widths(chain: Skeleton, state, S: np.ndarray, noise_mm: float) -> dict:
    """joint -> its widest marker distance's predicted 95 % half-width, mm, capped at :data:`CAP_MM` (a free
    distance counts as the cap)."""
    return {j: min(Z95 * max(se.values(), default=0.0), CAP_MM)
            for j, se in standard_errors(chain, state, S, noise_mm).items()}


def enlarged_information(model, fit: Fit, segment: str) -> tuple:
    """(enlarged chain, its state, its noise-free predictions, its information): :func:`with_added_marker` and
    the information of the enlarged plan at that truth."""
    chain, state, pred = with_added_marker(model, fit, segment)
    return chain, state, pred, information(replace(fit, chain=chain, state=state, pred=pred), pred)


def added_name(model, segment: str) -> str:
    """The added marker's name on ``segment``: :data:`ADDED`, never one of the model's own markers."""
    name = ADDED.format(segment=segment)
    while name in model.markers:
        name = "+" + name
    return name


def with_added_marker(model, fit: Fit, segment: str) -> tuple:
    """(enlarged chain, its state, its noise-free predictions): ``fit``'s skeleton with one marker added to
    ``segment`` at :func:`added_point`."""
    name = added_name(model, segment)
    seg = model.segments[segment]
    bigger = replace(model, segments={**model.segments, segment: replace(seg, markers=seg.markers + (name,))})
    chain = Skeleton.from_model(bigger, types=dict(fit.chain.types), markers=set(fit.chain.labels) | {name})
    rows = {m: fit.state.local[i] for i, m in enumerate(fit.chain.labels)}
    rows[name] = added_point(fit.chain, fit.state, segment)
    state = fit.state.copy()
    state.local = np.array([rows[m] for m in chain.labels])
    _, _, _, pred = forward(chain, fit.terms, state)
    return chain, state, pred


def marker_value(model, fit: Fit, noise_mm: float, progress=None) -> list:
    """One suggestion per segment, best first: ``{"segment", "marker_at_mm", "mm_saved", "joints": {joint:
    {"before_mm", "after_mm"}}, "determined_after": [joints whose interval falls within the practical tolerance
    only with it]}`` (see the module docstring). ``fit``: the whole-tree fit of the noise-free capture."""
    _, _, _, pred = forward(fit.chain, fit.terms, fit.state)
    before = half_widths(fit.chain, fit.state, information(fit, pred), noise_mm)
    out = []
    for k, segment in enumerate(fit.chain.segments):
        if progress:
            progress(f"one more marker: {segment} ({k + 1} of {len(fit.chain.segments)})")
        chain, state, _, S = enlarged_information(model, fit, segment)
        after = half_widths(chain, state, S, noise_mm)
        point = state.local[chain.labels.index(added_name(model, segment))]
        out.append({"segment": segment, "marker_at_mm": [round(float(x), 1) for x in point],
                    "mm_saved": round(sum(before[j] - after[j] for j in before), 2),
                    "joints": {j: {"before_mm": round(before[j], 2), "after_mm": round(after[j], 2)}
                               for j in before if round(after[j], 2) < round(before[j], 2)},
                    "determined_after": [j for j in before if before[j] > TOLERANCE_MM >= after[j]]})
    out.sort(key=lambda s: (-len(s["determined_after"]), -s["mm_saved"], s["segment"]))
    return out
