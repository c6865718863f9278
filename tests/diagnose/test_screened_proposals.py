"""The search's handling of proposals left at their screen (:func:`identcheck.diagnose.workflow.choose`): they are
fitted in full only when the round adopts nothing or a candidate well below its best, and the round then chooses as if
every proposal had been fitted in full from the start."""
from types import SimpleNamespace

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import identcheck.diagnose.workflow as W


class Candidate:
    """A fitted candidate as the adoption step sees it: its score, the standard error it leaves on the joints and the
    parameters its story adds."""

    def __init__(self, value: float, sd: float, params: int):
        self.value, self.sd, self.params = value, sd, params

    def polish(self):
        return self


class Stub:
    """An effect whose proposals are fitted to given candidates (`full`: proposal id -> Candidate), counting fits."""

    name, sparse = "stub", False

    def __init__(self, full: dict):
        self.full, self.fits = full, 0

    def apply(self, ctx, h, prop):
        self.fits += 1
        return self.full[id(prop)]

    def implausible(self, prop):
        return ""

    def read_without_joints(self, prop):
        return False

    def own_params(self, prop, h, cand):
        return cand.params


@pytest.fixture
def stubbed(monkeypatch):
    """The adoption step's judgments read off the stub candidates: score their value, no free directions, the worst
    standard error theirs (stateless: shared by every example hypothesis draws)."""
    monkeypatch.setattr(W, "score", lambda ctx, cand, h: cand.value)
    monkeypatch.setattr(W, "corrects_data_only", lambda h, cand: False)
    monkeypatch.setattr(W, "undetermined", lambda cand: 0)
    monkeypatch.setattr(W, "worst_joint", lambda ctx, cand: ("knee", cand.sd))
    monkeypatch.setattr(W, "creep", lambda ctx, h, iterations=W.CREEP_ITER: 0.0)


def equivalents(order: list, adopted) -> list:
    """The candidates the report would name indistinguishable from the adopted one (its round's rivals within the
    margin of equal explanations, :meth:`identcheck.diagnose.workflow.Step.equivalents`)."""
    step = W.Step("stub", adopted[2].where, 0.0, 0.0, adopted[0], {}, W.rivals(order, adopted[2]), ())
    return sorted(w["n"] for _, w in step.equivalents())


scores = st.floats(-500.0, 5e4, allow_nan=False)
candidates = st.tuples(scores, st.sampled_from([1.0, 1.0, 50.0]), st.integers(1, 31))   # 50 mm: refused


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(candidates, min_size=1, max_size=6), st.lists(candidates, max_size=4),
       st.floats(0.0, 0.49), st.sampled_from([0.0, W.DECISIVE_GAIN]))
def test_the_round_chooses_as_if_every_proposal_were_fitted_in_full(stubbed, caplog, fitted, screened, share, bar):
    """Random rounds: fitted candidates (score, standard error, parameters), and, where the best is at least
    SCREEN_FROM, screened ones whose full fit scores below half of it (what a screen below a tenth is taken to
    promise: measured, below a quarter). The choice, the refusals and the candidates equivalent to the choice are
    those of the round with every proposal fitted in full; the screened ones are fitted only when the choice fell
    below COMPLETE_SHARE of the best or nothing was adopted. The refusals are logged once each, as the round fitted in
    full logs them (a round considered again after its screened proposals were fitted had logged its first pass's
    refusals twice)."""
    caplog.clear()
    caplog.set_level("INFO", logger="identcheck")
    best = max([v for v, _, _ in fitted] + [0.0])
    screened = [(share * best * (v / 5e4), sd, n) for v, sd, n in screened] if best >= W.SCREEN_FROM else []

    def build():
        props = [SimpleNamespace(where={"n": i}) for i in range(len(fitted) + len(screened))]
        return props, {id(p): Candidate(*c) for p, c in zip(props, fitted + screened)}

    props, full = build()
    eff = Stub(full)
    tried = [(full[id(p)].value, eff, p, full[id(p)]) for p in props[:len(fitted)]]
    left = [(c[0] / W.SKIP_RATIO, eff, p) for p, c in zip(props[len(fitted):], screened)]
    bars = W.Bars(bar, best, 10.0, 0, 10.0)
    refused = {}
    order, adopted, _, _ = W.choose(None, None, None, tried, left, bars, refused, 0.0, None, 1)
    said = [r.getMessage() for r in caplog.records if "not adopted" in r.getMessage()]
    caplog.clear()

    props2, full2 = build()
    eff2 = Stub(full2)
    every = [(full2[id(p)].value, eff2, p, full2[id(p)]) for p in props2]
    refused2 = {}
    order2, adopted2, _, _ = W.choose(None, None, None, every, [], bars, refused2, 0.0, None, 1)
    said2 = [r.getMessage() for r in caplog.records if "not adopted" in r.getMessage()]
    assert len(said) == len(set(said)) and sorted(said) == sorted(said2)

    assert (adopted is None) == (adopted2 is None)
    if adopted is not None:
        assert adopted[2].where == adopted2[2].where and adopted[0] == adopted2[0]
        assert equivalents(order, adopted) == equivalents(order2, adopted2)
    assert {k: r.score for k, r in refused.items()} == {k: r.score for k, r in refused2.items()}
    near = adopted is not None and adopted[0] >= W.COMPLETE_SHARE * best
    if near and screened:
        assert eff.fits == 0            # adopted near the best: the screened proposals were never fitted in full
        assert [x[2].where for x in order] == [x[2].where for x in order2 if x[2].where["n"] < len(fitted)]
    if screened and not near:
        assert eff.fits == len(screened)
        assert [(x[0], x[2].where) for x in order] == [(x[0], x[2].where) for x in order2]


class PartlyImplausible(Stub):
    """A stub whose proposal 0 cannot be what it claims (a delay noise alone may make, say)."""

    def implausible(self, prop):
        return "noise alone may make it" if prop.where["n"] == 0 else ""


def test_a_round_considered_again_logs_each_refusal_once(stubbed, caplog):
    """An implausible candidate above the bar and one refused for the joints are logged when first considered; the
    round then fits its screened proposal in full (nothing was adopted) and considers them again, without logging them
    a second time; the screened one is adopted."""
    caplog.set_level("INFO", logger="identcheck")
    props = [SimpleNamespace(where={"n": i}) for i in range(3)]
    full = {id(props[0]): Candidate(1000.0, 1.0, 3), id(props[1]): Candidate(800.0, 50.0, 3),
            id(props[2]): Candidate(70.0, 1.0, 3)}
    eff = PartlyImplausible(full)
    tried = [(full[id(p)].value, eff, p, full[id(p)]) for p in props[:2]]
    bars = W.Bars(0.0, 800.0, 10.0, 0, 10.0)
    _, adopted, _, _ = W.choose(None, None, None, tried, [(7.0, eff, props[2])], bars, {}, 0.0, None, 1)
    said = [r.getMessage() for r in caplog.records if "not adopted" in r.getMessage()]
    assert adopted is not None and adopted[2] is props[2] and eff.fits == 1
    assert len(said) == 2 and len(set(said)) == 2, said
    assert any("noise alone" in m for m in said) and any("undetermined" in m for m in said), said
