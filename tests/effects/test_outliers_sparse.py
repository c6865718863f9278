"""Gross errors are sparse and brief in each marker: what the outlier effect sets aside never holds a marker flagged
too often or for too long (a slip's lasting offset), while sparse, brief flags are kept as they are."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.diagnose.workflow import diagnose
from identcheck.effects.outliers import MAX_FRACTION, sparse_and_brief
from identcheck.effects.registry import inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def runs(column: np.ndarray) -> list:
    """Lengths of the runs of True in a boolean series."""
    edges = np.diff(np.concatenate([[0], column.astype(np.int8), [0]]))
    return list(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1))


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(40, 400), st.integers(1, 8), st.floats(0.0, 0.3), st.integers(1, 12))
def test_what_is_kept_is_a_subset_sparse_and_brief(seed, n_frames, n_markers, rate, max_run):
    """Random flags, random gaps, a random lasting run on one marker: the kept flags are flags, no marker keeps more
    than MAX_FRACTION of its seen samples, no run is longer than max_run."""
    rng = np.random.default_rng(seed)
    seen = rng.random((n_frames, n_markers)) > 0.1
    mask = (rng.random((n_frames, n_markers)) < rate) & seen
    c, start = rng.integers(n_markers), rng.integers(n_frames)
    mask[start:start + rng.integers(1, n_frames), c] = True             # a slip's lasting offset, or a short burst
    out = sparse_and_brief(mask, seen, max_run)
    assert not (out & ~mask).any()
    assert np.all(out.sum(axis=0) <= MAX_FRACTION * np.maximum(seen.sum(axis=0), 1))
    assert all(r <= max_run for k in range(n_markers) for r in runs(out[:, k]))


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(200, 2000), st.integers(1, 12), st.integers(2, 10))
def test_sparse_brief_flags_are_kept_whole(seed, n_frames, n_markers, max_run):
    """Flags that are already sparse (each marker at most MAX_FRACTION of its samples) and brief (bursts of at most
    max_run frames) come back unchanged."""
    rng = np.random.default_rng(seed)
    seen = np.ones((n_frames, n_markers), dtype=bool)
    mask = np.zeros_like(seen)
    for k in range(n_markers):
        budget = int(MAX_FRACTION * n_frames)
        while budget > 0 and rng.random() < 0.8:
            length = int(min(rng.integers(1, max_run + 1), budget))
            start = int(rng.integers(0, n_frames - length))
            if mask[max(start - 1, 0):start + length + 1, k].any():
                continue                        # keep bursts apart: two touching bursts would be one longer run
            mask[start:start + length, k] = True
            budget -= length
    assert np.array_equal(sparse_and_brief(mask, seen, max_run), mask)


@pytest.mark.parametrize("seed", [0, 3])
def test_a_slip_beside_gross_errors_is_named_and_not_set_aside(seed, tmp_path):
    """A leg (500 frames, 0.5 mm) whose shank marker slips by 8 mm, with 15 gross errors of 10-30 mm elsewhere: both
    are named, and what is set aside as outliers is the gross errors (at most a few more samples), not the slipped
    marker's frames after its slip. Before the rule, these two trials set aside 210 and 143 samples and named the
    outliers first."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = inject_effect(simulate(model, n_frames=500, noise_mm=0.5, seed=seed), "marker_slip", seed=seed)
    rng = np.random.default_rng(seed)
    x = sim.trial.as_array()
    seen = np.flatnonzero(np.isfinite(x).all(axis=2).ravel())
    frames, cols = np.divmod(rng.choice(seen, 15, replace=False), x.shape[1])
    v = rng.normal(size=(15, 3))
    x[frames, cols] += rng.uniform(10, 30, (15, 1)) * v / np.linalg.norm(v, axis=1, keepdims=True)
    path = tmp_path / "slip_and_outliers.trc"
    sim.trial.replace(xyz=x).to_file(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        effects = {e["name"]: e["where"] for e in diagnose(model, Trial.from_file(path)).to_dict()["effects"]}
    assert effects["marker_slip"]["markers"] == sim.settings["effect"]["where"]["markers"]
    assert 15 <= effects["outliers"]["count"] <= 20
