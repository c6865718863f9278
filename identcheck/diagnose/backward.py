"""The backward check of a diagnosis: an effect adopted early is tested again once later ones are in the model.

The forward search adopts, each round, the effect that explains most of what is left. While the true effect is not
yet modelled, a flexible wrong one can take part of it: skin moving with the hip's angles absorbs much of a thigh
whose samples lag by a few frames, because the lag's residual also follows the motion. Once the delay is adopted,
the skin terms only repeat it, yet they stay first in the report. So every adopted effect but the newest is judged
again given all the others, by the forward step's own rule (:func:`identcheck.diagnose.workflow.needed`): the
hypothesis is rebuilt from the rigid fit with the other effects applied in their order, and the effect is kept only
if that rule would adopt it there. This is the backward half of stepwise selection; it drops nothing the data still
need, and what it drops cannot return (:func:`identcheck.diagnose.workflow.diagnose` never proposes it at that place
again), so the search ends.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from identcheck.bundle.hypothesis import Hypothesis
from identcheck.effects.base import Effect, Proposal

log = logging.getLogger("identcheck")


@dataclass(frozen=True)
class Adopted:
    """One adopted effect as the search applied it: the effect and its (fitted) proposal."""

    effect: Effect
    proposal: Proposal


@dataclass(frozen=True)
class Redundant:
    """An adopted effect the others make unnecessary: its index among the adopted, what it still gains given
    the others (criterion units, at most the rule's bar), the remaining effects as applied again, and the
    hypothesis after each of them."""

    index: int
    gain: float
    kept: tuple
    rebuilt: tuple


def rebuild(ctx, base: Hypothesis, adopted: list) -> tuple[tuple, tuple]:
    """(the effects as applied again, the hypothesis after each): `adopted` applied in order from `base`, the last
    fitted to convergence as the forward search polishes what it adopts (the others carry the fits of their
    augmentations; :func:`identcheck.diagnose.workflow.restated` polishes them if the rebuild is kept). Each is
    applied from a copy of its proposal (an augmentation writes what it fitted into the proposal: a delay, an
    outlier mask), so a rebuild that is not kept leaves the diagnosis as it was."""
    again, out, h = [], [], base
    for a in adopted:
        p = a.proposal
        copy = Adopted(a.effect, Proposal(p.effect, dict(p.where), p.strength, dict(p.payload)))
        h = a.effect.apply(ctx, h, copy.proposal)
        again.append(copy)
        out.append(h)
    out[-1] = out[-1].polish()
    return tuple(again), tuple(out)


def redundant(ctx, base: Hypothesis, adopted: list, judge) -> Redundant | None:
    """The earlier adopted effect (any but the newest) that the others make unnecessary, the one gaining least
    where there are several; None when each still earns its place.

    ``judge(without) -> (gain, needed)`` is the forward rule asked of an effect given the others: what the full
    hypothesis gains over `without` (the hypothesis rebuilt without the effect; criterion units), and whether the
    search would adopt an effect gaining that much there. An effect whose removal the rebuild cannot fit (a
    singular system, an effect that no longer applies) is kept."""
    found = None
    for k in range(len(adopted) - 1):
        rest = adopted[:k] + adopted[k + 1:]
        try:
            kept, hyps = rebuild(ctx, base, rest)
        except (np.linalg.LinAlgError, ValueError):
            continue
        gain, needed = judge(hyps[-1])
        log.debug("backward check: %s %s gains %.1f given the others (%s)", adopted[k].effect.name,
                  adopted[k].proposal.where, gain, "kept" if needed else "not needed")
        if needed:
            continue
        if found is None or gain < found.gain:
            found = Redundant(k, float(gain), kept, hyps)
    return found
