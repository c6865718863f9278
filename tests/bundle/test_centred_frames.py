"""Segment frames centred at their markers (identcheck.bundle.chain.centred_frame): the same poses of the same
points, and a whole-chain fit that converges on a walk that spans metres, where frames whose origin lay metres from
their markers left Gauss-Newton crawling."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.chain import centred_frame, fit_chain, initial_state
from identcheck.geometry.poses import Poses
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 7), st.floats(0.0, 20000.0))
def test_a_centred_frame_places_every_point_where_it_was(seed, n, offset_mm):
    """Any poses, body-fixed points any distance from their origin: centred, the points average to the origin and
    every frame puts them where it did."""
    rng = np.random.default_rng(seed)
    F = 40
    local = rng.uniform(-100, 100, (n, 3)) + offset_mm * Rotation.random(random_state=seed).apply([1.0, 0, 0])
    R = Rotation.random(F, random_state=seed + 1).as_matrix()
    t = rng.uniform(-3000, 3000, (F, 3))
    frame = Poses(R=R, t=t, valid=np.ones(F, bool), local=local, rms=np.zeros(F))
    new = centred_frame(frame)
    assert np.allclose(new.local.mean(axis=0), 0.0, atol=1e-9 * max(offset_mm, 1.0))
    assert np.allclose(new.to_world(new.local), frame.to_world(frame.local), rtol=0, atol=1e-9 * (offset_mm + 5000))
    assert np.array_equal(new.R, frame.R)


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 999))
def test_the_rigid_fit_of_a_long_walk_converges(seed):
    """A leg walked 20 m (recentred about its mean, as `diagnose` fits it: its first frame's world lies 10 m from
    the origin), 0.6 mm white noise: the whole-chain fit from the closed-form start converges within 8 iterations
    (3 on seeds 0-4), and 100 more lower the cost by less than σ². With frames whose origin was the first frame's
    world (markers 10 m from it), none of seeds 0-4 had converged after 8, and 100 more lowered the cost by 20-257
    σ²."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    data = simulate(model, n_frames=1200, noise_mm=0.0, seed=seed).trial.select(model.markers).as_array()
    data[..., 0] += np.linspace(-10000.0, 10000.0, len(data))[:, None]
    data = data + np.random.default_rng(seed).normal(0, 0.6, data.shape)
    chain = Skeleton.from_model(model)
    w = np.ones(data.shape[:2])
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=8)
    assert fit.converged
    more = fit_chain(chain, data, fit.state, weights=w, max_iter=100)
    assert fit.rss - more.rss < 0.6 ** 2
