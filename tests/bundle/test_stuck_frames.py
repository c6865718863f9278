"""Frames a whole-tree fit leaves in a wrong pose are found by their residual and restarted from a neighbour's pose,
which brings the fit back to the minimum the good frames have; a fit with none is returned as it was."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.stuck_frames import posed_from_neighbours, restarted_stuck_frames, stuck_frames
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).resolve().parents[2] / "examples" / "diagnose_leg.toml")
CHAIN = Skeleton.from_model(MODEL)


def _trial(seed: int, n_frames: int = 300):
    sim = simulate(MODEL, n_frames=n_frames, noise_mm=0.5, seed=seed)
    data = sim.trial.select(MODEL.markers).as_array()
    return data, fit_chain(CHAIN, data, initial_state(CHAIN, data), max_iter=60)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.lists(st.integers(5, 294), min_size=1, max_size=6, unique=True),
       st.floats(1.0, np.pi), st.integers(0, 2))
def test_frames_held_in_a_wrong_pose_are_found_and_restarted_to_the_minimum(seed, frames, angle, axis):
    """A converged fit of a simulated leg (0.5 mm noise) with some frames' root turned 57-180° about a lab axis
    through their markers' mean (a fit holding them there: Levenberg-Marquardt from such a pose can stay, as a pelvis
    seen by two markers did on a held-out gait trial): exactly those frames are found, and the restart brings the
    cost back to the good fit's."""
    data, good = _trial(seed)
    bad = np.array(sorted(frames))
    s = good.state.copy()
    turn = Rotation.from_rotvec(angle * np.eye(3)[axis]).as_matrix()
    c = data[bad].mean(axis=1)
    s.root_R[bad] = turn @ s.root_R[bad]
    s.root_t[bad] = c + np.einsum("ij,fj->fi", turn, s.root_t[bad] - c)
    astray = fit_chain(CHAIN, data, s, max_iter=0)            # the poses as they are, not refitted
    assert set(stuck_frames(astray, data, np.ones(data.shape[:2]))) == set(bad)
    again = restarted_stuck_frames(astray, data)
    assert again.rss <= good.rss * (1 + 1e-6)


def test_a_fit_with_no_frame_astray_is_returned_as_it_was():
    data, good = _trial(7)
    assert not len(stuck_frames(good, data, np.ones(data.shape[:2])))
    assert restarted_stuck_frames(good, data) is good


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**16))
def test_each_frame_astray_takes_the_pose_of_the_nearest_good_frame(seed):
    """Random frames marked astray: each takes every per-frame unknown (root pose, joint angles) of the nearest
    frame not marked (the earlier on a tie), and the good frames keep their own."""
    rng = np.random.default_rng(seed)
    data, good = _trial(seed % 5, 60)
    s = good.state.copy()
    F = len(data)
    bad = np.flatnonzero(rng.random(F) < 0.3)
    if len(bad) == F:
        bad = bad[1:]
    out = posed_from_neighbours(s, bad, F)
    ok = np.setdiff1d(np.arange(F), bad)
    for f in range(F):
        g = f if f in ok else ok[np.argmin(np.abs(ok - f))]
        assert np.array_equal(out.root_R[f], s.root_R[g]) and np.array_equal(out.root_t[f], s.root_t[g])
        for j in s.theta:
            assert out.theta[j][f] == s.theta[j][g]
        for j in s.rel_R:
            assert np.array_equal(out.rel_R[j][f], s.rel_R[j][g])
