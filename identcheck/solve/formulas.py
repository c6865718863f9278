"""Which derived expressions each closed-form solver evaluates (SymPy; imported only to generate code).

For every case this names the functions its solver calls: the derivation's expressions and the argument
groups they take (symbol order is data: the solvers pass arrays in this order), plus a few plain facts
the solver needs of the derivation (which column of M is constant, how many unknowns the linear system
has). It is the single list from which :mod:`identcheck.solve.generated.writer` prints the committed
modules, and from which :mod:`identcheck.solve.generated` generates the functions at run time when a
committed module is stale. Nothing here runs when the committed modules are current.
"""
from __future__ import annotations

from typing import NamedTuple


class Formulas(NamedTuple):
    """The functions of one case, ``{name: _Spec}``, and its plain ``facts`` (numbers, by name)."""

    functions: dict
    facts: dict


class _Spec(NamedTuple):
    """One function: its expressions and argument groups (tuples of symbols)."""

    exprs: list
    groups: list


def _trig(angles) -> list:
    """The (cos, sin) symbols of ``angles``, in order."""
    return [s for a in angles for s in (a.cos, a.sin)]


def revolute21(disk_cache: bool = True) -> Formulas:
    """Revolute (2,1), :mod:`identcheck.derive.revolute`: rows of (10), the cubic (13), the
    back-substitution, per-sample θ and β, the forward map and the axis distance."""
    from identcheck import derive
    from identcheck.symbols import Q, Z, case, cos_sign, l as l_sym

    cs = case("revolute", 2, 1)
    dv = derive.for_case(cs, disk_cache=disk_cache)
    sample = cs.sample
    inv = dv.result("invariants")
    par = cs.parameter_symbols  # (d, r, l, rho, c_alpha, s_alpha)
    vars_ = _trig(cs.variables)  # (c_theta, s_theta, c_beta, s_beta)
    back = dv.result("back")
    rho2 = back["rho2"].subs(back["l"], l_sym)  # ρ² in terms of l itself, see revolute21.cos_and_l
    if rho2.has(cos_sign):
        raise AssertionError("rho2 must depend on the sign of cos α only through l")
    h, dist2 = dv.result("axis_distance2")
    M = dv.result("M")
    const = [i for i, m in enumerate(M) if m.is_number and m != 0]
    if len(const) != 1:
        raise AssertionError(f"expected one constant column in M, found {const}")
    return Formulas({
        "m_row": _Spec([e.subs(inv) for e in M] + [dv.result("K").subs(inv)], [sample]),
        "cubic": _Spec(dv.result("cubic").all_coeffs(), [Z]),
        "back": _Spec([back[k] for k in ("r2", "sin2_alpha", "w", "v")], [(Q,), Z]),
        "rho2": _Spec([rho2], [(Q,), Z, (l_sym,)]),
        "theta": _Spec(dv.result("theta_cs"), [sample, par]),
        "local": _Spec(list(dv.result("local")), [sample, par, vars_[:2]]),
        "forward": _Spec(list(dv.result("forward")), [par, vars_]),
        "dist2": _Spec([dist2], [(h,), par]),
    }, {"constant_column": const[0]})


def spherical22(disk_cache: bool = True) -> Formulas:
    """Spherical (2,2), :mod:`identcheck.derive.spherical22`: rows of the full-rank linear system,
    the back-substitution, per-sample θ and the forward map."""
    from identcheck import derive
    from identcheck.symbols import case, d, r, rho1, rho2

    cs = case("spherical", 2, 2)
    dv = derive.for_case(cs, disk_cache=disk_cache)
    back = dv.result("back")
    par = (d, r, rho1, rho2)
    gamma = cs.constant_angles[0]
    return Formulas({
        "m_row": _Spec(list(dv.result("M")) + [dv.result("K")], [cs.sample]),
        "back": _Spec([back[k] for k in ("d", "r2", "rho1_2", "rho2_2")], [back["Z"]]),
        "theta": _Spec(list(dv.result("theta_cs")), [cs.sample, par]),
        "forward": _Spec(list(dv.result("forward")), [par + (gamma.cos, gamma.sin), _trig(cs.variables)]),
    }, {"n_unknowns": len(dv.result("Y"))})


def spherical31(disk_cache: bool = True) -> Formulas:
    """Spherical (3,1), :mod:`identcheck.derive.spherical31`: rows of the sphere's linear system, the
    centre and radius, and the forward map."""
    from identcheck import derive
    from identcheck.symbols import case

    cs = case("spherical", 3, 1)
    dv = derive.for_case(cs, disk_cache=disk_cache)
    back = dv.result("back")
    inv = dv.result("invariants")
    return Formulas({
        "m_row": _Spec([e.subs(inv) for e in dv.result("M")] + [dv.result("K").subs(inv)], [cs.sample]),
        "back": _Spec([back[k] for k in ("x_J", "y_J", "z_J", "rho2")], [back["Z"]]),
        "forward": _Spec(list(dv.result("forward")), [cs.constants, _trig(cs.variables)]),
    }, {})


CASES = {"revolute21": revolute21, "spherical22": spherical22, "spherical31": spherical31}
