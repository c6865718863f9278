"""One more marker, valued at the noise-free truth: the enlarged skeleton reproduces the original markers exactly,
adding a marker never widens an interval the plan already had, intervals scale with the noise, and the ranking
puts the segment that settles a practically undetermined joint first."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck import api
from identcheck.bundle.chain import information
from identcheck.bundle.model import forward
from identcheck.fit import marker_value as mv
from identcheck.fit.predict import noise_free_fit

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def leg():
    model = api.load_model(ROOT / "examples" / "leg.toml")
    _, tree = noise_free_fit(model, "functional", 150, 0)
    return model, tree.best.fit


@settings(max_examples=8, deadline=None)
@given(st.data())
def test_an_added_marker_changes_nothing_else_and_never_widens_an_interval(leg, data):
    model, fit = leg
    segment = data.draw(st.sampled_from(list(fit.chain.segments)))
    chain, state, pred = mv.with_added_marker(model, fit, segment)
    _, _, _, before = forward(fit.chain, fit.terms, fit.state)
    cols = [chain.labels.index(m) for m in fit.chain.labels]
    assert np.allclose(pred[:, cols], before, atol=1e-9)               # the old markers move exactly as before
    new = chain.labels.index(mv.added_name(model, segment))
    assert chain.marker_seg[new] == segment
    old_se = mv.standard_errors(fit.chain, fit.state, information(fit, before), 1.0)
    new_se = mv.standard_errors(chain, state, information(replace(fit, chain=chain, state=state, pred=pred), pred), 1.0)
    for j, by in old_se.items():                                       # information only grows: Loewner order
        for m, se in by.items():
            assert new_se[j][m] <= se * (1 + 1e-6) + 1e-9, (segment, j, m, se, new_se[j][m])


@settings(max_examples=5, deadline=None)
@given(st.floats(0.1, 5.0))
def test_intervals_scale_with_the_noise(leg, noise):
    model, fit = leg
    _, _, _, pred = forward(fit.chain, fit.terms, fit.state)
    S = information(fit, pred)
    one = mv.half_widths(fit.chain, fit.state, S, 1.0)
    scaled = mv.half_widths(fit.chain, fit.state, S, noise)
    for j in one:
        assert scaled[j] == pytest.approx(min(one[j] * noise, mv.CAP_MM), rel=1e-9)


def test_the_segment_that_settles_an_undetermined_knee_comes_first():
    """The minimal leg's knee (one thigh, one shank marker) is practically undetermined; a second marker on the
    shank or the thigh settles it, a fourth pelvis marker does not: the ranking says so."""
    model = api.load_model(ROOT / "examples" / "sparse_leg.toml")
    _, tree = noise_free_fit(model, "functional", 150, 0)
    out = mv.marker_value(model, tree.best.fit, 1.0)
    assert [s["segment"] for s in out][-1] == "pelvis"
    assert {out[0]["segment"], out[1]["segment"]} == {"thigh_r", "shank_r"}
    for s in out[:2]:
        assert "knee_r" in s["determined_after"]
        assert s["joints"]["knee_r"]["before_mm"] == mv.CAP_MM > s["joints"]["knee_r"]["after_mm"]
    assert out[-1]["mm_saved"] < out[1]["mm_saved"]


def test_plan_with_noise_ranks_one_more_marker_in_json_and_text(capsys):
    from identcheck import cli

    leg = str(ROOT / "examples" / "leg.toml")
    assert cli.main(["plan", leg, "--fast", "--noise-mm", "1", "--frames", "150", "--json"]) == 0
    import json

    doc = json.loads(capsys.readouterr().out)
    sugg = doc["practical_suggestions"]
    assert sorted(s["segment"] for s in sugg) == sorted(api.load_model(leg).segments)
    keys = [(-len(s["determined_after"]), -s["mm_saved"]) for s in sugg]
    assert keys == sorted(keys)
    assert all(v["after_mm"] < v["before_mm"] for s in sugg for v in s["joints"].values())
    assert cli.main(["plan", leg, "--fast", "--noise-mm", "1", "--frames", "150"]) == 0
    out = capsys.readouterr().out
    assert f"one more marker, by predicted gain: {sugg[0]['segment']} saves" in out


def test_the_added_marker_never_takes_a_name_the_model_uses(leg):
    """A model that already has a marker called like the added one: the added marker gets another name, and the
    model's own marker keeps its column."""
    model, fit = leg
    seg = model.segments["thigh_r"]
    named = replace(model, segments={**model.segments, "thigh_r": replace(seg, markers=seg.markers + ("+thigh_r",))})
    assert mv.added_name(named, "thigh_r") not in named.markers
    assert mv.added_name(model, "thigh_r") == "+thigh_r"
