"""The label screen's misfits for a marker against every marker of the other segments at once
(:func:`identcheck.estimate.labels.swap_costs_across`) are, number for number, those of the pair-by-pair
:func:`~identcheck.estimate.labels.swap_costs`: random segments of one to four markers, random positions with holes
(occlusion) and whole markers unseen over spans."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.estimate.labels import _Distances, swap_costs, swap_costs_across
from identcheck.io.model import Model
from identcheck.skeleton import Skeleton


def _chain(sizes: list) -> Skeleton:
    segments = {f"s{s}": {"markers": [f"M{s}_{k}" for k in range(n)]} for s, n in enumerate(sizes)}
    joints = {f"j{s}": {"type": "spherical", "parent": f"s{s - 1}", "child": f"s{s}"} for s in range(1, len(sizes))}
    return Skeleton.from_model(Model.from_dict({"units": "mm", "segments": segments, "joints": joints}))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 4), min_size=2, max_size=5), st.integers(5, 60), st.floats(0.0, 0.4),
       st.integers(0, 2**32 - 1))
def test_across_segments_equals_pair_by_pair(sizes, n_frames, holes, seed):
    chain = _chain(sizes)
    rng = np.random.default_rng(seed)
    data = rng.normal(0.0, 100.0, (n_frames, chain.n_markers, 3))
    data[rng.random((n_frames, chain.n_markers)) < holes] = np.nan
    gone = rng.integers(0, chain.n_markers)
    data[: n_frames // 2, gone] = np.nan                  # one marker unseen over half the trial
    seg = chain.marker_seg
    for i in range(chain.n_markers):
        js = [j for j in range(i + 1, chain.n_markers) if seg[j] != seg[i]]
        got = swap_costs_across(data, chain, i, js, _Distances(data, chain))
        for j in js:
            keep, swap = swap_costs(data, chain, i, j, _Distances(data, chain))
            if keep is None:
                assert j not in got
                continue
            np.testing.assert_array_equal(got[j][0], keep)
            np.testing.assert_array_equal(got[j][1], swap)
