"""Revolute joint, two markers on the parent and one on the child (Pham et al., section III-A).

From the Denavit–Hartenberg parametrisation of the hinge axis seen from the parent's two
markers, eliminate the per-sample angles θ (the unobservable roll of the parent about its
marker axis) and β (the joint angle) to obtain one equation per sample that is linear in five
functions Y of the constant parameters (eqs. 2–9); solve the system (12) for the constants
through a cubic (13); recover θ and β per sample. Every step is proved by exact polynomial
reduction modulo cos² + sin² − 1, and every printed equation is checked against it.

The root analysis at the end is the derivation's own: it proves that the "extraneous" root of
(13) is a second, genuine joint (see derivations/ERRATA.md, E1).
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from identcheck.symbols import A, B, Q, R2, Z, c_alpha as ca, c_beta as cb, c_theta as ct, case, cos_sign, d, l, r, rho, s_alpha as sa, s_beta as sb, s_theta as st, x, y, z
from identcheck.derive import printed
from identcheck.derive.algebra import equal, linear_form, reduce_circle
from identcheck.derive.base import Derivation, Step

CASE = case("revolute", 2, 1)
TRIG = CASE.trig_pairs
SOURCE = "Pham et al., section III-A, eqs. (2)-(13)"


def dh_matrix() -> sp.Matrix:
    """The Denavit–Hartenberg matrix D(θ; d, r, α) of the hinge axis in the frame F."""
    return sp.Matrix([
        [ct, -st * ca, st * sa, r * ct],
        [st, ct * ca, -ct * sa, r * st],
        [0, sa, ca, d],
        [0, 0, 0, 1],
    ])


@lru_cache(maxsize=1)
def derive() -> Derivation:
    """Run the whole derivation once (cached); see the module docstring."""
    dv = Derivation("revolute21", "Revolute joint, markers (2,1): eqs. (2)-(13)", SOURCE)
    Qdef = printed.Q_DEF

    # -- the output set --------------------------------------------------------------------
    D = dh_matrix()
    O = (D * sp.Matrix([0, 0, l, 1]))[:3, 0]
    axis = D[:3, 2]
    forward = (D * sp.Matrix([rho * cb, rho * sb, l, 1]))[:3, 0]
    dv.results["forward"] = forward
    dv.results["axis"] = axis
    dv.results["foot"] = D[:3, 3]
    dv.steps.append(Step(
        "Output set",
        "The parent's markers A1, A2 lie on the z axis of F (A1 at the origin). The hinge axis is "
        "z_θ of the DH frame D; the child marker B turns on a circle of radius ρ about it, centred "
        "at O_θ = D(0,0,l,1)ᵀ, at joint angle β. θ is the unobservable roll of the parent about "
        "A1A2, so it changes from sample to sample.",
        [("D", D), ("O_\\theta", O), ("B(\\theta,\\beta)", forward)]))
    dv.add_check(name="O_theta", where="text above (2)", printed=printed.O_THETA, derived=O,
                 agrees=all(equal(a, b, TRIG) for a, b in zip(printed.O_THETA, O)))

    # -- (2), (3): the circle conditions ----------------------------------------------------
    p = sp.Matrix([x, y, z])
    eq2 = ((p - O).T * (p - O))[0] - rho**2
    eq3 = ((p - O).T * axis)[0]
    on_set = dict(zip((x, y, z), forward))
    for name, mine, theirs in (("eq2", eq2, printed.EQ2), ("eq3", eq3, printed.EQ3)):
        vanishes = reduce_circle(mine.subs(on_set), TRIG) == 0
        dv.add_check(name=name, where=f"({name[2:]})", printed=theirs, derived=mine,
                     agrees=equal(mine, theirs, TRIG) and vanishes,
                     note="vanishes exactly on the parametrised output set" if vanishes else "")

    # -- (4), (5): eliminate beta, then theta ------------------------------------------------
    # write x, y through A = x sinθ - y cosθ and B = x cosθ + y sinθ
    to_AB = {x: A * st + B * ct, y: -A * ct + B * st}
    eq3_AB = reduce_circle(eq3.subs(to_AB), TRIG)
    A_of_z = sp.solve(eq3_AB, A)[0]
    dv.add_check(name="eq4", where="(4)", printed=printed.EQ4_A, derived=A_of_z,
                 agrees=equal(A_of_z, printed.EQ4_A, TRIG))
    # x² + y² = A² + B²: write A² through the invariant R² so that (2) is linear in A and B
    eq2_AB = sp.expand(reduce_circle(eq2.subs(to_AB), TRIG).subs(A**2, R2 - B**2 - z**2))
    dv.add_check(name="eq2_developed", where="text after (4)", printed=printed.EQ2_DEVELOPED,
                 derived=eq2_AB, agrees=equal(printed.EQ2_DEVELOPED, eq2_AB, TRIG))
    eq5 = sp.expand(eq2_AB.subs(A, A_of_z))
    eq5_printed = printed.EQ5.subs(Q, Qdef)
    dv.add_check(name="eq5", where="(5)", printed=printed.EQ5, derived=eq5,
                 agrees=equal(eq5, eq5_printed, TRIG))
    dv.steps.append(Step(
        "Eliminating β and θ",
        "Condition (3) is linear in A and gives (4); substituting it in (2) removes A and leaves "
        "(5), linear in B. Both were obtained by reduction modulo cos² + sin² − 1.",
        [("(3)\\Rightarrow A", A_of_z), ("(5)", sp.Eq(eq5, 0))]))

    # -- (6)-(9): square, and split into M·Y = K -----------------------------------------------
    B_of_z = sp.solve(eq5, B)[0]
    xy2 = R2 - z**2  # x² + y², written with the invariant R² so the split is unique
    # (5) says 2rB = R² + Q − 2zd; squaring and B² = x² + y² − A² give E = 0
    assert equal(2 * r * B_of_z - (R2 + Qdef - 2 * z * d), 0, TRIG)
    E = sp.expand((R2 + Qdef - 2 * z * d) ** 2 - 4 * r**2 * (xy2 - A_of_z**2))
    M, Y, K = linear_form(E, (R2, z), TRIG)
    # name the columns as the paper does: match each derived column to the printed monomial
    order = []
    for m_p in printed.M_ROW:
        hits = [i for i, m in enumerate(M) if sp.simplify(m / m_p).is_number]
        order.append(hits[0] if hits else None)
    if None in order or sorted(order) != list(range(len(M))):
        order = list(range(len(M)))
    M = [M[i] for i in order]
    Y = [Y[i] for i in order]
    # prove the identity on the output set: M·Y - K vanishes for x, y, z = B(θ, β)
    sample_subs = {R2: x**2 + y**2 + z**2}
    identity = sum(m.subs(sample_subs) * yy for m, yy in zip(M, Y)) - K.subs(sample_subs)
    proved = reduce_circle(sp.fraction(sp.together(identity.subs(on_set)))[0], TRIG) == 0
    dv.results.update(M=M, Y=Y, K=K, invariants={R2: x**2 + y**2 + z**2}, identity_proved=proved)
    for i, (m_d, m_p) in enumerate(zip(M, printed.M_ROW), start=1):
        dv.add_check(name=f"M{i}", where="(8)", printed=m_p, derived=m_d, agrees=equal(m_d, m_p))
    for i, (y_d, y_p) in enumerate(zip(Y, printed.Y_VEC), start=1):
        y_p = y_p.subs(Q, Qdef)
        dv.add_check(name=f"Y{i}", where="(9)", printed=printed.Y_VEC[i - 1], derived=y_d,
                     agrees=equal(y_d, y_p, TRIG))
    dv.add_check(name="K", where="(9)", printed=printed.K, derived=K, agrees=equal(K, printed.K))
    dv.add_check(name="identity_on_output_set", where="(7)", printed="M·Y = K on S",
                 derived="M·Y − K ≡ 0 mod cos²+sin²−1" if proved else "does not vanish",
                 agrees=proved)
    dv.add_check(name="eq6_equivalence", where="(6)", printed="(5) equivalent to (6) with +sqrt",
                 derived="(5) is equivalent to (6) with ±sqrt: B = x cosθ + y sinθ takes both "
                         "signs (the two θ solving (4)); squaring loses nothing for r > 0",
                 agrees=False, erratum="E3")
    dv.steps.append(Step(
        "The linear form (7)-(9)",
        "With B² = x² + y² − A², squaring (5) gives one polynomial equation per sample. Written in "
        "the rotation invariants R² = x²+y²+z² and z, each monomial carries one function of the "
        "constants: these are the unknowns Y, the monomials the row M, the numeric part K. "
        "The identity M·Y = K was proved on the parametrised output set.",
        [("M", sp.Matrix([M])), ("Y", sp.Matrix(Y)), ("K", K)]))

    # -- (12) -> (13): eliminate r, alpha, l, rho by substitution ------------------------------
    # structured unknowns: r2 = r², S = sin²α, w = cosα (l + d cosα), v = (l + d cosα)²
    r2, S, w, v = sp.symbols("r2 S w v", real=True)
    structured = [d, Q - 2 * r2, Q * d + 2 * r2 * w / S, Q**2 + 4 * r2 * v / S, d**2 + r2 / S]
    struct_subs = {r2: r**2, S: sa**2, w: ca * (l + d * ca), v: (l + d * ca) ** 2, Q: Qdef}
    assert all(equal(s_.subs(struct_subs), y_, TRIG) for s_, y_ in zip(structured, Y))
    sol = {d: Z[0]}
    sol[r2] = sp.solve(structured[1] - Z[1], r2)[0]
    sol[S] = sp.solve((structured[4] - Z[4]).subs(sol), S)[0]
    sol[w] = sp.solve((structured[2] - Z[2]).subs(sol), w)[0]
    sol[v] = sp.solve((structured[3] - Z[3]).subs(sol), v)[0]
    sol = {k: sp.factor(val) for k, val in sol.items()}
    relation = (w**2 - (1 - S) * v).subs(sol)          # cos²α (l + d cosα)² = (1 - sin²α)(...)²
    num = sp.fraction(sp.together(relation))[0]
    cubic = sp.Poly(sp.expand(num), Q)
    cubic = sp.Poly(sp.expand(-cubic.as_expr() / cubic.LC()), Q)  # leading coefficient -1 as printed
    dv.results["cubic"] = cubic
    dv.add_check(name="cubic", where="(13)", printed=printed.CUBIC, derived=cubic.as_expr(),
                 agrees=sp.expand(cubic.as_expr() - printed.CUBIC) == 0)
    dv.steps.append(Step(
        "The cubic (13)",
        "From Ẑ: d = Z1; r² from Z2, sin²α from Z5, w = cosα(l + d cosα) from Z3 and "
        "v = (l + d cosα)² from Z4, all in terms of Q; the relation w² = (1 − sin²α) v is "
        "the cubic in Q.",
        [("r^2", sol[r2]), ("\\sin^2\\alpha", sol[S]), ("w", sol[w]), ("v", sol[v]),
         ("(13)", sp.Eq(cubic.as_expr(), 0))]))

    # -- back-substitution ----------------------------------------------------------------------
    ca_k = cos_sign * sp.sqrt(1 - sol[S])
    l_k = sol[w] / ca_k - Z[0] * ca_k
    rho2_k = sol[r2] + Z[0] ** 2 - l_k**2 - Q
    dv.results["back"] = {"r2": sol[r2], "sin2_alpha": sol[S], "w": sol[w], "v": sol[v],
                          "cos_alpha": ca_k, "l": l_k, "rho2": rho2_k,
                          # when cos α = 0, l = ±sqrt(v) (u = l + d cos α = l)
                          "l_if_cos0": cos_sign * sp.sqrt(sol[v]),
                          "rho2_if_cos0": sol[r2] + Z[0] ** 2 - sol[v] - Q}
    dv.add_check(name="back_r", where="after (13)", printed=printed.BACK_R2, derived=sol[r2],
                 agrees=equal(sol[r2], printed.BACK_R2))
    dv.add_check(name="back_alpha", where="after (13)", printed=printed.BACK_SIN2_ALPHA,
                 derived=sol[S], agrees=equal(sol[S], printed.BACK_SIN2_ALPHA))
    dv.add_check(name="back_l", where="after (13)", printed=printed.BACK_L, derived=sol[w] / ca - Z[0] * ca,
                 agrees=equal(sol[w] / ca - Z[0] * ca, printed.BACK_L))
    rho2_printed = printed.BACK_RHO2_WITH_L.subs({r: sp.sqrt(sol[r2]), d: Z[0], l: l_k}, simultaneous=True)
    dv.add_check(name="back_rho", where="after (13)", printed=printed.BACK_RHO2_WITH_L,
                 derived=rho2_k, agrees=equal(rho2_k, rho2_printed))
    dv.add_check(name="alpha_branches", where="after (13)",
                 printed="alpha_k = asin(sqrt(...)): one alpha per root",
                 derived="sin²α fixes α only up to α → π − α; with l → −l this is the mirror image "
                         "of the joint in the plane of A1, A2, B, which reproduces every sample too",
                 agrees=False, erratum="E2")
    dv.steps.append(Step(
        "Back-substitution",
        "For each root Q_k and each sign σ = ±1 of cos α (the two mirror images):",
        [("r_k^2", sol[r2]), ("\\sin^2\\alpha_k", sol[S]), ("\\cos\\alpha_k", ca_k),
         ("l_k", l_k), ("\\rho_k^2", rho2_k)]))

    # -- per-sample angles θ, β for a given joint ---------------------------------------------
    A_s = A_of_z
    B_s = (x**2 + y**2 + z**2 + Qdef - 2 * z * d) / (2 * r)      # B from (5), proved above
    rxy2 = x**2 + y**2
    theta_cs = ((x * B_s - y * A_s) / rxy2, (x * A_s + y * B_s) / rxy2)
    local = (D[:3, :3].T * (p - D[:3, 3]))
    dv.results["theta_cs"] = theta_cs
    h = sp.Symbol("h", real=True)
    rel = sp.Matrix([0, 0, h]) - D[:3, 3]
    dist2 = reduce_circle(sp.expand((rel.T * rel)[0] - ((rel.T * axis)[0]) ** 2), TRIG)
    assert not dist2.has(ct, st), "distance of a parent marker to the axis must not depend on θ"
    dv.results["axis_distance2"] = (h, sp.factor(dist2))  # squared distance of (0, 0, h) to the axis
    dv.results["local"] = local  # (ρ cosβ, ρ sinβ, l) when the sample is on the joint's output set
    dv.steps.append(Step(
        "Per-sample angles",
        "Given the constants, (4) and (5) give A and B, hence cos θ and sin θ; the sample in the "
        "DH frame is (ρ cos β, ρ sin β, l), which gives β and two residuals that vanish exactly "
        "when the joint reproduces the sample.",
        [("\\cos\\theta", theta_cs[0]), ("\\sin\\theta", theta_cs[1]), ("D^{-1}B", local)]))

    _root_structure(dv, sol, cubic)
    return dv


def _root_structure(dv: Derivation, sol: dict, cubic: sp.Poly) -> None:
    """Prove what the three roots of (13) are, for every joint (erratum E1).

    With Z = Y(d, r, α, l, ρ), W = r²/sin²α, c = cos α, P = Q − d²: the cubic factors as
    −q·g(q) in q = Q' − Q, g(q) = q² + 2(P − Wc²)q − 4W(c²P + l²). Its discriminant is a sum of
    squares, g(2Wc²) = −4Wl² < 0 and g(−2r²) = 4Wρ² > 0, so one root gives sin²α' > 1 (not
    real) and the other gives a real joint with 0 < r'², 0 < sin²α' < 1 and, by the identity
    ρ'²·(2Wc² − q) ≡ r²(2Wc² + 2l² − q) mod g, ρ'² > 0: a second genuine joint.
    """
    Wsym, c, u, q = sp.symbols("W c u q", real=True)
    P = Q - d**2
    lval = u - d * c
    r2true = Wsym * (1 - c**2)
    Zt = {Z[0]: d, Z[1]: Q - 2 * r2true, Z[2]: Q * d + 2 * Wsym * c * u,
          Z[3]: Q**2 + 4 * Wsym * u**2, Z[4]: d**2 + Wsym}
    Qp = sp.Symbol("Qp")

    def at_root(expr):
        """An expression of (Q', Z) with Z = Y(true) and Q' = Q + q."""
        return sp.expand(expr.subs(Q, Qp).subs(Zt, simultaneous=True).subs(Qp, Q + q))

    shifted = at_root(cubic.as_expr())
    g = sp.expand(q**2 + 2 * (P - Wsym * c**2) * q - 4 * Wsym * (c**2 * P + lval**2))
    factor_ok = sp.expand(shifted + q * g) == 0
    disc = sp.expand(sp.discriminant(g, q) - 4 * ((P + Wsym * c**2) ** 2 + 4 * Wsym * lval**2))
    g_top = sp.expand(g.subs(q, 2 * Wsym * c**2) + 4 * Wsym * lval**2)
    rho2true = r2true + d**2 - lval**2 - Q
    g_bottom = sp.expand(g.subs(q, -2 * r2true) - 4 * Wsym * rho2true)
    # the second joint's parameters, in the true ones (from the back-substitution of the derivation)
    back = dv.results["back"]
    S_ok = equal(at_root(back["sin2_alpha"]), (1 - c**2) + q / (2 * Wsym))
    r2_ok = equal(at_root(back["r2"]), r2true + q / 2)
    c2_new = 1 - ((1 - c**2) + q / (2 * Wsym))                     # cos²α' = cos²α − q/(2W)
    lc_ok = equal(at_root(back["w"]) - d * c2_new, lval * c)       # l'cosα' = w' − d cos²α' = l cosα
    # ρ'² = r'² + d² − l'² − Q' with l'² = l²c²/c'², times 2W c'² = 2Wc² − q:
    rho2_times = sp.expand((r2true + q / 2 + d**2 - (Q + q)) * (2 * Wsym * c**2 - q)
                           - 2 * Wsym * (lval * c) ** 2)
    claim = sp.expand(r2true * (2 * Wsym * c**2 + 2 * lval**2 - q))
    rho_ok = sp.rem(sp.expand(rho2_times - claim), g, q) == 0
    proved = all([factor_ok, disc == 0, g_top == 0, g_bottom == 0, S_ok, r2_ok, lc_ok, rho_ok])
    dv.results["roots"] = {"g": g, "proved": proved, "factor": factor_ok, "discriminant": disc == 0,
                           "g_at_2Wc2": g_top == 0, "g_at_minus_2r2": g_bottom == 0,
                           "sin2_shift": S_ok, "r2_shift": r2_ok, "l_cos_invariant": lc_ok, "rho2_identity": rho_ok}
    dv.steps.append(Step(
        "Which roots of (13) are joints (erratum E1)",
        "Put W = r²/sin²α, c = cos α, P = Q − d², and q = Q' − Q for a root Q'. Substituting "
        "Z = Y(true) proves that the cubic factors as −q·g(q), with discriminant "
        "4[(P + Wc²)² + 4Wl²] ≥ 0: all three roots are real. Moreover g(2Wc²) = −4Wl² < 0 and "
        "g(−2r²) = 4Wρ² > 0. So the larger root q₊ exceeds 2Wc², giving sin²α' = sin²α + q/(2W) > 1 "
        "(no real joint), while the smaller root q₋ lies in (−2r², 2Wc²): r'² = r² + q₋/2 > 0 and "
        "0 < sin²α' < 1. Finally l'cos α' = l cos α and ρ'²(2Wc² − q) ≡ r²(2Wc² + 2l² − q) mod g, "
        "so ρ'² > 0. The root q₋ is therefore a second real joint, and it satisfies (7) with the same Y. "
        "Every real point of the quartic (7) lies on the output set of either joint (x² + y² − A² = "
        "(R² + Q − 2zd)²/4r² ≥ 0), so the two output sets are the same surface and no number of "
        "samples can tell the joints apart. With mirror images that makes 4 joints.",
        [("g(q)", g), ("\\rho'^2 (2Wc^2 - q)", sp.Symbol("r^2") * (2 * Wsym * c**2 + 2 * lval**2 - q))]))
    dv.add_check(name="root_structure_proof", where="(13)", printed="(not in the paper)",
                 derived="all eight identities of the root analysis reduce to 0" if proved else
                 "an identity of the root analysis failed: " + ", ".join(k for k, v in dv.results["roots"].items()
                                                                       if v is False),
                 agrees=proved)
    dv.add_check(name="root_extraneous", where="after (13)",
                 printed=f"{printed.CLAIM_EXTRANEOUS_ROOTS} root extraneous (fails (5))",
                 derived="0 roots extraneous: q₋ is a real joint whose output set equals the true one",
                 agrees=False, erratum="E1")
    dv.add_check(name="root_nonreal", where="after (13)",
                 printed=f"{printed.CLAIM_NONREAL_ROOTS} root gives non-real values",
                 derived="q₊ gives sin²α > 1 for every joint with l ≠ 0 (proved)" if g_top == 0 else "not proved",
                 agrees=g_top == 0)
    dv.add_check(name="unique_joint", where="after (13)",
                 printed=f"{printed.CLAIM_JOINTS} joint",
                 derived="2 joint-parameter sets (r, α, l, ρ) and (r', α', l', ρ'), 4 joints with mirror images",
                 agrees=False, erratum="E1")
