"""A round's candidate fits (``identcheck.diagnose.screening``): fitting the next candidate speculatively on a
second thread keeps exactly the fits, scores and order of the one-thread round; a speculative fit the skipping
rule would not have made is never reported."""
from __future__ import annotations

import copy
import threading
import time
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

import identcheck.diagnose.screening as screening
from identcheck import api
from identcheck.diagnose.workflow import start
from identcheck.effects.base import Proposal
from identcheck.effects.registry import EFFECTS

MODEL = Path(__file__).parents[2] / "examples" / "diagnose_leg.toml"


class _Fake:
    """An effect whose fit 'scores' its proposal's payload after a short sleep (so that threads overlap)."""

    always_fit = False

    def __init__(self, name):
        self.name = name
        self.calls = []
        self.lock = threading.Lock()

    def implausible(self, prop):
        return ""

    def apply(self, ctx, h, prop):
        time.sleep(0.002)
        with self.lock:
            self.calls.append(prop.where["i"])
        if prop.payload.get("fails"):
            raise np.linalg.LinAlgError("singular")
        return prop.payload["score"]


@settings(max_examples=40, deadline=None)
@given(rows=st.lists(st.tuples(st.integers(0, 2), st.floats(1.0, 1e4), st.floats(-50, 1e4), st.booleans()),
                     min_size=1, max_size=10))
def test_two_threads_keep_the_one_thread_rounds_fits_and_order(rows):
    """Random rounds of fake effects (some places far below the best, some fits failing): the fits reported with
    two threads are those of one thread, in the same order, with the same scores."""
    def run(threads):
        effects = [_Fake(f"e{k}") for k in range(3)]
        cands = sorted(((Proposal(effects[e].name, {"i": i}, strength, {"score": sc, "fails": fails}), effects[e])
                        for i, (e, strength, sc, fails) in enumerate(rows)), key=lambda pe: -pe[0].strength)
        saved = screening.score, screening.creep
        screening.score, screening.creep = (lambda ctx, cand, h: cand), (lambda ctx, h: 0.0)
        try:
            out = screening.fit_candidates(None, None, cands, threads=threads)
        finally:
            screening.score, screening.creep = saved
        return [(sc, eff.name, prop.where["i"]) for sc, eff, prop, _ in out]

    assert run(2) == run(1)


def test_a_real_round_is_the_same_on_one_and_two_threads():
    """A simulated leg with skin motion on the thigh: every effect's proposals of the first round, fitted on one
    thread and on two, give the same fits with identical scores and gaps."""
    sim = api.simulate(MODEL, n_frames=300, noise_mm=0.5, seed=3, effect="soft_tissue")
    ctx, h = start(api.load_model(MODEL), sim.trial.recentred()[0])
    cands = sorted(((p, eff) for eff in EFFECTS.values() for p in eff.propose(ctx, h)[:eff.max_proposals]),
                   key=lambda pe: -pe[0].strength)
    cands = [(p, e) for p, e in cands if p.strength > 0]
    assert len(cands) >= 3
    one = screening.fit_candidates(ctx, h, [(copy.deepcopy(p), e) for p, e in cands], threads=1)
    two = screening.fit_candidates(ctx, h, [(copy.deepcopy(p), e) for p, e in cands], threads=2)
    assert [(e.name, sc, c.rss) for sc, e, _, c in one] == [(e.name, sc, c.rss) for sc, e, _, c in two]


class _Overlap(_Fake):
    """A fake effect that records how many fits run at once."""

    active = 0
    most = 0
    guard = threading.Lock()

    def apply(self, ctx, h, prop):
        with _Overlap.guard:
            _Overlap.active += 1
            _Overlap.most = max(_Overlap.most, _Overlap.active)
        time.sleep(0.05)
        with _Overlap.guard:
            _Overlap.active -= 1
        return prop.payload["score"]


def test_each_effects_first_place_is_fitted_beside_the_one_before(monkeypatch):
    """Three effects' first places (each fitted whatever the others score): on two threads, two fits run at once;
    on one, never."""
    monkeypatch.setattr(screening, "score", lambda ctx, cand, h: cand)
    monkeypatch.setattr(screening, "creep", lambda ctx, h: 0.0)
    for threads, most in ((1, 1), (2, 2)):
        _Overlap.most = 0
        cands = [(Proposal(f"e{k}", {"i": k}, 100.0 - k, {"score": 10.0}), _Overlap(f"e{k}")) for k in range(3)]
        assert len(screening.fit_candidates(None, None, cands, threads=threads)) == 3
        assert _Overlap.most == most
