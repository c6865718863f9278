"""The backward check of a diagnosis: an effect adopted early is tested again once later ones are in the model.

The forward search adopts, each round, the effect that explains most of what is left. While the true effect is not
yet modelled, a flexible wrong one can take part of it: skin moving with the hip's angles absorbs much of a thigh
whose samples lag by a few frames, because the lag's residual also follows the motion. Once the delay is adopted,
the skin terms only repeat it, yet they stay first in the report. So when the search has nothing left to adopt,
every adopted effect but the newest is judged again given all the others, by the forward step's own rule
(:func:`identcheck.diagnose.workflow.needed`): the hypothesis is rebuilt without it (from the one before it, the
effects after it applied again in their order), and the effect is kept only if that rule would adopt it there. This
is the backward half of stepwise selection; it drops nothing the data still need, and what it drops cannot return
(:func:`identcheck.diagnose.workflow.diagnose` never proposes it at that place again), so the search ends.
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
    the others (criterion units, at most the rule's bar), the remaining effects (those after it applied again), and
    the hypothesis after each of them (from the index on, the rebuilt ones)."""

    index: int
    gain: float
    kept: tuple
    rebuilt: tuple


def rebuild(ctx, start: Hypothesis, adopted: list, polish_iter: int) -> tuple[tuple, tuple]:
    """(the effects as applied again, the hypothesis after each): `adopted` applied in order from `start`, the last
    refitted for `polish_iter` more iterations (the others carry the fits of their augmentations;
    :func:`identcheck.diagnose.workflow.restated` fits them to convergence if the rebuild is kept). Each is applied
    from a copy of its proposal (an augmentation writes what it fitted into the proposal: a delay, an outlier mask),
    so a rebuild that is not kept leaves the diagnosis as it was."""
    again, out, h = [], [], start
    for a in adopted:
        p = a.proposal
        copy = Adopted(a.effect, Proposal(p.effect, dict(p.where), p.strength, dict(p.payload)))
        h = a.effect.apply(ctx, h, copy.proposal)
        again.append(copy)
        out.append(h)
    if out:
        out[-1] = out[-1].polish(max_iter=polish_iter)
    return tuple(again), tuple(out)


def redundant(ctx, trail: list, adopted: list, judge, polish_iter: int) -> Redundant | None:
    """The earlier adopted effect (any but the newest) that the others make unnecessary, the one gaining least
    where there are several; None when each still earns its place.

    `trail` holds the hypotheses of the search: the rigid fit, then the hypothesis after each adopted effect. The
    model without effect k is rebuilt from the hypothesis before it, the effects after it applied again in their
    order (those before it are as they were). ``judge(without, effect) -> (gain, needed)`` is the forward rule asked
    of the adopted `effect` given the others: what the full hypothesis gains over `without` (criterion units), and
    whether the search would adopt that effect gaining that much there. The model without the effect is refitted for `polish_iter`
    iterations after the augmentations' own fits, not to convergence: further iterations only lower its residual, so
    an effect found unnecessary there is unnecessary at convergence too, and one kept is kept with the benefit of the
    doubt. An effect whose removal the rebuild cannot fit (a singular system, an effect that no longer applies) is
    kept, and so is one without which a later effect, applied again, is not what it claims
    (:meth:`identcheck.effects.base.Effect.implausible`)."""
    found = None
    for k in range(len(adopted) - 1):
        try:
            tail, hyps = rebuild(ctx, trail[k], adopted[k + 1:], polish_iter)
        except (np.linalg.LinAlgError, ValueError):
            continue
        why = next((a.effect.implausible(a.proposal) for a in tail if a.effect.implausible(a.proposal)), "")
        if why:
            # without it a later effect cannot be what it claims (a knee's second rotation taking up the skin motion
            # the dropped effect had modelled, beyond play): the effect is kept, as the forward search would not
            # adopt what remained
            log.debug("backward check: %s %s kept: without it %s", adopted[k].effect.name, adopted[k].proposal.where,
                      why)
            continue
        gain, needed = judge(hyps[-1], adopted[k])
        log.debug("backward check: %s %s gains %.1f given the others (%s)", adopted[k].effect.name,
                  adopted[k].proposal.where, gain, "kept" if needed else "not needed")
        if needed:
            continue
        if found is None or gain < found.gain:
            found = Redundant(k, float(gain), tuple(adopted[:k]) + tail, tuple(trail[1:k + 1]) + hyps)
    return found
