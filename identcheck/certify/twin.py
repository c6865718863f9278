"""An exact certificate that one more marker rejects the other joints of Pham's revolute (2,1) case.

Revolute (2,1) — two points A1, A2 on one segment, one point B on the other — admits four joints for
generic data (ERRATA E1, E2): the true hinge, its mirror image, and the second root of the cubic with
its mirror. In a tree the one-point segment S often carries another joint k whose far segment holds
a marker F. F stays at a fixed distance from k's centre (ball) or axis (hinge), a point fixed in S;
so in S's frame, F must lie on a sphere. Each candidate hinge moves S differently (its roll about
A1A2 and its hinge angle are fixed by B in every frame), so a candidate survives only if F, seen in
the candidate's S frame, stays on a sphere: the 5×5 determinant of rows (|p|², p, 1) vanishes for
every five frames. This module proves that it does not, for the three other candidates:

- a random *rational* subject and motion (half-angle rational rotations), so all data are exact;
- the true joint, run through the same formulas, gives determinant exactly 0 (over Q), and every
  candidate, conjugates included, keeps B at one point of its segment in every frame: the checks of
  the formulas themselves (a candidate that did not explain B would be rejected for nothing);
- the true joint's mirror (cos α, l) → (−cos α, −l) is rational: its determinant is computed over
  Q and must be non-zero;
- the second root lives in Q(√Δ) and its parameters need square roots (r', ρ', sin α', cos α'):
  they are computed modulo a prime p in which every radicand is a square, for *every* choice of the
  square roots' signs (all conjugates, which include the real second joint and its mirror). A
  determinant non-zero modulo a prime above p is non-zero in the number field, so no conjugate
  survives. Every conjugate must also satisfy sin²β + cos²β = 1 in every frame (it lies on B's
  output surface, E1), which checks the formulas once more.

Non-survival at one point of the (irreducible) space of subjects and motions makes survival a
proper algebraic condition: it fails for generic data. So generic data leave exactly one joint.
"""
from __future__ import annotations

import random
from fractions import Fraction
from functools import lru_cache

import flint

try:                                   # where python-flint 0.6+ keeps it
    from flint.utils.flint_exceptions import DomainError
except ImportError:                    # pragma: no cover
    DomainError = ValueError

from identcheck.exact.algebra import add as _add, axis_rotation, dot as _dot, half_angle as _half_angle, mv as _mv
from identcheck.exact.algebra import quaternion_rotation as _quat_matrix, random_prime as _random_prime, sub as _sub

N_FRAMES = 9
PRIME_BITS = 61
MAX_PRIMES = 4000


# -- exact rational subject ------------------------------------------------------------------------------
def _rot_axis(u, c, s, v):
    """Rot(u, φ) v with (cos φ, sin φ) = (c, s), u a unit vector."""
    return _mv(axis_rotation(u, c, s), v)


def _rz(c, s, v):
    return [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]


def subject(rng: random.Random, far_joint: str = "spherical") -> dict:
    """A random rational hinge (d, r, cos α, sin α, l, ρ) in the frame of A1A2 (A1 at 0, A2 on +z), the
    frames' rolls θ and hinge angles β, and a far marker F on a ball (or hinge) joint of the one-point
    segment."""
    def q(lo, hi, den=8):
        return Fraction(rng.randint(lo * den, hi * den), den)

    ca, sa = _half_angle(q(1, 3, 7) / 4)
    J = {"d": q(-80, 80), "r": q(20, 90), "c": ca, "s": sa, "l": q(-60, 60), "rho": q(60, 200)}
    frames = []
    centre = [q(-80, 80), q(-80, 80), q(150, 350)]          # k's centre in S
    foot = [q(-60, 60), q(-60, 60), q(20, 120)]              # F relative to it, in its segment
    axis = [q(-2, 2), q(-2, 2), Fraction(1)]                 # a hinge k's direction (unnormalised)
    for _ in range(N_FRAMES):
        ct, st = _half_angle(q(-2, 2, 16) / 3)
        cb, sb = _half_angle(q(-2, 2, 16) / 2)
        if far_joint == "spherical":
            R = _quat_matrix(*(q(-4, 4, 4) + (Fraction(5) if i == 0 else 0) for i in range(4)))
        else:                                                # a turn about one fixed axis
            t = q(-4, 4, 4)
            R = _quat_matrix(Fraction(5), t * axis[0], t * axis[1], t * axis[2])
        frames.append({"theta": (ct, st), "beta": (cb, sb), "ball": R})
    return {"joint": J, "frames": frames, "centre": centre, "foot": foot}


def _hinge(J):
    P = [J["r"], 0 * J["r"], J["d"]]
    u = [0 * J["r"], -J["s"], J["c"]]
    return P, u


def _to_world(J, theta, beta, p):
    """A point p of S (S coincides with the A1A2 frame at θ = β = 0) at roll θ and hinge angle β."""
    P, u = _hinge(J)
    return _rz(*theta, _add(P, _rot_axis(u, *beta, _sub(p, P))))


def data(sub: dict) -> tuple:
    """(B samples, F samples) in the A1A2 frame: exact rationals."""
    J = sub["joint"]
    P, u = _hinge(J)
    b_local = _add(P, [J["rho"] + 0 * J["r"], 0 * J["r"], 0 * J["r"]])
    b_local = _add(b_local, [J["l"] * x for x in u])
    B, F = [], []
    for fr in sub["frames"]:
        B.append(_to_world(J, fr["theta"], fr["beta"], b_local))
        f_local = _add(sub["centre"], _mv(fr["ball"], sub["foot"]))
        F.append(_to_world(J, fr["theta"], fr["beta"], f_local))
    return B, F


# -- a candidate joint's view of the far marker -------------------------------------------------------------
def far_marker_in_segment(J: dict, B: list, F: list, one) -> list:
    """F in the one-point segment's frame, per frame, for candidate hinge J (any field): the frame's
    hinge angle from B's height, its roll from B's azimuth (no square roots needed). Raises
    ValueError if some frame has sin²β + cos²β ≠ 1 (J does not pass through B's samples)."""
    P, u = _hinge(J)
    out = []
    for b, f in zip(B, F):
        sb = (b[2] - J["c"] * J["l"] - J["d"]) / (J["s"] * J["rho"])
        R2 = b[0] * b[0] + b[1] * b[1]
        yb = J["c"] * J["rho"] * sb - J["s"] * J["l"]
        cb = (R2 - J["rho"] * J["rho"] * (one - sb * sb) - J["r"] * J["r"] - yb * yb) / (2 * J["rho"] * J["r"])
        if cb * cb + sb * sb != one:
            raise ValueError("the candidate does not pass through B's samples")
        x = J["rho"] * cb + J["r"]
        ct, st = (x * b[0] + yb * b[1]) / R2, (x * b[1] - yb * b[0]) / R2
        g = _rz(ct, -st, f)                                  # undo the roll
        out.append(_add(P, _rot_axis(u, cb, -sb, _sub(g, P))))   # undo the hinge
    return out


def sphere_det(pts: list):
    """det of the 5×5 rows (|p|², x, y, z, 1): zero iff the five points lie on a sphere (or plane)."""
    rows = [[_dot(p, p), p[0], p[1], p[2], p[0] * 0 + 1] for p in pts]
    return _det(rows)


def _det(M):
    M = [list(r) for r in M]
    n, det = len(M), 1
    for i in range(n):
        piv = next((k for k in range(i, n) if M[k][i] != 0), None)
        if piv is None:
            return M[0][0] * 0
        if piv != i:
            M[i], M[piv] = M[piv], M[i]
            det = -det
        det = det * M[i][i]
        inv = 1 / M[i][i]
        for k in range(i + 1, n):
            f = M[k][i] * inv
            if f != 0:
                M[k] = [M[k][j] - f * M[i][j] for j in range(n)]
    return det


def _fixed(pts) -> bool:
    """All points equal: B, seen in a candidate's frame of its own segment, must not move."""
    return all(p == pts[0] for p in pts)


def _off_every_sphere(pts) -> bool:
    """Some five consecutive frames of ``pts`` lie on no sphere."""
    return any(sphere_det(pts[i:i + 5]) != 0 for i in range(len(pts) - 4))


# -- the second root, modulo a prime ------------------------------------------------------------------------
def _second_root_radicands(J):
    """The second root's squared parameters as functions of √Δ (E1: q = Q' − Q, g(q) = 0)."""
    d, r, c, s, l, rho = (J[k] for k in ("d", "r", "c", "s", "l", "rho"))
    Q = r * r + d * d - l * l - rho * rho
    P = Q - d * d
    W = r * r / (s * s)
    half_b = P - W * c * c
    disc4 = half_b * half_b + 4 * W * (c * c * P + l * l)     # (Δ/4): g(q) = q² + 2·half_b·q − 4W(c²P + l²)

    def params(sqrt_disc4):
        qq = -half_b + sqrt_disc4
        r2 = r * r + qq / 2
        s2 = s * s + qq / (2 * W)
        c2 = c * c - qq / (2 * W)
        lc = l * c                                            # l' cos α' = l cos α
        rho2 = r2 + d * d - lc * lc / c2 - (Q + qq)
        return {"r2": r2, "s2": s2, "c2": c2, "lc": lc, "rho2": rho2, "d": d}
    return disc4, params


def _field_sqrt(a: "flint.nmod", p: int):
    """A square root of a modulo p (FLINT), or None when a is not a square."""
    try:
        return a.sqrt()
    except DomainError:            # no square root modulo p
        return None


def _conjugates_mod_p(J, B, F, p: int) -> list | None:
    """Every conjugate of the second joint (and its mirror) modulo p, or None if p does not split."""
    one = flint.nmod(1, p)
    to = lambda v: flint.nmod(v.numerator, p) / flint.nmod(v.denominator, p)  # noqa: E731
    Jp = {k: to(v) for k, v in J.items()}
    Bp = [[to(v) for v in b] for b in B]
    Fp = [[to(v) for v in f] for f in F]
    disc4, params = _second_root_radicands(Jp)
    root = _field_sqrt(disc4, p)
    if root is None:
        return None
    out = []
    for sd in (root, -root):
        par = params(sd)
        roots = {k: _field_sqrt(par[k], p) for k in ("r2", "s2", "c2", "rho2")}
        if any(v is None or v == 0 for v in roots.values()):
            return None
        for sr in (1, -1):
            for ss in (1, -1):
                for sc in (1, -1):
                    for sp_ in (1, -1):
                        c = sc * roots["c2"]
                        out.append({"d": par["d"], "r": sr * roots["r2"], "s": ss * roots["s2"], "c": c,
                                    "l": par["lc"] / c, "rho": sp_ * roots["rho2"]})
    return [(cand, Bp, Fp, one) for cand in out]


@lru_cache(maxsize=8)
def certify(seed: int = 0, far_joint: str = "spherical") -> dict:
    """Prove, at a random rational subject, that a marker beyond a ``far_joint`` ("spherical" or
    "revolute") of the one-point segment rejects the three other candidates of revolute (2,1).
    Returns the certificate (``certified`` true or false, with what was checked)."""
    rng = random.Random(seed)
    sub = subject(rng, far_joint)
    J = sub["joint"]
    B, F = data(sub)
    one = Fraction(1)
    truth = sphere_det(far_marker_in_segment(J, B, F, one)[:5])
    mirror = dict(J, c=-J["c"], l=-J["l"])
    try:
        mirror_off = _off_every_sphere(far_marker_in_segment(mirror, B, F, one))
        mirror_ok = _fixed(far_marker_in_segment(mirror, B, B, one))
    except ValueError:
        mirror_off = mirror_ok = False
    cert = {"method": "exact: a random rational subject; the true joint and its mirror over Q, the second root's "
                      "conjugates modulo a prime that splits every radicand",
            "seed": seed, "far_joint": far_joint, "frames": N_FRAMES, "truth_determinant_zero": truth == 0,
            "mirror_explains_B": mirror_ok, "mirror_rejected": bool(mirror_off), "prime": None,
            "conjugates": 0, "conjugates_explain_B": False, "conjugates_rejected": 0, "certified": False}
    if truth != 0 or not mirror_off or not mirror_ok:
        return cert
    prng = random.Random(seed + 1)
    for _ in range(MAX_PRIMES):
        p = _random_prime(prng, PRIME_BITS)
        conj = _conjugates_mod_p(J, B, F, p)
        if conj is None:
            continue
        rejected, explain = 0, True
        for cand, Bp, Fp, onep in conj:
            try:
                explain &= _fixed(far_marker_in_segment(cand, Bp, Bp, onep))     # B stays put: a genuine joint
                rejected += _off_every_sphere(far_marker_in_segment(cand, Bp, Fp, onep))
            except ValueError:
                explain = False
        cert.update(prime=p, conjugates=len(conj), conjugates_explain_B=explain, conjugates_rejected=rejected,
                    certified=explain and rejected == len(conj))
        return cert
    return cert
