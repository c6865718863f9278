"""One round of a diagnosis: fit the effects' proposals, strongest first, each net of what the rigid fit gains by
iterating on, skipping places far weaker than the best fitted so far.

The rule that skips a proposal depends on the scores of those fitted before it, so the round is sequential in
what it decides. It need not be in what it computes: while one proposal is fitted, the next one is fitted beside
it on another thread (NumPy releases the GIL in its array work) when the rule is sure to fit it whatever the
first one scores, as it is for each effect's first place. The fits, their scores and their order are those of
the one-thread round, whatever the number of threads. (Starting whichever proposal the rule would fit as things
stand, and discarding it when the first one's score changed that, cost more than it saved: the discarded fits
held the GIL against the one being waited for.)
"""
from __future__ import annotations

import logging
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from identcheck.bundle.hypothesis import Context, Hypothesis, score

log = logging.getLogger("identcheck")

SKIP_RATIO = 10.0
"""Proposals are fitted strongest first. Every effect's strongest place is fitted whenever its detector clears
the bar: effects are compared by their fitted scores, never by their detectors' estimates, which are not on one
scale (a hip centre pistoning in the pelvis: the markers' mean residual seen from the pelvis estimated 1 816
where the fit scored 22 930, and skin on the thigh, estimated 5 020, scored 20 013 and was named instead). An
effect's further places are not fitted this round when their strength is below 1/SKIP_RATIO of the best score
fitted so far, unless the effect leads (a delay's linearised detector cannot tell which segment lags when the
lag is several frames) or is marked ``always_fit`` (a swap's strength is read from distances, not from the
residual)."""
CREEP_ITER = 12
"""Iterations of the null refit each round: what a candidate's refit gains by iterating on, without its
effect, is not the effect's (:func:`creep`)."""


def creep(ctx: Context, h: Hypothesis) -> float:
    """What refitting `h` as it is gains (:data:`CREEP_ITER` more iterations, no effect added), in the
    criterion's units (≥ 0): the rigid fit of data an effect corrupts creeps on for long, and every candidate's
    refit takes that gain too, so each candidate's score is counted net of it."""
    return max(score(ctx, h.refit(max_iter=CREEP_ITER), h), 0.0)


class _Round:
    """The skipping rule's state: the best score fitted so far, the effect that scored it, the effects placed."""

    def __init__(self):
        self.best, self.leader, self.placed = 0.0, None, set()

    def fits(self, prop, eff) -> bool:
        """Whether the rule fits `prop` now (each effect's first place, other places of the leader, effects whose
        strength is no estimate of their score, and places whose strength is within SKIP_RATIO of the best)."""
        return not (eff.name in self.placed and prop.strength * SKIP_RATIO < self.best and eff is not self.leader
                    and not eff.always_fit)

    def next_certain(self, candidates: list, i: int) -> int | None:
        """The candidate after `i` that the rule will fit next whatever `i` scores, or None when that depends on
        the score: those in between must be skipped now and stay skipped (the best only grows; but `i`'s effect
        may come to lead, and a further place of the leader is fitted), and it must be fitted anyway (its
        effect's first place, or an effect fitted always)."""
        current = candidates[i][1]
        for j in range(i + 1, len(candidates)):
            prop, eff = candidates[j]
            if eff.always_fit or (eff.name not in self.placed and eff is not current):
                return j
            if self.fits(prop, eff) or eff is current:
                return None
        return None


def fit_candidates(ctx: Context, h: Hypothesis, candidates: list, threads: int = 1, progress=None,
                   step: int = 1) -> list:
    """The round's fitted candidates [(score, effect, proposal, hypothesis)], in the order fitted.

    `candidates` are (proposal, effect) strongest first, each already past the bar and not adopted before;
    `threads` > 1 fits the next candidate speculatively beside the current one (see the module)."""
    state = _Round()
    tried, drift = [], None
    with ThreadPoolExecutor(max(1, threads)) as pool:
        ahead: dict[int, Future] = {}

        def start(i: int) -> Future:
            if i not in ahead:
                prop, eff = candidates[i]
                ahead[i] = pool.submit(eff.apply, ctx, h, prop)
            return ahead[i]

        def start_next(i: int) -> None:
            """Start the candidate the rule fits after `i`, if that is already certain whatever `i` scores."""
            j = state.next_certain(candidates, i)
            if j is not None:
                start(j)

        for i, (prop, eff) in enumerate(candidates):
            if not state.fits(prop, eff):
                log.debug("%s %s skipped: its detector strength is far below the best fit", eff.name, prop.where)
                ahead.pop(i, None)
                continue
            state.placed.add(eff.name)
            if progress:
                progress(f"step {step}: trying {eff.name} {prop.where}")
            job = start(i)
            if threads > 1:
                start_next(i)
            try:
                cand = job.result()
            except (np.linalg.LinAlgError, ValueError) as exc:
                log.debug("%s %s failed: %s", eff.name, prop.where, exc)
                continue
            finally:
                ahead.pop(i, None)
            drift = creep(ctx, h) if drift is None else drift
            sc = score(ctx, cand, h) - drift
            tried.append((sc, eff, prop, cand))
            if not eff.implausible(prop) and sc > state.best:
                state.best, state.leader = sc, eff
    return tried
