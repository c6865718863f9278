"""A hinge's joint translation reaches the refit whatever its detector says: the detector reads the residual the
rigid fit left after moving the hinge's axis, which can hide a centre that moves by millimetres. A ball joint's
proposal stays gated by its strength."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identcheck.diagnose.workflow import diagnose
from identcheck.effects import joint_translation as jt_module
from identcheck.effects.registry import inject_effect
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


def _knee_translation_trial(tmp_path: Path, seed: int) -> tuple[Path, dict]:
    """A simulated leg whose knee centre moves (the project's own injection), written to a file."""
    sim = simulate(MODEL, n_frames=500, noise_mm=0.5, seed=seed)
    for k in range(50):
        out = inject_effect(sim, "joint_translation", seed=seed * 100 + k)
        if out.settings["effect"]["where"]["joint"] == "knee":
            path = tmp_path / "knee.trc"
            out.trial.to_file(path)
            return path, out.settings["effect"]
    pytest.skip("the injection never picked the knee")


def test_gate_by_joint_type():
    hinge = jt_module.Proposal("joint_translation", {"joint": "knee"}, -50.0, {"hinge": True})
    ball = jt_module.Proposal("joint_translation", {"joint": "hip"}, -50.0, {"hinge": False})
    eff = jt_module.JointTranslation()
    assert eff.fits_always(hinge) and not eff.fits_always(ball)


@pytest.mark.parametrize("seed", [3, 8])
def test_a_hinge_translation_is_named_even_when_its_detector_sees_nothing(tmp_path, monkeypatch, seed):
    """The knee's detector strength forced to -100 (below every bar): the knee's translation is still found and
    named at the knee, because the refit, not the detector, decides."""
    path, effect = _knee_translation_trial(tmp_path, seed)
    original = jt_module.JointTranslation.propose

    def blind(self, ctx, hyp):
        props = original(self, ctx, hyp)
        for p in props:
            if p.payload.get("hinge"):
                p.strength = -100.0
        return props

    monkeypatch.setattr(jt_module.JointTranslation, "propose", blind)
    rep = diagnose(MODEL, Trial.from_file(path)).to_dict()
    named = [(e["name"], e["where"].get("joint")) for e in rep["effects"]]
    assert named and named[0] == ("joint_translation", "knee"), (named, effect["params"]["amplitude_mm"])
    assert rep["gap_after"] < rep["gap_before"]
