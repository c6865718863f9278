"""Spherical joints (3,1) and (2,2): random truth in, truth out (float64 and 50 digits), degeneracies named."""
import random
import warnings

import mpmath
import numpy as np
import pytest
from hypothesis import assume, given, settings

from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.solve import spherical22, spherical31
from strategies_spherical import sphere_problem, spherical22_problem


def _s22_samples(truth, angles, backend="numpy"):
    d, r, rho1, rho2, gamma = truth
    g = spherical22.generated(backend)
    par = np.array([d, r, rho1, rho2, np.cos(gamma), np.sin(gamma)])
    trig = np.stack([np.cos(angles), np.sin(angles)], -1).reshape(len(angles), 8)
    return g["forward"](par, trig)


def _well_posed(s):
    """Keep to data whose linear system is reasonably conditioned (float64 accuracy needs it)."""
    try:
        M, *_ = spherical22._system(s, 1e8)
    except DegenerateError:
        return False
    return True


@given(spherical22_problem())
def test_s22_recovers_truth_float64(problem):
    truth, angles = problem
    s = _s22_samples(truth, angles)
    assume(_well_posed(s))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        ident = spherical22.identify(s[:, :3], s[:, 3:])
    assert ident.unique
    j = ident.joints[0]
    scale = np.abs(truth[:4]).max()
    np.testing.assert_allclose(j.as_tuple(), truth[:4], atol=1e-8 * scale, rtol=0)
    # the per-sample centre is on the circle and at rho_k from each marker
    d, r, rho1, rho2, _ = truth
    np.testing.assert_allclose(np.hypot(j.centre[:, 0], j.centre[:, 1]), r, atol=1e-8 * scale)
    np.testing.assert_allclose(np.linalg.norm(j.centre - s[:, :3], axis=1), rho1, atol=1e-8 * scale)


@settings(max_examples=5)
@given(spherical22_problem(n=9))
def test_s22_recovers_truth_50_digits(problem):
    truth, angles = problem
    assume(_well_posed(_s22_samples(truth, angles)))
    g = spherical22.generated("mpmath")
    with mpmath.workdps(70):
        d, r, rho1, rho2, gamma = (mpmath.mpf(float(v)) for v in truth)
        par = [d, r, rho1, rho2, mpmath.cos(gamma), mpmath.sin(gamma)]
        pts = [g["forward"](par, [f(mpmath.mpf(float(a))) for a in row for f in (mpmath.cos, mpmath.sin)])
               for row in angles]
    ident = spherical22.identify([p[:3] for p in pts], [p[3:] for p in pts], precision=50)
    assert ident.unique
    for got, want in zip(ident.joints[0].as_tuple(), par[:4]):
        assert abs(got - want) < mpmath.mpf(10) ** -40 * 500


def test_s22_needs_nine_samples_and_varied_motion():
    truth = np.array([100.0, 80.0, 90.0, 400.0, 1.0])
    rng = np.random.default_rng(3)
    s = _s22_samples(truth, rng.uniform(-np.pi, np.pi, (8, 4)))
    with pytest.raises(InputError, match="at least 9"):
        spherical22.identify(s[:, :3], s[:, 3:])
    # the child only rotates about one axis through J (phi varies, psi = xi = 0) with theta fixed
    ang = np.zeros((12, 4))
    ang[:, 1] = np.linspace(-1, 1, 12)
    s = _s22_samples(truth, ang)
    with pytest.raises(DegenerateError, match="do not determine"):
        spherical22.identify(s[:, :3], s[:, 3:])


def test_s22_rejects_data_of_another_joint():
    truth = np.array([100.0, 80.0, 90.0, 400.0, 1.0])
    rng = np.random.default_rng(4)
    s = _s22_samples(truth, rng.uniform(-np.pi, np.pi, (12, 4)))
    s[:, 3:] += rng.normal(0, 5.0, s[:, 3:].shape)  # B2 not rigid with B1 about J
    with pytest.raises(DegenerateError):
        spherical22.identify(s[:, :3], s[:, 3:])


def test_s22_noisy_linear_solution_close_to_truth():
    truth = np.array([120.0, 80.0, 90.0, 400.0, 1.0])
    rng = np.random.default_rng(5)
    s = _s22_samples(truth, rng.uniform(-np.pi, np.pi, (400, 4)))
    got = spherical22.solve_linear(s[:, :3] + rng.normal(0, 0.05, (400, 3)), s[:, 3:] + rng.normal(0, 0.05, (400, 3)))
    np.testing.assert_allclose(got, truth[:4], atol=5.0)


def _sphere(centre, rho, dirs):
    az, el = dirs[:, 0], dirs[:, 1]
    return centre + rho * np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)], -1)


@given(sphere_problem())
def test_s31_recovers_truth_float64(problem):
    centre, rho, dirs = problem
    xyz = _sphere(centre, rho, dirs)
    assume(spherical31.conditioning(xyz).planarity > 0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        j = spherical31.identify(xyz).joints[0]
    scale = max(np.abs(centre).max(), rho)
    np.testing.assert_allclose(j.centre, centre, atol=1e-8 * scale)
    assert abs(j.rho - rho) < 1e-8 * scale


def test_s31_exact_rational_samples_at_50_digits():
    """Rational points on a rational sphere (half-angle directions) give the centre to 40+ digits."""
    rng = random.Random(2)
    from identcheck.certify import exact_rank as certify
    cs = spherical31.CASE
    params = certify.draw_parameters(cs, rng)
    pts = [certify.sample_point(cs, params, ts) for ts in certify.draw_angles(cs, rng, 5)]
    with mpmath.workdps(60):
        xyz = [[mpmath.mpf(c.p) / c.q for c in p] for p in pts]
    j = spherical31.identify(xyz, precision=50).joints[0]
    truth = [params[k] for k in ("x_J", "y_J", "z_J")]
    with mpmath.workdps(60):
        for got, want in zip(j.centre, truth):
            assert abs(got - mpmath.mpf(want.p) / want.q) < mpmath.mpf(10) ** -40


def test_s31_coplanar_samples_are_degenerate_and_named():
    a = np.linspace(-1, 1, 10)
    xyz = _sphere(np.array([10.0, -20.0, 300.0]), 420.0, np.stack([a, np.zeros(10)], -1))  # one circle
    with pytest.raises(DegenerateError, match="coplanar"):
        spherical31.identify(xyz)


def test_s31_near_coplanar_noisy_warns_with_uncertainty():
    rng = np.random.default_rng(1)
    a = np.linspace(-1, 1, 50)
    xyz = _sphere(np.array([10.0, -20.0, 300.0]), 420.0, np.stack([a, 0.02 * np.sin(5 * a)], -1))
    noisy = xyz + rng.normal(0, 0.5, xyz.shape)
    with pytest.warns(IdentifiabilityWarning, match="nearly coplanar"):
        res = spherical31.identify(noisy, rel_tol=np.inf, noise_mm=0.5)
    good = _sphere(np.array([10.0, -20.0, 300.0]), 420.0, np.stack([a * 3, 0.8 * np.sin(5 * a)], -1))
    res_good = spherical31.identify(good + rng.normal(0, 0.5, xyz.shape), rel_tol=np.inf, noise_mm=0.5)
    assert res.conditioning.uncertainty_mm > 5 * res_good.conditioning.uncertainty_mm
    # the predicted uncertainty is of the order of the actual error for the well-posed motion
    err = np.linalg.norm(res_good.joints[0].centre - np.array([10.0, -20.0, 300.0]))
    assert err < 5 * res_good.conditioning.uncertainty_mm


def test_frames_name_the_degenerate_frames():
    from identcheck.geometry.frames import pair_frame, parent_frame
    a = np.full((4, 3), 1e6)
    b = a + np.array([[0, 0, 100.0], [0, 0, 1e-8], [0, 0, 100.0], [0, 0, 100.0]])
    with pytest.raises(DegenerateError, match=r"frames \[1\]"):
        pair_frame(a, b, a)
    b[1, 2] = 100.0
    c = a + np.array([[0, 0, 200.0]] * 4)  # on the A1A2 line: collinear parent markers
    with pytest.raises(DegenerateError, match=r"parallel to A1A2 in frames \[0, 1, 2, 3\]"):
        parent_frame(a, b, c - a, names=("A1", "A2", "A3 - A1"))
