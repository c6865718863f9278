"""Groups split in two where one part turns as a rigid body in the other's pose
(identcheck.infer.two_segments.split_coherent): the coherence is about 1 for one rigid body whatever the noise and
whatever independent skin wobble the markers have, scale-free and blind to where the scene is, and large for two
bodies joined by a joint, whose split it finds; the grouping then holds the two segments it had merged."""
import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.infer.grouping import group_markers, pair_statistics, partition, rigidity_tolerance
from identcheck.infer.two_segments import (COHERENCE_LIMIT, SURE_COHERENCE, coherence, coherent_split,
                                           part_residual, split_coherent)
from identcheck.trial import Trial

F = 300
T = np.arange(F) / 60.0


def _rotations(rng, amplitude_rad, axis=None):
    if axis is not None:
        angle = amplitude_rad * np.sin(2 * np.pi * rng.uniform(0.2, 1.0) * T + rng.uniform(0, 6.3))
        return Rotation.from_rotvec(angle[:, None] * np.asarray(axis, dtype=float))
    w = np.stack([amplitude_rad * np.sin(2 * np.pi * rng.uniform(0.2, 1.0) * T + rng.uniform(0, 6.3))
                  for _ in range(3)], axis=1)
    return Rotation.from_rotvec(w)


def _wobble(rng, amplitude_mm, n):
    """Skin motion: each marker its own smooth displacement (three sinusoids per coordinate), peak `amplitude_mm`."""
    out = np.zeros((F, n, 3))
    for k in range(n):
        for c in range(3):
            for _ in range(3):
                out[:, k, c] += rng.uniform(-1, 1) * np.sin(2 * np.pi * rng.uniform(0.1, 1.5) * T + rng.uniform(0, 6.3))
    return amplitude_mm * out / max(np.abs(out).max(), 1e-12)


def _rigid(rng, n, sigma, wobble_mm=0.0):
    local = rng.uniform(-80, 80, size=(n, 3))
    X = np.einsum("fij,nj->fni", _rotations(rng, 0.8).as_matrix(), local) + (0.0, 0.0, 1000.0)
    return X + _wobble(rng, wobble_mm, n) + rng.normal(0, sigma, (F, n, 3))


def _jointed(rng, n_a, n_b, sigma, amplitude_rad):
    """A still body A and a body B turning about a ball joint 60 mm below A's centre, B's markers 60-100 mm below
    the joint."""
    a = rng.uniform(-60, 60, size=(n_a, 3))
    b = rng.uniform((-50, -50, -160), (50, 50, -120), size=(n_b, 3))
    centre = np.array([0.0, 0.0, -60.0])
    turn = _rotations(rng, amplitude_rad).as_matrix()
    B = np.einsum("fij,nj->fni", turn, b - centre) + centre
    X = np.concatenate([np.broadcast_to(a, (F, n_a, 3)), B], axis=1) + (0.0, 0.0, 1000.0)
    return X + rng.normal(0, sigma, X.shape)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.integers(5, 9), st.floats(0.1, 1.5), st.floats(0.0, 6.0))
def test_one_rigid_body_is_not_split_whatever_its_noise_and_skin_wobble(seed, n, sigma, wobble_mm):
    """One body, white noise σ and each marker's own smooth skin motion of up to 6 mm (far beyond the noise): the
    best split's coherence stays near 1 (below 2.5; 1.92 the largest of 200 such draws), and nothing is split."""
    rng = np.random.default_rng(seed)
    X = _rigid(rng, n, sigma, wobble_mm)
    S = pair_statistics(X).spread_mm
    value, a, b = coherent_split(X, S, list(range(n)))
    assert sorted(a + b) == list(range(n)) and len(a) >= 3 and len(b) >= 2
    assert 0.5 < value < 2.5 < COHERENCE_LIMIT
    groups, splits = split_coherent(X, S, [list(range(n))])
    assert groups == [list(range(n))] and splits == []


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 5), st.integers(2, 4), st.floats(0.2, 1.5))
def test_two_bodies_turning_a_little_are_split_where_they_meet(seed, n_a, n_b, sigma):
    """A and B joined by a ball joint turning by 12 σ / 100 mm radians (B's markers, 60-110 mm from the joint, move
    by several σ: within any rigidity tolerance): the group is split into exactly A and B."""
    rng = np.random.default_rng(seed)
    X = _jointed(rng, n_a, n_b, sigma, 12.0 * sigma / 100.0)
    S = pair_statistics(X).spread_mm
    groups, splits = split_coherent(X, S, [list(range(n_a + n_b))])
    assert sorted(map(tuple, groups)) == sorted([tuple(range(n_a)), tuple(range(n_a, n_a + n_b))])
    (value, a, b), = splits
    assert value >= COHERENCE_LIMIT


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.01, 100.0), st.floats(-2000, 2000))
def test_coherence_is_scale_free_and_blind_to_where_the_scene_is(seed, scale, shift):
    """Millimetres or metres, anywhere in the volume, turned any way: the same coherence (a ratio of residuals)."""
    rng = np.random.default_rng(seed)
    X = _jointed(rng, 4, 3, 0.7, 0.05)
    turn = Rotation.random(random_state=seed).as_matrix()
    Y = scale * np.einsum("ij,fnj->fni", turn, X) + shift
    a, b = [0, 1, 2, 3], [4, 5, 6]
    assert np.isclose(coherence(Y, a, b)[0], coherence(X, a, b)[0], rtol=1e-6)
    assert np.isclose(coherence(Y, a, b)[1], scale ** 2 * coherence(X, a, b)[1], rtol=1e-6)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.integers(2, 6), st.floats(0.2, 2.0))
def test_a_rigid_parts_residual_is_sigma_squared_per_degree_of_freedom(seed, n, sigma):
    """White noise σ on a rigid part of two or more markers: its residual per degree of freedom is σ² (within 15 %
    over 300 frames), and a lone marker has none."""
    rng = np.random.default_rng(seed)
    X = _rigid(rng, n, sigma)
    rss, dof, params = part_residual(X, list(range(n)))
    assert dof == (1 if n == 2 else 3 * n - 6) and params == (5 if n == 2 else 6)
    assert abs(np.mean(rss) / dof / sigma ** 2 - 1.0) < 4.0 * np.sqrt(2.0 / (F * dof)) + 0.03
    lone, dof1, params1 = part_residual(X, [0])
    assert dof1 == 0 and params1 == 3 and np.all(lone == 0)


def test_the_grouping_splits_two_segments_its_tolerance_merged():
    """A hinge turning ±15 degrees with its child's markers within 35 mm of the axis moves them by a few mm, within
    the tolerance 1 mm noise sets, so the rigid-body grouping merges the two segments (checked); the coherent split
    separates them and says so. A third segment swings widely on a ball joint (the trial is not static) and stays
    whole."""
    rng = np.random.default_rng(11)
    a = rng.uniform(-60, 60, size=(4, 3))
    b = rng.uniform((-60, -25, -95), (60, 25, -45), size=(4, 3))       # near the hinge axis: x through z = -70
    c = rng.uniform(-40, 40, size=(4, 3)) + (0.0, 0.0, 170.0)
    hinge = _rotations(rng, np.radians(15.0), axis=(1.0, 0.0, 0.0)).as_matrix()
    ball = _rotations(rng, 0.9).as_matrix()
    local = np.concatenate([np.broadcast_to(a, (F, 4, 3)),
                            np.einsum("fij,nj->fni", hinge, b - (0, 0, -70.0)) + (0, 0, -70.0),
                            np.einsum("fij,nj->fni", ball, c - (0, 0, 80.0)) + (0, 0, 80.0)], axis=1)
    X = np.einsum("fij,fnj->fni", _rotations(rng, 0.3).as_matrix(), local) + (0.0, 0.0, 1000.0)
    X = X + rng.normal(0, 1.0, X.shape)
    stats = pair_statistics(X)
    merged, _, _ = partition(X, stats.spread_mm, rigidity_tolerance(stats).tolerance_mm)
    assert list(range(8)) in merged                      # the premise: the tolerance alone holds A and B together
    labels = [f"{s}{k}" for s in "abc" for k in range(4)]
    g = group_markers(Trial(X, labels, 100.0, "hinge"))
    assert sorted(g.groups.values()) == [tuple(labels[:4]), tuple(labels[4:8]), tuple(labels[8:])]
    (entry,) = g.split
    assert {frozenset(p) for p in entry["parts"]} == {frozenset(labels[:4]), frozenset(labels[4:8])}
    assert entry["sure"] and entry["coherence"] >= SURE_COHERENCE
    assert [set(g.groups[s]) for s in entry["segments"]] in ([set(labels[:4]), set(labels[4:8])],
                                                           [set(labels[4:8]), set(labels[:4])])
    assert g.to_dict()["split"] == list(g.split)
