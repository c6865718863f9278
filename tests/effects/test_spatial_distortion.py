"""The distortion detector's plain Gram matrix, accumulated chunk by chunk, is that of the whole design (weights
included); each field is the one :func:`fields` lists at its place, named in :data:`FIELD_NAMES`."""
import numpy as np
from hypothesis import given, settings, strategies as st

import identcheck.effects.spatial_distortion as sd


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), frames=st.integers(3, 60), markers=st.integers(3, 9),
       chunk=st.sampled_from([27, 100, 8192]), hidden=st.floats(0.0, 0.4), planar=st.booleans())
def test_the_chunked_gram_matrix_is_the_whole_designs(seed, frames, markers, chunk, hidden, planar):
    """Random marker clouds (some flat, so that fields coincide and the design loses rank), samples unseen at
    random (NaN) and the others weighted 0.3-1: the chunked ``XᵀWX`` equals the whole design's to 1e-10 of its
    largest entry, for any chunk size."""
    rng = np.random.default_rng(seed)
    data = rng.uniform(-800, 800, (frames, markers, 3))
    if planar:
        data[..., 2] = 1000.0                              # no height: the z fields vanish or repeat others
    seen = rng.uniform(size=(frames, markers)) >= hidden
    weights = np.where(seen, rng.uniform(0.3, 1.0, seen.shape), 0.0)
    data = np.where(seen[..., None], data, np.nan)
    box = sd.volume(data)
    flds = [sd.field(data, k, box) for k in range(sd.N_FIELDS)]
    old_rows = sd.CHUNK_ROWS
    sd.CHUNK_ROWS = chunk
    try:
        got = sd.plain_gram(data, weights, box)
    finally:
        sd.CHUNK_ROWS = old_rows
    X = np.stack([f.reshape(-1) for f in flds], axis=1)
    assert not np.any(X[np.repeat(~seen.reshape(-1), 3)])               # every field is 0 where the data are NaN
    want = X.T @ (np.repeat(weights.reshape(-1), 3)[:, None] * X)
    assert got.shape == (sd.N_FIELDS, sd.N_FIELDS) == (len(sd.FIELD_NAMES),) * 2
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * max(float(np.max(np.abs(want))), 1.0))


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_each_field_is_what_its_name_says(seed):
    """At random points: a strain field is a symmetric traceless linear map of the normalised coordinates; ``scale
    along d`` is ``(e eᵀ − I/3)(x − c)`` in millimetres; a monomial field ``m along d`` has only its d component, the
    monomial of the normalised coordinates."""
    rng = np.random.default_rng(seed)
    data = rng.uniform(-800, 800, (7, 5, 3))
    centre, half = box = sd.volume(data)
    u = (data - centre) / half
    for k, name in enumerate(sd.FIELD_NAMES):
        f = sd.field(data, k, box)
        assert k >= sd.FIELDS[3] or np.array_equal(f, sd.fields(data, 3, box)[k])
        if name.startswith(("strain", "shear")):
            E = np.linalg.lstsq(u.reshape(-1, 3), f.reshape(-1, 3), rcond=None)[0].T
            np.testing.assert_allclose(f.reshape(-1, 3), u.reshape(-1, 3) @ E.T, atol=1e-9 * np.max(np.abs(f)))
            np.testing.assert_allclose(E, E.T, atol=1e-9 * np.max(np.abs(E)))
            assert abs(np.trace(E)) <= 1e-9 * np.max(np.abs(E))
            continue
        if name.startswith("radial"):       # a lens k |u - c|^2 (u - c), linearised in c about 0
            r2 = np.sum(u * u, axis=-1, keepdims=True)
            if name == "radial":
                np.testing.assert_allclose(f, r2 * u, rtol=1e-12, atol=1e-12)
            else:
                a = "xyz".index(name[-1])
                e = np.eye(3)[a]
                np.testing.assert_allclose(f, -(2 * u[..., a:a + 1] * u + r2 * e), rtol=1e-12, atol=1e-12)
            continue
        mono, axis = name.split(" along ")
        d = "xyz".index(axis)
        if mono == "scale":                 # a scale along the axis less its uniform part, in mm about the centre
            expected = -(data - centre) / 3.0
            expected[..., d] += data[..., d] - centre[d]
            np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-9)
            continue
        d = "xyz".index(axis)
        x, y, z = u[..., 0], u[..., 1], u[..., 2]
        value = {"x^2": x * x, "y^2": y * y, "z^2": z * z, "xy": x * y, "xz": x * z, "yz": y * z, "x^3": x ** 3,
                 "y^3": y ** 3, "z^3": z ** 3, "x^2y": x * x * y, "x^2z": x * x * z, "y^2x": y * y * x,
                 "y^2z": y * y * z, "z^2x": z * z * x, "z^2y": z * z * y, "xyz": x * y * z}[mono]
        np.testing.assert_allclose(f[..., d], value, rtol=1e-12, atol=1e-12)
        assert not np.any(np.delete(f, d, axis=-1))


def test_the_units_chosen_among_are_the_strains_one_by_one_and_each_higher_degree_whole():
    """Every field in exactly one unit; each strain (and each axis's scale) its own; the quadratic and the cubic fields
    each one family, and the lens's four another."""
    flat = sorted(k for u in sd.UNITS for k in u)
    assert flat == list(range(sd.N_FIELDS))
    assert sd.UNITS[:sd.FIELDS[1]] == [[k] for k in range(sd.FIELDS[1])]
    assert [len(u) for u in sd.UNITS[sd.FIELDS[1]:]] == [sd.FIELDS[2] - sd.FIELDS[1], sd.FIELDS[3] - sd.FIELDS[2],
                                                         len(sd.RADIAL)]
    assert all(sd.FIELD_NAMES[k].startswith(("strain", "shear", "scale")) for k in range(sd.FIELDS[1]))
