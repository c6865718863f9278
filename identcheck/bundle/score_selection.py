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

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from identcheck.bundle.chain import quadratic_form


@dataclass(frozen=True)
class Selection:
    """The units chosen (indices into the units given, in the order they were added), the fields they hold (sorted
    indices into the moments), the parameters charged for choosing them (:func:`choice_params`), and the
    criterion's gain of those fields to first order, that charge included."""

    units: tuple
    columns: tuple
    gain: float
    choice_params: int = 0


def choice_params(n_units: int, n_chosen: int, per_param: float | None) -> int:
    """What choosing `n_chosen` of `n_units` costs, in parameters of the criterion (each `per_param` units of it,
    ln(3N) for the Bayesian information criterion): the extended criterion's ``2 ln C(n_units, n_chosen)`` (Chen and
    Chen 2008, γ = 1: every subset of a size equally likely a priori, every size too), rounded up to whole parameters
    (:attr:`identcheck.bundle.hypothesis.Hypothesis.extra_params` counts discrete choices so). Without it, the best
    of many subsets earns its parameters on noise more often than any one of them would: 53 single fields of white
    noise, each a χ²(1), give one above ln(3N) ≈ 10 in about 7 % of trials. None when `per_param` is None."""
    if per_param is None or n_chosen <= 0 or n_chosen >= n_units:
        return 0
    return int(math.ceil(2.0 * math.log(math.comb(n_units, n_chosen)) / per_param))


def forward_selection(n: np.ndarray, G: np.ndarray, units: list, gain: Callable[[float, int], float],
                      per_param: float | None = None) -> Selection:
    """The subset of `units` (each a list of field indices into the moments ``(n, G)``, disjoint) the criterion
    prefers among those greedy forward selection visits: starting from none, add the unit that gives the largest
    ``gain(statistic, number of fields + choice_params)`` (the statistic ``n_Sᵀ G_SS⁺ n_S``; units may differ in
    size, so the statistic alone would not do; :func:`choice_params` charges the choice among the subsets of that
    many units when `per_param` is given), until every unit is in; of these nested subsets (the whole set is the
    last of them) return the one with the largest gain, even when no gain is positive (then nothing earns its
    parameters, and the caller's proposal says so by its strength).

    Greedy, so not the best of all subsets, but never worse than the best single unit (the first step) or all of
    them (the last), each with its charge; the number of statistics it evaluates is quadratic in the number of units,
    each on the moments only. An empty `units` gives an empty selection with the gain of nothing, ``gain(0, 0)``."""
    chosen: list = []
    left = list(range(len(units)))
    best = Selection((), (), float(gain(0.0, 0)))
    while left:
        charge = choice_params(len(units), len(chosen) + 1, per_param)

        def scored(u):  # noqa: E306 - the gain of the chosen units with u added
            cols = sorted(c for k in chosen + [u] for c in units[k])
            return float(gain(quadratic_form(n[cols], G[np.ix_(cols, cols)]), len(cols) + charge))
        gains = [scored(u) for u in left]
        k = int(np.argmax(gains))
        chosen.append(left.pop(k))
        if gains[k] > best.gain or not best.units:
            best = Selection(tuple(chosen), tuple(sorted(c for u in chosen for c in units[u])), gains[k], charge)
    return best
