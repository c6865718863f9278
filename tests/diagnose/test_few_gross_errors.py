"""Two gross errors in a clean trial are named ``outliers`` although the whole-trial gap passes the consistency
test: the outlier effect's own trial-wide test found them (:attr:`identcheck.effects.base.Effect.tested`), so the
decisive bar a gap consistent with noise asks of the other effects is not asked of it. Before, set aside they gained
less than that bar on many such trials and nothing was named (held-out draw 63, trial 43: eight 9 mm jumps under
1.2 mm of noise)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.diagnose.workflow import diagnose
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml"


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.3, 1.5))
def test_two_gross_errors_on_a_consistent_gap_are_named(seed, sigma):
    """A leg (1000 frames) with noise σ and two samples moved 9-12 σ in random directions: the gap before passes the
    consistency test, and the first effect named is ``outliers``, setting aside one of the moved samples at least."""
    model = Model.from_toml(MODEL)
    rng = np.random.default_rng(seed)
    sim = simulate(model, n_frames=1000, noise_mm=sigma, seed=seed % 10_000)
    x = sim.trial.as_array()
    frames = rng.choice(np.arange(5, x.shape[0] - 5), 2, replace=False)
    cols = rng.integers(0, x.shape[1], 2)
    v = rng.normal(size=(2, 3))
    x[frames, cols] += sigma * rng.uniform(9.0, 12.0, (2, 1)) * v / np.linalg.norm(v, axis=1, keepdims=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = diagnose(model, sim.trial.replace(xyz=x)).to_dict()
    assert doc["consistent_before"]["consistent"]
    first = doc["effects"][0]
    assert first["name"] == "outliers"
    moved = {(int(f), sim.trial.labels[c]) for f, c in zip(frames, cols)}
    assert any(f in first["where"]["frames"] and m in first["where"]["markers"] for f, m in moved)
