"""Hierarchy by minimum spanning tree (O'Brien et al. 3.3) and playback (3.4)."""
import itertools

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.estimate.hierarchy import infer_hierarchy, playback, points_by_segment, rebuild
from identcheck.estimate.obrien import joint_location
from identcheck.geometry.poses import Poses
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate


@st.composite
def trees(draw, max_segments=6):
    """(model, true parent map): a random tree s0..s{n-1} rooted at s0, 3 markers a segment."""
    n = draw(st.integers(2, max_segments))
    parents = [draw(st.integers(0, i - 1)) for i in range(1, n)]
    types = [draw(st.sampled_from(["spherical", "revolute"])) for _ in parents]
    segs = {f"s{i}": {"markers": [f"m{i}_{k}" for k in range(3)]} for i in range(n)}
    joints = {f"j{i}": {"type": types[i - 1], "parent": f"s{p}", "child": f"s{i}"}
              for i, p in enumerate(parents, start=1)}
    model = Model.from_dict({"units": "mm", "segments": segs, "joints": joints})
    return model, {f"s{i}": f"s{p}" for i, p in enumerate(parents, start=1)}


def undirected(parent):
    return {frozenset(e) for e in parent.items()}


def prufer_trees(n):
    """Every labelled tree on n nodes, as edge lists (Prüfer sequences)."""
    if n == 2:
        yield [(0, 1)]
        return
    for seq in itertools.product(range(n), repeat=n - 2):
        degree = [1] * n
        for x in seq:
            degree[x] += 1
        edges = []
        for x in seq:
            leaf = min(i for i in range(n) if degree[i] == 1)
            edges.append((leaf, x))
            degree[leaf] -= 1
            degree[x] -= 1
        u, v = [i for i in range(n) if degree[i] == 1]
        yield edges + [(u, v)]


# ---------------------------------------------------------------------- section 3.3
@given(trees(), st.integers(0, 2**16), st.sampled_from([0.0, 0.25]))
def test_mst_recovers_a_random_tree(tree, seed, occlusion):
    model, truth = tree
    sim = simulate(model, n_frames=60, seed=seed, occlusion=occlusion)
    h = infer_hierarchy(points_by_segment(sim.trial, model), root="s0")
    assert h.parent == truth and h.root == "s0" and h.root_rule == "given"
    assert all(f.rms_residual < 1e-6 for f in h.fits.values())
    # exact data: every other tree fits strictly worse (the margin can be small: a hinge whose
    # axis passes near a sibling's centre nearly fits that sibling too)
    assert all(m > 1e-6 for m in h.margin_mm.values())
    # the root is a convention: the default (tree centre) gives the same joints
    assert undirected(infer_hierarchy(points_by_segment(sim.trial, model)).parent) == undirected(truth)


@given(trees(max_segments=5), st.integers(0, 2**16), st.floats(0.2, 3.0))
def test_mst_is_the_minimum_over_every_tree_and_margins_are_exact(tree, seed, noise):
    """Brute force over all labelled trees: the chosen tree has the least summed residual, and
    each margin is the best tree without that joint minus the best tree."""
    model, _ = tree
    sim = simulate(model, n_frames=40, seed=seed, noise_mm=noise)
    h = infer_hierarchy(points_by_segment(sim.trial, model), root="s0")
    W, idx = h.residual_mm, {s: k for k, s in enumerate(h.segments)}
    totals = {frozenset(frozenset(e) for e in edges): sum(W[e] for e in edges)
              for edges in prufer_trees(len(W))}
    best = min(totals.values())
    assert h.total_residual_mm == pytest.approx(best, rel=1e-12)
    for child, parent in h.parent.items():
        edge = frozenset((idx[child], idx[parent]))
        without = min((v for k, v in totals.items() if edge not in k), default=np.inf)
        assert h.margin_mm[child] == pytest.approx(without - best, rel=1e-9, abs=1e-9)


@given(trees(max_segments=5), st.integers(0, 2**16), st.floats(0.2, 3.0), st.integers(0, 2**16))
def test_with_expected_residuals_the_tree_minimises_the_summed_excess(tree, seed, noise, salt):
    """With ``expected`` (what a perfect joint would leave at each pair), brute force over all labelled trees: the
    chosen tree has the least summed excess r² − expected²; a zero expectation gives the raw residual tree."""
    model, _ = tree
    sim = simulate(model, n_frames=40, seed=seed, noise_mm=noise)
    pts = points_by_segment(sim.trial, model)
    rng = np.random.default_rng(salt)
    scale = {frozenset(p): rng.uniform(0.0, 1.5) for p in itertools.combinations(model.segments, 2)}
    h = infer_hierarchy(pts, root="s0", expected=lambda a, b, fit: scale[frozenset((a, b))] * fit.rms_residual)
    E, idx = h.excess_mm2, {s: k for k, s in enumerate(h.segments)}
    W = h.residual_mm
    for (a, b), s in ((tuple(p), s) for p, s in scale.items()):
        assert E[idx[a], idx[b]] == pytest.approx(W[idx[a], idx[b]] ** 2 * (1.0 - s ** 2), rel=1e-9, abs=1e-12)
    totals = [sum(E[e] for e in edges) for edges in prufer_trees(len(E))]
    chosen = sum(E[idx[c], idx[p]] for c, p in h.parent.items())
    assert chosen == pytest.approx(min(totals), rel=1e-9, abs=1e-9)
    plain = infer_hierarchy(pts, root="s0")
    zero = infer_hierarchy(pts, root="s0", expected=lambda a, b, fit: 0.0)
    assert zero.parent == plain.parent and np.array_equal(zero.residual_mm, plain.residual_mm)


@given(trees(max_segments=4), st.integers(0, 2**16), st.floats(0, 2.0))
def test_edge_weights_are_symmetric_pair_fits(tree, seed, noise):
    model, _ = tree
    sim = simulate(model, n_frames=40, seed=seed, noise_mm=noise)
    pts = points_by_segment(sim.trial, model)
    h = infer_hierarchy(pts)
    W = h.residual_mm
    np.testing.assert_array_equal(W, W.T)
    a, b = h.segments[0], h.segments[1]
    assert W[0, 1] == pytest.approx(joint_location(pts[b], pts[a]).rms_residual, rel=1e-9, abs=1e-12)
    for child, fit in h.fits.items():   # oriented parent -> child
        direct = joint_location(pts[h.parent[child]], pts[child])
        np.testing.assert_allclose(fit.centre_parent, direct.centre_parent, atol=1e-6)
        np.testing.assert_allclose(fit.centre_child, direct.centre_child, atol=1e-6)


def test_default_root_is_the_tree_centre():
    segs = {f"s{i}": {"markers": [f"m{i}_{k}" for k in range(3)]} for i in range(5)}
    joints = {f"j{i}": {"type": "spherical", "parent": f"s{i - 1}", "child": f"s{i}"} for i in range(1, 5)}
    model = Model.from_dict({"units": "mm", "segments": segs, "joints": joints})
    sim = simulate(model, n_frames=60, seed=2)
    h = infer_hierarchy(points_by_segment(sim.trial, model))
    assert h.root == "s2" and h.root_rule == "centre"
    assert h.parent == {"s1": "s2", "s3": "s2", "s0": "s1", "s4": "s3"}
    assert h.order[0] == "s2" and [e[:2] for e in h.edges()][:2] == [("s2", "s1"), ("s2", "s3")]


# ---------------------------------------------------------------------- section 3.4
@given(trees(), st.integers(0, 2**16))
def test_playback_of_exact_data_rebuilds_the_markers(tree, seed):
    model, _ = tree
    sim = simulate(model, n_frames=50, seed=seed)
    pts = points_by_segment(sim.trial, model)
    pb = playback(infer_hierarchy(pts, root="s0"), pts)
    assert pb.reference == "measured" and pb.rms_mm < 1e-6 and pb.n_frames == 50


@given(trees(), st.integers(0, 2**16), st.floats(0.2, 3.0))
def test_playback_keeps_the_joints_together(tree, seed, noise):
    model, _ = tree
    sim = simulate(model, n_frames=50, seed=seed, noise_mm=noise)
    pts = points_by_segment(sim.trial, model)
    h = infer_hierarchy(pts, root="s0")
    pb = playback(h)
    for child, (l, c) in h.joints().items():
        p = h.parent[child]
        via_parent = np.einsum("fij,j->fi", pb.R[p], l) + pb.t[p]
        via_child = np.einsum("fij,j->fi", pb.R[child], c) + pb.t[child]
        np.testing.assert_allclose(via_parent, via_child, atol=1e-8)
    # the root is played back as measured; the rest absorb the discarded joint residuals
    assert pb.rms_by_segment["s0"] < 1e-9
    assert pb.reference == "rigid" and np.isfinite(pb.rms_mm)
    np.testing.assert_allclose(pb.R[child], h.poses[child].R, atol=1e-9)   # rotations as measured


def test_rebuild_by_hand():
    """Parent at rest at the origin; the child turns 90° about z about a joint 100 mm below."""
    Rz = Rotation.from_rotvec([[0, 0, 0], [0, 0, np.pi / 2]]).as_matrix()
    R, t, markers = rebuild({"child": "root"}, "root", {"child": ([0, 0, -100], [0, 0, 0])},
                            np.stack([np.eye(3)] * 2), np.zeros((2, 3)), {"child": Rz},
                            {"root": np.zeros((1, 3)), "child": np.array([[10.0, 0, 0]])})
    np.testing.assert_allclose(markers["child"][:, 0], [[10, 0, -100], [0, 10, -100]], atol=1e-12)
    np.testing.assert_allclose(t["child"], [[0, 0, -100]] * 2, atol=1e-12)


def test_rebuild_rejects_bad_trees():
    eye, zero = np.stack([np.eye(3)]), np.zeros((1, 3))
    loc = {s: zero for s in "abc"}
    with pytest.raises(InputError, match="not connected to the root"):
        rebuild({"b": "c", "c": "b"}, "a", {"b": (zero[0], zero[0]), "c": (zero[0], zero[0])}, eye, zero,
                {"b": eye, "c": eye}, loc)
    with pytest.raises(InputError, match="no joint location for 'b'"):
        rebuild({"b": "a"}, "a", {}, eye, zero, {"b": eye}, loc)


# ---------------------------------------------------------------------- input problems
def _two_segment_sim():
    model = Model.from_dict({"units": "mm",
                             "segments": {"a": {"markers": ["1", "2", "3"]},
                                          "b": {"markers": ["4", "5", "6"]},
                                          "c": {"markers": ["7", "8"]}},
                             "joints": {"ab": {"type": "spherical", "parent": "a", "child": "b"},
                                        "bc": {"type": "revolute", "parent": "b", "child": "c"}}})
    sim = simulate(model, n_frames=40, seed=1)
    return model, points_by_segment(sim.trial, model)


def test_segments_with_too_few_markers_are_skipped_and_named():
    _, pts = _two_segment_sim()
    h = infer_hierarchy(pts)
    assert h.segments == ("a", "b") and "2 marker" in h.skipped["c"]
    with pytest.raises(InputError, match=r"at least 2 segments.*skipped: c"):
        infer_hierarchy({"a": pts["a"], "c": pts["c"]})
    with pytest.raises(InputError, match=r"root 'c' is not among.*2 marker"):
        infer_hierarchy(pts, root="c")


def test_all_nan_and_mismatched_segments_are_all_reported():
    _, pts = _two_segment_sim()
    with pytest.raises(InputError, match=r"(?s)'x': every marker coordinate is NaN.*different frame counts"):
        infer_hierarchy({**pts, "x": np.full((40, 3, 3), np.nan), "y": pts["a"][:30]})


def test_segments_that_never_share_frames_are_reported():
    rng = np.random.default_rng(0)
    R = Rotation.random(20, random_state=rng).as_matrix()

    def seg(valid):
        return Poses(R=R, t=rng.normal(size=(20, 3)), valid=valid, local=np.eye(3), rms=np.zeros(20))

    early, late = np.arange(20) < 10, np.arange(20) >= 10
    with pytest.raises(InputError, match=r"2 groups.*\{a, b\} \{c\}"):
        infer_hierarchy({"a": seg(early), "b": seg(early), "c": seg(late)})


def test_playback_needs_points_for_every_segment():
    _, pts = _two_segment_sim()
    h = infer_hierarchy(pts)
    with pytest.raises(InputError, match="no marker points for segment"):
        playback(h, {"a": pts["a"]})
