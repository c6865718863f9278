"""Which of an effect's functions the data ask for: forward selection on the score test's moments.

An effect modelled by a family of functions (a joint centre moving with every product and cube of its angles: 9
functions in 3 directions for a ball joint, 31 parameters with its linear part) pays for all of them in the
criterion, however few carry the motion. A hip pistoning with its flexion (held-out draw 50, trial 35) showed
its whole translation estimated at 343 criterion units less 322 for its 31 parameters, where one function of the
flexion in three directions alone estimated 278 net; a one-frame delay of a pelvis marker (130) was named instead.
The statistic of any subset of the fields follows from the moments of all of them
(:func:`identcheck.bundle.chain.score_moments`), so the subsets are compared without touching the data again.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from identcheck.bundle.chain import quadratic_form


@dataclass(frozen=True)
class Selection:
    """The units chosen (indices into the units given, in the order they were added), the fields they hold (sorted
    indices into the moments), and the criterion's gain of those fields to first order."""

    units: tuple
    columns: tuple
    gain: float


def forward_selection(n: np.ndarray, G: np.ndarray, units: list, gain: Callable[[float, int], float]) -> Selection:
    """The subset of `units` (each a list of field indices into the moments ``(n, G)``, disjoint) the criterion
    prefers among those greedy forward selection visits: starting from none, add the unit that gives the largest
    ``gain(statistic, number of fields)`` (the statistic ``n_Sᵀ G_SS⁺ n_S``; units may differ in size, so the
    statistic alone would not do), until every unit is in; of these nested subsets (the whole set is the last of
    them) return the one with the largest gain, even when no gain is positive (then nothing earns its parameters,
    and the caller's proposal says so by its strength).

    Greedy, so not the best of all subsets, but never worse than the best single unit (the first step) or all of
    them (the last); the number of statistics it evaluates is quadratic in the number of units, each on the
    moments only. An empty `units` gives an empty selection with the gain of nothing, ``gain(0, 0)``."""
    chosen: list = []
    left = list(range(len(units)))
    best = Selection((), (), float(gain(0.0, 0)))
    while left:
        def scored(u):  # noqa: E306 - the gain of the chosen units with u added
            cols = sorted(c for k in chosen + [u] for c in units[k])
            return float(gain(quadratic_form(n[cols], G[np.ix_(cols, cols)]), len(cols)))
        gains = [scored(u) for u in left]
        k = int(np.argmax(gains))
        chosen.append(left.pop(k))
        if gains[k] > best.gain or not best.units:
            best = Selection(tuple(chosen), tuple(sorted(c for u in chosen for c in units[u])), gains[k])
    return best
