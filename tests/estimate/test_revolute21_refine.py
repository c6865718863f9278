"""The revolute (2,1) least squares solved through the arrow form of its normal equations
(:func:`identcheck.estimate.revolute21._refine`): the eliminated samples' angles give exactly the dense solution,
and the refinement reaches the least squares' minimum."""
import numpy as np
from hypothesis import given, settings, strategies as st

from identcheck.estimate import revolute21 as r21
from strategies import revolute21_problem, revolute21_samples


def _dense_jacobian(x, R, z):
    """The residuals' whole Jacobian (2N × (5 + N)), written out: the reference the arrow form is checked against."""
    _, Jp, jb1, jb2 = r21._odr_parts(x, R, z)
    N = len(R)
    J = np.zeros((2 * N, 5 + N))
    J[:, :5] = Jp
    J[np.arange(N), 5 + np.arange(N)] = jb1
    J[N + np.arange(N), 5 + np.arange(N)] = jb2
    return J


def _problem(truth, seed, n=40, noise=0.3):
    rng = np.random.default_rng(seed)
    theta, beta = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    local = revolute21_samples(truth, theta, beta) + rng.normal(scale=noise, size=(n, 3))
    return np.hypot(local[:, 0], local[:, 1]), local[:, 2]


@settings(max_examples=30, deadline=None)
@given(revolute21_problem(), st.integers(0, 2**16), st.floats(1e-4, 1e2))
def test_the_arrow_form_gives_the_dense_damped_step(problem, seed, lam):
    """The constants' step from the Schur complement, and each β's from it, solve the whole damped system
    (JᵀJ + λ diag) δ = −Jᵀr written out densely."""
    truth, _ = problem
    R, z = _problem(truth, seed)
    start = truth + np.random.default_rng(seed + 1).normal(scale=[3, 3, 0.05, 3, 3])
    x = np.r_[start, r21._nearest_beta(start, R, z)]
    r, Jp, jb1, jb2 = r21._odr_parts(x, R, z)
    A, B, D, gp, gb = r21._normal_pieces(Jp, jb1, jb2, r)
    J = _dense_jacobian(x, R, z)
    np.testing.assert_allclose(J.T @ J, np.block([[A, B.T], [B, np.diag(D)]]),       # B[i]: sample i's coupling
                               rtol=1e-9, atol=1e-9 * np.abs(J.T @ J).max())
    np.testing.assert_allclose(J.T @ r, np.r_[gp, gb], rtol=1e-9, atol=1e-9 * np.abs(J.T @ r).max())
    scale = np.r_[np.diag(A), D] + 1e-3
    dp, db = r21._damped_step((A, B, D, gp, gb), lam * scale[:5], lam * scale[5:])
    dense = np.linalg.solve(J.T @ J + lam * np.diag(scale), -J.T @ r)
    np.testing.assert_allclose(np.r_[dp, db], dense, rtol=1e-6, atol=1e-8 * np.abs(dense).max())


@settings(max_examples=30, deadline=None)
@given(revolute21_problem(), st.integers(0, 2**16))
def test_the_uncertainty_is_the_dense_covariance_of_the_lengths(problem, seed):
    """The 1-σ from the eliminated angles equals the one read off the dense inverse of JᵀJ (its constants' block)."""
    truth, _ = problem
    R, z = _problem(truth, seed)
    x = np.r_[truth, r21._nearest_beta(truth, R, z)]
    r, Jp, jb1, jb2 = r21._odr_parts(x, R, z)
    J = _dense_jacobian(x, R, z)
    info = J.T @ J
    if np.linalg.cond(info) > 1e12:
        return
    N = len(R)
    cov = np.sum(r**2) / max(N - 5, 1) * np.linalg.inv(info)[:5, :5]
    lengths = cov[np.ix_([0, 1, 3, 4], [0, 1, 3, 4])]
    expected = np.sqrt(max(np.linalg.eigvalsh(lengths)[-1], 0.0))
    assert np.isclose(r21._uncertainty(Jp, jb1, jb2, r, np.sqrt(np.mean(R**2 + z**2))), expected, rtol=1e-6)


@settings(max_examples=25, deadline=None)
@given(revolute21_problem(), st.integers(0, 2**16))
def test_a_refinement_from_near_the_truth_reaches_a_minimum_at_least_as_good(problem, seed):
    """Noisy samples, a start a few mm and degrees off the truth: the refinement ends where the gradient of the
    least squares vanishes (to 1e-6 of its size at the start) with a cost no higher than the truth's own best."""
    truth, _ = problem
    R, z = _problem(truth, seed, n=120, noise=0.2)
    start = truth + np.random.default_rng(seed + 1).normal(scale=[2, 2, 0.02, 2, 2])
    x0 = np.r_[start, r21._nearest_beta(start, R, z)]
    x, r, Jp, jb1, jb2 = r21._refine(x0, R, z, max_nfev=400)
    _, _, _, gp, gb = r21._normal_pieces(Jp, jb1, jb2, r)
    r0, Jp0, jb10, jb20 = r21._odr_parts(x0, R, z)
    _, _, _, gp0, gb0 = r21._normal_pieces(Jp0, jb10, jb20, r0)
    assert np.linalg.norm(np.r_[gp, gb]) <= 1e-6 * np.linalg.norm(np.r_[gp0, gb0]) + 1e-9
    at_truth = np.sum(r21.residuals(truth, R, z) ** 2)
    assert np.sum(r**2) <= at_truth * (1 + 1e-9)
    assert np.sum(r21.residuals(r21.canonical(x[:5]), R, z) ** 2) <= np.sum(r**2) * (1 + 1e-9)


@settings(max_examples=25, deadline=None)
@given(revolute21_problem(), st.integers(0, 2**16), st.floats(0.05, 1.5))
def test_a_refinement_never_ends_above_its_start(problem, seed, spread):
    """From starts far off (up to 1.5 times the constants' own size), the end point's cost is at most the start's."""
    truth, _ = problem
    R, z = _problem(truth, seed, n=80, noise=0.5)
    rng = np.random.default_rng(seed + 2)
    start = r21.canonical(truth * (1 + rng.normal(scale=spread, size=5)))
    start = np.clip(start, [-np.inf, 1e-3, 1e-3, -np.inf, 1e-3], [np.inf, np.inf, np.pi - 1e-3, np.inf, np.inf])
    x0 = np.r_[start, r21._nearest_beta(start, R, z)]
    r0 = r21._odr_parts(x0, R, z)[0]
    _, r, _, _, _ = r21._refine(x0, R, z, max_nfev=60)
    assert np.all(np.isfinite(r)) and r @ r <= r0 @ r0


def _narrow(seed: int):
    """A noisy (2,1) problem whose hinge angle sweeps a narrow range (a long, flat valley of joints), as in gait."""
    rng = np.random.default_rng(seed)
    n = int(rng.choice([50, 100, 200, 400]))
    noise = float(rng.uniform(0.1, 1.5))
    truth = np.array([rng.uniform(-200, 200), rng.uniform(10, 200), rng.uniform(0.3, np.pi - 0.3),
                      rng.uniform(-200, 200), rng.uniform(30, 200)])
    beta = rng.uniform(-np.pi, np.pi) + rng.uniform(0.8, 2.0) * (0.5 + 0.5 * np.sin(np.linspace(0, 12, n)))
    theta = rng.uniform(-np.pi, np.pi) + rng.uniform(0.3, 1.5) * np.sin(np.linspace(0, 7, n) + 1)
    local = revolute21_samples(truth, theta, beta) + rng.normal(scale=noise, size=(n, 3))
    return np.hypot(local[:, 0], local[:, 1]), local[:, 2]


def test_a_flat_valley_is_crossed_as_fast_as_minpack_crosses_it():
    """A start from the closed form in a flat valley (200 samples, 1.4 mm noise): a damping scaled by the current
    diagonal had crawled there (cost 46 359 after 400 evaluations, where MINPACK's Levenberg-Marquardt reaches 194
    within 100). With MINPACK's running maximum it does at least as well as MINPACK on the same budget."""
    from scipy.optimize import least_squares

    R, z = _narrow(19)
    start = np.array([-114.765, 2.003, 0.588, 210.657, 42.235])
    x0 = np.r_[start, r21._nearest_beta(start, R, z)]
    _, r, _, _, _ = r21._refine(x0, R, z, max_nfev=100)
    reference = least_squares(lambda x: r21._odr_parts(x, R, z)[0], x0, jac=lambda x: _dense_jacobian(x, R, z),
                              method="lm", x_scale="jac", max_nfev=100)
    assert r @ r / 2 <= reference.cost * 1.001


def test_the_uncertainty_in_a_flat_valley_is_the_jacobians_own_and_stable():
    """At the best joint of a narrow sweep (condition of JᵀJ beyond 10¹⁵), the 1-σ is the one the whole Jacobian's
    SVD gives (within 1 %), and moving the point by 10⁻¹⁰ of itself does not change it by more than 1 %: forming and
    inverting the Schur complement had given 0.7 mm there, and 10⁶ mm after such a move."""
    R, z = _narrow(17)
    local_scale = np.sqrt(np.mean(R**2 + z**2))
    best = r21.fit(np.c_[R, np.zeros_like(R), z])[0][0]
    x = r21._refine(np.r_[best, r21._nearest_beta(best, R, z)], R, z, max_nfev=400)[0]
    values = []
    for k in range(4):
        moved = x * (1 + 1e-10 * np.random.default_rng(k).normal(size=len(x))) if k else x
        r, Jp, jb1, jb2 = r21._odr_parts(moved, R, z)
        values.append(r21._uncertainty(Jp, jb1, jb2, r, local_scale))
    J = _dense_jacobian(x, R, z)
    r = r21._odr_parts(x, R, z)[0]
    _, sv, Vt = np.linalg.svd(J / np.linalg.norm(J, axis=0), full_matrices=False)
    cov = (r @ r) / (len(R) - 5) * ((Vt.T / sv**2) @ Vt) / np.outer(*[np.linalg.norm(J, axis=0)] * 2)
    lengths = cov[:5, :5][np.ix_([0, 1, 3, 4], [0, 1, 3, 4])]
    expected = np.sqrt(np.linalg.eigvalsh(lengths)[-1])
    assert expected > 1e3 * local_scale                        # the valley: the lengths are not determined at all
    assert np.isclose(values[0], expected, rtol=1e-2)
    assert np.ptp(values) <= 1e-2 * values[0]


@settings(max_examples=20, deadline=None)
@given(revolute21_problem(), st.integers(0, 2**16), st.sampled_from([1e-3, 1.0, 1e3]))
def test_the_uncertainty_scales_with_the_units(problem, seed, unit):
    """The same joint and samples in metres, millimetres or micrometres: the 1-σ (a length) scales with them."""
    truth, _ = problem
    R, z = _problem(truth, seed)
    x = np.r_[truth, r21._nearest_beta(truth, R, z)]
    sizes = np.r_[1.0, 1.0, 0.0, 1.0, 1.0]
    scaled = np.r_[truth * np.where(sizes > 0, unit, 1.0), x[5:]]
    base = r21._uncertainty(*_pieces(x, R, z), np.sqrt(np.mean(R**2 + z**2)))
    other = r21._uncertainty(*_pieces(scaled, R * unit, z * unit), unit * np.sqrt(np.mean(R**2 + z**2)))
    assert np.isclose(other, unit * base, rtol=1e-6) or (np.isinf(base) and np.isinf(other))


def _pieces(x, R, z):
    r, Jp, jb1, jb2 = r21._odr_parts(x, R, z)
    return Jp, jb1, jb2, r


@given(revolute21_problem(), st.integers(0, 2**16))
@settings(max_examples=10, deadline=None)
def test_no_uncertainty_is_claimed_without_residual_degrees_of_freedom_or_where_a_constant_cannot_move(problem, seed):
    """Five samples for five constants leave nothing to estimate the noise from; a hinge at α = π/2 with l = 0 (its
    meridian does not depend on α or l to first order) leaves those constants undetermined: both are infinite."""
    truth, _ = problem
    R, z = _problem(truth, seed, n=5)
    x = np.r_[truth, r21._nearest_beta(truth, R, z)]
    assert np.isinf(r21._uncertainty(*_pieces(x, R, z), np.sqrt(np.mean(R**2 + z**2))))
    flat = np.r_[truth[0], truth[1], np.pi / 2, 0.0, truth[4]]
    R, z = _problem(flat, seed, n=60, noise=0.0)
    x = np.r_[flat, r21._nearest_beta(flat, R, z)]
    assert np.isinf(r21._uncertainty(*_pieces(x, R, z), np.sqrt(np.mean(R**2 + z**2))))
