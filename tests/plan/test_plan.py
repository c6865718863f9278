"""`identcheck plan`: whole-tree rank, Pham V-B propagation, suggestions, robustness — checked against
simulation and against the exact-rational engine, not only against the rules."""
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck.plan import analysis as plan
from identcheck.certify import tree_rank
from identcheck import cli
from identcheck.fit.workflow import fit_model, report
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "examples"


def chain_model(types, counts) -> Model:
    """A chain root -> s1 -> ... with the given joint types and marker counts per segment."""
    segs = {f"s{i}": {"markers": [f"m{i}_{k}" for k in range(n)]} for i, n in enumerate(counts)}
    joints = {f"j{i + 1}": {"type": t, "parent": f"s{i}", "child": f"s{i + 1}"} for i, t in enumerate(types)}
    return Model.from_dict({"segments": segs, "joints": joints})


trees = st.integers(1, 3).flatmap(lambda n: st.tuples(
    st.lists(st.sampled_from(tree_rank.TYPES), min_size=n, max_size=n),
    st.lists(st.integers(0, 3), min_size=n + 1, max_size=n + 1)))


def test_table_summary_matches_a_fresh_table():
    """The packaged table copy plan reads is the certified table, recomputed."""
    from identcheck.certify.table import table

    fresh = {(c["joint"], c["p"], c["q"]): c for c in table(joints=tree_rank.TYPES).cases}
    for key, row in plan.table_summary().items():
        for k in ("identifiable", "local", "candidates", "min_samples"):
            assert row[k] == fresh[key][k], (key, k)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees)
def test_gfp_and_exact_rationals_agree(tree):
    """The fast modular rank and the exact rational rank give the same verdicts and dim W."""
    spec = tree_rank.TreeSpec.from_model(chain_model(*tree))
    a, b = tree_rank.analyse(spec, "GFp", seed=1), tree_rank.analyse(spec, "QQ", seed=2)
    assert a.dim_w == b.dim_w
    assert {n: j.local for n, j in a.joints.items()} == {n: j.local for n, j in b.joints.items()}
    assert a.failure_bound < 1e-9 and b.failure_bound < 1e-3


@settings(max_examples=30, deadline=None)
@given(trees)
def test_propagation_never_claims_more_than_the_whole_tree(tree):
    model = chain_model(*tree)
    spec = tree_rank.TreeSpec.from_model(model)
    p = plan.analyse(spec)                          # raises PlanInconsistency otherwise
    for name, j in p.joints.items():
        if j["settled_by"] == "propagation":
            assert p.rank.joints[name].local
        if j["identifiable"]:
            assert j["local"] and j["candidates"] == 1


@settings(max_examples=30, deadline=None)
@given(trees)
def test_single_joint_plans_agree_with_the_table(tree):
    """A one-joint tree is exactly a table row: the whole-tree verdict must equal the row's."""
    types, counts = tree
    model = chain_model(types[:1], counts[:2])
    j = plan.analyse(tree_rank.TreeSpec.from_model(model)).joints["j1"]
    row = plan.table_summary()[(types[0], min(counts[0], 3), min(counts[1], 3))]
    assert j["local"] == row["local"]
    assert j["identifiable"] == row["identifiable"]


def _true_distances(sim, model, name):
    truth = sim.truth.joints[name]
    out = {}
    for seg, centre, axis in ((truth.parent, truth.centre_parent, truth.axis_parent),
                              (truth.child, truth.centre_child, truth.axis_child)):
        for m, x in sim.truth.segments[seg].marker_local.items():
            w = x - centre
            out[m] = float(np.linalg.norm(w if axis is None else w - (w @ axis) * axis))
    return out


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees, st.integers(0, 10_000))
def test_identified_joints_are_recovered_from_a_simulated_trial(tree, seed):
    """Simulate the plan, run the estimators it names (``fit``); every joint the plan calls identifiable
    is recovered, uniquely, with the true marker distances."""
    model = chain_model(*tree)
    doc = plan.plan_model(model, motion=False, robust=False, suggest=False).to_dict()
    if not any(j["identifiable"] for j in doc["joints"].values()):
        return
    sim = simulate(model, n_frames=60, seed=seed, noise_mm=0.0)
    fitted, points = fit_model(model, sim.trial)
    rep = report(model, fitted, points)["joints"]
    pham21 = {n for n, j in doc["joints"].items() if j.get("rejected_by")}
    for name, j in doc["joints"].items():
        if not j["identifiable"]:
            continue
        if (name in pham21 or set(j["depends_on"]) & pham21) and not rep[name]["excitation"]["ok"]:
            # Pham (2,1) decided by a far marker: a hinge passing close to the two parent points is
            # generic but ill-conditioned, and the estimator says so instead of returning a number
            assert rep[name]["excitation"]["reason"]
            continue
        assert rep[name]["unique"], (name, j["case"], rep[name])
        want = _true_distances(sim, model, name)
        for m, d in rep[name]["marker_distances"].items():
            assert d == pytest.approx(want[m], abs=1e-3 + 1e-6 * want[m]), (name, m)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees)
def test_suggestions_fix_the_plan_and_are_fewest(tree):
    """The suggestion makes every joint locally identifiable with none left several candidates (the whole-tree
    rank's target), nothing with one marker fewer does; the propagation's fix makes every joint identifiable."""
    model = chain_model(*tree)
    spec = tree_rank.TreeSpec.from_model(model)
    rows = plan.table_summary()
    sugg = plan.suggestions(spec, rows, max_markers=4)
    if plan.analyse(spec, rows).all_identifiable:
        return
    assert sugg is not None
    extra = {s["segment"]: s["add_markers"] for s in sugg}
    assert plan.analyse(plan._with_extra(spec, extra), rows).passes
    k = sum(extra.values())
    if k > 1:                                       # nothing with one marker fewer works
        assert plan.suggestions(spec, rows, max_markers=k - 1) is None
    unique = plan.unique_suggestions(spec, rows, max_markers=4)
    if unique is not None:
        assert plan.analyse(plan._with_extra(spec, unique), rows).all_identifiable
        assert sum(unique.values()) >= k


def test_body16_paper_plan():
    """Pham V-B's 16-marker body: every joint is identifiable, as the paper says, but not for its reason. The
    knees and elbows are settled by revolute (2,1) on the hip or shoulder centre, which alone admits 4 joints
    (ERRATA E1, E2); the single foot and hand markers, beyond the ankles and wrists, reject the other 3
    (an exact certificate), and the ankles and wrists follow uniquely."""
    doc = plan.plan_model(Model.from_toml(EXAMPLES / "body16.toml")).to_dict()
    j = doc["joints"]
    assert len(j) == 13 and doc["all_local"] and doc["all_identifiable"] and doc["suggestions"] == []
    far = {"knee_l": "LANKLE", "knee_r": "RANKLE", "elbow_l": "LWRIST", "elbow_r": "RWRIST"}
    for n, marker in far.items():
        assert j[n]["case"] == "revolute(2,1)" and j[n]["candidates"] == 1
        assert j[n]["rejected_by"]["marker"] == marker
        assert any(v.endswith(".centre") for v in j[n]["uses_virtual_markers"])
    for n in ("ankle_l", "wrist_r"):
        assert j[n]["case"] == "spherical(3,1)" and j[n]["candidates"] == 1 and j[n]["depends_on"]
    assert not any(r["plan_survives"] for r in doc["robustness"].values())


def test_shared_motion_is_reported():
    """Two pelvis markers, one thigh, one shank marker: the hip (2,1) is not identifiable alone (table),
    but the whole tree pins it together with the knee — the report says so."""
    model = chain_model(["spherical", "revolute"], [2, 1, 1])
    doc = plan.plan_model(model, motion=False, robust=False).to_dict()
    assert doc["joints"]["j1"]["local"] and doc["joints"]["j1"]["jointly_only"]
    assert "shared_motion" in doc
    assert not plan.table_summary()[("spherical", 2, 1)]["local"]


def test_motion_needed_names_the_joint_itself():
    doc = plan.plan_model(Model.from_toml(EXAMPLES / "sparse_leg.toml"), robust=False).to_dict()
    assert doc["joints"]["knee_r"]["motion_needed"] == ["knee_r"]


def test_cli_plan_json_and_exit_codes(tmp_path, capsys):
    fig = tmp_path / "plan.png"
    rc = cli.main(["plan", str(EXAMPLES / "pig_lower_limb.toml"), "--json", "--figure", str(fig)])
    doc = json.loads(capsys.readouterr().out)
    assert rc == 0 and doc["all_identifiable"] and fig.stat().st_size > 10_000
    for j in doc["joints"].values():
        assert {"identifiable", "local", "candidates", "case", "min_samples", "uses_virtual_markers",
                "reason"} <= set(j)
    assert doc["suggestions"] == []
    rc = cli.main(["plan", str(EXAMPLES / "sparse_leg.toml")])
    out = capsys.readouterr().out
    assert rc == 1 and "fewest markers to add: 1 on thigh_r" in out
    assert math.isfinite(doc["certificate"]["failure_probability_bound"])


def test_cli_plan_bad_model(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[segments.a]\nmarkers=["x"]\n[segments.b]\nmarkers=["y"]\n'
                   '[joints.j]\ntype="screw"\nparent="a"\nchild="b"\n')
    rc = cli.main(["plan", str(bad), "--json"])
    err = capsys.readouterr().err
    assert rc == 2 and "screw" in err and "bad.toml" in err


@pytest.mark.parametrize("types,counts", [
    (["spherical", "revolute"], [2, 1, 1]),          # shared motion: hip (2,1) pinned through the knee
    (["spherical"], [2, 1]),                         # table: not identifiable
    (["revolute", "spherical"], [3, 1, 1]),
    (["revolute"], [1, 1]),
])
def test_whole_tree_verdicts_agree_with_an_independent_float_jacobian(types, counts):
    """Floating point only cross-checks here: an independently written finite-difference Jacobian of
    plain forward kinematics must agree with the exact engine on the marker-distance quantities."""
    from float_tree import FloatTree

    spec = tree_rank.TreeSpec.from_model(chain_model(types, counts))
    exact = tree_rank.analyse(spec)
    ft = FloatTree(spec, n_frames=exact.frames + 4, seed=3)
    for name, *_ in spec.joints:
        quantities = [q for q in exact.joints[name].quantities if not q.startswith("axial")]
        determined = [q for q in quantities if q not in exact.joints[name].undetermined]
        assert ft.locally_identifiable(name) == (len(determined) == len(quantities) > 0), name


def test_broken_body16_gets_the_fewest_marker_fix():
    """Losing the head marker breaks the neck; the fix is one head marker. Losing a foot marker leaves the
    knee's candidates undecided; the fix is one more marker on the thigh or the shank."""
    body = tree_rank.TreeSpec.from_model(Model.from_toml(EXAMPLES / "body16.toml"))
    rows = plan.table_summary()
    spec = body.without("HEAD")
    p = plan.analyse(spec, rows)
    assert not p.joints["neck"]["local"] and "head" in p.joints["neck"]["reason"]
    assert plan.suggestions(spec, rows) == [{"segment": "head", "add_markers": 1}]
    spec = body.without("LANKLE")
    p = plan.analyse(spec, rows)
    assert p.joints["knee_l"]["candidates"] == 4 and not p.joints["knee_l"]["identifiable"]
    sugg = plan.suggestions(spec, rows)
    assert sum(s["add_markers"] for s in sugg) == 1
    assert plan.analyse(plan._with_extra(spec, {s["segment"]: s["add_markers"] for s in sugg}), rows).all_identifiable


@pytest.mark.slow
def test_cli_fewest_local_finding(capsys):
    """The finding of issue 7: dropping markers greedily, body16 stays locally identifiable with 13."""
    rc = cli.main(["plan", str(EXAMPLES / "body16.toml"), "--json", "--fast", "--fewest"])
    doc = json.loads(capsys.readouterr().out)
    f = doc["fewest_local"]
    assert rc == 0 and f["markers"] == 16 - len(f["removable"])
    kept = tree_rank.TreeSpec.from_model(Model.from_toml(EXAMPLES / "body16.toml"))
    for m in f["removable"]:
        kept = kept.without(m)
    assert all(j.local for j in tree_rank.analyse(kept).joints.values())
    for seg, ms in f["per_segment"].items():       # and no single further marker can go
        for m in ms:
            assert not all(j.local for j in tree_rank.analyse(kept.without(m)).joints.values()), m


def _nothing_else_can_tell(spec, p, name) -> bool:
    """The joint was settled by a case with several candidates from real markers only, and those are the
    only markers of the whole tree: nothing else could reject the case's other candidates."""
    st = p.settled.get(name)
    if st is None or st.case_candidates == 1 or st.virtual:
        return False
    every = {m for ms in spec.markers.values() for m in ms}
    return every == set(st.parent_points) | set(st.child_points)


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees, st.integers(0, 10_000))
def test_non_identified_joints_admit_a_verified_alternative(tree, seed):
    """Simulate the plan; for every joint it does not identify, a second skeleton reproduces every marker
    of every frame — including frames the search never saw — to 1e-30 mm at 50 digits, with the joint's
    quantities changed. Not locally identifiable: always. Several candidates of a lone case: always."""
    from identcheck.plan import witness as plan_witness

    model = chain_model(*tree)
    spec = tree_rank.TreeSpec.from_model(model)
    p = plan.analyse(spec)
    ws = plan_witness.witnesses(model, spec, p, seed=seed)
    assert set(ws) == {n for n, j in p.joints.items() if not j["identifiable"]}
    for name, j in p.joints.items():
        if j["identifiable"]:
            continue
        w = ws[name]
        if not p.rank.joints[name].quantities or not any(spec.markers.values()):   # nothing to reproduce
            assert w["method"] is None and not w["verified"]
            continue
        if not j["local"] or _nothing_else_can_tell(spec, p, name):
            assert w["verified"], (name, j["case"], w)
        if w["verified"]:
            assert w["max_marker_error_mm"] <= 1e-30 and w["held_out_max_marker_error_mm"] <= 1e-30
            assert w["relative_change"] >= 1e-3 and w["held_out_frames"] >= 20


@pytest.mark.slow
def test_a_far_marker_decides_the_knee_in_plan_fit_and_search():
    """A leg with three pelvis markers and one on each of thigh, shank and foot: the knee is Pham's revolute
    (2,1) on the hip centre, 4 candidates by the table alone. The foot marker, beyond the ankle, rejects the
    other 3: the plan says identifiable (exact certificate), `fit` picks the true knee from a simulated
    trial, and the whole-tree search finds no second skeleton. Without the foot marker, the search finds
    and verifies the twin."""
    from identcheck.plan import witness as plan_witness
    from identcheck.plan import tree_kinematics as K
    from identcheck.plan import witness_search as W

    leg = chain_model(["spherical", "revolute", "spherical"], [3, 1, 1, 1])
    spec = tree_rank.TreeSpec.from_model(leg)
    p = plan.analyse(spec)
    knee = p.joints["j2"]
    assert knee["case"] == "revolute(2,1)" and knee["identifiable"] and knee["rejected_by"]["marker"] == "m3_0"

    sim = simulate(leg, n_frames=120, seed=3, noise_mm=0.0)
    fitted, points = fit_model(leg, sim.trial)
    rep = report(leg, fitted, points)["joints"]["j2"]
    assert rep["unique"] and any("chosen among 4" in n for n in rep["notes"])
    for m, d in rep["marker_distances"].items():
        assert d == pytest.approx(_true_distances(sim, leg, "j2")[m], abs=1e-3)

    truth, held = plan_witness.simulated_truth(leg, spec, 20, seed=2)
    search = W.construct(spec, truth, 20, "j2", "isolated", held_out_truth=held, n_held_out=20,
                         case_points={"j2": (p.settled["j2"].parent_points, p.settled["j2"].child_points)})
    assert search.attempts >= 1 and (search.witness is None or not search.witness.verified)
    assert search.closest_miss_mm is not None and search.closest_miss_mm > 0.1

    no_foot = spec.without("m3_0")
    p2 = plan.analyse(no_foot)
    assert p2.joints["j2"]["candidates"] == 4 and not p2.joints["j2"]["identifiable"]
    w2 = plan_witness.witnesses(leg, no_foot, p2, seed=2)["j2"]
    assert w2["verified"] and w2["max_marker_error_mm"] <= 1e-30 and w2["held_out_max_marker_error_mm"] <= 1e-30
    assert K.Layout(no_foot).markers == ["m0_0", "m0_1", "m0_2", "m1_0", "m2_0"]


@pytest.mark.slow
def test_cli_plan_witness(capsys):
    """`plan --witness` on the sparse leg: the knee's second joint is built and verified; the hip needs none."""
    rc = cli.main(["plan", str(EXAMPLES / "sparse_leg.toml"), "--json", "--fast", "--witness"])
    doc = json.loads(capsys.readouterr().out)
    assert rc == 1
    assert "alternative" not in doc["joints"]["hip_r"]
    w = doc["joints"]["knee_r"]["alternative"]
    assert w["verified"] and w["method"] == "isolated" and w["precision_digits"] == 50
    assert w["max_marker_error_mm"] <= 1e-30 and w["held_out_max_marker_error_mm"] <= 1e-30
    assert w["relative_change"] >= 1e-3
    cli.main(["plan", str(EXAMPLES / "sparse_leg.toml"), "--fast", "--witness"])
    assert "alternative: VERIFIED" in capsys.readouterr().out


def test_fewest_markers_can_sit_beyond_the_joint():
    """Pelvis 3, thigh 1, shank 1 and a markerless foot: one foot marker fixes both the knee (it rejects the
    (2,1) twin from beyond the ankle) and the ankle, where markers next to the open joints would need two."""
    model = Model.from_dict({
        "segments": {"pelvis": {"markers": ["A", "B", "C"]}, "thigh": {"markers": ["T"]},
                     "shank": {"markers": ["S"]}, "foot": {"markers": []}},
        "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
                   "knee": {"type": "revolute", "parent": "thigh", "child": "shank"},
                   "ankle": {"type": "spherical", "parent": "shank", "child": "foot"}}})
    spec = tree_rank.TreeSpec.from_model(model)
    rows = plan.table_summary()
    assert plan.suggestions(spec, rows) == [{"segment": "foot", "add_markers": 1}]
    assert plan.suggestions(spec, rows, max_markers=0) is None


def test_no_rejection_when_the_one_point_is_the_far_joints_centre():
    """A far marker rejects the (2,1) twin only through a point of the one-point segment other than the
    case's own point: if that point is the far joint's centre (or on its axis), the far marker keeps its
    distance in every candidate's frame and decides nothing."""
    model = Model.from_dict({
        "segments": {"pelvis": {"markers": ["A", "B", "C"]}, "thigh": {"markers": ["T"]},
                     "shank": {"markers": ["S"]}, "foot": {"markers": ["F"]}},
        "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
                   "knee": {"type": "revolute", "parent": "thigh", "child": "shank"},
                   "ankle": {"type": "spherical", "parent": "shank", "child": "foot"}}})
    spec = tree_rank.TreeSpec.from_model(model)
    assert plan.far_marker(spec, "knee", "shank", ["S"])["marker"] == "F"
    assert plan.far_marker(spec, "knee", "shank", ["ankle.centre"]) is None
    assert plan.far_marker(spec, "knee", "shank", ["ankle.axis[0]"]) is None
