"""Hypothesis strategies for spherical joints: random true joints and spread samples."""
import numpy as np
from hypothesis import strategies as st


@st.composite
def spherical22_problem(draw, n=12):
    """(truth (d, r, rho1, rho2, gamma), per-sample angles (n, 4)): a random hip-like (2,2) joint."""
    d = draw(st.floats(-300, 300))
    r = draw(st.floats(30, 200))
    rho1 = draw(st.floats(40, 450))
    rho2 = draw(st.floats(40, 450))
    gamma = draw(st.floats(0.3, np.pi - 0.3))
    angles = np.array(draw(st.lists(st.lists(st.floats(-np.pi, np.pi), min_size=4, max_size=4),
                                    min_size=n, max_size=n)))
    return np.array([d, r, rho1, rho2, gamma]), angles


@st.composite
def sphere_problem(draw, n=6):
    """(centre, rho, directions (n, 2) as azimuth/elevation) spread over a cap of the sphere."""
    centre = np.array(draw(st.lists(st.floats(-300, 300), min_size=3, max_size=3)))
    rho = draw(st.floats(30, 500))
    az = np.array(draw(st.lists(st.floats(-np.pi, np.pi), min_size=n, max_size=n)))
    el = np.array(draw(st.lists(st.floats(-1.2, 1.2), min_size=n, max_size=n)))
    return centre, rho, np.stack([az, el], -1)
