"""Segments without markers in `identcheck plan`: a joint is judged by its own quantities relative to what the
data determine on such a segment, so an undetermined neighbour (a neck whose head carries no marker) is that
neighbour's verdict, not the shoulders' and hips'. The fewest-marker suggestions are minimal for the whole-tree
rank and consider segments without markers (one head marker, not three trunk markers)."""
import itertools
import json
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck import cli
from identcheck.certify import tree_rank
from identcheck.io.model import Model
from identcheck.plan import analysis as plan
from identcheck.plan import tree_kinematics as K
from identcheck.report import text

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TRUNK_JOINTS = ("hip_l", "hip_r", "shoulder_l", "shoulder_r")
LIMB_SEGMENTS = ("thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r",
                 "uarm_l", "farm_l", "hand_l", "uarm_r", "farm_r", "hand_r")


def body(markers: dict) -> Model:
    """Pham's 16-marker body (examples/body16.toml) with the markers of the named segments replaced."""
    doc = tomllib.loads((EXAMPLES / "body16.toml").read_text(encoding="utf-8"))
    for seg, ms in markers.items():
        doc["segments"][seg]["markers"] = list(ms)
    return Model.from_dict(doc)


def spec_of(model: Model) -> tree_rank.TreeSpec:
    return tree_rank.TreeSpec.from_model(model)


BARE = {"trunk": [], "head": []}          # 12 markers: none on the trunk or the head
THIRTEEN = {"trunk": []}                  # 13 markers: the head marker kept (the plan's fewest_local finding)


def star(limb_markers: int, n_limbs: int, head: int = 0) -> Model:
    """A trunk without markers, ``n_limbs`` one-segment limbs on ball joints with ``limb_markers`` markers each,
    and a head on a ball joint with ``head`` markers: the smallest tree with an undetermined neck."""
    segs = {"trunk": {"markers": []}, "head": {"markers": [f"H{i}" for i in range(head)]}}
    joints = {"neck": {"type": "spherical", "parent": "trunk", "child": "head"}}
    for i in range(n_limbs):
        segs[f"limb{i}"] = {"markers": [f"L{i}_{k}" for k in range(limb_markers)]}
        joints[f"ball{i}"] = {"type": "spherical", "parent": "trunk", "child": f"limb{i}"}
    return Model.from_dict({"segments": segs, "joints": joints})


def test_body_without_trunk_and_head_markers():
    """Every limb joint is locally identifiable; only the neck is not, and its undetermined quantities are its
    own. The hips and shoulders are judged against each other's centres on the trunk, not against the neck's."""
    spec = spec_of(body(BARE))
    p = plan.analyse(spec)
    j = p.joints
    assert not j["neck"]["local"] and not j["neck"]["identifiable"]
    assert all(j[n]["local"] for n in j if n != "neck")
    assert set(p.rank.joints["neck"].undetermined) == {f"|{n} - centre|^2" for n in TRUNK_JOINTS}
    assert "nothing on head or below it carries a marker" in j["neck"]["reason"]
    for n in TRUNK_JOINTS:
        neck = {"joint": "neck", "segment": "trunk", "quantity": "|neck - centre|^2"}
        assert j[n]["undetermined_neighbours"] == [neck]
        assert "|neck - centre|^2" not in p.rank.joints[n].quantities
        assert {f"|{o} - centre|^2" for o in TRUNK_JOINTS if o != n} <= set(p.rank.joints[n].quantities)
        assert "belongs to the verdict of neck" in j[n]["reason"]
    for n in ("knee_l", "ankle_r", "elbow_l", "wrist_r"):
        assert "undetermined_neighbours" not in j[n]


def test_body_without_trunk_and_head_gets_the_one_marker_fix():
    """The fewest markers for the whole-tree rank: one on the head (a segment without markers). The plan itself
    (one marker fewer) fails, and of all single markers only the head's passes; three trunk markers and the
    head marker are what the propagation needs to prove every joint unique."""
    spec = spec_of(body(BARE))
    rows = plan.table_summary()
    base = plan.analyse(spec, rows)
    fix = plan.fewest_markers(spec, rows, base=base)
    assert fix.extra == {"head": 1} and fix.complete and fix.fewer_checked == 1
    assert not base.passes
    passing = [s for s in spec.markers if plan.analyse(plan._with_extra(spec, {s: 1}), rows).passes]
    assert passing == ["head"]
    assert fix.unique_extra == {"trunk": 3, "head": 1}
    assert plan.analyse(plan._with_extra(spec, fix.unique_extra), rows).all_identifiable


def test_a_spent_search_budget_falls_back_to_the_propagation_fix_and_says_so():
    spec = spec_of(body(BARE))
    rows = plan.table_summary()
    fix = plan.fewest_markers(spec, rows, budget=1)
    assert fix.extra == fix.unique_extra == {"trunk": 3, "head": 1} and not fix.complete
    assert fix.check()["minimal"] is False


def test_cli_body_without_trunk_and_head(tmp_path, capsys):
    model = tmp_path / "body12.toml"
    src = (EXAMPLES / "body16.toml").read_text(encoding="utf-8")
    model.write_text(src.replace('markers = ["L5", "LPELVIS", "RPELVIS"]', "markers = []")
                     .replace('markers = ["HEAD"]', "markers = []"), encoding="utf-8")
    rc = cli.main(["plan", str(model), "--json", "--fast"])
    doc = json.loads(capsys.readouterr().out)
    assert rc == 1 and not doc["all_local"]
    assert doc["suggestions"] == [{"segment": "head", "add_markers": 1}]
    assert doc["suggestions_check"]["minimal"] and doc["suggestions_check"]["markers"] == 1
    assert doc["suggestions_unique"] == [{"segment": "trunk", "add_markers": 3}, {"segment": "head", "add_markers": 1}]
    assert list(doc["undetermined"]) == ["neck"]
    assert [n for n, j in doc["joints"].items() if not j["local"]] == ["neck"]
    rc = cli.main(["plan", str(model), "--fast"])
    out = capsys.readouterr().out
    assert rc == 1 and "fewest markers to add: 1 on head" in out and "undetermined: neck:" in out


def test_thirteen_marker_body_is_locally_identifiable_and_needs_no_marker_for_the_rank():
    """No trunk marker, one head marker: every joint is locally identifiable, only together, with uncounted
    candidates. No marker is needed for the rank; the propagation's proof of uniqueness needs 3 trunk markers."""
    res = plan.plan_model(body(THIRTEEN), motion=False, robust=False)
    doc = res.to_dict()
    assert doc["all_local"] and not doc["all_identifiable"] and "undetermined" not in doc
    assert all(j["local"] and j["jointly_only"] and j["candidates"] is None for j in doc["joints"].values())
    assert doc["suggestions"] == [] and doc["suggestions_check"]["markers"] == 0
    assert doc["suggestions_unique"] == [{"segment": "trunk", "add_markers": 3}]
    out = text.plan_text(res)
    assert "all joints identifiable: not shown" in out and "no marker is needed for the rank" in out
    assert "fewest markers to add" not in out


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.integers(1, 2), min_size=len(LIMB_SEGMENTS), max_size=len(LIMB_SEGMENTS)),
       st.integers(0, 10_000))
def test_markerless_trunk_limbs_identifiable_neck_not(counts, seed):
    """Any limb markers (1-2 per limb segment), no trunk or head marker, any random point: every limb joint is
    locally identifiable and the neck is not; one head marker makes every joint locally identifiable."""
    markers = {s: [f"{s}_{k}" for k in range(c)] for s, c in zip(LIMB_SEGMENTS, counts)}
    r = tree_rank.analyse(spec_of(body({**markers, **BARE})), seed=seed)
    assert not r.joints["neck"].local and r.joints["neck"].undetermined
    assert all(jr.local for n, jr in r.joints.items() if n != "neck")
    assert all([a["joint"] for a in r.joints[n].set_aside] == ["neck"] for n in TRUNK_JOINTS)
    r = tree_rank.analyse(spec_of(body({**markers, "trunk": [], "head": ["HEAD"]})), seed=seed)
    assert all(jr.local and not jr.set_aside for jr in r.joints.values())


def test_modular_and_exact_rational_ranks_agree_on_a_markerless_trunk():
    """The same verdicts, with the same neighbours set aside, over GF(p) and over QQ: two limbs and a bare head
    (the limb joints identifiable, the neck not), three limbs and a head marker (every joint)."""
    for n_limbs, head in ((2, 0), (3, 1)):
        spec = spec_of(star(3, n_limbs, head))
        a, b = tree_rank.analyse(spec, "GFp", seed=1), tree_rank.analyse(spec, "QQ", seed=2)
        assert a.dim_w == b.dim_w
        for n in a.joints:
            assert (a.joints[n].local, a.joints[n].set_aside) == (b.joints[n].local, b.joints[n].set_aside), n
        assert a.joints["neck"].local == bool(head)
        assert all(a.joints[f"ball{i}"].local for i in range(n_limbs))


def test_an_independent_float_jacobian_agrees_on_a_markerless_trunk():
    """Floating point only cross-checks: the limb centres' distances on the trunk are determined, the neck's
    distance to them is not, and the limb joints' marker distances are determined."""
    from float_tree import FloatTree

    spec = spec_of(star(3, 3))
    exact = tree_rank.analyse(spec)
    assert [n for n, jr in exact.joints.items() if not jr.local] == ["neck"]
    ft = FloatTree(spec, n_frames=exact.frames + 4, seed=3)
    assert ft.determined(ft.centre_distance("ball0", "ball1"))
    assert not ft.determined(ft.centre_distance("neck", "ball0"))
    assert all(ft.locally_identifiable(f"ball{i}") for i in range(3))


def test_witness_quantities_are_the_judged_ones():
    """The witness search measures each joint by the quantities the verdict judged (not by the neck's)."""
    spec = spec_of(body(BARE))
    r = tree_rank.analyse(spec)
    L = K.Layout(spec, tuple((n, jr.points) for n, jr in r.joints.items()))
    const = np.ones(L.n_const)
    for n, jr in r.joints.items():
        assert set(K.joint_quantities(L, const, n)) == set(jr.quantities), n


chains = st.integers(1, 3).flatmap(lambda n: st.tuples(
    st.lists(st.sampled_from(tree_rank.TYPES), min_size=n, max_size=n),
    st.lists(st.integers(0, 2), min_size=n + 1, max_size=n + 1)))


def chain(types, counts) -> Model:
    segs = {f"s{i}": {"markers": [f"m{i}_{k}" for k in range(n)]} for i, n in enumerate(counts)}
    joints = {f"j{i + 1}": {"type": t, "parent": f"s{i}", "child": f"s{i + 1}"} for i, t in enumerate(types)}
    return Model.from_dict({"segments": segs, "joints": joints})


@settings(max_examples=25, deadline=None)
@given(chains)
def test_a_joint_above_a_bare_subtree_is_never_locally_identifiable(tree):
    """What the suggestion search skips without a rank: a joint with no marker on its child or below."""
    spec = spec_of(chain(*tree))
    r = tree_rank.analyse(spec)
    for name, _, _, chi in spec.joints:
        if not any(spec.markers[s] for s in plan._subtree(spec, chi)):
            assert not r.joints[name].local, name


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chains)
def test_no_plan_with_one_marker_fewer_passes(tree):
    """Checked independently of the search: every plan with one marker fewer than the suggestion, on any
    segment, fails the whole-tree rank target."""
    spec = spec_of(chain(*tree))
    rows = plan.table_summary()
    sugg = plan.suggestions(spec, rows, max_markers=3)
    if not sugg:
        return
    extra = {s["segment"]: s["add_markers"] for s in sugg}
    assert plan.analyse(plan._with_extra(spec, extra), rows).passes
    for combo in itertools.combinations_with_replacement(list(spec.markers), sum(extra.values()) - 1):
        assert not plan.analyse(plan._with_extra(spec, plan._count_segments(combo)), rows).passes, combo


def test_random_starts_move_the_constants_only():
    """A random start keeps every frame's poses and moves every constant, by a size-relative amount."""
    from identcheck.plan import witness_search as W

    spec = spec_of(star(2, 3, 1))
    L = K.Layout(spec)
    x0 = np.linspace(-50.0, 50.0, L.size(4))
    starts = W.random_starts(L, x0, 3, seed=5)
    assert len(starts) == 3
    for x in starts:
        assert np.array_equal(x[L.n_const:], x0[L.n_const:])
        assert np.all(x[:L.n_const] != x0[:L.n_const])
    assert all(np.array_equal(a, b) for a, b in zip(starts, W.random_starts(L, x0, 3, seed=5)))


def test_joints_identifiable_only_together_are_searched_and_said_uncounted():
    """A bare trunk with three two-marker limbs and a one-marker head: every joint is locally identifiable only
    together. The witness search starts from random whole-tree skeletons (each descended once for the whole
    group), and a joint without a verified alternative says its candidates cannot be counted exactly, and why."""
    from identcheck.plan import witness

    model = star(2, 3, 1)
    spec = spec_of(model)
    p = plan.analyse(spec)
    assert all(j["jointly_only"] for j in p.joints.values())
    found = witness.witnesses(model, spec, p, max_seconds=3600.0)   # what the searches say, not their budget
    assert set(found) == set(p.joints)
    for n, w in found.items():
        if w["verified"]:             # a second skeleton would be a counterexample: it must change this joint
            assert w["relative_change"] >= 1e-3, n
            continue
        assert w["attempts"] >= witness.RANDOM_STARTS, n
        assert "cannot be counted exactly" in w["note"] and "no table case settles it" in w["note"], n
    assert len({(w.get("attempts"), w.get("back_to_truth")) for w in found.values() if not w["verified"]}) == 1
