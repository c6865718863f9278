"""The whole-chain fit's analytic derivatives are the derivatives of its forward kinematics: every effect
term (marker offsets, centre offsets, a hinge's second rotations, world fields) checked against central
finite differences at random states."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import example, given, settings, strategies as st

from identcheck.bundle.chain import initial_state
from identcheck.bundle.jacobian import dense_jacobians, jacobian_blocks
from identcheck.bundle.model import Terms, apply_step, forward
from identcheck.bundle.hypothesis import angle_basis, time_basis
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

MODEL = Model.from_toml(Path(__file__).parents[2] / "examples" / "diagnose_leg.toml")


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), beta=st.floats(0.0, 3.2), size=st.floats(0.0, 0.3),
       second=st.floats(0.3, 2.8), two=st.booleans())
@example(seed=0, beta=0.4, size=0.3, second=1.6, two=True)
def test_constants_jacobian_matches_finite_differences(seed, beta, size, second, two):
    """`two`: the hinge turns about two axes across it (a ball joint's extra rotations), so that the second
    rotation's vector is not along either axis and a profile's derivative is not a turn about its own axis."""
    sim = simulate(MODEL, n_frames=40, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    s = initial_state(chain, data)
    rng = np.random.default_rng(seed)
    hinge = next(j for j in chain.joints if chain.types[j] == "revolute")
    ball = next(j for j in chain.joints if chain.types[j] == "spherical")
    tb = time_basis(40, 100.0, 0.1)
    seg0 = chain.seg_markers[chain.marker_seg[0]]
    terms = Terms(markers=[(0, angle_basis(rng.normal(size=(40, 1)))), (np.array(seg0), tb[:, :2])],
                  centres=[(ball, tb[:, :3])],
                  rotations=[(hinge, tb, beta)] + ([(hinge, tb[:, :4], beta + second)] if two else []),
                  screws=[(hinge, rng.normal(size=40)), (hinge, rng.normal(size=40))],
                  world=[(np.arange(chain.n_markers), rng.normal(size=data.shape)),   # a run of two on every marker
                         (np.arange(chain.n_markers), rng.normal(size=data.shape)),
                         (np.array([0, 2]), rng.normal(size=(40, 2, 3)))])
    s.term_params = [rng.normal(size=sh) * (size if len(sh) == 2 and sh[1] == 1 else 1.0) for sh in terms.shapes()]
    R, t, centre, pred = forward(chain, terms, s)
    lay, blocks = jacobian_blocks(chain, terms, s, R, centre, pred)
    J, G = dense_jacobians(lay, blocks, chain.n_markers)
    P = G.shape[-1]
    for p in range(P):
        dc = np.zeros(P)
        h = 1e-6
        dc[p] = h
        up = forward(chain, terms, apply_step(chain, terms, s, R, np.zeros((40, J.shape[-1])), dc))[3]
        dc[p] = -h
        down = forward(chain, terms, apply_step(chain, terms, s, R, np.zeros((40, J.shape[-1])), dc))[3]
        numeric = (up - down) / (2 * h)
        assert np.allclose(G[..., p], numeric, atol=1e-4 * (1 + np.abs(numeric).max())), p


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), turned=st.booleans())
def test_per_frame_jacobian_matches_finite_differences(seed, turned):
    """The per-frame columns (the root's pose, each joint's angles) against central differences of the step; with
    `turned`, every kind of effect term is on (a marker's and a centre's offsets, a hinge's screw, world fields) and the
    hinge also turns about two axes across it (fitted profiles of up to 0.3 rad)."""
    sim = simulate(MODEL, n_frames=12, seed=seed)
    chain = Skeleton.from_model(MODEL)
    data = sim.trial.as_array()
    s = initial_state(chain, data)
    terms = Terms()
    if turned:
        rng = np.random.default_rng(seed)
        hinge = next(j for j in chain.joints if chain.types[j] == "revolute")
        ball = next(j for j in chain.joints if chain.types[j] == "spherical")
        tb = time_basis(12, 100.0, 0.05)
        terms = Terms(markers=[(0, tb[:, :2])], centres=[(ball, tb[:, :3])],
                      rotations=[(hinge, tb, 0.3), (hinge, tb, 1.9)],
                      screws=[(hinge, rng.normal(size=12))],
                      world=[(np.arange(chain.n_markers), rng.normal(size=data.shape))])
        s.term_params = [rng.normal(size=sh) * (0.3 if len(sh) == 2 and sh[1] == 1 else 1.0) for sh in terms.shapes()]
    R, t, centre, pred = forward(chain, terms, s)
    lay, blocks = jacobian_blocks(chain, terms, s, R, centre, pred)
    J, G = dense_jacobians(lay, blocks, chain.n_markers)
    h = 1e-6
    for p in range(lay.k):
        dq = np.zeros((12, lay.k))
        dq[:, p] = h
        up = forward(chain, terms, apply_step(chain, terms, s, R, dq, np.zeros(lay.P)))[3]
        down = forward(chain, terms, apply_step(chain, terms, s, R, -dq, np.zeros(lay.P)))[3]
        numeric = (up - down) / (2 * h)
        assert np.allclose(J[..., p], numeric, atol=1e-4 * (1 + np.abs(numeric).max())), p
