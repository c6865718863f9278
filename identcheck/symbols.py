"""Canonical SymPy symbols, assumptions and order for every joint case.

Angles never appear as ``sin``/``cos`` calls: each angle φ is a pair of polynomial symbols
(c_φ, s_φ) tied by c_φ² + s_φ² = 1, so that identities are proved by exact polynomial
reduction (fast and certain) instead of ``trigsimp``. "Symbol order is data": generated
functions take their arguments in the order these tuples give.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from identcheck.errors import InputError
from identcheck.io.model import JOINT_TYPES

# sample coordinates of a child marker in the frame F of the parent's markers
x, y, z = sp.symbols("x y z", real=True)
R2 = sp.Symbol("R2", nonnegative=True)  # R² = x² + y² + z²

# coordinates of two child markers B1, B2 in the frame F (spherical (2,2), Pham section IV-C)
x1, y1, z1, x2, y2, z2 = sp.symbols("x1 y1 z1 x2 y2 z2", real=True)

# joint centre fixed in the frame of three parent markers (spherical (3,1), section IV-A)
x_J, y_J, z_J = sp.symbols("x_J y_J z_J", real=True)

# Denavit–Hartenberg constants of a revolute joint seen from two parent markers (Pham Fig. 2)
d, l = sp.symbols("d l", real=True)
r, rho = sp.symbols("r rho", positive=True)
rho1, rho2 = sp.symbols("rho1 rho2", positive=True)  # distances of B1, B2 to a spherical joint's centre

# angles as (cos, sin) symbol pairs; the angle symbols themselves are for display only
alpha, theta, beta = sp.symbols("alpha theta beta", real=True)
c_alpha, s_alpha = sp.symbols("c_alpha s_alpha", real=True)
c_theta, s_theta = sp.symbols("c_theta s_theta", real=True)
c_beta, s_beta = sp.symbols("c_beta s_beta", real=True)
# spherical joints: the child's orientation (phi, psi, xi) and the constant angle gamma = ∠B1 J B2
phi, psi, xi, gamma = sp.symbols("phi psi xi gamma", real=True)
c_phi, s_phi = sp.symbols("c_phi s_phi", real=True)
c_psi, s_psi = sp.symbols("c_psi s_psi", real=True)
c_xi, s_xi = sp.symbols("c_xi s_xi", real=True)
c_gamma, s_gamma = sp.symbols("c_gamma s_gamma", real=True)

# per-sample auxiliaries of eq. (4)-(5): A = x sinθ - y cosθ, B = x cosθ + y sinθ
A, B = sp.symbols("A B", real=True)

# the solved unknown vector Z of eq. (10) and the cubic's variable Q of eq. (13)
Q = sp.Symbol("Q", real=True)
Z = sp.symbols("Z1:6", real=True)
cos_sign = sp.Symbol("sigma", real=True)  # ±1: which sign cos α takes (mirror images)


@dataclass(frozen=True)
class Angle:
    """An angle carried as a (cos, sin) pair of symbols."""

    name: str
    symbol: sp.Symbol
    cos: sp.Symbol
    sin: sp.Symbol

    @property
    def circle(self) -> sp.Expr:
        """The polynomial c² + s² - 1 that vanishes for every real angle."""
        return self.cos**2 + self.sin**2 - 1


ALPHA = Angle("alpha", alpha, c_alpha, s_alpha)
THETA = Angle("theta", theta, c_theta, s_theta)
BETA = Angle("beta", beta, c_beta, s_beta)
PHI = Angle("phi", phi, c_phi, s_phi)
PSI = Angle("psi", psi, c_psi, s_psi)
XI = Angle("xi", xi, c_xi, s_xi)
GAMMA = Angle("gamma", gamma, c_gamma, s_gamma)


@dataclass(frozen=True)
class Case:
    """One identifiability case: a joint type with p markers on the parent, q on the child.

    Attributes
    ----------
    constants : tuple of Symbol
        Constant parameters Π_c + Σ_c (the same in every sample), canonical order.
    constant_angles : tuple of Angle
        Constant parameters that are angles (carried as cos/sin pairs).
    variables : tuple of Angle
        Per-sample variable parameters Π_v + Σ_v.
    sample : tuple of Symbol
        Output coordinates of one sample, in the frame of the parent's markers.
    """

    joint: str
    p: int
    q: int
    constants: tuple
    constant_angles: tuple
    variables: tuple
    sample: tuple

    @property
    def key(self) -> str:
        return f"{self.joint}({self.p},{self.q})"

    @property
    def trig_pairs(self) -> tuple:
        """Every (cos, sin) pair the case uses, constants first."""
        return tuple((a.cos, a.sin) for a in self.constant_angles + self.variables)

    @property
    def parameter_symbols(self) -> tuple:
        """Symbols a joint-parameter vector is made of: lengths then cos/sin of angles."""
        out = list(self.constants)
        for a in self.constant_angles:
            out += [a.cos, a.sin]
        return tuple(out)


_CASES = {
    ("revolute", 2, 1): Case(
        joint="revolute", p=2, q=1,
        constants=(d, r, l, rho),
        constant_angles=(ALPHA,),
        variables=(THETA, BETA),
        sample=(x, y, z),
    ),
    # the sphere of radius rho about a centre fixed among three parent markers
    ("spherical", 3, 1): Case(
        joint="spherical", p=3, q=1,
        constants=(x_J, y_J, z_J, rho),
        constant_angles=(),
        variables=(PHI, PSI),
        sample=(x, y, z),
    ),
    # centre on the circle (r cos θ, r sin θ, d) about A1A2; the rigid triangle J B1 B2
    # (sides rho1, rho2, angle gamma at J) turns about J by the Euler angles (phi, psi, xi)
    ("spherical", 2, 2): Case(
        joint="spherical", p=2, q=2,
        constants=(d, r, rho1, rho2),
        constant_angles=(GAMMA,),
        variables=(THETA, PHI, PSI, XI),
        sample=(x1, y1, z1, x2, y2, z2),
    ),
}



def case(joint: str, p: int, q: int) -> Case:
    """Return the canonical :class:`Case` for ``joint`` with p parent and q child markers.

    Raises
    ------
    InputError
        For an unknown joint type or a (p, q) case that has no derivation yet.
    """
    joint = str(joint).lower()
    if joint not in JOINT_TYPES:
        raise InputError(f"unknown joint type {joint!r}; known types: {', '.join(JOINT_TYPES)}")
    try:
        return _CASES[(joint, int(p), int(q))]
    except KeyError:
        known = ", ".join(f"{j} {a} {b}" for j, a, b in sorted(_CASES))
        raise InputError(
            f"no derivation for {joint} ({p},{q}) yet; derived cases: {known}"
        ) from None


def known_cases() -> list:
    """All cases with a derivation, in canonical order."""
    return [_CASES[k] for k in sorted(_CASES)]
