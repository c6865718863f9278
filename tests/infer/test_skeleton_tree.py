"""The tree and the joint types from a trial (identcheck.infer.tree, identcheck.infer.joint_types), through the
workflow (identcheck.infer.workflow)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.estimate.hierarchy import infer_hierarchy
from identcheck.estimate.joint import MIN_TRAVEL_MM
from identcheck.estimate.obrien import as_poses, joint_location
from identcheck.infer.joint_types import classify_posed, noise_wobble_deg
from identcheck.infer.tree import (REL_AMBIGUOUS, THROUGH_RATIO, THROUGH_TRAVEL, Z_AMBIGUOUS, Edge, SmallFit, Tree,
                                   _insert, _inserted_doubt, _oriented, compare_residuals, orient)
from identcheck.infer.workflow import _play, infer_skeleton
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from strategies_skeleton import cases, make_case


@settings(max_examples=12, deadline=None)
@given(cases(noise=(0.0, 0.3), wobble=(0.0,), loose=(0,)))
def test_tree_and_types_of_random_skeletons(case):
    """Random trees (2-5 segments), random types, every ball joint turned about three axes, noise up to 0.3 mm and
    occlusions: the grouping, the tree (as unordered joints) and every joint type come out right, and the
    result says so (ok)."""
    doc = infer_skeleton(case.trial).to_dict()
    assert {frozenset(ms) for ms in doc["segments"].values()} == {frozenset(ms) for ms in case.segments.values()}
    found = case.named_edges(doc)
    assert set(found) == case.edges
    assert found == case.types
    assert all(0.5 <= j["confidence"] <= 1 for j in doc["joints"])


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 5), st.sampled_from([0.0, 0.3]))
def test_given_segments_give_the_tree_and_types(seed, n, noise):
    """With the grouping given, only the tree and the types are inferred; the names are the user's."""
    case = make_case(seed, n, noise_mm=noise)
    names = {f"seg_{s}": ms for s, ms in case.segments.items()}
    doc = infer_skeleton(case.trial, segments=names).to_dict()
    assert doc["segments"] == names and doc["grouping"]["source"] == "--segments"
    edges = {frozenset((j["parent"][4:], j["child"][4:])): j["type"] for j in doc["joints"]}
    assert edges == case.types


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**16), st.sampled_from([1, 2]))
def test_a_one_or_two_marker_leaf_is_placed_on_its_parent(seed, q):
    """A leaf segment with one or two markers has no pose; a sphere (or circle) fit in its parent's frame places it,
    and its joint is typed from the sphere against the circle."""
    case = make_case(seed, 4, counts=[3, 4, 3, q], parents=[0, 1, 1], types=["spherical", "revolute", "spherical"],
                     noise_mm=0.2)
    doc = infer_skeleton(case.trial).to_dict()
    found = case.named_edges(doc)
    leaf = [j for j in doc["joints"] if len(doc["segments"][j["child"]]) == q][0]
    assert leaf["evidence"]["tree"]["method"].startswith("sphere and circle")
    if set(found) != case.edges:
        # The simulator puts both children of s1 at one joint centre, so the leaf's markers stay on a sphere about
        # it in s2's frame as well: then it must say so (its placement ambiguous, s1 the alternative).
        owner = case.owner()
        name = {g: owner[ms[0]] for g, ms in doc["segments"].items()}
        amb = [a for a in doc["ambiguous"] if name[a["joint"][1]] == "s3"]
        assert amb and {name[x] for x in amb[0]["joint"] + amb[0]["alternative"]} == {"s1", "s2", "s3"}
    else:
        assert found[frozenset(("s1", "s3"))] == "spherical"


def test_a_two_marker_segment_inside_a_chain_goes_between_its_neighbours():
    """s0 - s1 - s2 with s1 carrying two markers: the posed segments s0 and s2 fit no joint (their best one leaves
    tens of mm), and s1 fits a joint with both: it is put between them."""
    case = make_case(5, 3, counts=[3, 2, 3], parents=[0, 1], types=["spherical", "spherical"], noise_mm=0.2)
    doc = infer_skeleton(case.trial).to_dict()
    assert set(case.named_edges(doc)) == case.edges
    assert any("inserted" in j["evidence"]["tree"] for j in doc["joints"])
    assert not doc["poor_joints"]


AMBIGUOUS_MODEL = """
units = "mm"
[segments.pelvis]
markers = ["P1", "P2", "P3"]
positions = { P1 = [60, 0, 40], P2 = [-40, 80, 20], P3 = [-40, -80, 30] }
[segments.thigh_l]
markers = ["L1", "L2", "L3"]
positions = { L1 = [40, 20, -120], L2 = [-30, 40, -200], L3 = [10, -30, -300] }
length_mm = 400
[segments.thigh_r]
markers = ["R1", "R2", "R3"]
positions = { R1 = [40, -20, -120], R2 = [-30, -40, -200], R3 = [10, 30, -300] }
length_mm = 400
[joints.hip_l]
type = "revolute"
parent = "pelvis"
child = "thigh_l"
axis = [0, 1, 0]
centre_parent = [0, 90, -50]
centre_child = [0, 0, 0]
[joints.hip_r]
type = "revolute"
parent = "pelvis"
child = "thigh_r"
axis = [0, 1, 0]
centre_parent = [0, -90, -50]
centre_child = [0, 0, 0]
"""


def test_two_trees_within_the_noise_are_reported_with_the_motion_that_separates_them(tmp_path):
    """Both hips flex about one common axis (walking, idealised): a joint between the thighs anywhere on that axis
    fits as well as either hip, so the tree is not determined. The result says which joint is ambiguous, gives both
    trees, names a motion that would separate them, lists the unused low-residual pair as a loop, and is not ok."""
    path = tmp_path / "hips.toml"
    path.write_text(AMBIGUOUS_MODEL)
    sim = simulate(Model.from_toml(path), n_frames=300, seed=4, noise_mm=0.3, rom_deg=50)
    res = infer_skeleton(sim.trial, segments={"pelvis": ["P1", "P2", "P3"], "thigh_l": ["L1", "L2", "L3"],
                                              "thigh_r": ["R1", "R2", "R3"]}, root="pelvis")
    doc = res.to_dict()
    assert not res.ok and doc["ambiguous"]
    amb = doc["ambiguous"][0]
    pairs = [set(amb["joint"]), set(amb["alternative"])]
    assert {"thigh_l", "thigh_r"} in pairs
    chosen, alternative = (set(map(tuple, map(sorted, amb["trees"][k]))) for k in ("chosen", "alternative"))
    assert chosen != alternative
    assert "record" in amb["separating_motion"] and "thigh" in amb["separating_motion"]
    assert doc["loops"] and all(j["type"] == "revolute" for j in doc["joints"])


def test_runner_up_and_confidence_when_the_tree_is_clear():
    case = make_case(11, 4, noise_mm=0.3)
    doc = infer_skeleton(case.trial).to_dict()
    assert doc["ok"] and not doc["ambiguous"]
    assert {r["joint"] for r in doc["runner_up"]} == {j["name"] for j in doc["joints"]}
    for r in doc["runner_up"]:
        assert r["margin_mm"] > 0 and r["residual_mm"] > r["margin_mm"] - 1e-9


# ---------------------------------------------------------------------- pieces
def test_compare_residuals_counts_what_noise_allows():
    rng = np.random.default_rng(0)
    a = np.abs(rng.normal(5, 1, 500))
    same = np.abs(rng.normal(5, 1, 500))
    x_same, unit, _ = compare_residuals(a, same, float(np.sqrt(np.mean(a**2))), float(np.sqrt(np.mean(same**2))))
    assert abs(x_same) < 2 and unit >= 0.1 * 5
    far = a + 10
    x_far, _, _ = compare_residuals(a, far, float(np.sqrt(np.mean(a**2))), float(np.sqrt(np.mean(far**2))))
    assert x_far > 10


def test_orient_walks_from_the_root():
    assert orient([("b", "a"), ("b", "c"), ("d", "c")], "a") == [["a", "b"], ["b", "c"], ["c", "d"]]


@pytest.mark.parametrize("sigma", [0.5, 2.0])
def test_the_predicted_noise_wobble_of_a_hinge_matches_simulation(sigma):
    """A perfect hinge under marker noise σ: the wobble off its axis that O'Brien's fit shows is what
    noise_wobble_deg predicts, within a factor of two (median over seeds)."""
    ratios = []
    for seed in range(6):
        case = make_case(seed, 2, counts=[3, 3], types=["revolute"], noise_mm=sigma, n_frames=400)
        X = case.trial.xyz
        p, c = X[:, :3], X[:, 3:]
        fit = joint_location(p, c)
        from identcheck.geometry.poses import segment_poses
        pred = noise_wobble_deg(segment_poses(p).local, segment_poses(c).local, sigma)
        ratios.append(fit.spread_deg[0] / pred)
    assert 0.5 < np.median(ratios) < 2.0


class _Fit:
    def __init__(self, spread):
        self.spread_deg = np.array(spread, dtype=float)
        self.singular_values = np.ones(6)
        self.n_frames = 100


@pytest.mark.parametrize("spread, noise, kind", [
    ((0.3, 20, 20), 0.2, "revolute"),          # a clean hinge
    ((4.0, 25, 26), 0.2, "revolute"),          # a knee with skin wobble: under a quarter of the flexion
    ((12, 18, 25), 0.2, "spherical"),          # a ball joint turned about three axes
    ((6.0, 15, 16), 0.2, "spherical"),         # more than a quarter of the main rotation off the axis
    ((0.5, 1.0, 1.2), 0.2, "spherical"),       # hardly moves: the general type, no confidence
])
def test_type_rule(spread, noise, kind):
    jt = classify_posed(_Fit(spread), noise)
    assert jt.type == kind and jt.evidence["wobble_deg"] == spread[0] and "rule" in jt.evidence
    if spread[1] < 2:
        assert jt.confidence == 0.5


@settings(max_examples=200, deadline=None)
@given(st.floats(0.2, 5.0), st.lists(st.floats(0.1, 12.0), min_size=1, max_size=5), st.floats(1.0, 8.0),
       st.integers(0, 4))
def test_an_inserted_group_that_fits_another_segment_as_well_is_reported(r_parent, r_others, accept, n_below):
    """A group put between two posed segments hangs from the poor joint's parent, which the posed tree chose without
    it. A report is made exactly when some other segment outside the child's side fits it within the accepted
    residual and by less than Z_AMBIGUOUS units (REL_AMBIGUOUS of its residual with the parent) worse; segments on
    the child's side are never the alternative, and the report names the best alternative."""
    fits = {"P": SmallFit(r_parent, float("nan"), 50.0, 100.0, 500)}
    fits.update({f"S{k}": SmallFit(r, float("nan"), 50.0, 100.0, 500) for k, r in enumerate(r_others)})
    below = {f"S{k}" for k in range(min(n_below, len(r_others)))}
    out = _inserted_doubt("g", fits, "P", below, accept)
    outside = sorted((f.residual_mm, s) for s, f in fits.items() if s != "P" and s not in below
                     and f.residual_mm <= accept)
    unit = max(REL_AMBIGUOUS * r_parent, 1e-9)
    expected = bool(outside) and (outside[0][0] - r_parent) / unit < Z_AMBIGUOUS
    assert bool(out) == expected
    if out:
        (rep,) = out
        assert rep["joint"] == ["P", "g"] and rep["alternative"] == [outside[0][1], "g"]
        assert rep["alternative"][0] not in below and rep["margin_units"] < Z_AMBIGUOUS


class _Turnable:
    """A stand-in O'Brien fit that records how often it was turned parent <-> child."""

    def __init__(self, turns=0):
        self.turns = turns

    def reversed(self):
        return _Turnable(self.turns + 1)


def _path(pairs, a, b) -> list:
    """The undirected pairs on the tree path from a to b."""
    adj: dict = {}
    for u, v in pairs:
        adj.setdefault(u, []).append(v)
        adj.setdefault(v, []).append(u)
    back, queue = {a: None}, [a]
    while queue:
        u = queue.pop(0)
        for v in adj.get(u, []):
            if v not in back:
                back[v], queue = u, queue + [v]
    out, v = [], b
    while back[v] is not None:
        out.append(frozenset((back[v], v)))
        v = back[v]
    return out


@settings(max_examples=200, deadline=None)
@given(st.integers(2, 7), st.data(), st.floats(0.3, 4.0), st.floats(1.0, 6.0), st.floats(5.0, 60.0))
def test_a_small_group_goes_where_the_direct_joint_it_explains_is_worst(n, data, r_group, accept, travel):
    """Posed segments joined by a random tree of joints leaving 1-15 mm (none poor) and a one-marker group that
    fits a joint with two of them (a, b): the group replaces the worst joint on the tree path between a and b
    exactly when that joint leaves more than THROUGH_RATIO times the group's worst fit and the group moves at least
    THROUGH_TRAVEL x the accepted residual and x the travel a joint fit needs in both frames; the result is a tree
    over the posed segments and the group, oriented from the top, with every O'Brien fit turned exactly when its
    joint was."""
    parents = [data.draw(st.integers(0, i - 1)) for i in range(1, n)]
    res = data.draw(st.lists(st.floats(1.0, 15.0), min_size=n - 1, max_size=n - 1, unique=True))
    edges = [Edge(f"P{p}", f"P{i}", r, "obrien", None, 1.0, False, fit=_Turnable())
             for i, (p, r) in enumerate(zip(parents, res), 1)]
    a, b = data.draw(st.lists(st.integers(0, n - 1), min_size=2, max_size=2, unique=True))
    r_a, r_b = r_group, data.draw(st.floats(0.3, 4.0))
    r_a, r_b = min(r_a, accept), min(r_b, accept)
    nan = float("nan")
    fits = {"g": {f"P{k}": (SmallFit(r_a if k == a else r_b, nan, travel, 100.0, 500) if k in (a, b) else
                            SmallFit(nan, nan, travel, nan, 500, "no sphere"))
                  for k in range(n)}}
    out, used, poor, _, replaced = _insert(edges, fits, accept, "P0")
    on_path = _path([(e.parent, e.child) for e in edges], f"P{a}", f"P{b}")
    worst = max((e for e in edges if frozenset((e.parent, e.child)) in on_path), key=lambda e: e.residual_mm)
    expect = (worst.residual_mm > THROUGH_RATIO * max(r_a, r_b)
              and travel >= THROUGH_TRAVEL * max(accept, MIN_TRAVEL_MM))
    assert not poor
    assert (used == ["g"]) == expect
    assert replaced == ([(worst.parent, worst.child)] if expect else [])
    nodes = {f"P{k}" for k in range(n)} | ({"g"} if expect else set())
    assert len(out) == len(nodes) - 1
    gone = {frozenset((worst.parent, worst.child))} if expect else set()
    assert {frozenset((e.parent, e.child)) for e in out if e.method == "obrien"} == \
        {frozenset((e.parent, e.child)) for e in edges} - gone
    seen = {"P0"}
    for e in out:                                   # parents before children, each child once
        assert e.parent in seen and e.child not in seen
        seen.add(e.child)
    assert seen == nodes
    before = {(e.parent, e.child) for e in edges}
    for e in out:
        if e.method == "obrien":
            assert e.fit.turns == (0 if (e.parent, e.child) in before else 1)
        else:
            assert {e.parent, e.child} & {f"P{a}", f"P{b}"} and "g" in (e.parent, e.child)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 5))
def test_playback_follows_the_tree_however_its_joints_are_turned(seed, n):
    """A noise-free chain of ball joints whose O'Brien hierarchy is rooted at its last segment, with the tree's
    joints turned to hang from its first (as after a small group put between two segments re-roots a part): the
    playback runs from that one top through every joint and reproduces the markers."""
    case = make_case(seed, n, counts=[3] * n, parents=list(range(n - 1)), types=["spherical"] * (n - 1))
    points = {s: case.trial.select(ms).as_array() for s, ms in case.segments.items()}
    h = infer_hierarchy({s: as_poses(p, s) for s, p in points.items()}, root=f"s{n - 1}")
    edges = [Edge(h.parent[c], c, float(h.fits[c].rms_residual), "obrien", None, 1.0, False, fit=h.fits[c])
             for c in h.order[1:]]
    edges = _oriented(edges, "s0")
    assert [(e.parent, e.child) for e in edges] == [(f"s{k}", f"s{k + 1}") for k in range(n - 1)]
    tree = Tree("s0", "given", tuple(edges), dict(case.segments), (), (), (), {}, hierarchy=h, points=points)
    played, summary = _play(tree, np.zeros(3), ["spherical"] * (n - 1))
    assert summary["played_from"] == ["s0"]
    assert summary["rms_mm"] < 1e-6
