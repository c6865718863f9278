"""The non-identifiable cases of Pham et al.: revolute (1,1) (III-B) and spherical (2,1) (IV-B).

Revolute (1,1): with A at distance r from the hinge, B at distance ρ and axial offset l, the only
thing a sample shows is |AB|² = r² + ρ² + l² − 2rρ cos β (proved below). The output set is the
shell between the radii √((r ∓ ρ)² + l²); the paper's family r − δ, ρ + δ keeps the outer radius
and needs samples beyond its Δ = √((r − ρ − 2δ)² + l²), while the family with r'ρ' = rρ and
r'² + ρ'² + l'² = r² + ρ² + l² keeps both radii: the same output set (identity below).

Spherical (2,1): B is reproduced by the centre circle Γ' (radius r', height d about A1A2) and
radius ρ' iff (R − r')² + h² ≤ ρ'² ≤ (R + r')² + h², R = B's distance to the A1A2 line,
h = B's height above Γ's plane. For r' = r − δ, ρ' = ρ + δ the left side always holds (proved),
the right side not for every B of the output set when ρ > r (ERRATA E7, exact witness below).
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from identcheck.symbols import c_beta, c_theta, d, l, r, rho, s_beta, s_theta
from identcheck.derive.algebra import equal, reduce_circle
from identcheck.derive.base import Derivation, Step

SOURCE = "Pham et al., sections III-B and IV-B"


@lru_cache(maxsize=1)
def derive() -> Derivation:
    """Run both derivations once (cached); see the module docstring."""
    dv = Derivation("counterexamples", "Non-identifiable cases: revolute (1,1) and spherical (2,1)", SOURCE)
    _revolute11(dv)
    _spherical21(dv)
    return dv


def _revolute11(dv: Derivation) -> None:
    trig = ((c_beta, s_beta),)
    a = sp.Matrix([r, 0, 0])                                   # A in the hinge frame (hinge = z axis)
    b = sp.Matrix([rho * c_beta, rho * s_beta, l])             # B turned by β about the hinge
    D2 = reduce_circle(sp.expand(((b - a).T * (b - a))[0]), trig)
    shell = r**2 + rho**2 + l**2 - 2 * r * rho * c_beta
    ok = equal(D2, shell, trig)
    dv.add_check(name="revolute11_distance", where="III-B", printed="(1,1): a sample only shows B relative to A",
                 derived="|AB|² = r² + ρ² + l² − 2rρ cos β, so the output set is the shell "
                         "√((r−ρ)²+l²) ≤ |AB| ≤ √((r+ρ)²+l²)" if ok else "not proved", agrees=ok)
    r2, rho2, l2, delta = sp.symbols("r' rho' l' delta", real=True)
    same = {"product": r2 * rho2 - r * rho, "sum": r2**2 + rho2**2 + l2**2 - r**2 - rho**2 - l**2}
    D2p = shell.subs({r: r2, rho: rho2, l: l2}, simultaneous=True)
    # |AB|² of the alternative at the same cos β differs by a combination of the two invariants only
    exact = sp.expand(D2p - shell - same["sum"] + 2 * c_beta * same["product"]) == 0
    inner = sp.expand((r2 - rho2) ** 2 + l2**2 - ((r - rho - 2 * delta) ** 2 + l**2)).subs(
        {r2: r - delta, rho2: rho + delta, l2: l})
    outer = sp.expand((r2 + rho2) ** 2 + l2**2 - ((r + rho) ** 2 + l**2)).subs({r2: r - delta, rho2: rho + delta, l2: l})
    paper_ok = sp.expand(inner) == 0 and sp.expand(outer) == 0
    dv.add_check(name="revolute11_paper_family", where="III-B",
                 printed="r' = r − δ, ρ' = ρ + δ reproduces every sample farther than some Δ from A",
                 derived="outer radius unchanged, inner radius √((r − ρ − 2δ)² + l²): true with that Δ (all samples "
                         "when 0 ≤ δ ≤ r − ρ)" if paper_ok else "not proved", agrees=paper_ok)
    dv.add_check(name="revolute11_exact_family", where="III-B (extension)",
                 printed="(not in the paper)", derived="r'ρ' = rρ and r'² + ρ'² + l'² = r² + ρ² + l² give the same "
                 "shell: every sample, no Δ" if exact else "not proved", agrees=exact)
    dv.results["revolute11"] = {"distance2": D2, "invariants": (r * rho, r**2 + rho**2 + l**2)}
    dv.steps.append(Step(
        "Revolute (1,1): only |AB| is seen",
        "With one marker per link the parent's orientation is free per sample, so a sample is B − A up to "
        "rotation: only |AB| counts. It depends on the constants through rρ and r² + ρ² + l² only, a one-parameter "
        "family of joints with the same output set. The paper's r − δ, ρ + δ changes rρ, so it reproduces only "
        "the samples beyond the new inner radius (its Δ).",
        [("|AB|^2", shell), ("\\text{inner}'^2", (r - rho - 2 * delta) ** 2 + l**2)]))


def _spherical21(dv: Derivation) -> None:
    R, h, delta, phi = sp.symbols("R h delta phi", real=True)
    trig = ((c_theta, s_theta),)
    B = sp.Matrix([R, 0, h + d])                               # B in the half-plane of A1A2 through it
    J = sp.Matrix([r * c_theta, r * s_theta, d])               # the centre on Γ
    dist2 = reduce_circle(sp.expand(((B - J).T * (B - J))[0]), trig)
    ok = equal(dist2, R**2 + r**2 - 2 * R * r * c_theta + h**2, trig)
    dv.add_check(name="spherical21_circle_distance", where="IV-B", printed="J on Γ with |BJ| = ρ",
                 derived="|BJ|² = R² + r² − 2Rr cos θ + h²: B is reproduced iff (R−r)² + h² ≤ ρ² ≤ (R+r)² + h²"
                 if ok else "not proved", agrees=ok)
    # the left inequality survives r → r − δ, ρ → ρ + δ: the slack grows by 2δ(ρ − (R − r)) ≥ 0
    slack = sp.expand(((rho + delta) ** 2 - (R - r + delta) ** 2 - h**2) - (rho**2 - (R - r) ** 2 - h**2))
    left_ok = equal(slack, 2 * delta * (rho - (R - r)))
    dv.add_check(name="spherical21_inner", where="IV-B",
                 printed="Γ' meets the sphere of radius ρ' about B (lower bound)",
                 derived="(ρ+δ)² − (R−r+δ)² − h² = [ρ² − (R−r)² − h²] + 2δ(ρ − (R − r)) ≥ 0, as ρ ≥ |R − r| on the "
                         "output set" if left_ok else "not proved", agrees=left_ok)
    # the printed claim for every B ∈ S: exact witness on the A1A2 axis
    wit = {r: 3, rho: 5, d: 0, R: 0, h: 4, delta: sp.Rational(1, 2)}
    on_set = (R**2 + r**2 - 2 * R * r * sp.cos(phi) + h**2 - rho**2).subs(wit) == 0   # every θ: |BJ| = ρ
    reach = [((R - r + delta) ** 2 + h**2).subs(wit), ((R + r - delta) ** 2 + h**2).subs(wit), ((rho + delta) ** 2).subs(wit)]
    fails = on_set and not (reach[0] <= reach[2] <= reach[1])
    dv.add_check(name="spherical21_every_sample", where="IV-B",
                 printed="for an arbitrary B ∈ S, Γ' (radius r − δ) meets the sphere of radius ρ + δ about B; S ∩ S' = S",
                 derived="false when ρ > r: samples near the A1A2 axis are lost; true for every sample iff "
                         "ρ + δ ≤ r − δ, otherwise for samples with R ≥ ρ − r + 2δ",
                 agrees=not fails, erratum="E7" if fails else None,
                 witness={"r": "3", "rho": "5", "d": "0", "delta": "1/2", "B": "(0, 0, 4)",
                          "|BJ| for every J on Gamma": "5 = rho", "distance from B to Gamma'": "sqrt(89)/2 ≈ 4.717",
                          "rho'": "11/2"})
    dv.results["spherical21"] = {"distance2": dist2}
    dv.steps.append(Step(
        "Spherical (2,1): which samples the paper's family keeps",
        "The centre runs on the circle Γ; a sample B is reproduced by (r', ρ') iff the sphere of radius ρ' about B "
        "meets the circle of radius r'. Shrinking r by δ and growing ρ by δ keeps the near side; the far side "
        "fails for samples close to the A1A2 axis when ρ > r (e.g. r = 3, ρ = 5, B = (0, 0, 4) on the axis is at "
        "distance 5 from all of Γ but √89/2 < 11/2 from all of Γ'). The conclusion stands, since the samples with "
        "R ≥ ρ − r + 2δ have positive measure.",
        [("|BJ|^2", R**2 + r**2 - 2 * R * r * sp.Symbol("cos(theta)") + h**2)]))
