"""Skin's functions are of the joint angles smoothed in time, each frame's own angle left out, not the fitted angles:
the fitted angles carry the noise of the frames they were fitted to, and a skin term built from them fits that noise,
ever more as it is fitted on (its vectors grow while the joint's axis turns to take up their smooth part). The same
functions of the true, noise-free angles set the bound: built from what the data give, they may explain less (the
angles' noise blurs them), not more."""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from identcheck.bundle.hypothesis import angle_basis, driving_angles
from identcheck.diagnose.workflow import score, start
from identcheck.effects.registry import EFFECTS, inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml"


@lru_cache(maxsize=None)
def _model() -> Model:
    return Model.from_toml(MODEL)


@pytest.mark.parametrize("seed", [3, 8])            # (seeds whose simulated translation is the knee's)
def test_skin_built_from_the_data_explains_no_more_than_from_the_true_angles(seed):
    """A knee translating with its angle (the simulator's even profile, 8-15 mm), white noise 0.5 mm, 1 000 frames.
    Skin's leading proposal on the shank's markers, each its own way with functions of the knee's angle, is fitted on
    to convergence as the effect built it, and again with the same functions of the true knee angle: the first
    explains less, or more by no more than the 0.999 quantile of χ² with its number of parameters. With the fitted
    angles, seed 3 explained 965 criterion units more than with the true ones (1 416 from 1 500 frames; with these,
    121 less)."""
    model = _model()
    sim = inject_effect(simulate(model, n_frames=1000, seed=seed, rom_deg=40.0, noise_mm=0.5), "joint_translation",
                        seed)
    assert sim.settings["effect"]["where"]["joint"] == "knee"
    ctx, h = start(model, sim.trial.recentred()[0])
    h = h.polish(60)
    skin = EFFECTS["soft_tissue"]
    shank = [p for p in skin.propose(ctx, h) if p.where["segment"] == "shank" and p.payload.get("each")
             and p.where["joint"] == "knee" and "joints" not in p.where]
    assert shank
    prop = shank[0]
    built = angle_basis(driving_angles(h, ctx.rate_hz)["knee"])           # the functions skin chose from, in order
    true_basis = angle_basis(np.deg2rad(np.asarray(sim.truth.joints["knee"].angles_deg, dtype=float))[:, None])
    same = []                                                             # each marker's, of the true angle
    for b in prop.payload["bases"]:
        cols = [int(np.argmin(np.linalg.norm(built - b[:, [i]], axis=0))) for i in range(b.shape[1])]
        assert np.allclose(built[:, cols], b)
        same.append(true_basis[:, cols])
    from_truth = replace(prop, payload={**prop.payload, "bases": same})
    per_param = ctx.bic_gain(0.0, -1)                        # what the criterion charges a parameter
    got = []
    for p in (prop, from_truth):
        cand = skin.apply(ctx, h, p)
        k = cand.n_params() - h.n_params()
        got.append(score(ctx, cand.polish(300), h) + k * per_param)
    assert got[0] - got[1] < chi2.ppf(0.999, k), (got, k)
