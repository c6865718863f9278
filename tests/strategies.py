"""Hypothesis strategies shared by the tests: random true joints and well-spread samples."""
import numpy as np
from hypothesis import assume, strategies as st

from identcheck.solve.revolute21 import generated


@st.composite
def revolute21_problem(draw):
    """(truth (d, r, alpha, l, rho), samples (5, 3)) with samples spread over θ and β."""
    d = draw(st.floats(-200, 200))
    l = draw(st.floats(-200, 200))
    r = draw(st.floats(30, 200))
    rho = draw(st.floats(30, 200))
    a = draw(st.floats(0.3, np.pi - 0.3))
    th0, be0 = draw(st.floats(-np.pi, np.pi)), draw(st.floats(-np.pi, np.pi))
    jt = np.array(draw(st.lists(st.floats(-0.4, 0.4), min_size=5, max_size=5)))
    jb = np.array(draw(st.lists(st.floats(-0.4, 0.4), min_size=5, max_size=5)))
    k = np.arange(5)
    th = th0 + 2 * np.pi * k / 5 + jt
    be = be0 + 2 * np.pi * (2 * k % 5) / 5 + jb
    # stay off the special locus where the cubic has a double root (the twin joint of erratum E1
    # meets the true one: q- = 0, e.g. l = 0 and r = rho); float64 accuracy is sqrt(eps) there
    W, c, P = r**2 / np.sin(a) ** 2, np.cos(a), r**2 - l**2 - rho**2
    q_minus = -(P - W * c**2) - np.sqrt((P + W * c**2) ** 2 + 4 * W * l**2)
    assume(abs(q_minus) > 1e-2 * max(r, rho, abs(d), abs(l)) ** 2)
    par = np.array([d, r, l, rho, np.cos(a), np.sin(a)])
    xyz = generated()["forward"](par, np.stack([np.cos(th), np.sin(th), np.cos(be), np.sin(be)], -1))
    return np.array([d, r, a, l, rho]), xyz
