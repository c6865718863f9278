"""Which of an effect's functions the data ask for: forward selection on the score test's moments.

An effect modelled by a family of functions (a joint centre moving with every product and cube of its angles: 9
functions in 3 directions for a ball joint, 31 parameters with its linear part) pays for all of them in the
criterion, however few carry the motion. A hip pistoning with its flexion (held-out draw 50, trial 35) showed
its whole translation estimated at 343 criterion units less 322 for its 31 parameters, where one function of the
flexion in three directions alone estimated 278 net; a one-frame delay of a pelvis marker (130) was named instead.
The statistic of any subset of the fields follows from the moments of all of them
(:func:`identcheck.bundle.score_test.score_moments`), so the subsets are compared without touching the data again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Selection:
    """The units chosen (indices into the units given, in the order they were added), the fields they hold (sorted
    indices into the moments: rows, when the moments are a matrix), the parameters charged for choosing them
    (:func:`choice_params`), and the criterion's gain of those fields to first order, that charge included."""

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
    them (the last), each with its charge. Each step adds to the statistic of the chosen fields C what a unit U adds
    to it, ``trace(r_Uᵀ D_U⁺ r_U)`` with ``r_U = n_U − G_UC G_CC⁺ n_C`` and ``D_U = G_UU − G_UC G_CC⁺ G_CU`` (the
    moments of U with C regressed out: the statistic of C ∪ U is that of C plus this), so a step costs one
    pseudo-inverse of the chosen fields' block, not one of every candidate's union (on a 42-marker body, skin's
    selections had made 17 700 of them a round, 1.3 CPU s). An empty `units` gives an empty selection with the gain
    of nothing, ``gain(0, 0)``.

    With `n` a matrix (k, w), each row is a function with a free w-vector whose directions share the Gram matrix `G`
    (k, k) (:func:`~identcheck.bundle.score_test.quadratic_form`): a unit's rows count w fields each."""
    width = n.shape[1] if np.ndim(n) == 2 else 1
    moments = np.asarray(n, dtype=float).reshape(len(n), width)      # (fields, w): one column unless n is a matrix
    chosen: list = []
    cols: list = []
    stat = 0.0
    left = list(range(len(units)))
    best = Selection((), (), float(gain(0.0, 0)))
    while left:
        charge = choice_params(len(units), len(chosen) + 1, per_param)
        if cols:
            B = G[:, cols] @ np.linalg.pinv(G[np.ix_(cols, cols)], rcond=1e-10, hermitian=True)
            resid, D = moments - B @ moments[cols], G - B @ G[cols, :]
        else:
            resid, D = moments, G
        added = _added_each(resid, D, G, [units[u] for u in left])
        gains = [float(gain(stat + a, width * (len(cols) + len(units[u])) + charge)) for a, u in zip(added, left)]
        k = int(np.argmax(gains))
        stat += added[k]
        cols += list(units[left[k]])
        chosen.append(left.pop(k))
        if gains[k] > best.gain or not best.units:
            best = Selection(tuple(chosen), tuple(sorted(cols)), gains[k], charge)
    return best


def _added_each(resid: np.ndarray, D: np.ndarray, G: np.ndarray, units: list) -> list:
    """What each of `units` adds to the statistic given the chosen fields: ``trace(r_Uᵀ D_U⁺ r_U)`` (`resid`, `D`: the
    moments and the Gram matrix with the chosen fields regressed out). Single fields at once (a skin term's functions,
    a translation's linear fields), ``r_u² / D_uu``; a field the chosen ones already span (its ``D`` within 1e-10 of
    its own ``G``, the pseudo-inverse's cut) adds nothing. A unit of several fields through its block's
    pseudo-inverse."""
    out = np.zeros(len(units))
    single = [i for i, u in enumerate(units) if len(u) == 1]
    if single:
        idx = np.array([units[i][0] for i in single])
        d, g = np.diagonal(D)[idx], np.diagonal(G)[idx]
        spanned = d <= 1e-10 * np.maximum(g, 1e-300)
        out[single] = np.where(spanned, 0.0, np.sum(resid[idx] ** 2, axis=1) / np.where(spanned, 1.0, d))
    for i, u in enumerate(units):
        if len(u) > 1:
            r = resid[u]
            out[i] = np.sum(r * (np.linalg.pinv(D[np.ix_(u, u)], rcond=1e-10, hermitian=True) @ r))
    return out.tolist()
