"""A closed-form joint estimate is computed once for the same points (:func:`identcheck.estimate.closed_forms.
estimate_once`): a call with equal arrays gives the earlier answer, as a copy, and its warnings again; any change of a
point, or of the warning filters, computes it again; and the model's closed forms come out the same from a cold or a
warm cache."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.estimate import closed_forms
from identcheck.estimate.closed_forms import estimate_once, fit_model
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@dataclass
class _Answer:
    value: float
    notes: list = field(default_factory=list)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60), where=st.integers(0, 10**6))
def test_equal_points_are_estimated_once_and_any_change_again(seed, n, where):
    rng = np.random.default_rng(seed)
    P, C = [rng.normal(size=(n, 3)) for _ in range(2)], [rng.normal(size=(n, 3))]
    calls = []
    closed_forms._cache.clear()                                  # (an example may be drawn twice)

    def estimator(parent, child, case):
        calls.append(case)
        return _Answer(float(sum(a.sum() for a in parent + child)))

    first = estimate_once(estimator, P, C, "revolute", f"revolute(2,1) {seed}")
    again = estimate_once(estimator, [a.copy() for a in P], [a.copy() for a in C], "revolute",
                          f"revolute(2,1) {seed}")
    assert len(calls) == 1 and again == first and again is not first
    again.notes.append("marked by a caller")                     # a caller's marks stay its own
    assert estimate_once(estimator, P, C, "revolute", f"revolute(2,1) {seed}").notes == []
    changed = [a.copy() for a in C]
    changed[0].flat[where % changed[0].size] += 1e-9 * (1.0 + abs(changed[0].flat[where % changed[0].size]))
    estimate_once(estimator, P, changed, "revolute", f"revolute(2,1) {seed}")
    estimate_once(estimator, P, C, "spherical", f"revolute(2,1) {seed}")      # another kind: another estimator
    assert len(calls) == 3


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    arrays = [(getattr(a, k), getattr(b, k)) for k in ("centre", "point", "direction")]
    return (a.unique == b.unique and len(a.alternatives) == len(b.alternatives) and a.rms_residual == b.rms_residual
            and all((x is None and y is None) or np.array_equal(x, y, equal_nan=True) for x, y in arrays))


def test_the_model_closed_forms_are_the_same_from_a_cold_and_a_warm_cache():
    """A sparse leg (its (2, 1) hinge among four candidates decided by a far marker): every joint alike."""
    model = Model.from_toml(EXAMPLES / "sparse_leg.toml")
    trial = simulate(model, n_frames=300, noise_mm=0.5, seed=4).trial
    closed_forms._cache.clear()
    cold = fit_model(model, trial)[0]
    warm = fit_model(model, trial)[0]
    assert len(closed_forms._cache) >= 1
    assert all(_same(cold[j][0], warm[j][0]) for j in model.joint_order)


def test_the_warnings_an_estimate_gave_are_given_again_and_filters_keep_answers_apart():
    """A verb reports the warnings the estimators give (a sphere centre the motion barely determines): a kept
    answer gives them again. An estimate's notes record warnings as the filters in force let them through, so an
    answer computed with warnings ignored is not handed out where they are shown."""
    closed_forms._cache.clear()
    P, C = [np.arange(6.0).reshape(2, 3)], [np.ones((2, 3))]
    calls = []

    def estimator(parent, child, case):
        calls.append(case)
        with warnings.catch_warnings(record=True) as caught:           # as the estimators keep notes
            warnings.warn("residuals correlated", UserWarning)
        warnings.warn("the motion barely determines it", UserWarning)     # for the verb to report
        return _Answer(1.0, [str(w.message) for w in caught])

    for _ in range(2):
        with warnings.catch_warnings(record=True) as shown:
            warnings.simplefilter("always")
            got = estimate_once(estimator, P, C, "spherical", "spherical(3,1)")
        assert [str(w.message) for w in shown] == ["the motion barely determines it"]
        assert got.notes == ["residuals correlated"]
    assert len(calls) == 1
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("ignore")
        quiet = estimate_once(estimator, P, C, "spherical", "spherical(3,1)")
    assert len(calls) == 2 and quiet.notes == [] and not shown
