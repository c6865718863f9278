"""The Gauss-Newton products the whole-tree fit is built on, against their definition written out frame by frame."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.bundle.chain import normal_products


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), weights=st.sampled_from(["ones", "gaps", "fractional"]),
       F=st.integers(1, 6), M=st.integers(1, 4), k=st.integers(1, 5), P=st.integers(1, 7))
def test_products_are_the_weighted_sums_they_stand_for(seed, weights, F, M, k, P):
    rng = np.random.default_rng(seed)
    J, G, r = rng.normal(size=(F, M, 3, k)), rng.normal(size=(F, M, 3, P)), rng.normal(size=(F, M, 3))
    w = {"ones": np.ones((F, M)), "gaps": (rng.random((F, M)) < 0.7).astype(float),
         "fractional": rng.random((F, M))}[weights]
    A, B, C, g, h = normal_products(J, G, r, w)
    _, _, _, _, h_frames = normal_products(J, G, r, w, per_frame=True)
    C_want, h_want = np.zeros((P, P)), np.zeros(P)
    for f in range(F):
        Jf = np.concatenate([np.sqrt(w[f, m]) * J[f, m] for m in range(M)])      # (3M, k)
        Gf = np.concatenate([np.sqrt(w[f, m]) * G[f, m] for m in range(M)])
        rf = np.concatenate([np.sqrt(w[f, m]) * r[f, m] for m in range(M)])
        np.testing.assert_allclose(A[f], Jf.T @ Jf, atol=1e-9)
        np.testing.assert_allclose(B[f], Jf.T @ Gf, atol=1e-9)
        np.testing.assert_allclose(g[f], Jf.T @ rf, atol=1e-9)
        np.testing.assert_allclose(h_frames[f], Gf.T @ rf, atol=1e-9)
        C_want += Gf.T @ Gf
        h_want += Gf.T @ rf
    np.testing.assert_allclose(C, C_want, atol=1e-9)
    np.testing.assert_allclose(h, h_want, atol=1e-9)
