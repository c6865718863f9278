"""Swapped marker labels, caught before a fit: a joint fitted through frames where two markers' labels are
exchanged is silently wrong, and real recordings do contain such spans (examples/real_diagnose_report.md).

Markers on one segment keep their distances apart. The model-free detector of ``diagnose``
(:func:`identcheck.diagnose.effects.marker_swap.detect`) compares, frame by frame, those distances as
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

from ..errors import InputError

MAX_SWAPS = 5            # swaps looked for, strongest first, each exchanged back before the next search


def screen(model, trial) -> tuple:
    """(trial with each detected swap span set missing for its two markers, list of warnings)."""
    from ..diagnose.chain import Chain
    from ..diagnose.effects.marker_swap import detect
    from ..diagnose.noise import noise_floor
    from ..trial import Trial

    chain = Chain.from_model(model)
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
        warnings.append(f"{trial.source}: markers {mi} and {mj} look swapped in frames {a}-{b} (there, their distances "
                        f"to the other markers of their segments fit clearly better exchanged than as labelled in the "
                        f"rest of the trial); those frames are left out for these two markers. Which labelling is "
                        f"right, only a reference (static) trial can tell: check the labels.")
    if not warnings:
        return trial, []
    return Trial(xyz, trial.labels, trial.rate_hz, trial.source), warnings
