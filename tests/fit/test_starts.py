"""Where the whole-tree fit starts: a centre seen by one or two markers on one side also starts fits along its
weak line, at scaled distances, each a rigid point of the side it is moved on."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.estimate.joint import JointEstimate
from identcheck.bundle.starts import RADIAL_FACTORS, radial_variants


def _two_segments(seed: int, n_parent: int, n_child: int, frames: int = 120):
    """A parent with `n_parent` markers and a child with `n_child` turning about a common centre; the chain
    object carries only what :func:`radial_variants` reads."""
    rng = np.random.default_rng(seed)
    R_p = Rotation.random(frames, random_state=seed).as_matrix()
    t_p = rng.normal(0, 300, (frames, 3))
    parent_local = rng.normal(0, 80, (n_parent, 3))
    centre_local = rng.normal(0, 80, 3)
    child_local = rng.normal(0, 150, (n_child, 3))
    rel = Rotation.from_rotvec(rng.normal(0, 0.4, (frames, 3))).as_matrix()
    centre = np.einsum("fij,j->fi", R_p, centre_local) + t_p
    R_c = R_p @ rel
    parent = np.einsum("fij,kj->fki", R_p, parent_local) + t_p[:, None]
    child = np.einsum("fij,kj->fki", R_c, child_local) + centre[:, None]
    data = np.concatenate([parent, child], axis=1)
    chain = SimpleNamespace(parent={"j": "P"}, child={"j": "C"},
                            seg_markers={"P": np.arange(n_parent), "C": np.arange(n_parent, n_parent + n_child)})
    est = JointEstimate(kind="spherical", estimator="test", case="spherical", centre=centre)
    return chain, data, est, (R_p, t_p), (R_c, centre)


def _in_frame(points, pose):
    R, t = pose
    return np.einsum("fji,fj->fi", R, points - t)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n_child=st.integers(1, 2), n_parent=st.integers(3, 5))
def test_a_moved_centre_is_rigid_on_the_posed_side_at_the_scaled_distance(seed, n_child, n_parent):
    """Parent with three markers or more: every moved centre is one fixed point of the parent, on the line from
    the child markers' mean (in the parent frame) through the centre, at k times the centre's distance."""
    chain, data, est, parent_pose, _ = _two_segments(seed, n_parent, n_child)
    variants = radial_variants(chain, data, "j", est)
    assert len(variants) == len(RADIAL_FACTORS)
    c_loc = _in_frame(est.centre, parent_pose).mean(axis=0)
    a_loc = _in_frame(data[:, chain.seg_markers["C"]].mean(axis=1), parent_pose).mean(axis=0)
    for k, v in zip(RADIAL_FACTORS, variants):
        local = _in_frame(v.centre, parent_pose)
        assert np.ptp(local, axis=0).max() < 1e-6                       # rigid on the parent
        assert np.allclose(local[0], a_loc + k * (c_loc - a_loc), atol=1e-6)
        assert not v.unique and f"×{k:g}" in v.estimator


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n_child=st.integers(1, 2), n_parent=st.integers(1, 2))
def test_with_no_posed_side_the_centre_is_scaled_on_the_sparse_side(seed, n_child, n_parent):
    """Both sides sparse: the moved centre is scaled about the sparser side's marker centroid in every frame,
    so it stays a rigid point of that side (an affine combination of its points)."""
    chain, data, est, parent_pose, child_pose = _two_segments(seed, n_parent, n_child)
    sparse = min((chain.seg_markers["P"], chain.seg_markers["C"]), key=len)
    pose = parent_pose if sparse is chain.seg_markers["P"] else child_pose
    anchor = data[:, sparse].mean(axis=1)
    for k, v in zip(RADIAL_FACTORS, radial_variants(chain, data, "j", est)):
        assert np.allclose(v.centre, anchor + k * (est.centre - anchor))
        assert np.ptp(_in_frame(v.centre, pose), axis=0).max() < 1e-6


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_no_variants_where_the_fit_is_well_conditioned_or_the_joint_is_a_hinge(seed):
    chain, data, est, _, _ = _two_segments(seed, 3, 3)
    assert radial_variants(chain, data, "j", est) == []
    chain, data, est, _, _ = _two_segments(seed, 3, 1)
    hinge = JointEstimate(kind="revolute", estimator="test", case="revolute", point=est.centre,
                          direction=np.tile([0.0, 0.0, 1.0], (len(est.centre), 1)))
    assert radial_variants(chain, data, "j", hinge) == []


def test_occluded_frames_do_not_move_the_line():
    """Gaps in the sparse side's markers leave those frames out of the averages, not NaN the variants."""
    chain, data, est, parent_pose, _ = _two_segments(3, 3, 2)
    data = data.copy()
    data[10:40, 3] = np.nan
    variants = radial_variants(chain, data, "j", est)
    assert len(variants) == len(RADIAL_FACTORS)
    for v in variants:
        assert np.isfinite(v.centre).all()
        assert np.ptp(_in_frame(v.centre, parent_pose), axis=0).max() < 1e-6


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 5), min_size=0, max_size=7), st.integers(1, 40))
def test_every_one_joint_change_is_started_before_any_combination(sizes, cap):
    """The start combinations: the first candidate of every joint, then every combination that changes exactly
    one joint (all of them, whatever the cap), then those that change several, up to the cap; the count of
    those left out makes up the product of the candidate counts."""
    import math

    from identcheck.bundle.starts import by_changes as _by_changes

    names = [f"j{k}" for k in range(len(sizes))]
    cands = {n: list(range(s)) for n, s in zip(names, sizes)}
    singles = sum(s - 1 for s in sizes)
    chosen, unlisted = _by_changes(cands, names, max(cap, 1 + singles))
    changes = [sum(i > 0 for i in idx) for idx in chosen]
    assert chosen[0] == (0,) * len(sizes)
    assert changes[1:1 + singles] == [1] * singles and all(c > 1 for c in changes[1 + singles:])
    assert len(set(chosen)) == len(chosen) <= max(cap, 1 + singles)
    assert len(chosen) + unlisted == math.prod(sizes)
    assert all(0 <= i < s for idx in chosen for i, s in zip(idx, sizes))


def _leg_3_1_1():
    from identcheck.io.model import Model

    return Model.from_dict({
        "units": "mm",
        "segments": {"pelvis": {"markers": ["P1", "P2", "P3"]}, "thigh": {"markers": ["T1"], "length_mm": 420},
                     "shank": {"markers": ["S1"], "length_mm": 400}},
        "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
                   "knee": {"type": "revolute", "parent": "thigh", "child": "shank"}}})


def test_a_moved_centre_restarts_the_joints_posed_through_it():
    """A hip moved along its weak line starts its fits with the knee fitted again from the moved hip (the knee's
    closed form takes the hip's centre as a thigh point): each moved start's knee is the closed form with that hip
    fixed, not the first start's knee; without a restart the first start's knee is kept."""
    import warnings

    from identcheck.bundle.starts import start_combinations
    from identcheck.estimate.closed_forms import fit_model
    from identcheck.fit.whole_tree import skeleton_of
    from identcheck.simulate.rigid import simulate

    model = _leg_3_1_1()
    trial = simulate(model, n_frames=400, noise_mm=0.3, seed=5).trial
    chain = skeleton_of(model, trial)
    data = trial.select(chain.labels).as_array()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = fit_model(model, trial)[0]

        def restart(fixed):
            return fit_model(model, trial, fixed=fixed)[0]

        combos = start_combinations(chain, fitted, restart, data)[0]
        moved = [c for c in combos if "×" in c["hip"].estimator]
        assert len(moved) == len(RADIAL_FACTORS)
        for combo in moved:
            again = restart({"hip": combo["hip"]})["knee"][0]
            assert np.allclose(combo["knee"].point, again.point, equal_nan=True)
            assert not np.allclose(combo["knee"].point, combos[0]["knee"].point, equal_nan=True)
        plain = start_combinations(chain, fitted, None, data)[0]
        assert all(c["knee"] is plain[0]["knee"] for c in plain if "×" in c["hip"].estimator)


def _chain_of_joints(n: int):
    """Joints j0..j(n-1) in a line of segments s0..sn (j_k from s_k to s_k+1): the chain object carries only what
    :func:`dependents` and :func:`with_dependents` read."""
    return SimpleNamespace(parent={f"j{k}": f"s{k}" for k in range(n)}, child={f"j{k}": f"s{k + 1}" for k in range(n)},
                           seg_markers={f"s{k}": [0] * (1 + k % 3) for k in range(n + 1)})


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 7), st.data(), st.randoms(use_true_random=False))
def test_dependents_are_reached_through_points_on_the_moved_side_and_onward(n, data, rnd):
    """In a line of joints whose closed forms took their neighbours' points on either segment at random (in any order
    of the closed forms), the dependents of a joint moved on one side are exactly the joints reached by walking away
    from the other side: the next joint took the moved one's points on the segment they share, then its own next one
    took its points, and so on; never a joint across the other side, which the moved centre does not change."""
    from identcheck.bundle.starts import dependents
    from identcheck.io.model import virtual_names

    chain = _chain_of_joints(n)
    moved = data.draw(st.integers(0, n - 1))
    down = data.draw(st.booleans())                     # moved on its child's side, else its parent's
    took_above = [data.draw(st.booleans()) for _ in range(n)]   # j_k took j_(k-1)'s points on s_k
    took_below = [data.draw(st.booleans()) for _ in range(n)]   # j_k took j_(k+1)'s points on s_(k+1)
    closed = {}
    for k in rnd.sample(range(n), n):
        kind = "revolute" if k % 2 else "spherical"
        above = list(virtual_names(f"j{k - 1}", kind)) if k > 0 and took_above[k] else []
        below = list(virtual_names(f"j{k + 1}", "spherical")) if k < n - 1 and took_below[k] else []
        closed[f"j{k}"] = (None, {"parent_markers": ["M"] + above, "child_markers": ["N"] + below})
    expected, k = [], moved
    while True:
        k = k + 1 if down else k - 1
        if not 0 <= k < n or not (took_above[k] if down else took_below[k]):
            break
        expected.append(f"j{k}")
    side = chain.child[f"j{moved}"] if down else chain.parent[f"j{moved}"]
    found = dependents(chain, closed, f"j{moved}", side)
    assert set(found) == set(expected)
    assert found == [name for name in closed if name in found]


def test_a_restart_that_cannot_fit_leaves_the_moved_start_as_it_was():
    """A restart from the moved centre that raises (too few points for a closed form, a singular system) or leaves
    a dependent joint without an estimate keeps the start as it was, rather than stopping the fit; one that makes
    them takes every joint but the moved one from that restart."""
    from identcheck.bundle.starts import with_dependents
    from identcheck.errors import DegenerateError

    chain = SimpleNamespace(parent={"hip": "pelvis", "knee": "thigh", "hip_l": "pelvis"},
                            child={"hip": "thigh", "knee": "shank", "hip_l": "thigh_l"},
                            seg_markers={"pelvis": [0, 1, 2], "thigh": [3], "shank": [4], "thigh_l": [5]})
    closed = {"hip": (None, {"parent_markers": ["P1", "hip_l.centre"], "child_markers": ["T1"]}),
              "knee": (None, {"parent_markers": ["T1", "hip.centre"], "child_markers": ["S1"]}),
              "hip_l": (None, {"parent_markers": ["P1", "hip.centre"], "child_markers": ["L1"]})}
    combo = {"hip": "moved hip", "knee": "first knee", "hip_l": "first left hip"}

    def raising(error):
        def restart(fixed):
            raise error
        return restart

    for error in (DegenerateError("too few frames"), np.linalg.LinAlgError("singular"), ValueError("nan")):
        assert with_dependents(chain, closed, combo, "hip", raising(error)) == combo
    assert with_dependents(chain, closed, combo, "hip", lambda fixed: {"knee": (None, {})}) == combo
    again = with_dependents(chain, closed, combo, "hip",
                            lambda fixed: {"hip": ("copy", {}), "knee": ("new knee", {}), "hip_l": ("new left", {})})
    assert again == {"hip": "moved hip", "knee": "new knee", "hip_l": "new left"}
    assert with_dependents(chain, closed, combo, "hip_l", raising(ValueError())) == combo   # nothing took its points
    #                                                   on the left thigh: the right hip took them on the pelvis




def test_moved_starts_the_cap_would_cut_are_not_restarted(monkeypatch):
    """A moved start beyond the start cap is never fitted, so its restart (a pass of the closed forms) is not made:
    on the 3 | 1 | 1 leg each of the hip's moved starts restarts the knee under the default cap, none when the cap
    leaves room only for the first combination and its one-joint changes."""
    import warnings

    import identcheck.bundle.starts as starts
    from identcheck.estimate.closed_forms import fit_model
    from identcheck.fit.whole_tree import skeleton_of
    from identcheck.simulate.rigid import simulate

    model = _leg_3_1_1()
    trial = simulate(model, n_frames=400, noise_mm=0.3, seed=5).trial
    chain = skeleton_of(model, trial)
    data = trial.select(chain.labels).as_array()
    calls = []

    def restart(fixed):
        calls.append(fixed)
        return fit_model(model, trial, fixed=fixed)[0]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = fit_model(model, trial)[0]
        singles = starts.start_combinations(chain, fitted, restart, data)[3]
        assert len(calls) == len(RADIAL_FACTORS)
        calls.clear()
        monkeypatch.setattr(starts, "MAX_STARTS", 1)
        combos = starts.start_combinations(chain, fitted, restart, data)[0]
    assert calls == [] and len(combos) == 1 + singles
