"""One contract over every registered effect: it injects itself into a simulated trial, its detector
proposes the place it was injected, and its augmentation closes most of the gap it opened."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from identcheck.diagnose.workflow import start
from identcheck.effects.registry import EFFECTS, NAMES, inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate


def _places(where: dict) -> set:
    out = set(where.get("markers", []))
    for key in ("segment", "joint"):
        if where.get(key):
            out.add(where[key])
    return out


@pytest.fixture(scope="module")
def rigid(examples):
    return simulate(Model.from_toml(examples / "diagnose_leg.toml"), n_frames=400, noise_mm=0.3, seed=21)


def test_the_registry_is_the_contract_list():
    assert NAMES == ("soft_tissue", "marker_slip", "marker_swap", "joint_translation", "extra_dof",
                     "time_offset", "outliers", "spatial_distortion")
    for name, eff in EFFECTS.items():
        assert eff.name == name
        assert callable(eff.inject) and callable(eff.propose) and callable(eff.apply)


@pytest.mark.parametrize("name", NAMES)
def test_inject_propose_augment(rigid, name):
    sim = inject_effect(rigid, name, seed=3)
    injected = sim.settings["effect"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = start(sim.model, sim.trial)
        eff = EFFECTS[name]
        proposals = eff.propose(ctx, h)
        assert proposals, f"{name}: no proposal on a trial that carries it"
        where = _places(injected["where"])
        best = next((p for p in proposals if not where or _places(p.where) & where), None)
        assert best is not None, (name, injected["where"], [p.where for p in proposals])
        after = eff.apply(ctx, h, best)
    assert after.gap(ctx) < 0.8 * h.gap(ctx), (name, h.gap(ctx), after.gap(ctx))
    assert np.isfinite(after.gap(ctx))
