"""The Gauss-Newton products the whole-tree fit is built on, assembled block by block, against their definition
written out frame by frame from the full Jacobians: random chains' states, effect terms, weights and residuals."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.hypothesis import angle_basis, time_basis
from identcheck.bundle.jacobian import dense_jacobians, jacobian_blocks
from identcheck.bundle.model import State, Terms, forward
from identcheck.bundle.normal import coupling_transposed_times, field_gradients, normal_equations
from identcheck.io.model import Model
from identcheck.skeleton import Skeleton

MODELS = {name: Model.from_toml(Path(__file__).parents[2] / "examples" / f"{name}.toml")
          for name in ("diagnose_leg", "sparse_leg", "real_walking2_legs")}


def _random_state(chain: Skeleton, F: int, rng) -> State:
    rot = lambda n: Rotation.random(n, random_state=rng).as_matrix()  # noqa: E731
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    hinges = [j for j in chain.joints if chain.types[j] == "revolute"]
    return State(local=100 * rng.normal(size=(chain.n_markers, 3)),
                 c_parent={j: 100 * rng.normal(size=3) for j in chain.joints},
                 c_child={j: 100 * rng.normal(size=3) for j in chain.joints},
                 axis={j: unit(rng.normal(size=3)) for j in hinges}, rest={j: rot(1)[0] for j in hinges},
                 root_R=rot(F), root_t=500 * rng.normal(size=(F, 3)),
                 rel_R={j: rot(F) for j in chain.joints if j not in hinges},
                 theta={j: rng.uniform(-2, 2, F) for j in hinges})


def _terms(chain: Skeleton, F: int, rng, kind: str) -> Terms:
    if kind == "none":
        return Terms()
    hinge = [j for j in chain.joints if chain.types[j] == "revolute"]
    ball = [j for j in chain.joints if chain.types[j] == "spherical"]
    tb = time_basis(F, 100.0, 0.1)
    seg = chain.seg_markers[chain.marker_seg[-1]]
    cols = rng.choice(chain.n_markers, size=min(2, chain.n_markers), replace=False)
    return Terms(markers=[(0, angle_basis(rng.normal(size=(F, 2)))), (np.array(seg), tb[:, :2])],
                 centres=[(ball[0], tb[:, :3])] if ball else [],
                 rotations=[(hinge[0], tb[:, :3], 0.4)] if hinge else [],
                 screws=[(hinge[0], rng.normal(size=F))] if hinge else [],
                 world=[(np.arange(chain.n_markers), rng.normal(size=(F, chain.n_markers, 3))),
                        (np.sort(cols), rng.normal(size=(F, len(cols), 3)))])


def _state_and_terms(seed: int, model: str, terms: str, F: int):
    """A random chain's state and terms, predicted: (rng, chain, terms, state, R, centre, pred)."""
    rng = np.random.default_rng(seed)
    chain = Skeleton.from_model(MODELS[model])
    s = _random_state(chain, F, rng)
    tm = _terms(chain, F, rng, terms)
    s.term_params = [0.1 * rng.normal(size=sh) for sh in tm.shapes()]
    R, _, centre, pred = forward(chain, tm, s)
    return rng, chain, tm, s, R, centre, pred


def _blocks_and_weights(seed: int, model: str, weights: str, terms: str, F: int):
    """A random chain's state and terms with their blocks, residuals and weights: (chain, lay, blocks, r, w)."""
    rng, chain, tm, s, R, centre, pred = _state_and_terms(seed, model, terms, F)
    lay, blocks = jacobian_blocks(chain, tm, s, R, centre, pred)
    M = chain.n_markers
    r = rng.normal(size=(F, M, 3))
    w = {"ones": np.ones((F, M)), "gaps": (rng.random((F, M)) < 0.7).astype(float),
         "fractional": rng.random((F, M))}[weights]
    return chain, lay, blocks, r, w


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), model=st.sampled_from(sorted(MODELS)),
       weights=st.sampled_from(["ones", "gaps", "fractional"]), terms=st.sampled_from(["none", "all"]),
       F=st.integers(1, 7))
def test_block_products_are_the_weighted_sums_they_stand_for(seed, model, weights, terms, F):
    chain, lay, blocks, r, w = _blocks_and_weights(seed, model, weights, terms, F)
    rng = np.random.default_rng(seed + 1)
    J, G = dense_jacobians(lay, blocks, chain.n_markers)
    M = chain.n_markers
    A, coupling, C, g, h = normal_equations(lay, blocks, r, w)
    B = coupling.dense()
    h_frames = normal_equations(lay, blocks, r, w, per_frame=True)[4]
    C_want, h_want = np.zeros((lay.P, lay.P)), np.zeros(lay.P)
    for f in range(F):
        Jf = np.concatenate([np.sqrt(w[f, m]) * J[f, m] for m in range(M)])      # (3M, k)
        Gf = np.concatenate([np.sqrt(w[f, m]) * G[f, m] for m in range(M)])
        rf = np.concatenate([np.sqrt(w[f, m]) * r[f, m] for m in range(M)])
        scale = 1 + np.abs(Gf).max() ** 2
        np.testing.assert_allclose(A[f], Jf.T @ Jf, atol=1e-9 * scale)
        np.testing.assert_allclose(B[f], Jf.T @ Gf, atol=1e-9 * scale)
        np.testing.assert_allclose(g[f], Jf.T @ rf, atol=1e-9 * scale)
        np.testing.assert_allclose(h_frames[f], Gf.T @ rf, atol=1e-9 * scale)
        C_want += Gf.T @ Gf
        h_want += Gf.T @ rf
    np.testing.assert_allclose(C, C_want, atol=1e-9 * (1 + np.abs(C_want).max()))
    np.testing.assert_allclose(h, h_want, atol=1e-9 * (1 + np.abs(h_want).max()))
    # Bᵀu of several vectors a frame at once from the blocks, B never formed: each vector's through B
    u = rng.normal(size=(F, lay.k, 3))
    for per_frame in (False, True):
        many = coupling_transposed_times(lay, blocks, u, w, per_frame=per_frame)
        for q in range(3):
            one = coupling.transposed_times(u[..., q], per_frame=per_frame)
            np.testing.assert_allclose(many[..., q], one, atol=1e-9 * (1 + np.abs(one).max()))
    # the gradients of several fields at once (weights on the fields, not on the Jacobians): each field's own sums
    V = np.stack([r, rng.normal(size=r.shape), np.zeros_like(r)], axis=-1)
    for per_frame in (False, True):
        g_all, h_all = field_gradients(lay, blocks, V, w, per_frame=per_frame)
        for q in range(V.shape[-1]):
            _, _, _, g_q, h_q = normal_equations(lay, blocks, V[..., q], w, per_frame=per_frame)
            np.testing.assert_allclose(g_all[..., q], g_q, atol=1e-9 * (1 + np.abs(g_q).max()))
            np.testing.assert_allclose(h_all[..., q], h_q, atol=1e-9 * (1 + np.abs(h_q).max()))
    # the coupling kept by structure (term columns a base times a basis) eliminates the frames as B written out does
    from identcheck.bundle import coupling as kept
    from identcheck.bundle.normal import eliminate_frames, ridged
    Ad = ridged(A) + np.eye(lay.k)
    for hh, chunk in ((h, kept.CHUNK_ENTRIES), (h_frames, 1)):          # (1: the frames summed one at a time)
        with mock.patch.object(kept, "CHUNK_ENTRIES", chunk):
            S1, red1, back1 = eliminate_frames(Ad, coupling, C, g, hh)
        S2, red2, back2 = eliminate_frames(Ad, B, C, g, hh)
        np.testing.assert_allclose(S1, S2, atol=1e-9 * (1 + np.abs(S2).max()))
        np.testing.assert_allclose(red1, red2, atol=1e-9 * (1 + np.abs(red2).max()))
        dc = rng.normal(size=lay.P)
        np.testing.assert_allclose(back1(dc), back2(dc), atol=1e-9 * (1 + np.abs(back2(dc)).max()))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), model=st.sampled_from(sorted(MODELS)),
       weights=st.sampled_from(["ones", "gaps", "fractional"]), terms=st.sampled_from(["none", "all"]),
       F=st.integers(1, 9), chunk_frames=st.integers(1, 10), per_frame=st.booleans())
def test_frames_eliminated_a_chunk_at_a_time_as_all_at_once(seed, model, weights, terms, F, chunk_frames, per_frame):
    """:func:`frames_eliminated` (B formed a chunk of frames at a time, chunks down to one frame, the last one short,
    frames without a marker) gives the Schur complement and the reduced gradient that eliminating every frame at once
    gives, and A as built. (Whether each chunk's ridge takes the whole trial's floor or its own is beyond what this
    can see: the ridge is 1e-12 of a frame's scale, and a frame without markers couples to nothing.)"""
    from identcheck.bundle import normal
    _, lay, blocks, r, w = _blocks_and_weights(seed, model, weights, terms, F)
    if weights == "gaps":
        w[0] = 0.0                                                # a frame with no marker: held by the ridge alone
    A, B, C, g, h = normal_equations(lay, blocks, r, w, per_frame=per_frame)
    S_want, red_want, _ = normal.eliminate_frames(normal.ridged(A), B, C, g, h)
    with mock.patch.object(normal, "ELIMINATION_CHUNK_ENTRIES", chunk_frames * lay.k * lay.P):
        S, red, A_got = normal.frames_eliminated(lay, blocks, w, r, per_frame=per_frame)
        S0, red0, _ = normal.frames_eliminated(lay, blocks, w)
    np.testing.assert_allclose(A_got, A, atol=1e-12 * (1 + np.abs(A).max()))
    np.testing.assert_allclose(S, S_want, atol=1e-8 * (1 + np.abs(S_want).max()))
    np.testing.assert_allclose(red, red_want, atol=1e-8 * (1 + np.abs(red_want).max()))
    np.testing.assert_allclose(S0, S, atol=1e-8 * (1 + np.abs(S).max()))      # the residual does not enter S
    assert not np.any(red0)                                                     # nor, without one, the gradient


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), F=st.integers(1, 6), k=st.integers(1, 6), P=st.integers(1, 8),
       singular=st.booleans(), per_frame=st.booleans())
def test_frames_eliminated_solve_the_whole_system(seed, F, k, P, singular, per_frame):
    """The Schur complement and the back-substitution give the solution of the full normal equations (every
    frame's unknowns and the constants together), whether each block's Cholesky factor exists or not (a block
    that is not positive definite is solved as a general system)."""
    from identcheck.bundle.normal import eliminate_frames
    rng = np.random.default_rng(seed)
    Jf = rng.normal(size=(F, k + 2, k))
    A = Jf.transpose(0, 2, 1) @ Jf
    Ad = A + 1e-3 * np.eye(k)
    if singular:                                    # indefinite: no Cholesky factor, the general solve takes over
        Ad[0, 0, 0] = -1.0 - Ad[0, 0, 0]
        with pytest.raises(np.linalg.LinAlgError):
            np.linalg.cholesky(Ad)
    Gf = rng.normal(size=(F, k + 2, P))
    B = Jf.transpose(0, 2, 1) @ Gf
    C = sum(Gf[f].T @ Gf[f] for f in range(F)) + np.eye(P)
    g, hf = rng.normal(size=(F, k)), rng.normal(size=(F, P))
    h = hf if per_frame else hf.sum(axis=0)
    S, reduced, back = eliminate_frames(Ad, B, C, g, h)
    full = np.zeros((F * k + P, F * k + P))
    for f in range(F):
        full[f * k:(f + 1) * k, f * k:(f + 1) * k] = Ad[f]
        full[f * k:(f + 1) * k, F * k:] = B[f]
        full[F * k:, f * k:(f + 1) * k] = B[f].T
    full[F * k:, F * k:] = C
    rhs = np.concatenate([g.ravel(), hf.sum(axis=0)])
    x = np.linalg.solve(full, rhs)
    red_total = reduced.sum(axis=0) if per_frame else reduced
    dc = np.linalg.solve(S, red_total)
    np.testing.assert_allclose(dc, x[F * k:], rtol=1e-6, atol=1e-8 * (1 + np.abs(x).max()))
    np.testing.assert_allclose(back(-dc), x[:F * k].reshape(F, k), rtol=1e-6, atol=1e-8 * (1 + np.abs(x).max()))
    want = np.stack([hf[f] - B[f].T @ np.linalg.solve(Ad[f], g[f]) for f in range(F)])
    np.testing.assert_allclose(reduced, want if per_frame else want.sum(axis=0), rtol=1e-6,
                               atol=1e-8 * (1 + np.abs(want).max()))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), F=st.integers(1, 5), k=st.integers(1, 16), spread=st.floats(0.0, 6.0))
def test_lower_inverse_inverts_every_frame(seed, F, k, spread):
    """Lower-triangular factors with diagonals spread over up to six orders of magnitude: each frame's inverse is
    lower triangular, and its product with the factor is the identity to rounding (relative to the sizes of the
    two: forward substitution is backward stable)."""
    from identcheck.bundle.normal import lower_inverse
    rng = np.random.default_rng(seed)
    L = np.tril(rng.normal(size=(F, k, k)), -1)
    L[:, np.arange(k), np.arange(k)] = 10.0 ** rng.uniform(-spread / 2, spread / 2, size=(F, k))
    X = lower_inverse(L)
    assert np.all(np.triu(X, 1) == 0)
    eps = np.finfo(float).eps
    for f in range(F):
        bound = 10 * k ** 2 * eps * np.abs(X[f]).max() * np.abs(L[f]).max()
        assert np.abs(X[f] @ L[f] - np.eye(k)).max() <= bound


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), model=st.sampled_from(sorted(MODELS)), terms=st.sampled_from(["none", "all"]),
       F=st.integers(1, 5))
def test_blocks_formed_one_at_a_time_are_the_blocks(seed, model, terms, F):
    """``jacobian_blocks(..., lazy=True)`` forms each block only when it is reached (the fit's normal equations let
    each go once summed), and they are the blocks of the list, giving the same normal equations."""
    rng, chain, tm, s, R, centre, pred = _state_and_terms(seed, model, terms, F)
    lay, listed = jacobian_blocks(chain, tm, s, R, centre, pred)
    lay2, lazy = jacobian_blocks(chain, tm, s, R, centre, pred, lazy=True)
    assert isinstance(lazy, Iterator) and not isinstance(lazy, (list, tuple))     # formed as they are reached
    got = list(lazy)
    assert [b.group.cols.tolist() for b in got] == [b.group.cols.tolist() for b in listed] == [
        g.cols.tolist() for g in lay2.groups]
    for a, b in zip(got, listed):
        np.testing.assert_array_equal(a.J, b.J)
        np.testing.assert_array_equal(a.G, b.G)
        assert (a.base is None) == (b.base is None) and (a.base is None or np.array_equal(a.base, b.base))
    r, w = rng.normal(size=pred.shape), np.ones(pred.shape[:2])
    want = normal_equations(lay, listed, r, w)
    have = normal_equations(*jacobian_blocks(chain, tm, s, R, centre, pred, lazy=True), r, w)
    for x, y in zip(want, have):
        if hasattr(x, "dense"):
            x, y = x.dense(), y.dense()
        np.testing.assert_array_equal(x, y)
