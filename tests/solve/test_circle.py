"""The least-squares circle through marker samples (:func:`identcheck.solve.minimal.circle_fit`), by which
``skeleton`` measures a hinge's fit: exact through noise-free points of any arc, and under noise its residual the
noise's (the algebraic fit, :func:`identcheck.solve.minimal.circle`, leaves 10-17 mm RMS on a 90° arc with 0.5 mm of
noise), and no line-sized circle for a nearly straight path."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.errors import DegenerateError
from identcheck.solve.minimal import circle, circle_fit


def _arc(seed: int, radius: float, arc_deg: float, n: int, noise: float):
    """`n` points on an arc of `arc_deg` of a circle of `radius` with a random centre and plane, plus isotropic
    noise; (points, centre, normal)."""
    rng = np.random.default_rng(seed)
    centre = rng.normal(0.0, 200.0, 3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    t = np.deg2rad(rng.uniform(0.0, 360.0) + np.linspace(0.0, arc_deg, n))
    pts = centre + radius * (np.cos(t)[:, None] * q[:, 0] + np.sin(t)[:, None] * q[:, 1])
    return pts + rng.normal(0.0, noise, pts.shape) if noise else pts, centre, q[:, 2]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.floats(20.0, 600.0), arc=st.floats(10.0, 360.0),
       n=st.integers(3, 200))
def test_noise_free_points_give_their_circle(seed, radius, arc, n):
    pts, centre, normal = _arc(seed, radius, arc, n, 0.0)
    J, nrm, r = circle_fit(pts)
    assert np.allclose(J, centre, atol=1e-6 * radius) and r == pytest.approx(radius, rel=1e-8)
    assert abs(abs(nrm @ normal) - 1.0) < 1e-9


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.floats(100.0, 500.0), arc=st.floats(45.0, 360.0),
       noise=st.floats(0.05, 1.5))
def test_noisy_samples_leave_the_noise_as_residual(seed, radius, arc, noise):
    """300 samples with noise σ per coordinate: the residuals (in-plane radial and out-of-plane) of the least-squares
    circle have about the noise's RMS, σ·√(2/3) for these two of three coordinates, and the truth is no better a
    circle than the fit (within 2 %: the plane and the circle in it are fitted one after the other)."""
    pts, centre, normal = _arc(seed, radius, arc, 300, noise)

    def rms(J, nrm, r):
        w = pts - J
        along = w @ nrm
        radial = np.linalg.norm(w - along[:, None] * nrm, axis=1)
        return float(np.sqrt(np.mean(np.concatenate([radial - r, along]) ** 2)))

    fitted = rms(*circle_fit(pts))
    assert rms(*circle(pts)) >= fitted - 1e-9          # (the algebraic fit's residuals are no smaller)
    assert fitted <= 1.2 * noise, (fitted, noise)
    assert fitted <= 1.02 * rms(centre, normal, radius) + 1e-9


@pytest.mark.parametrize("fit", [circle, circle_fit])
def test_collinear_samples_are_no_circle(fit):
    with pytest.raises(DegenerateError, match="collinear"):
        fit(np.outer(np.linspace(0.0, 1.0, 10), [1.0, 2.0, 3.0]))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.floats(100.0, 500.0), arc=st.floats(0.5, 15.0),
       noise=st.floats(0.1, 1.0))
def test_a_short_noisy_arc_gives_a_circle_of_its_own_size_or_none(seed, radius, arc, noise):
    """A few degrees of arc under noise: the least-squares circle of a nearly straight path heads for a line (radii
    of 10⁷-10¹¹ mm had come out, and a hinge start weighting circles by radius² trusted them most); either a circle
    within CIRCLE_REACH times the points' extent comes out, or DegenerateError says the path is too straight."""
    from identcheck.solve.minimal import CIRCLE_REACH

    pts, _, _ = _arc(seed, radius, arc, 300, noise)
    extent = float(np.ptp(pts, axis=0).max())
    try:
        _, _, r = circle_fit(pts)
    except DegenerateError as exc:
        assert "straight" in str(exc) or "collinear" in str(exc)
        return
    assert np.isfinite(r) and r <= CIRCLE_REACH * extent * 1.01


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(20.0, 400.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0))
def test_circle_deviations_are_the_offsets_off_the_circle_and_out_of_its_plane(seed, radius, out, off):
    """Points on a random circle, moved off it by `off` within its plane and by `out` across it: the radial
    deviations are `off` (radius given) and the out-of-plane ones `out`; with no radius, the mean distance from the
    axis is the radius and the radial deviations have mean zero."""
    from identcheck.solve.minimal import circle_deviations

    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    e1 = np.cross(normal, rng.normal(size=3))
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    centre = rng.uniform(-500, 500, 3)
    t = rng.uniform(0, 2 * np.pi, 50)
    pts = centre + (radius + off) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2) + out * normal
    radial, along, r = circle_deviations(pts, centre, normal, radius)
    assert np.allclose(radial, off, atol=1e-7) and np.allclose(along, out, atol=1e-7) and r == radius
    radial, _, r = circle_deviations(pts, centre, normal)
    assert abs(r - (radius + off)) < 1e-7 and abs(radial.mean()) < 1e-7
