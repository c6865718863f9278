"""The plan's optional analyses (motion each joint needs, markers the plan cannot lose) are one whole-tree rank
per joint and per marker: on a long chain they stop at their time budget, say what they did not analyse, and
report progress, instead of running on; within the budget they analyse everything."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from identcheck import api, cli


def chain_model(path, n: int):
    """A chain of n joints, alternating hinge and ball, three markers on every third segment and one elsewhere."""
    lines = ['units = "mm"']
    for i in range(n + 1):
        names = [f"m{i}{c}" for c in ("a", "b", "c")] if i % 3 == 0 else [f"m{i}a"]
        lines += [f"[segments.s{i}]", "markers = [" + ", ".join(f'"{m}"' for m in names) + "]"]
    for i in range(n):
        lines += [f"[joints.j{i}]", f'type = "{"spherical" if i % 2 else "revolute"}"', f'parent = "s{i}"',
                  f'child = "s{i + 1}"']
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_spent_budget_lists_every_joint_and_marker_not_analysed(tmp_path):
    model = chain_model(tmp_path / "chain.toml", 8)
    res = api.plan(model, max_seconds=1e-9).to_dict()
    every = [f"m{i}{c}" for i in range(9) for c in (("a", "b", "c") if i % 3 == 0 else ("a",))]
    assert res["unfinished"]["motion_needed"] == [f"j{i}" for i in range(8)]
    assert sorted(res["unfinished"]["robustness"]) == sorted(every)
    assert res["robustness"] == {}
    assert all(j["motion_needed"] is None for j in res["joints"].values())
    assert "--max-seconds" in res["unfinished"]["reason"]
    assert res["all_identifiable"] is True          # the verdicts themselves never depend on the budget


def test_within_the_budget_everything_is_analysed(tmp_path):
    model = chain_model(tmp_path / "chain.toml", 4)
    res = api.plan(model, max_seconds=600).to_dict()
    assert "unfinished" not in res
    assert sorted(res["robustness"]) == sorted(["m0a", "m0b", "m0c", "m1a", "m2a", "m3a", "m3b", "m3c", "m4a"])
    assert all(isinstance(j["motion_needed"], list) for j in res["joints"].values())
    # every hinge and ball of a chain needs its own motion
    assert all(n in j["motion_needed"] for n, j in res["joints"].items())


def test_the_cli_reports_progress_and_what_it_left(tmp_path, capsys):
    model = chain_model(tmp_path / "chain.toml", 8)
    assert cli.main(["plan", str(model), "--max-seconds", "0.001", "--json"]) == 0
    out, err = capsys.readouterr()
    assert "whole-tree rank of 8 joints" in err and " of at most 0.001 s" in err
    doc = json.loads(out)
    assert "unfinished" in doc


@pytest.mark.parametrize("value", ["0", "-3", "nan", "1e9"])
def test_a_budget_out_of_range_is_named(tmp_path, capsys, value):
    model = chain_model(tmp_path / "chain.toml", 2)
    assert cli.main(["plan", str(model), "--max-seconds", value]) == 2
    assert "--max-seconds" in capsys.readouterr().err


def test_witness_searches_stop_at_their_budget_and_say_which_joints_they_left():
    """`plan --witness` searches one joint after another; past its budget the joints left are answered
    `not_searched` with the budget named, listed under `unfinished.witness`, and the verdicts do not move."""
    from pathlib import Path

    knee = Path(__file__).resolve().parents[2] / "examples" / "knee_21.toml"
    res = api.plan(knee, witness=True, max_seconds=1e-9, motion=False, robust=False).to_dict()
    left = [n for n, j in res["joints"].items() if not j["identifiable"]]
    assert left and res["unfinished"]["witness"] == left
    for n in left:
        alt = res["joints"][n]["alternative"]
        assert alt["method"] == "not_searched" and alt["verified"] is False and "budget" in alt["note"]
    assert "witness" in res["unfinished"]["reason"]
    plain = api.plan(knee, motion=False, robust=False).to_dict()
    assert {n: j["identifiable"] for n, j in plain["joints"].items()} == {n: j["identifiable"] for n, j in res["joints"].items()}


def bare_star(path, n: int):
    """A root without markers and n ball joints to children without markers: every joint open, and the multisets of
    segments the fewest-marker search would try grow as n^6."""
    lines = ['units = "mm"', "[segments.root]", "markers = []"]
    for i in range(n):
        lines += [f"[segments.c{i}]", "markers = []", f"[joints.j{i}]", 'type = "spherical"', 'parent = "root"',
                  f'child = "c{i}"']
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_fewest_marker_search_stops_at_its_budget_and_says_so(tmp_path):
    """A bare star of 30 balls (a 1 kB model) had run past 120 s in the search for the fewest markers to add,
    whatever ``--max-seconds`` said: it now stops at its own budget, suggests nothing, and names the joints it was
    settling, in the tree's order, under ``unfinished`` and in the note."""
    res = api.plan(bare_star(tmp_path / "star.toml", 30), max_seconds=0.5, motion=False, robust=False).to_dict()
    assert res["suggestions"] == []
    assert res["unfinished"]["suggestions"] == [f"j{i}" for i in range(30)]
    assert "fewest markers" in res["unfinished"]["reason"] and "--max-seconds" in res["unfinished"]["reason"]
    assert "time budget" in res["suggestions_note"]
    assert res["all_identifiable"] is False         # the verdicts themselves never depend on the budget


def test_a_small_bare_star_gets_its_suggestions_within_the_budget(tmp_path):
    """Where the search ends within its budget, nothing is left unfinished and a marker is suggested on each bare
    child (the fewest that pose them)."""
    res = api.plan(bare_star(tmp_path / "star.toml", 2), max_seconds=600, motion=False, robust=False).to_dict()
    assert "unfinished" not in res
    assert res["suggestions"] and {s["segment"] for s in res["suggestions"]} >= {"c0", "c1"}


def chain_with_bare_leaves(path, n: int, leaves: int):
    """A chain of n segments with three markers each (hinges), and `leaves` bare segments on ball joints beside it."""
    lines = ['units = "mm"']
    for i in range(n):
        lines += [f"[segments.s{i}]", "markers = [" + ", ".join(f'"m{i}{c}"' for c in "abc") + "]"]
    for i in range(1, n):
        lines += [f"[joints.j{i}]", 'type = "revolute"', f'parent = "s{i - 1}"', f'child = "s{i}"']
    for k in range(leaves):
        lines += [f"[segments.leaf{k}]", "markers = []", f"[joints.l{k}]", 'type = "spherical"',
                  f'parent = "s{(7 * k) % n}"', f'child = "leaf{k}"']
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_check_that_fewer_markers_would_not_do_stops_at_its_budget_and_says_so(tmp_path):
    """Every bare leaf needs a marker, and the check that no plan with fewer markers passes lists the plans with fewer
    one by one, those it skips as bare too (46 million on a chain of 80 with six leaves: 57 s whatever --max-seconds
    said). Stopped by its budget, the propagation's fix is suggested, its minimality reported unchecked."""
    res = api.plan(chain_with_bare_leaves(tmp_path / "c.toml", 40, 6), max_seconds=0.3, motion=False,
                   robust=False).to_dict()
    assert sorted(s["segment"] for s in res["suggestions"]) == [f"leaf{k}" for k in range(6)]
    assert res["unfinished"]["suggestions_minimal"] is False and res["suggestions_check"]["minimal"] is False
    assert "may not be the fewest" in res["unfinished"]["reason"]


@pytest.mark.parametrize("motion", ["bogus", "Functional", "no_such_trial.trc", "flexion,small"])
def test_a_motion_plan_cannot_use_is_refused_before_any_analysis(motion, monkeypatch, capsys):
    """``--motion`` is checked with the arguments (exit 2), not after the whole analysis (a 60-segment chain had run
    7.6 s before its name was refused)."""
    def analysed(*args, **kwargs):
        raise AssertionError("the plan was analysed")

    monkeypatch.setattr(api, "plan", analysed)
    model = str(Path(__file__).resolve().parents[2] / "examples" / "leg.toml")
    assert cli.main(["plan", model, "--noise-mm", "1", "--motion", motion]) == 2
    assert "--motion" in capsys.readouterr().err


def test_fewest_out_of_time_keeps_what_it_did_not_try_and_says_so(tmp_path):
    """``--fewest``'s greedy removal stops at its budget (a 20-segment chain had run past 120 s whatever
    ``--max-seconds`` said): nothing removed beyond what it tried, ``complete`` false, ``unfinished`` and the text
    say so."""
    from identcheck.report.text import plan_text

    model = chain_model(tmp_path / "chain.toml", 6)
    res = api.plan(model, fewest=True, motion=False, robust=False, max_seconds=1e-9)
    doc = res.to_dict()
    f = doc["fewest_local"]
    assert f["complete"] is False and f["removable"] == [] and doc["unfinished"]["fewest_local"] is True
    assert "fewest_local stopped at its budget" in doc["unfinished"]["reason"]
    assert "stopped at its time budget" in plan_text(res)


def _restarting_removal(spec, seed: int = 0) -> list:
    """The greedy removal as it was written first: after each removal, start again from the first marker."""
    from identcheck.certify import tree_rank

    removed, changed = [], True
    while changed:
        changed = False
        for m in [m for ms in spec.markers.values() for m in ms]:
            cand = spec.without(m)
            if all(j.local for j in tree_rank.analyse(cand, "GFp", seed).joints.values()):
                spec, changed = cand, True
                removed.append(m)
                break
    return removed


@settings(max_examples=10, deadline=None)
@given(st.lists(st.integers(1, 3), min_size=2, max_size=5), st.lists(st.booleans(), min_size=4, max_size=4))
def test_trying_each_marker_once_removes_what_restarting_removed(tmp_path_factory, counts, balls):
    """The whole-tree rank only falls as markers go, so a marker that cannot go cannot go later either: one pass
    over the markers removes exactly what restarting from the first marker after each removal did."""
    from identcheck.certify import tree_rank
    from identcheck.io.model import Model
    from identcheck.plan.analysis import fewest_local

    segs = {f"s{i}": {"markers": [f"m{i}{k}" for k in range(c)]} for i, c in enumerate(counts)}
    joints = {f"j{i}": {"type": "spherical" if balls[i % len(balls)] else "revolute", "parent": f"s{i}",
                        "child": f"s{i + 1}"} for i in range(len(counts) - 1)}
    spec = tree_rank.TreeSpec.from_model(Model.from_dict({"units": "mm", "segments": segs, "joints": joints}))
    found = fewest_local(spec, {}, 0)
    assert found["complete"] and found["removable"] == _restarting_removal(spec)


def test_a_witness_search_under_way_stops_at_its_deadline(tmp_path):
    """A search past its deadline descends no start and says so (``out_of_time``), and Gauss-Newton begins no
    iteration; the plan then answers the joint ``not_searched`` and lists it unfinished (a 20-segment chain's first
    search had run past 120 s with a 5 s budget)."""
    import time

    import numpy as np

    from identcheck.certify import tree_rank
    from identcheck.io.model import Model
    from identcheck.plan import tree_kinematics as K
    from identcheck.plan import witness as plan_witness
    from identcheck.plan import witness_search as W
    from identcheck.plan.analysis import analyse

    model = Model.from_toml(chain_model(tmp_path / "chain.toml", 5))       # its last joint is not identifiable
    spec = tree_rank.TreeSpec.from_model(model)
    p = analyse(spec)
    todo = [n for n, j in p.joints.items() if not j["identifiable"]]
    assert todo
    name = todo[0]
    truth, held = plan_witness.simulated_truth(model, spec, 20, seed=2)
    gone = time.monotonic() - 1.0
    search = W.construct(spec, truth, 20, name, "isolated" if p.joints[name]["local"] else "family",
                         undetermined=p.rank.joints[name].undetermined, held_out_truth=held, n_held_out=20,
                         deadline=gone)
    assert search.out_of_time and search.attempts == 0 and search.witness is None
    L = K.Layout(spec)
    moved, _ = W.gauss_newton(L, truth + 0.01, 20, W.trial(L, truth, 20), deadline=gone)
    assert np.array_equal(moved, truth + 0.01)
