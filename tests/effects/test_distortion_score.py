"""The strain detector's score statistic: the Gram matrix of what a refit cannot absorb, and the statistic itself
against what a refit with the strain fields actually explains."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.score_test import (score_moments, score_moments_streamed, score_statistic, unabsorbed,
                                          unabsorbed_gram)
from identcheck.bundle.hypothesis import Hypothesis
from identcheck.bundle.model import Terms
from identcheck.effects.spatial_distortion import (FIELDS, N_FIELDS, RADIAL, SCALED_AXES, field, fields, plain_gram,
                                                   volume, where_fields_act)
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _strains(x: np.ndarray) -> list:
    """The five strain fields of the volume at `x` (the degree-1 fields less the axes' scales, which they span
    together with the uniform scale the segments absorb)."""
    return fields(x, 1)[:FIELDS[1] - len(SCALED_AXES)]


def _fitted_leg(seed: int, frames: int, noise_mm: float, strain_mm: float = 0.0):
    """A simulated leg (the bundled diagnose model), optionally warped by a random strain field of `strain_mm`
    at its largest, fitted by the rigid chain: (hypothesis, the strain's coefficients)."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    data = simulate(model, n_frames=frames, noise_mm=0.0, seed=seed).trial.select(model.markers).as_array()
    rng = np.random.default_rng(seed)
    flds = np.stack(_strains(data))
    coef = rng.normal(size=len(flds))
    warp = np.einsum("k,kfmi->fmi", coef, flds)
    if strain_mm > 0:
        coef *= strain_mm / np.max(np.linalg.norm(warp, axis=2))
        data = data + np.einsum("k,kfmi->fmi", coef, flds)
    data = data + rng.normal(0, noise_mm, data.shape)
    chain = Skeleton.from_model(model)
    w = np.ones(data.shape[:2])
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=60)
    return Hypothesis(chain, fit.terms, data, w, fit), coef


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**16), st.integers(2, 6))
def test_the_gram_matrix_is_a_projection_s_inner_products(seed, k):
    """On a fitted leg, k random fields: the Gram matrix is symmetric positive semi-definite, its diagonal is
    what :func:`unabsorbed` leaves of each field, and it is bilinear (the unabsorbed norm of a sum of two fields
    is their entries' sum ``G_aa + 2 G_ab + G_bb``). With a tenth of the samples unweighted, a field that lives
    only there (NaN elsewhere) has a zero row, and the others' diagonal is still :func:`unabsorbed`'s."""
    h, _ = _fitted_leg(seed % 1000, 80, 0.5)
    rng = np.random.default_rng(seed)
    vs = [rng.normal(0, 1.0, h.data.shape) for _ in range(k)]
    G = unabsorbed_gram(h.fit, h.weights, vs)
    scale = float(np.max(np.diag(G)))
    assert np.allclose(G, G.T, atol=1e-9 * scale)
    assert np.min(np.linalg.eigvalsh(G)) >= -1e-8 * scale
    assert np.allclose(np.diag(G), unabsorbed(h.fit, h.weights, vs), rtol=1e-9, atol=1e-9 * scale)
    both = unabsorbed(h.fit, h.weights, [vs[0] + vs[1]])[0]
    assert abs(both - (G[0, 0] + 2 * G[0, 1] + G[1, 1])) <= 1e-6 * scale          # rounding: ~1e-8 seen
    hidden = rng.uniform(size=h.weights.shape) < 0.1
    w = np.where(hidden, 0.0, h.weights)
    only_hidden = np.where(hidden[..., None], rng.normal(0, 1.0, h.data.shape), np.nan)
    G2 = unabsorbed_gram(h.fit, w, vs + [only_hidden])
    assert np.allclose(G2[-1], 0.0, atol=1e-9 * scale)
    # (to rounding: a stack of one field more multiplies in another order, and the constants' weakly determined
    # directions, S⁺'s eigenvalues near 1e5 against |reduced|², magnify that to a few 1e-9 of the diagonal)
    assert np.allclose(np.diag(G2)[:-1], unabsorbed(h.fit, w, vs), rtol=1e-7, atol=1e-9 * scale)


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**16), st.floats(1.0, 6.0), st.floats(0.3, 1.0))
def test_the_score_statistic_is_what_a_refit_with_the_strain_explains(seed, strain_mm, noise_mm):
    """A leg in a volume warped by a random strain of 1-6 mm at its largest, white noise 0.3-1 mm, fitted rigid:
    the score statistic is within 10 % of the residual sum of squares a refit with the 5 strain fields takes off
    (to first order they are equal), and never less than a plain regression of the residual on the fields (what
    the detector read before, 5-10 times less on such legs: the segments absorb most of a linear field)."""
    h, _ = _fitted_leg(seed % 1000, 300, noise_mm, strain_mm)
    res = np.where(h.weights[..., None] > 0, np.nan_to_num(h.residuals()), 0.0)
    stat = score_statistic(h.fit, h.weights, res, _strains(where_fields_act(h)))
    cols = np.arange(h.chain.n_markers)
    new = h.refit(terms=h.terms + Terms(world=[(cols, f) for f in _strains(h.data)]), max_iter=30)
    gain = h.rss - new.rss
    assert gain > 0
    assert abs(stat - gain) <= 0.1 * gain + 3 * noise_mm ** 2
    X = np.stack([f.reshape(-1) for f in _strains(where_fields_act(h))], axis=1)
    plain = X @ np.linalg.lstsq(X, res.reshape(-1), rcond=None)[0]
    assert plain @ plain <= stat * (1 + 1e-9)


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.0, 4.0))
def test_the_streamed_moments_are_the_moments(seed, strain_mm):
    """The distortion's moments read one field at a time with the plain Gram matrix summed over chunks of frames
    (:func:`score_moments_streamed`, :func:`plain_gram`) are those of all the fields held at once, with a tenth of
    the samples unweighted and the others weighted 0.3-1; and :func:`field` is :func:`fields`' k-th."""
    h, _ = _fitted_leg(seed % 1000, 120, 0.5, strain_mm)
    rng = np.random.default_rng(seed)
    w = np.where(rng.uniform(size=h.weights.shape) < 0.1, 0.0, rng.uniform(0.3, 1.0, h.weights.shape))
    at = np.where((w > 0)[..., None], h.fit.pred, np.nan)
    box = volume(at)
    every = fields(at, 3, box) + [field(at, k, box) for k in RADIAL]         # (the lens's after the polynomials)
    assert len(every) == N_FIELDS and all(np.array_equal(field(at, k, box), every[k]) for k in (0, 4, 5, 27, 52, 57))
    (n, G), = score_moments(h.fit, w, h.residuals(), [every])
    plain = plain_gram(at, w, box)
    n2, G2 = score_moments_streamed(h.fit, w, h.residuals(), iter(every), plain)
    np.testing.assert_allclose(n2, n, rtol=1e-9, atol=1e-9 * np.max(np.abs(n)))
    # what a refit absorbs is nearly all of a linear field: G is a difference of near-equal sums (rounding ~1e-9 of
    # the plain Gram matrix seen)
    np.testing.assert_allclose(G2, G, rtol=1e-7, atol=1e-7 * float(np.max(np.abs(plain))))
    assert np.max(np.abs(G2 - G)) < 1e-3 * np.max(np.abs(G))


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.6, 0.9))
def test_fields_at_predicted_positions_do_not_fit_correlated_noise(seed, phi):
    """A leg walked 15 m along x (a volume long and low), serially correlated noise (AR(1), φ 0.6-0.9, 1 mm) and no
    distortion: the strain fields made where the rigid fit predicts the markers (:func:`where_fields_act`) gain
    what 5 parameters gain on noise (prewhitened, a χ²(5): below 30 in units of σ², p ≈ 10⁻⁵), below the
    criterion's cost of 5 ln(3N). Made at the measured positions they carry the noise itself and gained 30-80."""
    from identcheck.bundle.hypothesis import whitened_rss

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    data = simulate(model, n_frames=1200, noise_mm=0.0, seed=seed % 1000).trial.select(model.markers).as_array()
    data[..., 0] += np.linspace(0.0, 15000.0, len(data))[:, None]
    rng = np.random.default_rng(seed)
    e = np.zeros(data.shape)
    e[0] = rng.normal(0, 1.0, data.shape[1:])
    for t in range(1, len(e)):
        e[t] = phi * e[t - 1] + rng.normal(0, np.sqrt(1 - phi ** 2), data.shape[1:])
    data = data + e
    chain = Skeleton.from_model(model)
    w = np.ones(data.shape[:2])
    fit = fit_chain(chain, data, initial_state(chain, data), weights=w, max_iter=60)
    h = Hypothesis(chain, fit.terms, data, w, fit)
    cols = np.arange(chain.n_markers)
    new = h.refit(terms=h.terms + Terms(world=[(cols, f) for f in fields(where_fields_act(h), 1, box=volume(data))]),
                  max_iter=20)
    gain = whitened_rss(h.residuals(), w, phi) - whitened_rss(new.residuals(), w, phi)
    assert gain < 30.0
    assert gain < 5 * np.log(3 * w.sum())


@pytest.mark.parametrize("axis", [0, 2])
def test_diagnose_names_a_few_millimetres_of_scale_error_along_one_axis(axis):
    """A volume calibrated 0.4 % long along one of its axes (about 4 mm over the leg's metre along z, less across it),
    0.6 mm white noise, 1500 frames: `diagnose` names a spatial distortion first, as the one field a scale along that
    axis is, less its uniform part (``scale along x|y|z``: one parameter, not the five strains, nor two of them, which
    an x or y scale had needed). Read by regressing the residual on the raw fields (before the score statistic), the
    segments' poses had taken most of it up and nothing was named."""
    import identcheck as ic

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=1500, noise_mm=0.0, seed=11)
    xyz = sim.trial.as_array().copy()
    along = xyz[..., axis] - np.nanmedian(xyz[..., axis])
    xyz[..., axis] += (0.004 if axis == 2 else 0.012) * along       # (the leg sweeps less across than up)
    xyz += np.random.default_rng(11).normal(0, 0.6, xyz.shape)
    report = ic.diagnose(model, sim.trial.replace(xyz=xyz)).to_dict()
    first = report["effects"][0]
    assert first["name"] == "spatial_distortion" and first["where"]["degree"] == 1
    # along z, whose half-extent is the volume's largest, the normalised strain xx+yy-2zz is as good a fit
    assert first["where"]["fields"] in ([f"scale along {'xyz'[axis]}"], ["strain xx+yy-2zz"] if axis == 2 else [])


@pytest.mark.parametrize("seed", [3, 8])
def test_diagnose_names_a_lens_about_a_centre_with_its_four_fields(seed):
    """A volume distorted like a lens, ``k |u − c|² (u − c)`` over the normalised coordinates about a random centre c
    near the volume's, about 4 mm at the markers' farthest, 0.6 mm white noise, 1500 frames: `diagnose` names a spatial
    distortion first, with the lens's fields among those fitted (:data:`RADIAL`, linearised in the centre). As the
    quadratic and the cubic families alone, a lens paid 48 parameters and their choice, and one at a held-out visible
    χ² of 267 had named nothing."""
    import identcheck as ic
    from identcheck.effects.spatial_distortion import FIELD_NAMES, RADIAL

    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=1500, noise_mm=0.0, seed=seed)
    xyz = sim.trial.as_array().copy()
    centre, half = volume(xyz)
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.3, 0.3, 3)
    u = (xyz - centre) / half - c
    lens = np.sum(u * u, axis=-1, keepdims=True) * u
    xyz += 4.0 * lens / np.nanmax(np.linalg.norm(lens, axis=-1))
    xyz += rng.normal(0, 0.6, xyz.shape)
    report = ic.diagnose(model, sim.trial.replace(xyz=xyz)).to_dict()
    first = report["effects"][0]
    assert first["name"] == "spatial_distortion", report["effects"]
    assert {FIELD_NAMES[k] for k in RADIAL} <= set(first["where"]["fields"]), first["where"]["fields"]
