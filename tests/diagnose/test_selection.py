"""How ``diagnose`` chooses among the effects' proposals each round (:func:`identcheck.diagnose.workflow.diagnose`):
effects are compared by their fitted scores, not by their detectors' estimates, and a place already adopted is
not proposed again. The effects here are stand-ins whose detector strength and fitted score are set by the test,
on a real context and rigid fit (a short simulated leg), so only the selection logic is under test."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from identcheck.diagnose import workflow
from identcheck.effects.base import Effect, Proposal
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

MODEL = Path(__file__).parents[2] / "examples" / "diagnose_leg.toml"


class _Candidate:
    """What a stand-in effect's fit returns: a hypothesis whose score against any other is `gain`."""

    def __init__(self, base, gain: float, name: str, where: dict):
        self.base, self.gain, self.name, self.where = base, gain, name, where
        self.chain = base.chain

    def polish(self):
        return self

    def gap(self, ctx):
        return self.base.gap(ctx)

    def floor(self, ctx):
        return self.base.floor(ctx)


class _StandIn(Effect):
    def __init__(self, name: str, places: list):
        self.name = name
        self.places = places          # [(where, detector strength, fitted score)]
        self.max_proposals = len(places)
        self.fitted = []

    def propose(self, ctx, hyp):
        return [Proposal(self.name, dict(w), s, {"score": sc}) for w, s, sc in self.places]

    def apply(self, ctx, hyp, proposal):
        self.fitted.append(proposal.where)
        base = hyp.base if isinstance(hyp, _Candidate) else hyp
        return _Candidate(base, proposal.payload["score"], self.name, proposal.where)


@pytest.fixture(scope="module")
def trial():
    model = Model.from_toml(MODEL)
    return model, simulate(model, n_frames=200, noise_mm=0.5, seed=3).trial


def _run(model, trial, effects, max_steps=1):
    with pytest.MonkeyPatch.context() as monkeypatch:
        return _patched(monkeypatch, model, trial, effects, max_steps)


def _patched(monkeypatch, model, trial, effects, max_steps):
    monkeypatch.setattr(workflow, "EFFECTS", {e.name: e for e in effects})
    monkeypatch.setattr(workflow, "score", lambda ctx, cand, h: getattr(cand, "gain", 0.0))
    monkeypatch.setattr(workflow, "creep", lambda ctx, h: 0.0)
    monkeypatch.setattr(workflow, "undetermined", lambda cand: 0)
    monkeypatch.setattr(workflow, "worst_sd", lambda ctx, h: 0.0)
    monkeypatch.setattr(workflow, "consistency", lambda ctx, h: {"consistent": False})
    return workflow.diagnose(model, trial, max_steps=max_steps)


@settings(max_examples=15, deadline=None)
@given(st.floats(1e3, 1e5), st.floats(2.0, 1e3), st.floats(1.01, 3.0))
def test_an_effect_whose_detector_underestimates_is_fitted_and_named(trial, big, ratio, lead):
    """An effect whose detector strength is any factor below the best fitted score (here up to 1000x) is still
    fitted once, and named when its fitted score is the best; a further place of an effect that does not lead,
    that far below, is not fitted."""
    model, tr = trial
    weak = big / (workflow.SKIP_RATIO * ratio)
    loud = _StandIn("loud", [({"segment": "thigh"}, big, big)])
    quiet = _StandIn("quiet", [({"joint": "hip"}, weak, big * lead)])
    third = _StandIn("third", [({"joint": "knee"}, weak, big / 10), ({"joint": "hip"}, weak / 2, big / 10)])
    diag = _run(model, tr, [loud, quiet, third])
    assert [s.name for s in diag.steps] == ["quiet"]
    assert quiet.fitted == [{"joint": "hip"}]
    assert third.fitted == [{"joint": "knee"}]


def test_an_adopted_place_is_not_proposed_again(trial):
    """The same effect at the same place (fitted sizes aside) is adopted once; another place of it may follow."""
    model, tr = trial
    eff = _StandIn("skin", [({"joint": "knee", "amplitude_mm": 3.0}, 500.0, 400.0),
                            ({"joint": "hip", "amplitude_mm": 1.0}, 100.0, 90.0)])
    diag = _run(model, tr, [eff], max_steps=3)
    assert [s.where["joint"] for s in diag.steps] == ["knee", "hip"]
    assert workflow.place("skin", {"joint": "knee", "amplitude_mm": 3.0}) == \
        workflow.place("skin", {"joint": "knee", "amplitude_mm": 7.5})
    assert workflow.place("skin", {"markers": ["A", "B"]}) != workflow.place("skin", {"markers": ["A"]})


def test_a_translating_joint_above_a_last_segment_is_reported_alike_its_cluster_moving_as_one():
    """Above a last segment, a centre moving in the parent by D(θ) and the segment's cluster moving as one by
    Rot(θ)ᵀ D(θ) move every marker alike: each names the other as indistinguishable, whatever the scores; a
    joint with a segment below its child (markers further down) has no such twin."""
    from identcheck.effects.registry import EFFECTS
    from identcheck.skeleton import Skeleton

    chain = Skeleton.from_model(Model.from_toml(MODEL))
    jt, st_ = EFFECTS["joint_translation"], EFFECTS["soft_tissue"]
    knee = jt.alike(chain, {"joint": "knee"})
    assert knee == [("soft_tissue", {"markers": list(Model.from_toml(MODEL).segments["shank"].markers),
                                     "segment": "shank", "joint": "knee", "together": True})]
    assert jt.alike(chain, {"joint": "hip"}) == []
    (name, where), = st_.alike(chain, knee[0][1])
    assert name == "joint_translation" and where["joint"] == "knee"
    assert st_.alike(chain, {"markers": ["RTIB"], "segment": "shank", "joint": "knee"}) == []      # one marker
    assert st_.alike(chain, {"markers": ["RGT", "RTHI", "RKNE"], "segment": "thigh", "joint": "hip",
                             "together": True}) == []                                            # shank below
    step = workflow.Step("soft_tissue", knee[0][1], 1.0, 0.9, 500.0,
                         rejected=(("joint_translation", where, 495.0),), alike=(("joint_translation", where),))
    assert step.equivalents() == [("joint_translation", where)]                        # named once
    alone = workflow.Step("soft_tissue", knee[0][1], 1.0, 0.9, 500.0, rejected=(), alike=(("joint_translation", where),))
    assert alone.equivalents() == [("joint_translation", where)]


def test_a_place_is_hashable_whatever_where_holds():
    """Nested lists, dicts, arrays and numpy scalars in `where` give a place; fitted sizes (floats) are left out."""
    import numpy as np

    a = workflow.place("x", {"frames": np.array([1, 2]), "sub": {"m": ["A"]}, "size": np.float32(2.5), "n": 3})
    b = workflow.place("x", {"frames": [1, 2], "sub": {"m": ("A",)}, "size": 7.0, "n": 3})
    assert a == b and hash(a) == hash(b)
