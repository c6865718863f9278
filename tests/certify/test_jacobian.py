"""Local identifiability from the exact Jacobian rank (identcheck.certify.jacobian, identcheck.certify.joint_models)."""
from fractions import Fraction
from itertools import product

import pytest
import sympy as sp
from hypothesis import given, settings, strategies as st

from identcheck.certify import jacobian
from identcheck.certify.jacobian import local_identifiability, table_rows, verdict
from identcheck.certify.joint_models import DERIVED, JOINTS, MARKERS, agrees_with_derivation, model
from identcheck.symbols import Angle

CASES = list(product(JOINTS, MARKERS, MARKERS))


@pytest.mark.parametrize("key", sorted(DERIVED))
def test_parametrisation_is_the_derivations_output_set(key):
    assert agrees_with_derivation(model(*key))


@pytest.mark.parametrize("joint,p,q,local,min_samples", [
    ("revolute", 2, 1, True, 5),     # Pham III-A: 5 unknowns, one equation per sample
    ("spherical", 3, 1, True, 4),    # Pham IV-A: the sphere through 4 samples
    # Pham IV-C: the linearised system needs 9 samples (9 unknown monomials), but locally the
    # 4 constants d, r, rho1, rho2 need only 4 equations (14), plus the rigid shape |B1B2| which
    # every sample repeats: 4 samples.
    ("spherical", 2, 2, True, 4),
    ("revolute", 1, 1, False, None),   # Pham III-B
    ("spherical", 2, 1, False, None),  # Pham IV-B
])
def test_known_verdicts(joint, p, q, local, min_samples):
    c = verdict(joint, p, q)
    assert c.local is local and c.min_samples == min_samples and c.stable
    assert c.full_jacobian["minor_nonzero"] and c.full_jacobian["rank"] == c.ranks[-1]["rank_J"]
    if local:   # full column rank at the final N: deterministic
        assert c.deterministic and c.full_jacobian["full_column_rank"] and not c.null_space_constants
        assert c.n_samples == min_samples
    assert float(c.probability_bound) < 1e-6


def test_fixed_sample_count_below_and_at_the_minimum():
    m = model("revolute", 2, 1)
    assert not local_identifiability(m, n_samples=4).local
    c = local_identifiability(m, n_samples=5)
    assert c.local and c.min_samples == 5 and c.deterministic


@pytest.mark.parametrize("joint,p,q", [("revolute", 1, 1), ("spherical", 2, 1)])
def test_paper_family_direction_is_in_the_null_space(joint, p, q):
    """Pham's family r' = r − δ, ρ' = ρ + δ: (r, ρ) → (−1, +1) must be a null direction.

    It is, but it is not singled out: each sample's variable columns already have full row rank
    (the output set is an open subset of R³), so the null space is every constant direction and
    the family is one curve in it; the verdict is deterministic.
    """
    c = verdict(joint, p, q)
    names = c.constants
    null = [[Fraction(v.get(n, "0")) for n in names] for v in c.null_space_constants]
    family = [Fraction({"r": -1, "rho": 1}.get(n, 0)) for n in names]
    assert sp.Matrix(null).rank() == len(names)
    assert sp.Matrix(null + [family]).rank() == sp.Matrix(null).rank()
    assert c.deterministic and not c.local


def test_universal_31_null_space_keeps_centre_and_radius():
    """One child marker on a universal joint moves on a zone of a sphere: J and |JB| are
    identifiable, the axes are not; every null direction fixes x_J, y_J, z_J and |JB|²."""
    c = verdict("universal", 3, 1)
    ok = {i["name"]: i["identifiable"] for i in c.interest}
    assert ok == {"x_J": True, "y_J": True, "z_J": True, "mu": False, "nu": False, "|JB1|^2": True, "h1": False}
    pt = c.points[0]["constants"]
    h1, m1 = Fraction(pt["h1"]), Fraction(pt["m1"])
    assert len(c.null_space_constants) == 3
    for v in c.null_space_constants:
        assert not {"x_J", "y_J", "z_J"} & set(v)
        assert h1 * Fraction(v.get("h1", "0")) + m1 * Fraction(v.get("m1", "0")) == 0


def test_null_space_is_exact():
    """Every reported null direction u of the constants is matched by per-sample variable moves:
    C_i u lies in the column space of V_i for every sample i (exact ranks)."""
    m = model("universal", 1, 3)
    c = verdict("universal", 1, 3)
    pt = jacobian.point(m, c.seed, 0)
    J = jacobian.full_jacobian(m, pt, c.n_samples)
    nc, nv, rows = len(c.constants), len(c.per_sample_variables), c.outputs_per_sample
    assert c.null_space_constants
    for v in c.null_space_constants:
        u = [Fraction(v.get(n, "0")) for n in c.constants]
        for i in range(c.n_samples):
            block = J[i * rows:(i + 1) * rows]
            V = sp.Matrix([[sp.Rational(x.numerator, x.denominator) for x in r[nc + i * nv: nc + (i + 1) * nv]]
                           for r in block])
            Cu = sp.Matrix([sum(r[j] * u[j] for j in range(nc)) for r in block])
            assert V.row_join(Cu.applyfunc(lambda x: sp.Rational(x.numerator, x.denominator))).rank() == V.rank()


@pytest.mark.parametrize("joint,p,q", [("revolute", 2, 1), ("prismatic", 0, 2), ("universal", 1, 1)])
def test_compiled_jacobian_matches_sympy(joint, p, q):
    """The compiled exact entries equal SymPy's derivatives at a rational point."""
    m = model(joint, p, q)
    sym = jacobian.symbolic(m)
    vals = jacobian.point(m, 3, 0).sample_qq(0)
    sub = {g: sp.Rational(int(v.p), int(v.q)) for g, v in zip(sym.gens, vals)}
    cols = list(m.constants) + list(m.constant_angles) + list(m.per_sample_lengths) + list(m.variables)
    for o, row in zip(m.outputs, sym.J1):
        for c, e in zip(cols, row):
            d = (-c.sin * sp.diff(o, c.cos) + c.cos * sp.diff(o, c.sin)) if isinstance(c, Angle) else sp.diff(o, c)
            got = e(vals)
            assert sp.Rational(int(got.p), int(got.q)) == d.xreplace(sub)


@pytest.fixture(scope="module")
def table():
    rows = table_rows()
    return {(r["joint"], r["p"], r["q"]): r for r in rows}


@pytest.mark.slow
def test_table_rows_cover_every_case(table):
    assert set(table) == set(CASES)
    for r in table.values():
        assert set(r) >= {"joint", "p", "q", "local", "min_samples", "certificate"}
        assert r["certificate"]["format"] == jacobian.FORMAT and r["verdict_kind"] == "local"
        assert (r["min_samples"] is not None) == r["local"]
        assert r["certificate"]["stable"]
        assert float(r["certificate"]["probability_bound"]) < 1e-6


def test_no_markers_on_one_side_is_never_identifiable(table):
    for j in JOINTS:
        for k in MARKERS:
            assert not table[(j, 0, k)]["local"] and not table[(j, k, 0)]["local"]


def test_adding_a_marker_never_loses_identifiability(table):
    """Pham Remark 1: (p, q) identifiable ⇒ (p', q) for p' ≥ p, and with symmetry (p, q') for q' ≥ q.
    The engine also finds min_samples non-increasing."""
    for (j, p, q), r in table.items():
        if not r["local"]:
            continue
        for p2, q2 in ((p + 1, q), (p, q + 1)):
            if p2 <= 3 and q2 <= 3:
                bigger = table[(j, p2, q2)]
                assert bigger["local"], (j, p, q, p2, q2)
                assert bigger["min_samples"] <= r["min_samples"], (j, p, q, p2, q2)


def test_symmetry_in_p_and_q(table):
    """Pham Remark 1: (p, q) and (q, p) agree. With a free parent pose per sample (p ≤ 2) the data
    is the configuration of all p + q markers up to a rigid motion, which is symmetric in the two
    links; for p = 0 or q = 0 both sides are non-identifiable (nothing relates the joint to a
    marker of one link). The engine finds the same min_samples too."""
    for (j, p, q), r in table.items():
        other = table[(j, q, p)]
        assert (r["local"], r["min_samples"]) == (other["local"], other["min_samples"]), (j, p, q)


def test_new_joints_expected_verdicts(table):
    got = {(j, p, q): (r["local"], r["min_samples"]) for (j, p, q), r in table.items() if j in ("universal", "prismatic")
           and p and q}
    assert got == {
        ("universal", 1, 1): (False, None), ("universal", 1, 2): (False, None), ("universal", 1, 3): (False, None),
        ("universal", 2, 1): (False, None), ("universal", 2, 2): (True, 4), ("universal", 2, 3): (True, 4),
        ("universal", 3, 1): (False, None), ("universal", 3, 2): (True, 4), ("universal", 3, 3): (True, 4),
        ("prismatic", 1, 1): (False, None), ("prismatic", 1, 2): (True, 3), ("prismatic", 1, 3): (True, 2),
        ("prismatic", 2, 1): (True, 3), ("prismatic", 2, 2): (True, 2), ("prismatic", 2, 3): (True, 2),
        ("prismatic", 3, 1): (True, 2), ("prismatic", 3, 2): (True, 2), ("prismatic", 3, 3): (True, 2),
    }


def test_same_seed_same_certificate():
    m = model("prismatic", 2, 1)
    assert local_identifiability(m, seed=7).to_dict() == local_identifiability(m, seed=7).to_dict()


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 10**9), st.sampled_from([("revolute", 2, 1), ("spherical", 2, 1), ("universal", 3, 1),
                                                ("prismatic", 2, 1), ("spherical", 1, 2)]))
def test_verdict_does_not_depend_on_the_random_point(seed, case):
    ref = verdict(*case)
    c = local_identifiability(model(*case), seed=seed)
    assert (c.local, c.min_samples) == (ref.local, ref.min_samples)
    assert [i["identifiable"] for i in c.interest] == [i["identifiable"] for i in ref.interest]
    assert c.ranks[-1]["kappa"] == ref.ranks[-1]["kappa"]
