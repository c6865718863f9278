"""The distortion detector's least squares, accumulated chunk by chunk, is the least squares of the whole design."""
import numpy as np
from hypothesis import given, settings, strategies as st

import identcheck.effects.spatial_distortion as sd


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), frames=st.integers(3, 60), markers=st.integers(3, 9),
       chunk=st.sampled_from([27, 100, 8192]), hidden=st.floats(0.0, 0.4), planar=st.booleans())
def test_the_chunked_fit_explains_what_the_whole_design_explains(seed, frames, markers, chunk, hidden, planar):
    """Random marker clouds (some flat, so that fields coincide and the design loses rank), samples unseen at
    random, residuals that are partly a random field of degree 3 and partly noise: for both degrees the squared norm
    of the fit equals that of NumPy's least squares on the whole design, to 1e-8 of the residual's energy."""
    rng = np.random.default_rng(seed)
    data = rng.uniform(-800, 800, (frames, markers, 3))
    if planar:
        data[..., 2] = 1000.0                              # no height: the z fields vanish or repeat others
    seen = rng.uniform(size=(frames, markers)) >= hidden
    flds = sd.fields(data, 3)
    true_field = np.einsum("k,kfmi->fmi", rng.normal(0, 2, len(flds)), np.stack(flds))
    res = np.where(seen[..., None], true_field + rng.normal(0, 1, data.shape), 0.0)
    old_rows = sd.CHUNK_ROWS
    sd.CHUNK_ROWS = chunk
    try:
        got = sd.explained(data, seen, res)
    finally:
        sd.CHUNK_ROWS = old_rows
    energy = float(np.sum(res ** 2))
    for degree, k in sd.FIELDS.items():
        X = np.stack([np.where(seen[..., None], f, 0.0).reshape(-1) for f in flds[:k]], axis=1)
        coef = np.linalg.lstsq(X, res.reshape(-1), rcond=None)[0]
        want = float(np.sum((X @ coef) ** 2))
        assert abs(got[degree] - want) <= 1e-8 * max(energy, 1.0)
        assert got[degree] <= energy * (1 + 1e-9)
    assert got[2] <= got[3] * (1 + 1e-9) + 1e-9             # more fields never explain less
