"""Markers into rigid segments from a trial alone (identcheck.infer.grouping)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.infer.grouping import (FLOOR_MM, _column_percentile, given_grouping, group_markers, pair_statistics,
                                       partition, rigidity_tolerance)
from identcheck.trial import Trial
from strategies_skeleton import cases, make_case


def partition_of(groups: dict) -> set:
    return {frozenset(ms) for ms in groups.values()}


@settings(max_examples=25)
@given(st.lists(st.lists(st.one_of(st.floats(-1e3, 1e3), st.just(np.nan)), min_size=3, max_size=3),
                min_size=1, max_size=40), st.sampled_from([2.5, 50.0, 97.5]))
def test_column_percentile_is_numpys(rows, q):
    D = np.array(rows, dtype=float)
    n = np.isfinite(D).sum(axis=0)
    ok = n > 0
    with np.errstate(all="ignore"), pytest.warns(RuntimeWarning) if not ok.all() else _nothing():
        want = np.nanpercentile(D, q, axis=0)
    np.testing.assert_allclose(_column_percentile(D, n, q)[ok], want[ok], rtol=1e-12, atol=1e-9)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@settings(max_examples=12, deadline=None)
@given(cases())
def test_random_trees_are_grouped_exactly(case):
    """Random trees, noise up to 0.5 mm, 20 % occlusion, 1 mm of wobble and a random-walk marker: every segment is
    found exactly, and the loose marker belongs to nothing."""
    g = group_markers(case.trial)
    assert partition_of(g.groups) == partition_of(case.segments)
    assert set(g.loose) == set(case.loose) and not g.unused


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**16), st.integers(0, 2**16))
def test_grouping_ignores_where_the_volume_is_and_marker_order(seed, seed2):
    """A rigid motion of the whole capture (50 m away) and a shuffled column order give the same grouping."""
    case = make_case(seed, 4, noise_mm=0.3)
    rng = np.random.default_rng(seed2)
    R = Rotation.random(random_state=seed2).as_matrix()
    X = case.trial.as_array() @ R.T + rng.uniform(-5e4, 5e4, 3)
    order = rng.permutation(case.trial.n_markers)
    moved = Trial(X[:, order], [case.trial.labels[k] for k in order], 100.0)
    assert partition_of(group_markers(moved).groups) == partition_of(group_markers(case.trial).groups)


def test_tolerance_is_measured_from_the_data():
    """Noise-free: the floor. Noisy: a few times the distance noise, which itself is about √2 σ."""
    clean = make_case(3, 4)
    assert rigidity_tolerance(pair_statistics(clean.trial.xyz)).tolerance_mm == FLOOR_MM
    noisy = make_case(3, 4, noise_mm=1.0)
    tol = rigidity_tolerance(pair_statistics(noisy.trial.xyz))
    assert 1.0 < tol.distance_noise_mm < 2.0 and 4 < tol.tolerance_mm < 12


def test_a_marker_near_a_joint_stays_in_its_own_segment():
    """A child marker 15 mm from a ball joint keeps nearly constant distances to the parent's markers, but moves in
    the parent's frame: it is grouped with its own segment."""
    rng = np.random.default_rng(0)
    F = 400
    parent_local = np.array([[60.0, 0, 0], [0, 70, 0], [-50, -40, 30]])
    child_local = np.array([[0, 0, -15.0], [40, 0, -120], [-30, 30, -150], [10, -40, -200]])
    t = np.arange(F) / 100
    rot = Rotation.from_rotvec(np.stack([0.5 * np.sin(2 * np.pi * 0.7 * t), 0.4 * np.sin(2 * np.pi * 0.45 * t + 1),
                                         0.3 * np.sin(2 * np.pi * 0.3 * t)], axis=1))
    parent = np.repeat(parent_local[None], F, axis=0) + [0, 0, 1000]
    child = np.stack([rot[f].apply(child_local) for f in range(F)]) + [0, 0, 1000]
    X = np.concatenate([parent, child], axis=1) + rng.normal(0, 0.3, (F, 7, 3))
    trial = Trial(X, ["p0", "p1", "p2", "c0", "c1", "c2", "c3"], 100.0)
    st_ = pair_statistics(trial.xyz)
    assert max(st_.spread_mm[3, :3]) < 10                 # the near marker's distances hardly change ...
    assert partition_of(group_markers(trial).groups) == {frozenset(["p0", "p1", "p2"]),
                                                          frozenset(["c0", "c1", "c2", "c3"])}   # ... still its own


def test_partition_without_rigid_pairs_leaves_every_marker_loose():
    S = np.full((4, 4), 50.0)
    np.fill_diagonal(S, 0)
    groups, loose, widened = partition(np.zeros((20, 4, 3)), S, 1.0)
    assert groups == [] and loose == [0, 1, 2, 3] and widened == []


# ---------------------------------------------------------------------- bad input
def test_fewer_than_two_markers_is_bad_input():
    with pytest.raises(InputError, match="1 marker"):
        group_markers(Trial(np.ones((50, 1, 3)), ["A"], 100.0, "one.trc"))


def test_a_never_visible_marker_is_named():
    case = make_case(1, 3)
    X = case.trial.as_array()
    X[:, 2] = np.nan
    with pytest.raises(InputError, match=f"marker '{case.trial.labels[2]}' is never visible"):
        group_markers(Trial(X, case.trial.labels, 100.0, "gap.trc"))


def test_one_rigid_body_is_bad_input():
    case = make_case(1, 1, counts=[5])
    with pytest.raises(InputError, match="move as one rigid body"):
        group_markers(case.trial)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.2, 2.0), st.floats(0.05, 1.0))
def test_a_nearly_static_trial_is_refused(seed, sway_deg, noise):
    """Random trees held in one pose, swaying as one body by up to 2 degrees: whatever the noise, the trial is
    refused as static, naming it, instead of grouped by noise."""
    case = make_case(seed, 4, noise_mm=noise)
    X = case.trial.as_array()
    still = np.repeat(X[:1], len(X), axis=0)              # the first pose, held ...
    t = np.arange(len(X)) / 100.0
    wave = np.stack([np.sin(2 * np.pi * 0.3 * t), np.cos(2 * np.pi * 0.2 * t), 0 * t], axis=1)
    turn = Rotation.from_rotvec(np.radians(sway_deg) * wave)
    centre = np.nanmean(still[0], axis=0)
    still = np.einsum("fij,fnj->fni", turn.as_matrix(), still - centre) + centre      # ... swaying as one
    noisy = still + np.random.default_rng(seed).normal(0, noise, still.shape)
    with pytest.raises(InputError, match="the trial is static") as err:
        group_markers(Trial(noisy, case.trial.labels, 100.0, "standing.trc"))
    assert "standing.trc" in str(err.value)


def test_given_grouping_names_unknown_markers_and_the_file():
    case = make_case(2, 3)
    bad = {"a": ["m0_0", "m0_1", "m0_2"], "b": ["m1_0", "m1_l"]}
    with pytest.raises(InputError, match=r"segs\.toml.*'m1_l' is not in the trial.*did you mean 'm1_"):
        given_grouping(case.trial, bad, "segs.toml")


def test_given_grouping_warns_about_a_segment_that_is_not_rigid():
    case = make_case(2, 3, noise_mm=0.2)
    mixed = {"a": case.segments["s0"][:2] + case.segments["s1"][:1], "b": case.segments["s1"][1:]}
    g = given_grouping(case.trial, mixed, "segs.toml")
    assert g.groups["a"] == tuple(mixed["a"]) and any("'a'" in w for w in g.warnings)
    assert set(g.unused) == set(case.trial.labels) - set(mixed["a"]) - set(mixed["b"])


def test_a_small_hinge_is_not_taken_for_a_static_trial():
    """A finger: two segments of four markers 18-35 mm from a hinge flexing 0-60 deg. No pair's distance changes
    by 15 mm, but by far more than 3 % of the markers' size: grouped, not refused."""
    F = 600
    t = np.arange(F) / 100.0
    a = np.array([[5, 8, 25], [-6, -7, 30], [8, -5, 35], [-4, 6, 20]], float)
    b = np.array([[5, 8, -22], [-7, -6, -28], [7, -6, -34], [-5, 6, -18]], float)
    angle = np.radians(30) * (1 - np.cos(2 * np.pi * 0.4 * t))
    turn = Rotation.from_rotvec(np.stack([angle, 0 * t, 0 * t], axis=1)).as_matrix()
    X = np.concatenate([np.repeat(a[None], F, axis=0), np.einsum("fij,nj->fni", turn, b)], axis=1)
    X = X + np.random.default_rng(3).normal(0, 0.1, X.shape)
    trial = Trial(X, [f"m{k}" for k in range(8)], 100.0, "finger.trc")
    assert np.nanmax(pair_statistics(X).spread_mm) < 15
    assert partition_of(group_markers(trial).groups) == {frozenset(f"m{k}" for k in range(4)),
                                                          frozenset(f"m{k}" for k in range(4, 8))}


def test_segments_never_seen_together_are_not_called_static():
    """Two segments seen in alternate halves of the trial: their spreads across are unknown, not small, so the
    static refusal says nothing (the tree step names the split)."""
    case = make_case(4, 2, counts=[4, 4], parents=[0], types=["spherical"], noise_mm=0.1, n_frames=600)
    X = case.trial.as_array()
    X[:300, 4:] = np.nan
    X[300:, :4] = np.nan
    group_markers(Trial(X, case.trial.labels, 100.0, "halves.trc"))       # no InputError here
