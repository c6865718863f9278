"""Spherical joint, two markers on each link (Pham et al., section IV-C, eqs. 14–17).

In the frame F of the parent's markers (A1 at the origin, A2 on +z) the centre J is on the
circle Γ(d, r) = (r cos θ, r sin θ, d), θ unknown per sample; B1, B2 sit at distances ρ1, ρ2
from J. The two sphere conditions are linear in (cos θ, sin θ); eliminating θ gives (14).
Expanding (14) in the parameters shows which unknown monomials really occur, and a search for
polynomial relations among their coefficients shows which of them the output set can tell
apart — the derivation builds the full-rank linear system on what it finds, not on (17).
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from identcheck.symbols import c_gamma, c_phi, c_psi, c_theta, c_xi, case, d, r, rho1, rho2, s_gamma, s_phi, s_psi, s_theta, s_xi, x1, x2, y1, y2, z1, z2
from identcheck.derive import printed
from identcheck.derive.algebra import equal, linear_form_in_parameters, polynomial_relations, reduce_circle
from identcheck.derive.base import Derivation, Step

CASE = case("spherical", 2, 2)
TRIG = CASE.trig_pairs
SOURCE = "Pham et al., section IV-C, eqs. (14)-(17)"
SAMPLE = CASE.sample
P1, P2 = sp.symbols("P1 P2", real=True)    # d² + r² − ρ1², d² + r² − ρ2² (the printed Y1, Y2)


def rotation() -> sp.Matrix:
    """R = Rz(φ)·Ry(ψ)·Rz(ξ): the child's orientation about J, polynomial in cos/sin pairs."""
    Rz = lambda c, s: sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    Ry = sp.Matrix([[c_psi, 0, s_psi], [0, 1, 0], [-s_psi, 0, c_psi]])
    return Rz(c_phi, s_phi) * Ry * Rz(c_xi, s_xi)


@lru_cache(maxsize=1)
def derive() -> Derivation:
    """Run the whole derivation once (cached); see the module docstring."""
    dv = Derivation("spherical22", "Spherical joint, markers (2,2): eqs. (14)-(17)", SOURCE)
    J = sp.Matrix([r * c_theta, r * s_theta, d])
    R = rotation()
    B1 = J + rho1 * R[:, 0]
    B2 = J + rho2 * (c_gamma * R[:, 0] + s_gamma * R[:, 1])
    forward = sp.Matrix([*B1, *B2])
    L2 = rho1**2 + rho2**2 - 2 * rho1 * rho2 * c_gamma          # |B1B2|², constant on the output set
    dv.results.update(forward=forward, centre=J, L2=L2)
    dv.steps.append(Step(
        "Output set",
        "A1 is the origin of F and A2 is on +z. The centre J is on the circle Γ(d, r); the triangle "
        "J B1 B2 is rigid (sides ρ1, ρ2, angle γ at J) and turns about J by R(φ, ψ, ξ).",
        [("J", J), ("B_1", B1), ("B_2", B2)]))
    on_set = dict(zip(SAMPLE, forward))

    # -- (15), (14): the two sphere conditions are linear in (cos θ, sin θ) ------------------------
    b1, b2 = sp.Matrix([x1, y1, z1]), sp.Matrix([x2, y2, z2])
    Jg = sp.Matrix([r * c_theta, r * s_theta, d])
    sph1 = sp.expand(((b1 - Jg).T * (b1 - Jg))[0] - rho1**2)
    sph2 = sp.expand(((b2 - Jg).T * (b2 - Jg))[0] - rho2**2)
    H = sp.expand(reduce_circle(sph1 + 2 * r * (x1 * c_theta + y1 * s_theta), TRIG) / 2)
    G = sp.expand(reduce_circle(sph2 + 2 * r * (x2 * c_theta + y2 * s_theta), TRIG) / 2)
    # sphere_k = 0  ⇔  x_k cos θ + y_k sin θ = H_k / r
    for name, mine, theirs in (("H", H, printed.H), ("G", G, printed.G)):
        dv.add_check(name=name, where="(15)", printed=theirs, derived=mine, agrees=equal(mine, theirs))
    delta = x1 * y2 - x2 * y1
    cos_t = (H * y2 - G * y1) / (r * delta)
    sin_t = (G * x1 - H * x2) / (r * delta)
    solved = all(equal(e.subs({c_theta: cos_t, s_theta: sin_t}), 0) for e in
                 (x1 * c_theta + y1 * s_theta - H / r, x2 * c_theta + y2 * s_theta - G / r))
    eq14 = sp.expand((H * y2 - G * y1) ** 2 + (G * x1 - H * x2) ** 2 - r**2 * delta**2)
    dv.add_check(name="eq14", where="(14)", printed=printed.EQ14, derived=eq14,
                 agrees=solved and equal(eq14, printed.EQ14))
    # (14) on the output set: H = r(x1 c + y1 s), G = r(x2 c + y2 s) there, so H y2 − G y1 = r δ c and
    # G x1 − H x2 = r δ s, and (14) = r²δ²(c² + s² − 1).
    on_H = reduce_circle(sp.expand((H - r * (x1 * c_theta + y1 * s_theta)).subs(on_set)), TRIG) == 0
    on_G = reduce_circle(sp.expand((G - r * (x2 * c_theta + y2 * s_theta)).subs(on_set)), TRIG) == 0
    hc, gc = sp.symbols("h_c g_c")
    chain = sp.expand(((hc * y2 - gc * y1) ** 2 + (gc * x1 - hc * x2) ** 2 - r**2 * delta**2).subs(
        {hc: r * (x1 * c_theta + y1 * s_theta), gc: r * (x2 * c_theta + y2 * s_theta)}))
    chain_ok = reduce_circle(chain, TRIG) == 0
    vanishes = on_H and on_G and chain_ok
    dv.results["eq14"] = eq14
    dv.add_check(name="eq14_on_output_set", where="(14)", printed="(14) holds for every sample",
                 derived="H − r(x1 cosθ + y1 sinθ), G − r(x2 cosθ + y2 sinθ) ≡ 0 on the output set and (14) = "
                         "r²δ²(cos²θ + sin²θ − 1) there" if vanishes else "does not vanish", agrees=vanishes)
    dv.results["theta_cs"] = (cos_t, sin_t)
    dv.steps.append(Step(
        "Eliminating θ: (14), (15)",
        "Each sphere |B_k − J| = ρ_k is linear in (cos θ, sin θ): x1 cos θ + y1 sin θ = H/r, "
        "x2 cos θ + y2 sin θ = G/r. Solving (δ ≠ 0) and using cos²θ + sin²θ = 1 gives (14). "
        "On the output set (14) reduces to r²δ²(cos²θ + sin²θ − 1) = 0.",
        [("H", H), ("G", G), ("\\cos\\theta", cos_t), ("\\sin\\theta", sin_t)]))

    # -- (16), (17): the unknowns the expansion actually has -------------------------------------
    in_P = sp.expand(eq14.subs({rho1**2: d**2 + r**2 - P1, rho2**2: d**2 + r**2 - P2}))
    M10, Y10, K = linear_form_in_parameters(in_P, (d, r, P1, P2))
    to_params = {P1: d**2 + r**2 - rho1**2, P2: d**2 + r**2 - rho2**2}
    Y10_params = [sp.expand(y.subs(to_params)) for y in Y10]
    printed_set = [sp.expand(y) for y in printed.Y17]
    missing = [y for y, yp in zip(Y10, Y10_params)
               if not any(equal(yp, q) for q in printed_set)]
    extra = [q for q in printed_set if not any(equal(q, yp) for yp in Y10_params)]
    covered = not missing and not extra
    dv.add_check(name="Y17_covers_expansion", where="(16)-(17)",
                 printed="Y1..Y9 of (17)", derived=f"{len(Y10)} unknown monomials: "
                 + ", ".join(str(y) for y in Y10) + (f"; (17) lacks {', '.join(map(str, missing))}" if missing else ""),
                 agrees=covered, erratum=None if covered else "E4",
                 witness={"missing": [str(m) for m in missing],
                          "its_column": [str(M10[Y10.index(m)]) for m in missing]} if missing else None)

    # -- relations among the columns on the output set ------------------------------------------
    dist2 = sp.expand(((b1 - b2).T * (b1 - b2))[0])
    Lsym = sp.Symbol("L2", positive=True)
    rel_L = polynomial_relations(M10, [(sp.Integer(1), sp.Integer(1)), (dist2, Lsym)], SAMPLE)
    rigid = reduce_circle(sp.expand((dist2 - L2).subs(on_set)), TRIG) == 0
    dv.results["expansion"] = {"unknowns": Y10, "M": M10, "relations": rel_L, "L2_symbol": Lsym,
                               "meaning": "sum_k c_k * M_k = 0 on the output set, where L2 = |B1 - B2|^2"}
    dv.add_check(name="rigid_link", where="IV-C", printed="(B1 and B2 sit on one rigid link)",
                 derived="|B1 − B2|² − L² ≡ 0 on the output set" if rigid else "not constant", agrees=rigid)
    n_rel = len(rel_L)
    dv.add_check(name="expansion_rank", where="(16)", printed=f"{printed.CLAIM_S22_SAMPLES} independent unknowns",
                 derived=f"{len(Y10)} monomials with {n_rel} linear relation(s) on the output set: "
                         f"rank ≤ {len(Y10) - n_rel}", agrees=covered and n_rel == 0, erratum=None if n_rel == 0 else "E5")

    # -- reparametrise: eliminate one column per relation --------------------------------------
    M9, Y9 = list(M10), list(Y10_params)
    subs_L = {Lsym: L2}
    for rel in rel_L:
        k = _pivot(rel, Y10)
        ck = rel[k]
        for i in range(len(Y9)):
            if i != k:
                Y9[i] = sp.expand(Y9[i] - (rel[i] / ck).subs(subs_L) * Y9[k])
        Y9[k] = None
    keep = [i for i, yv in enumerate(Y9) if yv is not None]
    M9 = [M10[i] for i in keep]
    Y9 = [sp.factor(Y9[i]) for i in keep]
    # M9·Y9 − K = (14) − Y_k·(Σ c_i M_i)/c_k, and Σ c_i M_i = (L² − |B1B2|²)·(…) vanishes on the set
    identity = sp.expand(sum(m * yv for m, yv in zip(M9, Y9)) - K - eq14)
    residual = sp.expand(identity.subs(c_gamma, (rho1**2 + rho2**2 - Lsym) / (2 * rho1 * rho2)))
    divides = sp.rem(sp.Poly(sp.expand(sp.fraction(sp.together(residual))[0]), Lsym),
                     sp.Poly(Lsym - dist2, Lsym)).is_zero
    dv.results.update(M=M9, Y=Y9, K=K, invariants={}, identity_proved=divides and vanishes and rigid)
    dv.add_check(name="identity_on_output_set", where="(16)", printed="M·Y = K on S",
                 derived="M·Y − K − (14) is a multiple of L² − |B1 − B2|², zero on the output set"
                 if divides else "does not vanish", agrees=divides and vanishes and rigid)
    dv.steps.append(Step(
        "The linear form (16): what the expansion says",
        "Write H, G with P1 = d² + r² − ρ1², P2 = d² + r² − ρ2² (the printed Y1, Y2) and expand (14) in "
        "(d, r, P1, P2). Every parameter monomial that occurs is an unknown. The expansion has "
        f"{len(Y10)} of them, including d², which (17) omits (erratum E4). A search over rational "
        "combinations of the columns, with coefficients 1 or |B1 − B2|², finds the relation(s) below. "
        "Since |B1 − B2|² = L² on the output set, the columns are dependent there (erratum E5). "
        "Eliminating one column per relation gives the unknowns of the full-rank system.",
        [("Y_{expansion}", sp.Matrix(Y10)), ("relations", sp.Matrix(rel_L)),
         ("M", sp.Matrix([M9])), ("Y", sp.Matrix(Y9)), ("K", K)]))

    _back_substitution(dv, Y9)
    return dv


def _pivot(rel, unknowns) -> int:
    """The column to eliminate: a numeric non-zero coefficient, preferring an unknown of degree 2."""
    numeric = [i for i, c in enumerate(rel) if c != 0 and c.is_number]
    numeric.sort(key=lambda i: (-sp.Poly(unknowns[i], d, r, P1, P2).total_degree(), str(unknowns[i])))
    if not numeric:
        raise RuntimeError("no column with a numeric relation coefficient to eliminate")
    # prefer r² (its column is −δ², and every other unknown then stays a function of d, P1, P2)
    for i in numeric:
        if unknowns[i] == r**2:
            return i
    return numeric[0]


def _back_substitution(dv: Derivation, Y9) -> None:
    """Recover (d, r², ρ1², ρ2²) from the solved unknowns Z, one linear step at a time.

    Each step takes an unknown that is linear in exactly one of the still-unknown quantities
    once the known ones are substituted; the unknowns left over are consistency conditions.
    Linear steps mean a unique joint: the derivation records whether every step was linear.
    """
    Z = sp.symbols(f"Z1:{len(Y9) + 1}", real=True)
    sq = {"r2": sp.Symbol("r2"), "rho1_2": sp.Symbol("rho1_2"), "rho2_2": sp.Symbol("rho2_2")}
    to_sq = {r**2: sq["r2"], rho1**2: sq["rho1_2"], rho2**2: sq["rho2_2"]}
    targets = [d, sq["r2"], sq["rho1_2"], sq["rho2_2"]]
    eqs = [sp.expand(y.subs(to_sq)) - z for y, z in zip(Y9, Z)]
    known, used, linear = {}, [], True
    while len(known) < len(targets):
        steps = []  # (needs a division?, equation, quantity)
        for i, e in enumerate(eqs):
            e2 = sp.expand(e.subs(known))
            if i in used or e2.has(rho1, rho2, c_gamma):
                continue
            free = [t for t in targets if t not in known and e2.has(t)]
            if len(free) == 1 and sp.Poly(e2, free[0]).degree() == 1:
                steps.append((not sp.Poly(e2, free[0]).LC().is_number, i, free[0], e2))
        if not steps:
            linear = False
            break
        _, i, t, e2 = min(steps, key=lambda s_: s_[:2])  # prefer steps without a division
        known[t] = sp.expand(sp.solve(e2, t)[0])
        used.append(i)
    back = {"d": known.get(d), "r2": known.get(sq["r2"]), "rho1_2": known.get(sq["rho1_2"]),
            "rho2_2": known.get(sq["rho2_2"]), "Z": Z, "used": used}
    truth = {Z[i]: Y9[i] for i in range(len(Y9))}
    exact = linear and all(equal(back[k].subs(truth), v) for k, v in
                           (("d", d), ("r2", r**2), ("rho1_2", rho1**2), ("rho2_2", rho2**2)))
    dv.results["back"] = back
    dv.results["unique"] = exact
    dv.add_check(name="back_substitution", where="after (17)",
                 printed="9-identifiability 'using the same arguments as in III-A' (a polynomial root selection)",
                 derived=("d, r², ρ1², ρ2² follow linearly from unknowns " + ", ".join(f"Z{i + 1}" for i in used)
                          + ": no root selection, a unique joint" if exact else "not recovered linearly"),
                 agrees=exact)
    dv.steps.append(Step(
        "Back-substitution: a unique joint",
        "Each parameter follows linearly from one solved unknown (the others are consistency "
        "conditions), so a full-rank system gives exactly one (d, r, ρ1, ρ2) with r, ρ1, ρ2 > 0. "
        "The centre in each sample then follows from cos θ, sin θ above.",
        [(str(k), v) for k, v in back.items() if k in ("d", "r2", "rho1_2", "rho2_2")]))
