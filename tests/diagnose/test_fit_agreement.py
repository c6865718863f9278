"""fit is diagnose's model with no effect adopted (one estimator, one set of rules, bundle.honest): on trials
where diagnose adopts nothing, both report the same marker distances, 95 % intervals (and how each was made),
standard errors and practical verdicts. Hips turned about two or three axes: a hip turned about one leaves its
centre free along that axis, where the two fits stop at different points of the valley and the joints below
move with it by ~0.1 mm (both call the hip unbounded: tests/bundle/test_single_axis.py). Agreement is to within
the fit's own convergence tolerance: ``fit`` stops when what is left to gain is at most FAST_CHI2_TOL in chi² units,
within 0.045 standard errors of the minimum, so two fits may differ by 0.09 of a standard error (and 5e-3 mm)."""
from __future__ import annotations

import math
from pathlib import Path

from hypothesis import assume, given, settings, strategies as st

import identcheck as ic
from identcheck.diagnose.workflow import diagnose
from identcheck.bundle.converge import FAST_CHI2_TOL
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10_000), noise=st.floats(0.2, 1.2), frames=st.integers(300, 400),
       n_axes=st.sampled_from([2, 3]))
def test_fit_and_diagnose_answer_alike_when_no_effect_is_adopted(seed, noise, frames, n_axes):
    sim = simulate(MODEL, n_frames=frames, seed=seed, n_axes=n_axes, noise_mm=noise)
    diag = diagnose(MODEL, sim.trial)
    assume(not diag.steps)
    fit, dg = ic.fit(MODEL, sim.trial).to_dict()["joints"], diag.to_dict()["joints"]
    for j, a in fit.items():
        b = dg[j]
        assert a["practical"]["verdict"] == b["practical"]["verdict"], j
        assert a["interval_method"] == b["interval_method"], j
        for m, d in a["marker_distances"].items():
            if a["interval_method"][m] == "unbounded":
                continue                 # a flat valley: any point of it is the estimate (checked: both unbounded)
            lo, hi = a["marker_distances_ci95"][m]
            near = 5e-3 + 2 * math.sqrt(2 * FAST_CHI2_TOL) * (hi - lo) / 3.92     # 0.09 standard errors
            assert abs(d - b["marker_distances"][m]) <= near, (j, m)
            for x, y in zip(a["marker_distances_ci95"][m], b["marker_distances_ci95"][m]):
                assert (x is None and y is None) or abs(x - y) <= near, (j, m, a["marker_distances_ci95"][m],
                                                                          b["marker_distances_ci95"][m])
        if "unbounded" not in a["interval_method"].values():
            assert abs(a["uncertainty_mm"] - b["uncertainty_mm"]) <= 1e-3 * max(1.0, a["uncertainty_mm"]), j
