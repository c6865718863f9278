"""Hypothesis strategies shared by the tests: random true joints and well-spread samples."""
import numpy as np
from hypothesis import assume, strategies as st

from identcheck.solve.revolute21 import generated

GENERIC_ALPHA = st.floats(0.3, np.pi - 0.3)


def near_perpendicular(width=1e-2):
    """α = π/2 + δ: the hinge (nearly) perpendicular to the A1A2 line, cos α ≈ −δ.

    |δ| is drawn on a log scale from 1e-13 to ``width``, and δ = 0 exactly, so that every
    order of magnitude of cos α is tried, not only the largest.
    """
    size = st.floats(-13, np.log10(width)).map(lambda e: 10.0**e)
    delta = st.one_of(st.just(0.0), st.builds(lambda sign, s: sign * s, st.sampled_from([-1.0, 1.0]), size))
    return delta.map(lambda x: np.pi / 2 + x)


def spread_angles(th0, be0, jt=0.0, jb=0.0):
    """Five θ and β spread over the circle (β visits the fifths in the order 0, 2, 4, 1, 3)."""
    k = np.arange(5)
    return th0 + 2 * np.pi * k / 5 + jt, be0 + 2 * np.pi * (2 * k % 5) / 5 + jb


def revolute21_samples(truth, theta, beta):
    """Exact samples (n, 3) of the joint ``truth`` = (d, r, α, l, ρ) at angles θ, β (n,)."""
    d, r, a, l, rho = truth
    par = np.array([d, r, l, rho, np.cos(a), np.sin(a)])
    return generated()["forward"](par, np.stack([np.cos(theta), np.sin(theta), np.cos(beta), np.sin(beta)], -1))


def double_root_gap(truth):
    """How far the true root of (13) is from the other two, over the squared length scale.

    Erratum E1: the other roots are Q + q± with q± the roots of
    g(q) = q² + 2(P − Wc²)q − 4W(c²P + l²). q₋ = 0 where the twin joint meets the true one
    (e.g. l = 0 and r = ρ); q₊ = 0 where l = 0 and cos α = 0 (with P > 0). Near either, the
    root is a near-double one and float64 keeps only about half its digits.
    """
    d, r, a, l, rho = truth
    W, c, P = r**2 / np.sin(a) ** 2, np.cos(a), r**2 - l**2 - rho**2
    half_gap = np.sqrt((P + W * c**2) ** 2 + 4 * W * l**2)
    q = -(P - W * c**2) + np.array([-half_gap, half_gap])
    return float(np.min(np.abs(q))) / max(r, rho, abs(d), abs(l)) ** 2


@st.composite
def revolute21_problem(draw, alpha=GENERIC_ALPHA):
    """(truth (d, r, alpha, l, rho), samples (5, 3)) with samples spread over θ and β.

    ``alpha``: the strategy for α (default: uniform in (0.3, π − 0.3)).
    """
    d = draw(st.floats(-200, 200))
    l = draw(st.floats(-200, 200))
    r = draw(st.floats(30, 200))
    rho = draw(st.floats(30, 200))
    a = draw(alpha)
    th0, be0 = draw(st.floats(-np.pi, np.pi)), draw(st.floats(-np.pi, np.pi))
    jt = np.array(draw(st.lists(st.floats(-0.4, 0.4), min_size=5, max_size=5)))
    jb = np.array(draw(st.lists(st.floats(-0.4, 0.4), min_size=5, max_size=5)))
    truth = np.array([d, r, a, l, rho])
    # stay off the special loci where the cubic has a double root (double_root_gap)
    assume(double_root_gap(truth) > 1e-2)
    return truth, revolute21_samples(truth, *spread_angles(th0, be0, jt, jb))
