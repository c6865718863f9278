"""Seed 001: ball-joint centre from two rigid clusters, its covariance, noise and validation index."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import Phase, assume, given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.geometry.poses import refine_local
from identcheck.estimate.seed001 import (EXPECTED_MEAN_V, CentreFit, centre_eq9, fit_centre, fit_joint,
                                    marker_noise, validation_index)
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


# ---------------------------------------------------------------------- synthetic ball joints
class Joint:
    """A random ball joint: clusters, true centres in both body frames, world motion."""

    def __init__(self, rng, c0, c1, rom_deg=40.0, m=(3, 3), n_axes=3, lever=400.0, spread=70.0):
        self.c0, self.c1 = np.asarray(c0, float), np.asarray(c1, float)
        self.x0 = self._cluster(rng, self.c0, m[0], lever, spread)
        self.x1 = self._cluster(rng, self.c1, m[1], lever, spread)
        self.rng, self.rom, self.n_axes = rng, np.deg2rad(rom_deg), n_axes
        self.axes = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()[:, :n_axes]
        self.freq = rng.uniform(0.5, 2.0, (3, 3))
        self.phase = rng.uniform(0, 2 * np.pi, (3, 3))
        self.rest = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
        self.root = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()

    @staticmethod
    def _cluster(rng, c, m, lever, spread):
        direction = rng.normal(size=3)
        centroid = c + lever * direction / np.linalg.norm(direction)
        while True:
            x = centroid + rng.normal(0, spread, (m, 3))
            if np.linalg.svd(x - x.mean(0), compute_uv=False)[1] > 0.3 * spread:
                return x

    def poses(self, n):
        """World-from-body rotations and translations of parent and child, n frames over 4 s."""
        t = np.linspace(0, 4, n)[:, None, None]
        s = np.sin(2 * np.pi * self.freq * t + self.phase).sum(axis=2) / 3          # (n, 3)
        omega = self.rom * s[:, :self.n_axes] @ self.axes.T
        rel = Rotation.from_rotvec(omega).as_matrix() @ self.rest                   # parent-from-child
        root = Rotation.from_rotvec(0.2 * s[:, ::-1]).as_matrix() @ self.root
        d0 = 300 * s + np.array([0, 0, 900.0])
        R0, R1 = root, root @ rel
        d1 = np.einsum("fij,fj->fi", R0, self.c0 - np.einsum("fij,j->fi", rel, self.c1)) + d0
        return R0, d0, R1, d1

    def markers(self, n, noise=0.0, rng=None):
        R0, d0, R1, d1 = self.poses(n)
        y0 = np.einsum("fij,mj->fmi", R0, self.x0) + d0[:, None]
        y1 = np.einsum("fij,mj->fmi", R1, self.x1) + d1[:, None]
        if noise:
            rng = rng or self.rng
            y0, y1 = y0 + rng.normal(0, noise, y0.shape), y1 + rng.normal(0, noise, y1.shape)
        return y0, y1


coord = st.floats(-150, 150)
centres = st.tuples(st.lists(coord, min_size=3, max_size=3), st.lists(coord, min_size=3, max_size=3))
seeds = st.integers(0, 2**32 - 1)


def quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


# ---------------------------------------------------------------------- exact recovery
@given(seeds, centres, st.integers(3, 5), st.integers(3, 5), st.floats(10, 90))
def test_exact_centre_on_noise_free_data(seed, cc, m0, m1, rom):
    """Noise-free markers, random centres, clusters and motion: both methods return the true
    centre (moved into the true body frames), and the world centres from both segments agree."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, rom_deg=rom, m=(m0, m1))
    y0, y1 = joint.markers(40)
    for method in ("pair", "paper"):
        fit = fit_centre(y0, y1, noise_mm=0.0, method=method)
        c, W = fit.in_frame(joint.x0)
        np.testing.assert_allclose(c, joint.c0, atol=1e-6)
        assert np.all(W == 0) and fit.rms_residual < 1e-6
        world1 = fit.child.to_world(fit.centre_child[None])[:, 0]
        np.testing.assert_allclose(fit.centre_world(), world1, atol=1e-6)


@given(seeds, centres)
def test_eq9_is_the_least_squares_of_eq6(seed, cc):
    """Eq. (9) is the normal equation of eq. (6): it equals a direct least-squares solve of the
    stacked rows (R0 − R1) c = d1 − d0, on noisy poses too."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc)
    y0, y1 = joint.markers(30, noise=1.0)
    _, p0 = refine_local(y0, ref_frame=0)
    _, p1 = refine_local(y1, ref_frame=0)
    c = centre_eq9(p0, p1)
    rows = (p0.R - p1.R).reshape(-1, 3)
    rhs = (p1.t - p0.t).reshape(-1)
    np.testing.assert_allclose(c, np.linalg.lstsq(rows, rhs, rcond=None)[0], rtol=1e-8, atol=1e-6)
    y0, y1 = joint.markers(30)                          # noise-free: the world centre at frame 0
    _, p0 = refine_local(y0, ref_frame=0)
    _, p1 = refine_local(y1, ref_frame=0)
    R0, d0 = joint.poses(30)[:2]
    np.testing.assert_allclose(centre_eq9(p0, p1), R0[0] @ joint.c0 + d0[0], atol=1e-6)


# ---------------------------------------------------------------------- covariance
MONTE_CARLO = settings(max_examples=3, deadline=None, phases=[Phase.explicit, Phase.reuse, Phase.generate])
"""Few examples and no shrinking: each example is a Monte-Carlo run of a hundred fits."""


@pytest.mark.slow
@MONTE_CARLO
@given(seeds, centres, st.floats(0.3, 1.5))
def test_covariance_matches_monte_carlo_scatter(seed, cc, noise):
    """Same joint and motion, fresh noise each repeat: when the motion passes the excitation
    check, the errors' Mahalanobis distances under the predicted covariance average 3 (χ²₃),
    and the predicted and empirical covariances agree along every direction to within sampling
    error. A covariance off by 30% (in variance) fails."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, rom_deg=30)
    assume(fit_centre(*joint.markers(150, noise=noise, rng=rng), noise_mm=noise, warn=False).excitation_ok)
    n_rep = 120
    errs, covs = [], []
    for _ in range(n_rep):
        y0, y1 = joint.markers(150, noise=noise, rng=rng)
        c, W = fit_centre(y0, y1, noise_mm=noise).in_frame(joint.x0)
        errs.append(c - joint.c0)
        covs.append(W)
    errs, W = np.array(errs), np.mean(covs, axis=0)
    e = np.einsum("ri,ij,rj->r", errs, np.linalg.inv(W), errs)
    assert abs(e.mean() - 3) < 3 * np.sqrt(6 / n_rep)              # sd of the mean of χ²₃ is √(6/n)
    ratio = np.linalg.eigvalsh(np.linalg.solve(W, np.cov(errs.T)))
    assert 0.6 < ratio.min() and ratio.max() < 1.5


@pytest.mark.slow
def test_bias_correction_removes_the_sigma2_bias():
    """At high noise on a long trial the uncorrected Gauss–Markov centre is off by several of
    its standard errors (bias ∝ σ², not shrinking with frames); the corrected one is not."""
    rng = np.random.default_rng(7)
    joint = Joint(rng, [20, -40, 10], [-30, 10, 50], rom_deg=25)
    out = {True: [], False: []}
    for _ in range(30):
        y0, y1 = joint.markers(400, noise=3.0, rng=rng)
        for bc in out:
            out[bc].append(fit_centre(y0, y1, noise_mm=3.0, bias_correction=bc).in_frame(joint.x0)[0] - joint.c0)
    z = {bc: np.abs(np.mean(e, 0)) / (np.std(e, 0) / np.sqrt(len(e))) for bc, e in out.items()}
    assert z[False].max() > 6
    assert z[True].max() < 3.5


def test_chi2_and_autocorrelation_white_noise():
    """White noise of the stated size: χ²/dof ≈ 1 and no serial correlation, no warning."""
    rng = np.random.default_rng(3)
    joint = Joint(rng, [0, 0, 0], [10, 20, 30])
    y0, y1 = joint.markers(400, noise=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = fit_centre(y0, y1, noise_mm=1.0)
    assert abs(fit.chi2_dof - 1) < 0.15
    assert abs(fit.residual_autocorr) < 4 / np.sqrt(3 * 400)
    assert fit.covariance_inflation == 1.0


@settings(max_examples=5, deadline=None, phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(seeds, st.floats(0.4, 0.85))
def test_serially_correlated_noise_is_detected(seed, rho):
    """AR(1) marker noise: the whitened residuals' lag-1 autocorrelation estimates ρ, "white"
    warns, and "ar1" inflates the covariance by (1 + ρ̂)/(1 − ρ̂)."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, [0, 0, 0], [10, 20, 30])
    y0, y1 = joint.markers(600)
    y = np.concatenate([y0, y1], axis=1)
    y = y + lfilter([np.sqrt(1 - rho**2)], [1, -rho], rng.normal(0, 1.0, y.shape), axis=0)
    with pytest.warns(UserWarning, match="lag-1 autocorrelation"):
        white = fit_centre(y[:, :3], y[:, 3:], noise_mm=1.0)
    assert abs(white.residual_autocorr - rho) < 0.1
    ar1 = fit_centre(y[:, :3], y[:, 3:], noise_mm=1.0, serial="ar1")
    k = (1 + ar1.residual_autocorr) / (1 - ar1.residual_autocorr)
    np.testing.assert_allclose(ar1.covariance, white.covariance * k, rtol=1e-9)


# ---------------------------------------------------------------------- degenerate motion
@given(seeds, centres)
def test_single_axis_noise_free_raises(seed, cc):
    """Rotation about one fixed axis, no noise: the centre is free along the axis → DegenerateError
    naming that axis (in the parent frame)."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, n_axes=1)
    y0, y1 = joint.markers(50)
    with pytest.raises(DegenerateError, match="free along") as info:
        quiet(fit_centre, y0, y1, noise_mm=0.0)
    # the reported direction (parent body frame = world at frame 0) is the hinge axis
    R0 = joint.poses(50)[0][0]
    free = np.array(eval(str(info.value).split("free along ")[1].split(" in the")[0]))
    assert abs(free / np.linalg.norm(free) @ (R0 @ joint.axes[:, 0])) > 0.99


@given(seeds, centres)
def test_single_axis_noisy_is_not_determined_along_the_axis(seed, cc):
    """Rotation about one axis with noise: the off-axis "excitation" is pose noise, the
    information fraction says so, IdentifiabilityWarning, infinite uncertainty, and the
    direction reported is the hinge axis."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, n_axes=1)
    y0, y1 = joint.markers(100, noise=0.5)
    with pytest.warns(IdentifiabilityWarning, match="not determined along"):
        fit = fit_centre(y0, y1, noise_mm=0.5)
    assert not fit.excitation_ok and fit.information_fraction < 0.25
    assert fit.uncertainty_mm == np.inf and fit.rms_uncertainty_mm == np.inf
    R0 = joint.poses(100)[0][0]
    assert abs(fit.weakest_direction @ (R0 @ joint.axes[:, 0])) > 0.95
    assert np.isnan(fit.validation_index(joint.c0, joint.x0))


@settings(max_examples=10, deadline=None)
@given(seeds, centres, st.floats(0.3, 1.0))
def test_well_excited_motion_has_real_information(seed, cc, noise):
    """Rotation about three axes over tens of degrees: nearly all information is real."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, rom_deg=40)
    y0, y1 = joint.markers(100, noise=noise)
    fit = fit_centre(y0, y1, noise_mm=noise)
    assert fit.excitation_ok and fit.information_fraction > 0.8 and np.isfinite(fit.uncertainty_mm)


def test_no_motion_raises():
    rng = np.random.default_rng(0)
    joint = Joint(rng, [0, 0, 0], [0, 0, 0], rom_deg=0.0)
    y0, y1 = joint.markers(20)
    with pytest.raises(DegenerateError, match="does not determine the centre"):
        quiet(fit_centre, y0, y1, noise_mm=0.0)


# ---------------------------------------------------------------------- noise (section 8)
@settings(max_examples=10)
@given(seeds, st.floats(0.2, 3.0), st.integers(3, 5))
def test_marker_noise_recovers_sigma(seed, sigma, m):
    """Distances within a rigid cluster scatter by σ√2: the estimate is within 10% of σ with
    2 × 3 pairs × 500 frames, and within 15% with 5% of the samples grossly wrong."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, [0, 0, 0], [0, 0, 0], m=(m, 3))
    y0, y1 = joint.markers(500, noise=sigma)
    est = marker_noise(y0, y1)
    assert abs(est.noise_mm / sigma - 1) < 0.1
    assert est.n_pairs == m * (m - 1) // 2 + 3
    assert est.distance_sd_mm == pytest.approx(est.noise_mm * np.sqrt(2))
    bad = rng.random(y0.shape[:2]) < 0.05
    y0 = y0.copy()
    y0[bad] += rng.normal(0, 50 * sigma, (bad.sum(), 3))
    y0[rng.random(y0.shape[:2]) < 0.1] = np.nan                      # gaps too
    assert abs(marker_noise(y0, y1).noise_mm / sigma - 1) < 0.15


def test_marker_noise_bad_input():
    with pytest.raises(InputError, match="cannot be estimated"):
        marker_noise(np.zeros((10, 1, 3)))
    with pytest.raises(InputError, match="expected shape"):
        marker_noise(np.zeros((10, 3)))


# ---------------------------------------------------------------------- validation index
def test_expected_mean_validation_index_is_not_one():
    """E[sqrt(χ²₃/3)] = 2√2/√(3π) ≈ 0.921 (seed 001 says the expected value is 1); E[v²] = 1."""
    rng = np.random.default_rng(0)
    W = np.diag([1.0, 4.0, 9.0])
    d = rng.multivariate_normal(np.zeros(3), W, 200_000)
    v = np.sqrt(np.einsum("ri,ij,rj->r", d, np.linalg.inv(W), d) / 3)
    assert EXPECTED_MEAN_V == pytest.approx(0.9213, abs=1e-4)
    assert v.mean() == pytest.approx(EXPECTED_MEAN_V, abs=3e-3)
    assert (v**2).mean() == pytest.approx(1.0, abs=0.01)
    assert validation_index(d[0], np.zeros(3), W) == pytest.approx(v[0])
    assert validation_index(np.ones(3), np.ones(3), W) == 0.0


@given(seeds)
def test_validation_index_is_frame_independent(seed):
    """Moving the truth (centre and parent markers) by any rigid motion leaves v unchanged."""
    rng = np.random.default_rng(seed)
    joint = Joint(rng, [10, 0, -20], [0, 30, 0])
    y0, y1 = joint.markers(60, noise=1.0)
    fit = fit_centre(y0, y1, noise_mm=1.0)
    v = fit.validation_index(joint.c0, joint.x0)
    G = Rotation.random(random_state=seed % (1 << 31)).as_matrix()
    g = rng.uniform(-1000, 1000, 3)
    assert fit.validation_index(G @ joint.c0 + g, joint.x0 @ G.T + g) == pytest.approx(v, rel=1e-6)
    # in the fit's own frame (no markers given) it is the same number
    c, _ = fit.in_frame(fit.parent_local)
    np.testing.assert_allclose(c, fit.centre_parent, atol=1e-9)


# ---------------------------------------------------------------------- result and methods
def test_paper_method_shares_one_point_and_result_fields():
    rng = np.random.default_rng(5)
    joint = Joint(rng, [0, 0, 0], [5, 5, 5])
    y0, y1 = joint.markers(80, noise=0.5)
    with pytest.warns(UserWarning, match="lag-1 autocorrelation"):     # its frame-0 bias shows
        fit = fit_centre(y0, y1, method="paper", bias_correction=False)
    np.testing.assert_array_equal(fit.centre_parent, fit.centre_child)
    np.testing.assert_array_equal(fit.covariance_full[:3, :3], fit.covariance_full[3:, 3:])
    assert isinstance(fit, CentreFit) and fit.noise_estimated and fit.n_frames == 80
    assert fit.uncertainty_mm == pytest.approx(np.sqrt(np.linalg.eigvalsh(fit.covariance)[-1]))
    assert fit.rms_uncertainty_mm == pytest.approx(np.sqrt(np.trace(fit.covariance)))
    d = fit.marker_distances(["A", "B", "C"])
    assert list(d)[:3] == ["A", "B", "C"] and len(d) == 6
    np.testing.assert_allclose(list(d.values())[:3], np.linalg.norm(joint.x0 - joint.c0, axis=1), rtol=0.02)


def test_gaps_and_frames_used():
    rng = np.random.default_rng(11)
    joint = Joint(rng, [0, 0, 0], [5, 5, 5], m=(4, 3))
    y0, y1 = joint.markers(100, noise=0.5)
    y0[10:20, 0] = np.nan                          # three left: still a pose
    y1[30:35, 1] = np.nan                          # two left: frames dropped
    fit = fit_centre(y0, y1, noise_mm=0.5)
    assert fit.n_frames == 95 and not np.isin(np.arange(30, 35), fit.frames).any()
    assert fit.validation_index(joint.c0, joint.x0) < 4


# ---------------------------------------------------------------------- bad input
def test_bad_input_is_named():
    rng = np.random.default_rng(2)
    y0, y1 = Joint(rng, [0, 0, 0], [0, 0, 0]).markers(20, noise=0.5)
    with pytest.raises(InputError, match="parent segment has 2 marker"):
        fit_centre(y0[:, :2], y1)
    with pytest.raises(InputError, match="child points are NaN in every frame"):
        fit_centre(y0, np.full_like(y1, np.nan))
    with pytest.raises(InputError, match="parent has 20 frames, child 10"):
        fit_centre(y0, y1[:10])
    with pytest.raises(InputError) as info:
        fit_centre(y0, y1, method="magic", noise_mm=-1.0, serial="pink")
    assert len(info.value.problems) == 3
    few = y1.copy()
    few[2:, 0] = np.nan
    with pytest.raises(InputError, match="only 2 frame"):
        fit_centre(y0, few)


def test_fit_joint_from_model_and_trial():
    model = Model.from_toml(EXAMPLES / "hip_s22.toml")
    sim = simulate(model, n_frames=300, noise_mm=0.5, seed=2)
    fit = quiet(fit_joint, sim.trial, model, "hip_r")
    truth = sim.truth
    local = np.array(list(truth.segments["pelvis"].marker_local.values()))
    assert fit.validation_index(truth.joints["hip_r"].centre_parent, local) < 4
    assert abs(fit.noise_mm - 0.5) < 0.1
    with pytest.raises(InputError, match="has 1 marker"):
        fit_joint(sim.trial, Model.from_toml(EXAMPLES / "hip_31.toml"), "hip_r")
    with pytest.raises(InputError, match="no joint 'knee'"):
        fit_joint(sim.trial, model, "knee")
    with pytest.raises(InputError, match="revolute"):
        fit_joint(sim.trial, Model.from_toml(EXAMPLES / "knee_21.toml"), "knee_r")


# ---------------------------------------------------------------------- the O(σ²) terms
@MONTE_CARLO
@given(seeds, centres)
def test_second_order_terms_match_monte_carlo(seed, cc):
    """The expected noise terms the corrections remove, checked against Monte-Carlo means
    (true body-fixed coordinates, weights at the truth, 3 mm noise so O(σ²) stands out):
    E[ψ(a_true)] = Σ E[δMᵀ G r] + Σ Mᵀ G E[r] (_bias_term) and E[A] − A_clean = N
    (_noise_information)."""
    from identcheck.estimate import seed001 as S
    from identcheck.geometry.poses import segment_poses

    rng = np.random.default_rng(seed)
    joint = Joint(rng, *cc, rom_deg=30)
    n, noise, reps = 40, 3.0, 400
    a_true = np.r_[joint.c0, joint.c1]
    y0, y1 = joint.markers(n)
    p0, p1 = segment_poses(y0, joint.x0), segment_poses(y1, joint.x1)
    g0 = S._cluster_geometry(joint.x0, np.ones((n, len(joint.x0)), bool))
    g1 = S._cluster_geometry(joint.x1, np.ones((n, len(joint.x1)), bool))
    Wi = np.linalg.inv(S._prediction_covariance(p0.R, joint.c0, g0) + S._prediction_covariance(p1.R, joint.c1, g1))
    M, _ = S._design(p0.R, p1.R, p0.t, p1.t, "pair")
    A_clean = np.einsum("fki,fkl,flj->ij", M, Wi, M)
    eiv, mean_r = S._bias_term(p0.R, p1.R, joint.c0, joint.c1, g0, g1, Wi, noise**2, "pair")
    psi_pred = eiv + np.einsum("fki,fkl,fl->i", M, Wi, mean_r)
    N_pred = S._noise_information(p0.R, p1.R, g0, g1, Wi, noise**2, "pair")
    psi, A = [], []
    for _ in range(reps):
        q0 = segment_poses(y0 + rng.normal(0, noise, y0.shape), joint.x0)
        q1 = segment_poses(y1 + rng.normal(0, noise, y1.shape), joint.x1)
        Mn, yn = S._design(q0.R, q1.R, q0.t, q1.t, "pair")
        psi.append(np.einsum("fki,fkl,fl->i", Mn, Wi, Mn @ a_true - yn))
        A.append(np.einsum("fki,fkl,flj->ij", Mn, Wi, Mn))
    psi, A = np.array(psi), np.array(A)
    se = psi.std(axis=0) / np.sqrt(reps)
    assert np.all(np.abs(psi.mean(axis=0) - psi_pred) < 4 * se + 0.05 * np.abs(psi_pred))
    assert np.abs(psi_pred).max() > 4 * se.max()                 # the term is really there
    dA = A.mean(axis=0) - A_clean
    np.testing.assert_allclose(dA, N_pred, atol=4 * A.std(axis=0).max() / np.sqrt(reps) + 0.1 * np.abs(N_pred).max())


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), F=st.integers(1, 7))
def test_skew_sandwich_is_the_expectation_it_stands_for(seed, F):
    """``Σ_kn Σφ_kn K_kᵀ G K_n`` against its definition written as one contraction, on random covariances and
    weights; and for a single φ (Σφ = φφᵀ) it is ``[φ]×ᵀ G [φ]×`` itself."""
    from identcheck.estimate.seed001 import _SKEW_BASIS, _skew_sandwich
    from identcheck.geometry.rotations import skew
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(F, 3, 3))
    Sphi, G = X @ np.swapaxes(X, 1, 2), rng.normal(size=(F, 3, 3))
    want = np.einsum("fkn,kji,fjm,nml->fil", Sphi, _SKEW_BASIS, G, _SKEW_BASIS)
    np.testing.assert_allclose(_skew_sandwich(Sphi, G), want, atol=1e-12 * (1 + np.abs(want).max()))
    phi = rng.normal(size=(F, 3))
    cross = skew(phi)
    np.testing.assert_allclose(_skew_sandwich(phi[:, :, None] * phi[:, None, :], G),
                               np.swapaxes(cross, 1, 2) @ G @ cross, atol=1e-12 * (1 + np.abs(G).max() * 9))
