"""Skin that pays only for the functions of the angles it moves with (``soft_tissue``'s forward selection): the
moments give the regression's explained sum of squares for any subset of the functions, a marker moving with one
function of a ball joint's angles is proposed with that function alone, and each function is named for what it is."""
from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck.bundle.score_test import quadratic_form
from identcheck.bundle.hypothesis import angle_basis, joint_angles
from identcheck.diagnose import workflow
from identcheck.effects.injection import marker_column, rotate, rotations
from identcheck.effects.registry import EFFECTS
from identcheck.effects.soft_tissue import basis_names, explained, regression_moments
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
LEG = EXAMPLES / "diagnose_leg.toml"


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.data())
def test_a_subsets_statistic_is_what_its_functions_explain(seed, k, data):
    """``trace(N_Sᵀ A_SS⁺ N_S)`` of :func:`regression_moments` equals :func:`explained` with the functions S alone
    (a constant always in), for any subset, with unseen rows left out; and it is the statistic of the 3|S| fields
    with the Gram matrix ``A ⊗ I₃`` written out."""
    rng = np.random.default_rng(seed)
    basis = rng.normal(size=(120, k)) + rng.normal(size=k)
    resid = rng.normal(size=(120, 3)) + basis[:, :1] * rng.normal(size=3)
    resid[rng.random(120) < 0.1] = np.nan
    n, G = regression_moments(resid, basis)
    subset = data.draw(st.lists(st.integers(0, k - 1), min_size=1, max_size=k, unique=True))
    rows = sorted(subset)
    stat = quadratic_form(n[rows], G[np.ix_(rows, rows)])
    assert np.isclose(stat, explained(resid, basis[:, rows]), rtol=1e-8, atol=1e-9)
    cols = [3 * f + a for f in rows for a in range(3)]
    flat, full = n.reshape(-1), np.kron(G, np.eye(3))
    assert np.isclose(quadratic_form(flat[cols], full[np.ix_(cols, cols)]), stat, rtol=1e-8, atol=1e-9)


def test_too_few_rows_give_no_moments():
    n, G = regression_moments(np.full((5, 3), np.nan), np.ones((5, 2)))
    assert n.shape == (0, 3) and G.shape == (0, 0)


def test_each_function_is_named_for_the_product_it_is():
    """The names follow :func:`angle_basis`'s columns: each column is the product (or the square, or the angle) its
    name says, for a hinge, a ball joint and the two together."""
    chain = Skeleton.from_model(Model.from_toml(LEG))
    rng = np.random.default_rng(3)
    for joints in [("knee",), ("hip",), ("hip", "knee")]:
        raw = {j: rng.uniform(-1, 1, (50, 1 if chain.types[j] == "revolute" else 3)) for j in joints}
        stacked = np.column_stack([raw[j] for j in joints])
        basis = angle_basis(stacked)
        names = basis_names(chain, joints)
        assert len(names) == basis.shape[1] == len(set(names))
        symbols = names[:stacked.shape[1]]
        scaled = 2 * (stacked - stacked.min(axis=0)) / np.ptp(stacked, axis=0) - 1
        value = dict(zip(symbols, scaled.T))
        for a, b in itertools.combinations_with_replacement(symbols, 2):
            name = f"{a}²" if a == b else f"{a}·{b}"
            col = basis[:, names.index(name)]
            product = value[a] * value[b]
            np.testing.assert_allclose(col, product - product.mean(), atol=1e-12)


def _one_function_skin(seed: int, size_mm: float, noise_mm: float = 0.5):
    """The leg with one thigh marker moving on the thigh along a random direction by one function of the hip's
    rotation vector (the fitted joint's own, one of its nine), `size_mm` at its largest; returns the model, the
    trial, the marker and that function's index among the hip's."""
    model = Model.from_toml(LEG)
    sim = simulate(model, n_frames=800, noise_mm=noise_mm, seed=seed)
    rng = np.random.default_rng(seed)
    marker = str(rng.choice(list(model.segments["thigh"].markers)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = workflow.start(model, sim.trial.recentred()[0])
    basis = angle_basis(joint_angles(h)["hip"])
    f = int(rng.integers(0, 3))                       # one of the hip's own angles (flexion, abduction, rotation)
    shape = basis[:, f] - basis[:, f].mean()
    move = np.outer(shape / np.abs(shape).max() * size_mm, rng.normal(size=3) / np.sqrt(3))
    clean = sim.clean.as_array()
    clean[:, marker_column(sim, marker)] += rotate(rotations(sim, "thigh"), move)
    trial = sim.trial.replace(xyz=clean + (sim.trial.as_array() - sim.clean.as_array()))
    return model, trial, marker, f


@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), size=st.floats(5.0, 10.0))
def test_a_marker_moving_with_one_of_the_hips_angles_pays_for_that_function(seed, size):
    """Skin on one thigh marker with one of the hip's angles: the single-marker proposal there (with the hip's
    angles, or the hip's and the knee's, whichever earns more) names the injected function among those it fits,
    fits fewer than its driver's whole basis (9 functions, 14 with the knee's), and charges for what it fits."""
    model, trial, marker, f = _one_function_skin(seed, size)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = workflow.start(model, trial.recentred()[0])
    props = [p for p in EFFECTS["soft_tissue"].propose(ctx, h) if p.where["markers"] == [marker]]
    assert len(props) == 1, "one proposal a place"
    p = props[0]
    chain = Skeleton.from_model(model)
    drivers = tuple(p.where.get("joints", [p.where["joint"]]))
    assert "hip" in drivers
    names = basis_names(chain, drivers)
    assert basis_names(chain, ("hip",))[f] in p.where["functions"]
    assert len(p.where["functions"]) < len(names)
    assert p.payload["basis"].shape[1] == len(p.where["functions"])
    after = EFFECTS["soft_tissue"].apply(ctx, h, p)
    assert after.n_params() - h.n_params() == 3 * len(p.where["functions"]) + p.payload["choice_params"]


def test_skin_on_the_root_fits_every_function():
    """The root's pose takes up its markers' common motion, so their residuals do not show what their skin terms will
    fit: a proposal on the root carries every function of its driving angles and no charge for a choice, while one on
    another segment chooses (here a pelvis marker and a thigh marker each moving with one of the hip's angles)."""
    model = Model.from_toml(LEG)
    sim = simulate(model, n_frames=800, noise_mm=0.5, seed=5)
    rng = np.random.default_rng(5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = workflow.start(model, sim.trial.recentred()[0])
    basis = angle_basis(joint_angles(h)["hip"])
    clean = sim.clean.as_array()
    for seg in ("pelvis", "thigh"):
        marker = model.segments[seg].markers[0]
        shape = basis[:, 0] - basis[:, 0].mean()
        move = np.outer(shape / np.abs(shape).max() * 8.0, rng.normal(size=3) / np.sqrt(3))
        clean[:, marker_column(sim, marker)] += rotate(rotations(sim, seg), move)
    trial = sim.trial.replace(xyz=clean + (sim.trial.as_array() - sim.clean.as_array()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, h = workflow.start(model, trial.recentred()[0])
    chain = Skeleton.from_model(model)
    props = EFFECTS["soft_tissue"].propose(ctx, h)
    root = [p for p in props if p.where["segment"] == chain.root and len(p.where["markers"]) == 1]
    other = [p for p in props if p.where["segment"] != chain.root and len(p.where["markers"]) == 1]
    assert root and other
    for p in root:
        drivers = tuple(p.where.get("joints", [p.where["joint"]]))
        assert p.where["functions"] == basis_names(chain, drivers) and p.payload["choice_params"] == 0
    assert any(len(p.where["functions"]) < len(basis_names(chain, tuple(p.where.get("joints", [p.where["joint"]]))))
               for p in other)
