"""Spherical joint, three markers on the parent and one on the child (Pham et al., section IV-A).

Three parent markers fix the parent, so the joint centre J is a constant point of the frame F
and the child marker B moves on the sphere of centre J and radius ρ. The sphere equation is
linear in (J, ρ² − |J|²): four samples off a common plane determine it. When the samples are
coplanar every point of the plane's normal through J is equidistant from them — the
degeneracy of the paper's Fig. 3 — which the derivation proves for every such configuration.
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from identcheck.symbols import R2, c_phi, c_psi, case, rho, s_phi, s_psi, x, x_J, y, y_J, z, z_J
from identcheck.derive.algebra import equal, linear_form, reduce_circle
from identcheck.derive.base import Derivation, Step

CASE = case("spherical", 3, 1)
TRIG = CASE.trig_pairs
SOURCE = "Pham et al., section IV-A"


@lru_cache(maxsize=1)
def derive() -> Derivation:
    """Run the whole derivation once (cached); see the module docstring."""
    dv = Derivation("spherical31", "Spherical joint, markers (3,1): the sphere through 4 samples", SOURCE)
    J = sp.Matrix([x_J, y_J, z_J])
    u = sp.Matrix([c_phi * c_psi, s_phi * c_psi, s_psi])   # direction of JB: azimuth φ, elevation ψ
    forward = J + rho * u
    dv.results["forward"] = forward
    dv.steps.append(Step(
        "Output set",
        "Three parent markers fix the parent in F, so the centre J = (x_J, y_J, z_J) is constant; "
        "the child marker B is at distance ρ from J in the direction (φ, ψ), which changes per sample.",
        [("B(\\phi,\\psi)", forward)]))

    p = sp.Matrix([x, y, z])
    sphere = sp.expand(((p - J).T * (p - J))[0] - rho**2)
    on_set = dict(zip((x, y, z), forward))
    vanishes = reduce_circle(sphere.subs(on_set), TRIG) == 0
    dv.add_check(name="sphere_on_output_set", where="IV-A", printed="the output set is a sphere of centre J, radius ρ",
                 derived="|B − J|² − ρ² ≡ 0 mod cos²+sin²−1" if vanishes else "does not vanish", agrees=vanishes)

    E = sp.expand(sphere.subs(x**2, R2 - y**2 - z**2))
    M, Y, K = linear_form(E, (R2, x, y, z), TRIG)
    identity = sum(m * yy for m, yy in zip(M, Y)) - K
    proved = reduce_circle(sp.expand(identity.subs(R2, x**2 + y**2 + z**2).subs(on_set)), TRIG) == 0
    dv.results.update(M=M, Y=Y, K=K, invariants={R2: x**2 + y**2 + z**2}, identity_proved=proved)
    dv.add_check(name="identity_on_output_set", where="IV-A", printed="one linear equation per sample",
                 derived="M·Y − K ≡ 0 on the output set" if proved else "does not vanish", agrees=proved)
    dv.steps.append(Step(
        "The linear form",
        "Expanding |B − J|² = ρ² and collecting the functions of the constants gives one equation per "
        "sample, linear in the four unknowns Y: the centre and ρ² − |J|².",
        [("M", sp.Matrix([M])), ("Y", sp.Matrix(Y)), ("K", K)]))

    # back-substitution: J from the three linear unknowns, ρ² from the fourth
    Zs = sp.symbols("Z1:5", real=True)
    centre = {s: sp.solve(yy - zz, s)[0] for s, yy, zz in zip((x_J, y_J, z_J), Y[:3], Zs[:3])} \
        if all(yy.free_symbols == {s} for s, yy in zip((x_J, y_J, z_J), Y[:3])) else None
    if centre is None:
        raise RuntimeError("spherical (3,1): the first three unknowns are not the centre coordinates")
    rho2 = sp.solve((Y[3] - Zs[3]).subs(centre), rho**2)[0]
    dv.results["back"] = {"x_J": centre[x_J], "y_J": centre[y_J], "z_J": centre[z_J], "rho2": rho2, "Z": Zs}
    back_ok = equal(rho2.subs({Zs[i]: Y[i] for i in range(4)}), rho**2)
    dv.add_check(name="radius_from_centre", where="IV-A",
                 printed="ρ = distance between the centre and any sample",
                 derived="ρ² recovered from Y exactly" if back_ok else "not recovered", agrees=back_ok)

    # the paper's construction: the mediating planes of consecutive samples
    Bs = [sp.Matrix(sp.symbols(f"b{i}x b{i}y b{i}z", real=True)) for i in range(2)]
    row = lambda b: sp.expand(sum(m.subs(R2, (b.T * b)[0]).subs(dict(zip((x, y, z), b))) * yy
                                  for m, yy in zip(M, Y)) - K.subs(R2, (b.T * b)[0]))
    difference = sp.expand(row(Bs[0]) - row(Bs[1]))
    mediating = sp.expand(2 * ((Bs[1] - Bs[0]).T * J)[0] - ((Bs[1].T * Bs[1])[0] - (Bs[0].T * Bs[0])[0]))
    med_ok = equal(difference, mediating) or equal(difference, -mediating)
    dv.add_check(name="mediating_planes", where="IV-A",
                 printed="J is the intersection of the mediating planes of (B1,B2), (B2,B3), (B3,B4)",
                 derived="the difference of two sample rows is the mediating plane of the two samples"
                 if med_ok else "differences are not the mediating planes", agrees=med_ok)

    _coplanar_degeneracy(dv)
    dv.steps.append(Step(
        "Uniqueness and the coplanar degeneracy",
        "Differences of rows are the mediating planes of pairs of samples, so four samples off a common "
        "plane give a unique centre and ρ = |B − J|. If the samples lie in a plane with unit normal n, "
        "then for every t the point J + t·n is equidistant from all of them (proved below): a line of "
        "centres, the rank of M drops to 3, and the centre is not identifiable from that motion.",
        [("|B - (J + t n)|^2", sp.Symbol("rho")**2 + sp.Symbol("t")**2
          - 2 * sp.Symbol("t") * sp.Symbol("(n\\cdot B_0 - n\\cdot J)"))]))
    return dv


def _coplanar_degeneracy(dv: Derivation) -> None:
    """Prove Fig. 3 (right): for coplanar samples, J + t·n is equidistant from every sample.

    A sample in the plane n·B = c (|n| = 1) satisfies |B − J − t n|² = |B − J|² − 2t(n·B − n·J) + t²
    = ρ² − 2t(c − n·J) + t², the same for every sample of the plane.
    """
    t, c = sp.symbols("t c", real=True)
    n = sp.Matrix(sp.symbols("n1 n2 n3", real=True))
    b = sp.Matrix([x, y, z])
    J = sp.Matrix([x_J, y_J, z_J])
    shifted = ((b - J - t * n).T * (b - J - t * n))[0]
    claim = ((b - J).T * (b - J))[0] - 2 * t * (c - (n.T * J)[0]) + t**2
    # on the plane n·b = c with |n|² = 1: substitute c and |n|² and compare
    diff = sp.expand(shifted - claim.subs(c, (n.T * b)[0]))
    diff = sp.expand(diff.subs(n[2] ** 2, 1 - n[0] ** 2 - n[1] ** 2))
    proved = diff == 0
    dv.results["coplanar_line"] = proved
    dv.add_check(name="coplanar_degeneracy", where="IV-A, Fig. 3 right",
                 printed="coplanar samples: every J' on the normal through J is equidistant",
                 derived="|B − J − t n|² = ρ² − 2t(c − n·J) + t² for every B in the plane n·B = c"
                 if proved else "not proved", agrees=proved)
