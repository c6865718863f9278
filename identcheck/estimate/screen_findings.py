"""What the screens before a fit left out, said where it explains an error: samples read as spikes
(:mod:`identcheck.estimate.spikes`) and spans read as swapped labels (:mod:`identcheck.estimate.labels`) leave frames
with fewer markers than the file had, and an error about too few frames should not read as the file's."""
from __future__ import annotations

from identcheck.errors import InputError


def with_screen_findings(exc: InputError, swaps: list, spikes: dict | None) -> InputError:
    """`exc`, when it is about frames, with a last problem saying what the screens before the fit left out, when they
    left any out (samples read as spikes, `spikes` as :func:`identcheck.estimate.spikes.without_spikes` reports them;
    spans read as swapped labels, `swaps` as :func:`identcheck.estimate.labels.screen` does): frames missing after
    them are their doing, not the file's (random numbers under six labels lost 875 samples as spikes, and ``fit`` then
    said only two frames showed three markers a segment, where every frame of the file showed all six; ``diagnose``,
    that no two markers of a segment were seen together in 10 frames)."""
    found = []
    if spikes:
        found.append(f"{spikes.get('count', 'some')} sample(s) as spikes (jumps out and back)")
    if swaps:
        pairs = sorted({" and ".join(s["markers"]) for s in swaps})
        found.append(f"the samples of {len(swaps)} span(s) as swapped labels ({'; '.join(pairs[:6])}"
                     f"{'; ...' if len(pairs) > 6 else ''})")
    if not found or not any("frame" in p for p in exc.problems):
        return exc
    note = (f"before the fit, the screens left out {' and '.join(found)}; see the warnings. Markers that do not stay "
            "rigid on their segment read so: check that each segment's markers are on one rigid body and labelled "
            "alike throughout")
    return InputError(exc.problems + [note], source=exc.source, segment=exc.segment)
