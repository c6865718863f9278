"""A hypothesis refitted to corrected data (labels swapped back, a delay undone) from its own state and from a fresh
start: the better of the two is kept, with the changes asked for (:meth:`Hypothesis.refit_corrected`)."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 2**16), st.sampled_from([("LASI", "RASI"), ("RTHI", "RKNE"), ("RTIB", "RANK")]),
       st.integers(20, 200))
def test_the_better_of_the_warm_and_the_fresh_start_is_kept(seed, pair, length):
    """Two markers of a segment swapped for `length` frames of a 600-frame trial: refitted with the labels put back,
    the fit kept is the one of the warm and the fresh start (the same iterations each) that leaves less unexplained
    as the noise model sees it, carries the
    parameters charged and the effect, and fits the corrected data to the noise's share."""
    from identcheck.diagnose.workflow import start

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=600, noise_mm=0.5, seed=seed)
    xyz = sim.trial.as_array().copy()
    i, j = sim.trial.index(pair[0]), sim.trial.index(pair[1])
    a = int(np.random.default_rng(seed).integers(0, 600 - length))
    xyz[a:a + length, [i, j]] = xyz[a:a + length, [j, i]]
    ctx, h = start(model, sim.trial.replace(xyz=xyz))
    data = h.data.copy()
    data[a:a + length, [i, j]] = data[a:a + length, [j, i]]
    warm = h.refit(data=data, weights=h.weights, max_iter=15)
    fresh = h.restarted(ctx, data, h.weights, max_iter=15)
    kept = h.refit_corrected(ctx, data, h.weights, max_iter=15, extra_params=3, effect="swap")
    assert ctx.rss(kept) == min(ctx.rss(warm), ctx.rss(fresh))
    assert kept.extra_params == h.extra_params + 3 and kept.effects[-1] == "swap"
    assert np.array_equal(kept.data, data, equal_nan=True)
    expected = 0.5 ** 2 * (3 * h.weights.sum() - kept.n_params())
    assert kept.rss < 1.1 * expected
