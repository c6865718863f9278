"""The equations of Pham et al. (sections III-A and IV-C) transcribed as printed, for comparison only.

Nothing here is used to compute an answer: every result identcheck uses comes from the
derivation; these forms exist so that each printed equation can be checked against it.
"""
from __future__ import annotations

import sympy as sp

from identcheck.symbols import A, B, Q, R2, Z, c_alpha as ca, c_theta as ct, d, l, r, rho, s_alpha as sa, s_theta as st, x, y, z

SOURCE = "Pham, Ayusawa, Kubota, Nakamura: On the structural identifiability of joint parameters from motion capture data"

Q_DEF = r**2 + d**2 - l**2 - rho**2  # printed below (5)

O_THETA = sp.Matrix([l * st * sa + r * ct, -l * ct * sa + r * st, l * ca + d])  # D (0,0,l,1)^T

_v = sp.Matrix([x - l * st * sa - r * ct, y + l * ct * sa - r * st, z - l * ca - d])
EQ2 = (_v.T * _v)[0] - rho**2                                    # (2), as "= 0"
EQ3 = (_v.T * sp.Matrix([st * sa, -ct * sa, ca]))[0]               # (3)
EQ4_A = (l + d * ca - z * ca) / sa                                  # (4): A = ...
EQ2_DEVELOPED = (R2 + l**2 + r**2 + d**2 - rho**2 + 2 * l * d * ca
                 - 2 * z * (l * ca + d) - 2 * l * sa * A - 2 * r * B)  # text after (4)
EQ5 = R2 + Q - 2 * z * d - 2 * r * B                               # (5), as "= 0"

M_ROW = [-4 * R2 * z, 2 * R2, -4 * z, sp.Integer(1), 4 * z**2]     # (8)
Y_VEC = [d,                                                          # (9)
         Q - 2 * r**2,
         Q * d + 2 * r**2 * ca * (l + d * ca) / sa**2,
         Q**2 + 4 * r**2 * (l + d * ca) ** 2 / sa**2,
         d**2 + r**2 / sa**2]
K = -R2**2

_a = 2 * (Z[4] - Z[0] ** 2) + Z[1] + 2 * Z[0] ** 2                  # below (13)
_b = -4 * Z[0] * Z[2] + Z[3]
_c = 2 * Z[2] ** 2 - Z[3] * (2 * (Z[4] - Z[0] ** 2) + Z[1])
CUBIC = -Q**3 + _a * Q**2 + _b * Q + _c                              # (13)

# back-substitution printed after (13); alpha is given through sin(alpha) = asin's argument
BACK_R2 = (Q - Z[1]) / 2
BACK_SIN2_ALPHA = (Q - Z[1]) / (2 * (Z[4] - Z[0] ** 2))
BACK_L = (Z[2] - Q * Z[0]) / (2 * (Z[4] - Z[0] ** 2) * ca) - Z[0] * ca
BACK_RHO2_WITH_L = r**2 + d**2 - l**2 - Q                           # rho_k^2 = r_k^2 + d^2 - l_k^2 - Q_k

CLAIM_EXTRANEOUS_ROOTS = 1   # "one of the Q_k corresponds to the extraneous solution ..."
CLAIM_NONREAL_ROOTS = 1      # "a second Q_k is usually associated with non-real values"
CLAIM_JOINTS = 1             # "there remains a unique Q_k, associated with unique values of r, alpha, l, rho"
CLAIM_ALPHA_BRANCHES = 1     # alpha_k = asin(...): one alpha per root

# --- section IV-C: spherical joint, two markers on each link ---------------------------------
from identcheck.symbols import rho1, rho2, x1, x2, y1, y2, z1, z2  # noqa: E402

DELTA = x1 * y2 - x2 * y1                                             # below (14)
H = (x1**2 + y1**2 + (z1 - d) ** 2 + r**2 - rho1**2) / 2              # (15)
G = (x2**2 + y2**2 + (z2 - d) ** 2 + r**2 - rho2**2) / 2              # (15)
EQ14 = H**2 * (x2**2 + y2**2) + G**2 * (x1**2 + y1**2) - 2 * H * G * (x1 * x2 + y1 * y2) - r**2 * DELTA**2
_P1, _P2 = d**2 + r**2 - rho1**2, d**2 + r**2 - rho2**2
Y17 = [_P1, _P2, d, _P1 * _P2, _P1 * d, _P2 * d, _P1**2, _P2**2, r**2]  # (17)
CLAIM_S22_SAMPLES = 9        # "9 equations ... prove the 9-identifiability"
