"""The verdicts of a plan's variants (a marker removed, a joint held still) taken from small windows of the tree are
the whole-tree rank's verdicts of those variants: random trees in, every variant compared."""
from __future__ import annotations

import time

from hypothesis import given, settings, strategies as st

from identcheck import api
from identcheck.certify import tree_rank
from identcheck.plan import windows as plan_windows
from test_plan_budget import chain_model


@st.composite
def trees(draw):
    """A random skeleton of 1–6 joints: each segment hangs from an earlier one, ball or hinge joints, 0–4 markers."""
    n = draw(st.integers(1, 6))
    parents = [draw(st.integers(0, i)) for i in range(n)]
    kinds = [draw(st.sampled_from(tree_rank.TYPES)) for _ in range(n)]
    counts = [draw(st.integers(0, 4)) for _ in range(n + 1)]
    markers = {f"s{i}": tuple(f"m{i}{c}" for c in "abcd"[:counts[i]]) for i in range(n + 1)}
    joints = tuple((f"j{i}", kinds[i], f"s{parents[i]}", f"s{i + 1}") for i in range(n))
    return tree_rank.TreeSpec("s0", markers, joints)


def _whole_tree_local(spec, names, frames, seed):
    rank = tree_rank.analyse(spec, "GFp", seed, warm_frames=frames - 1, search_min_frames=False)
    return {n: rank.joints[n].local for n in names}


@settings(max_examples=25, deadline=None)
@given(trees(), st.integers(1, 3), st.integers(0, 3))
def test_window_verdicts_of_every_variant_are_the_whole_trees(spec, chunk, seed):
    base = tree_rank.analyse(spec, "GFp", seed)
    local = [n for n, j in base.joints.items() if j.local]
    windows = plan_windows.Windows(spec, local, base.frames, seed, chunk=chunk)
    for seg, ms in spec.markers.items():
        for m in ms:
            variant = spec.without(m)
            got = windows.variant_local(variant, plan_windows.Change(segments=frozenset([seg])))
            assert got == _whole_tree_local(variant, local, base.frames, seed), (m, windows.regions)
    for name, _, _, _ in spec.joints:
        variant = spec.freezing([name])
        got = windows.variant_local(variant, plan_windows.Change(joints=frozenset([name])))
        assert got == _whole_tree_local(variant, local, base.frames, seed), (name, windows.regions)


@settings(max_examples=40, deadline=None)
@given(trees(), st.integers(1, 4))
def test_regions_cover_every_joint_once_and_are_connected(spec, chunk):
    found = plan_windows.regions(spec, chunk)
    assert sorted(n for r in found for n in r) == sorted(j[0] for j in spec.joints)
    for region in found:
        part = plan_windows.window_spec(spec, region)          # raises unless connected
        assert {j[0] for j in part.joints} == region


@given(trees())
@settings(max_examples=40, deadline=None)
def test_a_told_window_gives_its_boundary_poses_and_nothing_else(spec):
    region = plan_windows.regions(spec, 1)[0]
    told = plan_windows.window_spec(spec, region, told=True)
    outside = [j for j in spec.joints if j[0] not in region]
    assert told.known == {s for j in outside for s in (j[2], j[3])} & set(told.markers)


def test_isomorphic_windows_share_a_shape_and_renamed_ones_only():
    a = tree_rank.TreeSpec("p", {"p": ("x", "y", "z"), "c": ("w",)}, (("k", "revolute", "p", "c"),))
    b = tree_rank.TreeSpec("P", {"P": ("1", "2", "3"), "C": ("4",)}, (("K", "revolute", "P", "C"),))
    assert plan_windows.shape(a) == plan_windows.shape(b)
    assert plan_windows.shape(a) != plan_windows.shape(a.without("w"))
    assert plan_windows.shape(a) != plan_windows.shape(a.freezing(["k"]))


def test_a_200_segment_chain_is_planned_whole_with_every_analysis(tmp_path):
    """The default plan of a 200-joint chain analyses every joint's motion and every marker (nothing left
    unfinished under the default budget): a hinge or ball of a chain needs its own motion, and a lone marker's
    loss is named where it costs a joint."""
    t0 = time.process_time()
    res = api.plan(chain_model(tmp_path / "chain.toml", 200)).to_dict()
    assert "unfinished" not in res, res.get("unfinished")
    assert time.process_time() - t0 < 120          # far inside: the analyses no longer grow as the square
    assert all(n in j["motion_needed"] for n, j in res["joints"].items())
    assert len(res["robustness"]) == sum(3 if i % 3 == 0 else 1 for i in range(201))
