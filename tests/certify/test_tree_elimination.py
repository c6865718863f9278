"""The whole-tree rank by staged elimination (:mod:`identcheck.certify.tree_elimination`) against an
independent formulation: the joint-angle Jacobian with one dense matrix per frame
(:mod:`dense_tree_reference`), on random trees — random parents, joint types, marker counts (segments
without markers included) and joints held at one angle."""
import random

import flint
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck.certify import tree_elimination, tree_rank
from identcheck.certify.tree_equations import axis_rotation_derivative, tilt_rates
from identcheck.exact.linalg import Field
from identcheck.exact.algebra import axis_rotation, half_angle, mm, quaternion_rotation

from dense_tree_reference import dense_verdicts


@st.composite
def trees(draw, max_joints=6):
    n = draw(st.integers(1, max_joints))
    parents = [draw(st.integers(0, i)) for i in range(n)]
    types = draw(st.lists(st.sampled_from(tree_rank.TYPES), min_size=n, max_size=n))
    counts = draw(st.lists(st.integers(0, 3), min_size=n + 1, max_size=n + 1))
    frozen = draw(st.sets(st.integers(1, n), max_size=2))
    markers = {f"s{i}": tuple(f"m{i}_{k}" for k in range(c)) for i, c in enumerate(counts)}
    joints = tuple((f"j{i + 1}", types[i], f"s{parents[i]}", f"s{i + 1}") for i in range(n))
    return tree_rank.TreeSpec("s0", markers, joints, frozenset(f"j{i}" for i in frozen))


def _verdicts(spec, frames, seed=0):
    tj = tree_rank.TreeJacobian(spec, "GFp", seed)
    tj.add_frame(frames)
    state = tj.at(frames)
    asked = {j[0]: tree_rank.quantities(tj, j[0]) for j in spec.joints}
    points, judged, verdict = tree_rank._judge(state, asked)
    return state.dim_w(), {n: (bool(judged[n]) and not verdict[n], sorted(verdict[n]), points[n]) for n in asked}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees(), st.sampled_from([1, 2, 3, 5]))
def test_staged_elimination_agrees_with_the_dense_joint_angle_jacobian(spec, frames):
    """Same dim W and the same verdict, undetermined quantities and judged points for every joint, at a
    different random point of a different parametrisation."""
    assert _verdicts(spec, frames, seed=3) == dense_verdicts(spec, frames, seed=4)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees(max_joints=5))
def test_analyse_matches_the_dense_scan(spec):
    """The scan stops where the dense scan stops (one more frame changes nothing), with its dim W and its
    verdicts."""
    rank = tree_rank.analyse(spec, "GFp", seed=5)
    dim, verdicts = dense_verdicts(spec, rank.frames, seed=6)
    assert rank.dim_w == dim
    assert dense_verdicts(spec, rank.frames - 1, seed=6)[0] == dim
    assert {n: j.local for n, j in rank.joints.items()} == {n: v[0] for n, v in verdicts.items()}
    for n, j in rank.joints.items():
        if j.local:                                   # local from min_frames on, not one frame earlier
            assert all(dense_verdicts(spec, f, seed=6)[1][n][0] for f in range(j.min_frames, rank.frames + 1))
            if j.min_frames > 1:
                assert not dense_verdicts(spec, j.min_frames - 1, seed=6)[1][n][0]


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32), st.integers(0, 2**32))
def test_tilt_rates_are_the_rotation_vectors_of_a_skew_product(seed, p_seed):
    """∂Rot/∂ε · Rotᵀ is exactly skew-symmetric (so its vee is the whole of it), in GF(p)."""
    rng = random.Random(seed)
    p = flint.fmpz(2**61 - 1)
    F = lambda: flint.nmod(rng.randrange(int(p)), int(p))
    R = quaternion_rotation(F(), F(), F(), F())
    a, u = [R[i][2] for i in range(3)], [R[i][0] for i in range(3)]
    c, s = half_angle(F())
    Q = axis_rotation(a, c, s)
    M = mm(axis_rotation_derivative(a, u, c, s), [[Q[j][i] for j in range(3)] for i in range(3)])
    assert all(M[i][j] == -M[j][i] for i in range(3) for j in range(3))
    g = tilt_rates(a, u, [R[i][1] for i in range(3)], c, s)[0]
    assert [M[2][1], M[0][2], M[1][0]] == g


def test_shared_eliminations_change_no_answer():
    """A plan and its variants (a marker removed, a joint held still) give the same ranks whether their
    eliminations were shared through the memo or all done afresh."""
    spec = tree_rank.TreeSpec("s0", {"s0": ("a", "b", "c"), "s1": ("d",), "s2": ("e", "f"), "s3": ()},
                              (("j1", "spherical", "s0", "s1"), ("j2", "revolute", "s1", "s2"),
                               ("j3", "spherical", "s0", "s3")))
    variants = [spec, spec.without("d"), spec.without("e"), spec.freezing(["j2"]), spec.without("a")]

    def summary(r):
        return (r.frames, r.dim_w, {n: (j.local, j.min_frames, tuple(j.undetermined)) for n, j in r.joints.items()})

    tree_elimination.MEMO.clear()
    shared = [summary(tree_rank.analyse(v, seed=7)) for v in variants]
    fresh = []
    for v in variants:
        tree_elimination.MEMO.clear()
        fresh.append(summary(tree_rank.analyse(v, seed=7)))
    assert shared == fresh


def test_work_grows_linearly_with_the_chain():
    """Eliminations per frame count grow in proportion to the segments (the dense form grew as the cube)."""
    def eliminations(n):
        spec = tree_rank.TreeSpec("s0", {f"s{i}": (f"m{i}a", f"m{i}b") for i in range(n + 1)},
                                  tuple((f"j{i}", "spherical", f"s{i - 1}", f"s{i}") for i in range(1, n + 1)))
        calls = [0]
        real = tree_elimination.eliminate

        def counted(*args, **kwargs):
            calls[0] += 1
            return real(*args, **kwargs)
        tree_elimination.eliminate = counted
        try:
            tree_elimination.MEMO.clear()
            tj = tree_rank.TreeJacobian(spec, "GFp", 0)
            tj.add_frame(3)
            tj.at(3).dim_w()
            tj.at(3).in_joint_span("j1", [])
            for j in spec.joints:
                tj.at(3).in_joint_span(j[0], [{}])
        finally:
            tree_elimination.eliminate = real
        return calls[0]
    assert eliminations(24) <= 2.2 * eliminations(12)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(trees(max_joints=4))
def test_warm_starts_keep_the_verdicts_and_say_what_min_frames_means(spec):
    """A warm start changes no verdict; its min_frames is the cold scan's, floored at the warm count; a
    variant ranked only for its verdicts (no min_frames search) reports an upper bound: the fewest frames
    seen to give the final W."""
    cold = tree_rank.analyse(spec, seed=9)
    warm = tree_rank.analyse(spec, seed=9, warm_frames=2)
    quick = tree_rank.analyse(spec, seed=9, warm_frames=max(1, cold.frames - 1), search_min_frames=False)
    for r in (warm, quick):
        assert {n: j.local for n, j in r.joints.items()} == {n: j.local for n, j in cold.joints.items()}
    for n, j in cold.joints.items():
        if j.local:
            assert warm.joints[n].min_frames == max(2, j.min_frames)
            assert j.min_frames <= quick.joints[n].min_frames == quick.frames - 1      # the scan stopped: stable


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 12), st.integers(1, 10), st.integers(0, 10), st.floats(0.05, 0.9), st.integers(0, 2**32))
def test_eliminate_reads_the_echelon_rows_over_the_kept_columns(n_rows, n_elim, n_keep, density, seed):
    """The summary rows equal the rows of the reduced echelon form with their pivot among the kept columns, read
    entry by entry (the reading skips the other rows' pivot columns and everything left of each pivot); the
    ranks are the rank of all rows and of the eliminated columns alone."""
    rng = random.Random(seed)
    F = Field("GFp", rng)
    elim = [("e", i) for i in range(n_elim)]
    keep = [("k", i) for i in range(n_keep)]
    rows = [{key: F(rng.randrange(1, 7)) for key in elim + keep if rng.random() < density} for _ in range(n_rows)]
    got = tree_elimination.eliminate(F, [rows], keep)
    cols = [key for key in elim if any(key in r for r in rows)] + keep
    M = F.zeros(n_rows, len(cols))
    for i, r in enumerate(rows):
        for key, v in r.items():
            M[i, cols.index(key)] = v
    R, rank = M.rref()
    ne = len(cols) - n_keep
    expected = []
    for r in range(rank):
        if all(R[r, c] == 0 for c in range(ne)):
            expected.append({keep[c - ne]: R[r, c] for c in range(ne, len(cols)) if R[r, c] != 0})
    assert got.rank == rank
    assert got.rank_eliminated == rank - len(expected)
    assert got.summary.rows == expected
    assert [list(r) for r in got.summary.rows] == [list(r) for r in expected]      # kept columns in their order
