"""The gauge of a whole-chain fit, written out (identcheck.bundle.gauge), and what it is for.

The weakest direction of a joint and its standard error (``practical.weakest_se_mm``) describe the joint
relative to its parent segment, so they do not depend on where the fit put that segment's body frame: moving and
turning the frame (a change of coordinates that changes no fitted marker) turns the direction with it and leaves
the standard error where it was. Before, they were read from the centre's covariance in the fit's own gauge, and
moving the frames' origins to the markers' centroid had moved biobuddy's knee from 38.8 to 63.1 mm."""
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from identcheck.bundle.gauge import gauge_basis, turning_blocks
from identcheck.bundle.chain import fit_chain, initial_state
from identcheck.bundle.model import Terms, forward, tangents
from identcheck.bundle.practical import weakest
from identcheck.bundle.uncertainty import GAUGE_TOL, block_scaled, chain_inverse, covariance
from identcheck.fit.whole_tree import fit_tree
from identcheck.fit.workflow import fit_model
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.skeleton import Skeleton

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def regauge(chain, state, segment: str, R0: np.ndarray, t0: np.ndarray, terms: Terms = Terms()):
    """The same fit with `segment`'s body coordinates x replaced by R0 x + t0: its markers, the joint points and
    hinge axes it carries, the rotations that pose it and its effect terms' offsets, so that every segment sits
    where it sat."""
    s = state.copy()
    cols = chain.seg_markers[segment]
    s.local[cols] = s.local[cols] @ R0.T + t0
    for j in chain.joints:
        if chain.parent[j] == segment:          # R_child = R_parent @ rel: the parent's turn is undone in rel
            s.c_parent[j] = R0 @ s.c_parent[j] + t0
            if chain.types[j] == "revolute":
                s.axis[j] = R0 @ s.axis[j]
                s.rest[j] = R0 @ s.rest[j]
            else:
                s.rel_R[j] = R0 @ s.rel_R[j]
        if chain.child[j] == segment:
            s.c_child[j] = R0 @ s.c_child[j] + t0
            if chain.types[j] == "revolute":
                s.rest[j] = s.rest[j] @ R0.T
            else:
                s.rel_R[j] = s.rel_R[j] @ R0.T
    if segment == chain.root:
        s.root_R = s.root_R @ R0.T
        s.root_t = s.root_t - s.root_R @ t0
    owners = [chain.marker_seg[int(np.atleast_1d(col)[0])] for col, _ in terms.markers]
    owners += [chain.parent[j] for j, _ in terms.centres]
    for k, owner in enumerate(owners):      # a marker's or a centre's offsets are vectors in its segment's frame
        if owner == segment:
            s.term_params[k] = s.term_params[k] @ R0.T
    return s


@pytest.fixture(scope="module", params=[("diagnose_leg.toml", 3), ("sparse_leg.toml", 5), ("sparse_leg.toml", 3),
                                        ("leg.toml", 3)])
def fitted(request):
    """`fit`'s own whole-tree fit of a simulated trial: three markers on every segment, and one on the thigh and
    shank (whose knee is placed relative to the thigh's marker and the hip's centre).

    The one-marker leg at seed 3 has its knee's weakest direction near the rank cutoff: scaled column by column,
    the information read 9e-9 of its largest eigenvalue there in the fit's own frames against the cutoff's 1e-9,
    and 8e-12 to 4e-11 in turned ones, so whether the knee counted as free depended on the frames. Scaled by the
    blocks a change of frames turns (:func:`identcheck.bundle.gauge.turning_blocks`), it reads the same in all of
    them."""
    name, seed = request.param
    model = Model.from_toml(EXAMPLES / name)
    trial = simulate(model, n_frames=600, noise_mm=0.7, seed=seed).trial
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        closed, _ = fit_model(model, trial)
        fit = fit_tree(model, trial, closed).best.fit
    data = trial.select(model.markers).as_array()
    return fit.chain, data, np.ones(data.shape[:2]), fit


def update_coordinates(chain, before, after) -> np.ndarray:
    """The constants' step (P,) in the fit's update coordinates (identcheck.bundle.model.apply_step) that takes
    state `before` to `after`, to first order: differences of the points, the rotation vector of a hinge's rest
    rotation's left turn, and the axis' change along its two tangents."""
    out = [(after.local - before.local).ravel()]
    for j in chain.joints:
        out += [after.c_parent[j] - before.c_parent[j], after.c_child[j] - before.c_child[j]]
        if chain.types[j] == "revolute":
            out.append(Rotation.from_matrix(after.rest[j] @ before.rest[j].T).as_rotvec())
            out.append([float(b @ (after.axis[j] - before.axis[j])) for b in tangents(before.axis[j])])
    return np.concatenate([np.ravel(x) for x in out])


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**16), st.data())
def test_every_move_of_a_segment_frame_lies_in_the_written_out_gauge(fitted, seed, data):
    """A small move of any segment's frame (turn ω, shift τ, any segment), carried out exactly on the fitted state,
    is a combination of the written-out gauge directions to first order; and the information annihilates each of
    them (to :data:`GAUGE_TOL` of its unit diagonal, the test `fit` applies before using them)."""
    chain, data_, w, fit = fitted
    B = gauge_basis(chain, fit.state, len(covariance(fit, data_, weights=w).information))
    assert B.shape[1] == chain.gauge()
    segment = data.draw(st.sampled_from(chain.segments))
    rng = np.random.default_rng(seed)
    eps = 1e-6
    omega, tau = rng.normal(size=3), rng.normal(size=3) * 100.0
    step = update_coordinates(chain, fit.state,
                              regauge(chain, fit.state, segment, Rotation.from_rotvec(eps * omega).as_matrix(),
                                      eps * tau)) / eps
    coef = np.linalg.lstsq(B, step, rcond=None)[0]
    assert np.linalg.norm(B @ coef - step) <= 1e-4 * np.linalg.norm(step)
    scaled, d = block_scaled(covariance(fit, data_, weights=w).information, turning_blocks(chain))
    N = np.linalg.qr(B * d[:, None])[0]
    assert np.max(np.abs(scaled @ N)) <= GAUGE_TOL


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.0, 3000.0), st.sampled_from([0, 1]))
def test_the_weakest_direction_does_not_depend_on_the_gauge(fitted, seed, offset_mm, which):
    """Under white noise (σ² times the information's gauge-free inverse) to the roundoff of the Schur complement
    (1e-3 relative; it was 3e-3 for the hip and 40 % for the one-marker thigh's knee); within 3 % with the sandwich,
    whose AR(1) prewhitening takes one coefficient from the median of the scores' components, and the components
    are the constants' coordinates. A centre the data leave free (the one-marker thigh's knee: its marker, the
    knee's axis and the shank's marker trade off along a direction the information does not determine) has no
    standard error in any gauge."""
    chain, data, w, fit = fitted
    joint = chain.joints[which]
    R0 = Rotation.random(random_state=seed).as_matrix()
    t0 = offset_mm * Rotation.random(random_state=seed + 1).apply([1.0, 0.0, 0.0])
    moved = replace(fit, state=regauge(chain, fit.state, chain.parent[joint], R0, t0))
    assert np.allclose(forward(chain, moved.terms, moved.state)[3], fit.pred, atol=1e-6)   # the same fit
    cov0, cov1 = covariance(fit, data, weights=w), covariance(moved, data, weights=w)
    for white in (True, False):
        c0, c1 = (replace(c, sandwich=c.naive) if white else c for c in (cov0, cov1))
        (d0, se0), (d1, se1) = weakest(chain, fit, c0, joint), weakest(chain, moved, c1, joint)
        assert abs(float(d1 @ (R0 @ d0))) == pytest.approx(1.0, abs=1e-4 if white else 1e-2)
        if se0 is None:
            assert se1 is None
        else:
            assert se1 == pytest.approx(se0, rel=1e-3 if white else 0.03)


@pytest.fixture(scope="module")
def with_terms():
    """A whole-chain fit carrying effect terms of the four kinds whose gauge is written out: a thigh marker's
    offset and the knee's centre offset following smooth functions of time, the knee's centre moving along its axis
    (a screw, 20 mm over the trial, in the data too: its fitted scalar is far from 0), and a world field on the ankle
    marker."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=400, noise_mm=0.7, seed=5)
    data = sim.trial.select(model.markers).as_array()
    chain = Skeleton.from_model(model)
    F = len(data)
    time = np.linspace(0.0, 1.0, F)
    smooth = np.stack([np.sin(2 * np.pi * time), np.cos(3 * np.pi * time)], axis=1)
    ankle = chain.labels.index("RANK")
    field = np.zeros((F, 1, 3))
    field[:, 0] = np.stack([time, time ** 2, np.sin(time)], axis=1) * 10.0
    data[:, chain.downstream["knee"]] += (20.0 * (time - 0.5))[:, None, None] * sim.truth.axis_world("knee")[:, None]
    terms = Terms(markers=[(chain.labels.index("RTHI"), smooth)], centres=[("knee", smooth[:, :1])],
                  screws=[("knee", time - time.mean())], world=[(np.array([ankle]), field)])
    w = np.ones(data.shape[:2])
    rigid = fit_chain(chain, data, initial_state(chain, data), weights=w)
    start = rigid.state.copy()
    start.term_params = [np.zeros(shape) for shape in terms.shapes()]
    return chain, data, w, fit_chain(chain, data, start, terms=terms, weights=w), terms


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.0, 1000.0))
def test_effect_terms_turn_with_their_segment_in_the_written_out_gauge(with_terms, seed, offset_mm):
    """With marker, centre, screw and world terms: a move of any segment's frame lies in the written-out gauge,
    which the information annihilates, and the weakest direction's standard error is the same in the moved frame
    (under white noise, to 1e-3)."""
    chain, data, w, fit, terms = with_terms
    assert abs(float(fit.state.term_params[terms.screws_start()][0])) > 10.0      # the screw is fitted (20 mm)
    cov = covariance(fit, data, weights=w)
    B = gauge_basis(chain, fit.state, len(cov.information), terms)
    assert B is not None and B.shape[1] == chain.gauge()
    rng = np.random.default_rng(seed)
    segment = chain.segments[seed % len(chain.segments)]
    eps = 1e-6
    small = regauge(chain, fit.state, segment, Rotation.from_rotvec(eps * rng.normal(size=3)).as_matrix(),
                    eps * rng.normal(size=3) * 100.0, terms)
    step = np.concatenate([update_coordinates(chain, fit.state, small)]
                          + [(b - a).ravel() for a, b in zip(fit.state.term_params, small.term_params)]) / eps
    coef = np.linalg.lstsq(B, step, rcond=None)[0]
    assert np.linalg.norm(B @ coef - step) <= 1e-4 * np.linalg.norm(step)
    scaled, d = block_scaled(cov.information, turning_blocks(chain, terms))
    assert np.max(np.abs(scaled @ np.linalg.qr(B * d[:, None])[0])) <= GAUGE_TOL
    joint = chain.joints[seed % 2]
    R0 = Rotation.random(random_state=seed).as_matrix()
    t0 = offset_mm * Rotation.random(random_state=seed + 1).apply([1.0, 0.0, 0.0])
    moved = replace(fit, state=regauge(chain, fit.state, chain.parent[joint], R0, t0, terms))
    assert np.allclose(forward(chain, terms, moved.state)[3], fit.pred, atol=1e-6)
    c0, c1 = cov, covariance(moved, data, weights=w)
    (d0, se0), (d1, se1) = (weakest(chain, f, replace(c, sandwich=c.naive), joint) for f, c in ((fit, c0), (moved, c1)))
    assert se1 == pytest.approx(se0, rel=1e-3)
    assert abs(float(d1 @ (R0 @ d0))) == pytest.approx(1.0, abs=1e-4)


@settings(max_examples=5, deadline=None)
@given(st.integers(0, 2**16), st.floats(0.0, 300.0))
def test_whether_a_direction_is_free_does_not_depend_on_the_gauge(fitted, seed, offset_mm):
    """Every segment's frame moved (up to 300 mm) and turned at random, the same fit: the information scaled by the
    blocks a change of frames turns has the same spectrum beyond the gauge (each eigenvalue above 1e-8 of the largest
    to 1e-3 relative: the frames' ridge and the Schur complement's roundoff move them by up to 1e-4 for a frame moved
    by a metre; scaled column by column they move by factors), and the inverse leaves out as many directions."""
    chain, data, w, fit = fitted
    rng = np.random.default_rng(seed)
    state = fit.state
    for segment in chain.segments:
        state = regauge(chain, state, segment, Rotation.random(random_state=rng.integers(2**31)).as_matrix(),
                        offset_mm * rng.normal(size=3) / np.sqrt(3))
    moved = replace(fit, state=state)
    assert np.allclose(forward(chain, moved.terms, moved.state)[3], fit.pred, atol=1e-6)   # the same fit

    def spectrum(f):
        S = covariance(f, data, weights=w).information
        scaled, d = block_scaled(S, turning_blocks(chain))
        N = np.linalg.qr(gauge_basis(chain, f.state, len(S)) * d[:, None])[0]
        rest = np.linalg.svd(N, full_matrices=True)[0][:, N.shape[1]:]
        vals = np.linalg.eigvalsh(rest.T @ scaled @ rest)
        return vals / vals.max(), chain_inverse(chain, f.state, S)[1]
    (v0, free0), (v1, free1) = spectrum(fit), spectrum(moved)
    strong = v0 > 1e-8
    assert np.array_equal(strong, v1 > 1e-8)
    assert np.allclose(v1[strong], v0[strong], rtol=1e-3)
    assert free0 == free1


def test_scaling_blocks_must_cover_every_column_once():
    """Blocks that leave a column out or take one twice are refused (a column left out would keep an unset scale)."""
    S = np.eye(4)
    assert np.allclose(block_scaled(S, [np.array([0, 1]), np.array([2, 3])])[0], S)
    for bad in ([np.array([0, 1]), np.array([1, 2])], [np.array([0, 1, 2])], [np.array([0, 1, 2, 3]), np.array([3])]):
        with pytest.raises(ValueError, match="cover"):
            block_scaled(S, bad)
