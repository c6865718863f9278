"""The score tests' fields projected in stacks (:func:`identcheck.bundle.score_test.stacked`): several stacks give what
one gives, a stack is never a field of another shape, and the caller's fields are left as they were."""
from __future__ import annotations

from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.bundle import score_test
from identcheck.bundle.score_test import modulated_score_moments, score_moments, stacked, unabsorbed, unabsorbed_gram
from tests.bundle.test_projection_reuse import _hypothesis


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**16), per_stack=st.integers(1, 4))
def test_several_stacks_give_what_one_gives(seed, per_stack):
    """Seven random fields (some NaN) on a fitted leg with gaps, in stacks of 1-4 fields: the Gram matrix, the
    unabsorbed norms, the score moments and the modulated moments equal those of one stack (to 1e-7 of their scale:
    another order of sums), and the fields are not changed."""
    h = _hypothesis(seed, 0.1)
    rng = np.random.default_rng(seed)
    fields = [rng.normal(size=h.data.shape) for _ in range(7)]
    fields[2][rng.uniform(size=h.data.shape) < 0.1] = np.nan
    copies = [f.copy() for f in fields]
    basis = rng.normal(size=(h.data.shape[0], 2))

    def all_of():
        return (unabsorbed_gram(h.fit, h.weights, fields, h.projection),
                np.array(unabsorbed(h.fit, h.weights, fields, h.projection)),
                *score_moments(h.fit, h.weights, h.residuals(), [fields], h.projection)[0],
                *modulated_score_moments(h.fit, h.weights, h.residuals(), fields[:3], [basis], h.projection)[0])
    one = all_of()
    with mock.patch.object(score_test, "FIELD_CHUNK_ENTRIES", per_stack * h.data.size):
        many = all_of()
    for a, b in zip(many, one):
        np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-7 * float(np.max(np.abs(b))))
    for f, c in zip(fields, copies):
        np.testing.assert_array_equal(f, c)


def test_a_field_of_another_shape_is_refused():
    with pytest.raises(ValueError, match="shape"):
        list(stacked([np.ones((4, 2, 3)), np.arange(3.0)]))


@settings(max_examples=30, deadline=None)
@given(sizes=st.lists(st.integers(1, 4), min_size=1, max_size=9), per_stack=st.integers(1, 8))
def test_a_unit_of_fields_stays_in_one_stack(sizes, per_stack):
    """Items of one field (F, M, 3) and units of several (F, M, 3, q) come out in their order, each unit whole in one
    stack, no stack beyond the entries allowed unless one unit alone is larger."""
    rng = np.random.default_rng(len(sizes) * 10 + per_stack)
    items = [rng.normal(size=(5, 2, 3)) if q == 1 and rng.random() < 0.5 else rng.normal(size=(5, 2, 3, q))
             for q in sizes]
    with mock.patch.object(score_test, "FIELD_CHUNK_ENTRIES", per_stack * 30):
        stacks = list(stacked(iter(items)))
    columns = [x[..., None] if x.ndim == 3 else x for x in items]
    np.testing.assert_array_equal(np.concatenate(stacks, axis=-1), np.concatenate(columns, axis=-1))
    ends = np.cumsum([s.shape[-1] for s in stacks])
    starts = np.cumsum([0] + [c.shape[-1] for c in columns])
    for a, b in zip(starts[:-1], starts[1:]):
        assert not any(a < e < b for e in ends)                  # no stack ends inside a unit
    for s in stacks:
        assert s.shape[-1] <= max(per_stack, max(sizes))
