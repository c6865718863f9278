"""Two gross errors in a clean trial are named ``outliers`` although the whole-trial gap passes the consistency
test. The consistency test sums a few gross samples into tens of thousands of ordinary ones; each sample the
outlier effect sets aside has failed a trial-wide bound of its own and pays its own parameters, so the effect is held
to the equivalence margin there, not to the decisive bar (:func:`identcheck.diagnose.workflow.bar_for`). Before,
set aside such samples often gained less than that bar and nothing was named (held-out draw 63, trial 43: eight
9 mm jumps under 1.2 mm of noise)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.diagnose import workflow
from identcheck.diagnose.workflow import diagnose
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml"


def _diagnosed(seed: int, sigma: float, sizes: tuple, draw):
    """The leg (1000 frames, noise `sigma`) with two samples moved `sizes` (in σ) in random directions, and its
    diagnosis as JSON, and the moved samples as {(frame, label)}."""
    model = Model.from_toml(MODEL)
    sim = simulate(model, n_frames=1000, noise_mm=sigma, seed=seed)
    x = sim.trial.as_array()
    frames = draw.choice(np.arange(5, x.shape[0] - 5), 2, replace=False)
    cols = draw.integers(0, x.shape[1], 2)
    v = draw.normal(size=(2, 3))
    x[frames, cols] += sigma * np.asarray(sizes)[:, None] * v / np.linalg.norm(v, axis=1, keepdims=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = diagnose(model, sim.trial.replace(xyz=x)).to_dict()
    return doc, {(int(f), sim.trial.labels[c]) for f, c in zip(frames, cols)}


def _named_first(doc, moved):
    assert doc["consistent_before"]["consistent"]
    first = doc["effects"][0]
    assert first["name"] == "outliers"
    assert any(f in first["where"]["frames"] and m in first["where"]["markers"] for f, m in moved)
    return first


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 9_999), st.floats(0.3, 1.5), st.floats(12.0, 15.0), st.floats(12.0, 15.0))
def test_two_gross_errors_on_a_consistent_gap_are_named(seed, sigma, a, b):
    """Two samples moved 12-15 σ: the gap passes the consistency test, and the first effect named is ``outliers``,
    setting aside one of the moved samples at least (40 random draws: every one named, gaining 82-272)."""
    _named_first(*_diagnosed(seed, sigma, (a, b), np.random.default_rng(seed)))


def test_gross_errors_gaining_less_than_the_decisive_bar_are_named():
    """Two samples moved 10.5 and 10.8 σ under 0.45 mm of noise: set aside they gain 29, short of the decisive bar
    that the other effects must clear on a gap consistent with noise, and are named all the same."""
    draw = np.random.default_rng(11)
    sigma = draw.uniform(0.3, 1.5)
    sizes = draw.uniform(9.0, 12.0, 2)
    first = _named_first(*_diagnosed(11, sigma, tuple(sizes), draw))
    assert workflow.EQUIVALENT_GAIN < first["score"] < workflow.DECISIVE_GAIN
