"""The whole-chain fit's start across gaps (identcheck.bundle.chain.filled_poses and the root moved onto the markers
seen where its own are not): a segment seen by one or two markers is put on them, and a walk whose pelvis drops out
of view starts next to the markers still seen, not where the pelvis was last posed."""
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.chain import filled_poses, fit_chain, initial_state
from identcheck.bundle.model import Terms, forward
from identcheck.geometry.poses import Poses
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**16), st.integers(3, 6), st.integers(1, 2))
def test_an_unposed_frame_is_put_on_the_markers_it_sees(seed, n, n_seen):
    """Any poses, any body-fixed points; frames left unposed with one or two of the points seen: the filled pose puts
    those points exactly where they were measured; the posed frames keep their poses."""
    rng = np.random.default_rng(seed)
    F = 30
    local = rng.uniform(-150, 150, (n, 3))
    R = Rotation.random(F, random_state=seed).as_matrix()
    t = rng.uniform(-3000, 3000, (F, 3))
    pts = np.einsum("fij,mj->fmi", R, local) + t[:, None]
    valid = rng.random(F) < 0.5
    valid[rng.integers(F)] = True
    for f in np.flatnonzero(~valid):
        pts[f, rng.permutation(n)[n_seen:]] = np.nan
    poses = Poses(R=np.where(valid[:, None, None], R, np.nan), t=np.where(valid[:, None], t, np.nan), valid=valid,
                  local=local, rms=np.zeros(F))
    out = filled_poses(pts, local, poses)
    world = out.to_world(local)
    seen = np.isfinite(pts).all(axis=2)
    assert np.allclose(world[seen], pts[seen], rtol=0, atol=1e-6)
    assert np.array_equal(out.R[valid], R[valid]) and np.array_equal(out.t[valid], t[valid])


@settings(max_examples=3, deadline=None)
@given(st.integers(0, 999))
def test_a_walk_whose_pelvis_drops_out_of_view_starts_on_the_markers_still_seen(seed):
    """A leg walked 20 m, 0.5 mm noise, its pelvis unseen in the last 200 of 1200 frames and its thigh seen by one
    marker there: the closed-form start predicts the markers seen there within 100 mm RMS and 300 mm at most
    (seeds 0-3: 28-82 and 89-207 mm; holding the pelvis where it was last posed put them 2.0 m RMS and 3.4 m at
    most off), and the fit from it converges within 15 iterations."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    data = simulate(model, n_frames=1200, noise_mm=0.0, seed=seed).trial.select(model.markers).as_array()
    data[..., 0] += np.linspace(-10000.0, 10000.0, len(data))[:, None]
    data = data + np.random.default_rng(seed).normal(0, 0.5, data.shape)
    chain = Skeleton.from_model(model)
    col = {m: i for i, m in enumerate(chain.labels)}
    data[-200:, [col[m] for m in ("LASI", "RASI", "SACR", "RTHI", "RKNE")]] = np.nan
    state = initial_state(chain, data)
    pred = forward(chain, Terms(), state)[3]
    off = np.linalg.norm(pred - data, axis=2)
    assert np.sqrt(np.nanmean(off[-200:] ** 2)) < 100.0 and np.nanmax(off) < 300.0
    fit = fit_chain(chain, data, state, weights=np.isfinite(data).all(axis=2).astype(float), max_iter=15)
    assert fit.converged
