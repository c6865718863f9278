"""Constructed counterexamples: random true joints in, a verified second joint (or the stated range) out."""
import json
import random

import mpmath
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from identcheck.certify import counterexamples as C
from identcheck.derive import get as get_derivation

FAST = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
NOT_LOCAL = [("revolute", 1, 1), ("revolute", 0, 1), ("revolute", 0, 3), ("revolute", 2, 0), ("revolute", 3, 0),
             ("spherical", 1, 1), ("spherical", 2, 1), ("spherical", 1, 2), ("spherical", 0, 2), ("spherical", 3, 0)]


@pytest.fixture(autouse=True)
def _digits():
    """The tests compare quantities at the constructions' working precision."""
    with mpmath.workdps(C.DPS + C.GUARD):
        yield


def _truth(joint, p, q, seed, n=6):
    rng = random.Random(seed)
    with mpmath.workdps(C.DPS + C.GUARD):
        g = C.random_geometry(joint, p, q, rng)
        data, poses = C.simulate(g, n, rng)
    return g, data, poses


@FAST
@given(seed=st.integers(0, 10**6), frac=st.floats(-0.9, 0.9))
def test_revolute11_exact_family_reproduces_every_sample(seed, frac):
    assume(abs(frac) > 0.01)      # δ = 0 is the truth itself
    g, data, poses = _truth("revolute", 1, 1, seed)
    r, rho, l = C.revolute11_invariants(g)
    try:
        C.revolute11_family(r, rho, l, frac * r, "exact")
    except ValueError:
        assume(False)
    cx = C.revolute11(g, data, frac * r, "exact")
    cx.truth_poses = poses
    chk = cx.check()
    assert chk.ok, chk.to_dict()
    assert chk.change > abs(frac * r) * mpmath.mpf("0.99")     # r' = r − δ: A's distance moved by |δ|
    # same shell: the family keeps both invariants rρ and r² + ρ² + l²
    r2, rho2, l2 = C.revolute11_invariants(cx.alternative)
    assert abs(r2 * rho2 - r * rho) < mpmath.mpf(10) ** -40 * r * rho


@FAST
@given(seed=st.integers(0, 10**6), frac=st.floats(-0.95, 0.95))
def test_revolute11_paper_family_works_exactly_beyond_delta(seed, frac):
    """r − δ, ρ + δ reproduces a sample iff |AB| lies in the alternative's shell (the paper's Δ)."""
    g, data, _ = _truth("revolute", 1, 1, seed, n=8)
    r, rho, l = C.revolute11_invariants(g)
    delta = frac * min(r, rho)
    r2, rho2, l2 = C.revolute11_family(r, rho, l, delta, "paper")
    lo, hi = C.revolute11_shell(r2, rho2, l2)
    assert abs(hi - C.revolute11_shell(r, rho, l)[1]) < mpmath.mpf(10) ** -40 * hi   # outer radius kept
    for A, B in data:
        D = mpmath.sqrt(sum((b - a) ** 2 for a, b in zip(A[0], B[0])))
        assume(abs(D - lo) > mpmath.mpf(10) ** -20)
        admitted = lo <= D <= hi
        try:
            C.revolute11(g, [(A, B)], delta, "paper").check().ok
            built = True
        except C.ConstructionError:
            built = False
        assert built == admitted
        if r >= rho and 0 <= delta <= r - rho:     # then every sample of S is kept
            assert built


def _cylindrical(g, A, B):
    L, d, r, rho = C.spherical21_invariants(g)
    F, R, zb = C._axis_frame(A[0], A[1], B[0])
    return R, zb - d


@FAST
@given(seed=st.integers(0, 10**6), frac=st.floats(0.01, 0.95))
def test_spherical21_construction_succeeds_exactly_when_admissible(seed, frac):
    g, data, poses = _truth("spherical", 2, 1, seed, n=8)
    L, d, r, rho = C.spherical21_invariants(g)
    delta = frac * r
    for A, B in data:
        R, h = _cylindrical(g, A, B)
        assert C.spherical21_admissible(R, h, r, rho)                              # the truth's own samples
        assert (R - (r - delta)) ** 2 + h * h <= (rho + delta) ** 2                # the left side always holds
        admitted = C.spherical21_admissible(R, h, r - delta, rho + delta)
        try:
            ok = C.spherical21(g, [(A, B)], delta).check().ok
        except C.ConstructionError:
            ok = False
        assert ok == admitted
        if rho + delta <= r - delta or R >= rho - r + 2 * delta:
            assert ok


def test_spherical21_loses_samples_on_the_axis_when_rho_exceeds_r():
    """ERRATA E7: B on the A1A2 axis is a sample when ρ > r, and no J' on Γ' is at distance ρ + δ."""
    with mpmath.workdps(C.DPS + C.GUARD):
        r, rho, d, L = mpmath.mpf(3), mpmath.mpf(5), mpmath.mpf(0), mpmath.mpf(10)
        g = C._canonical_spherical21(L, d, r, rho)
        B = C.vec([0, 0, 4])
        J = g.parent_joint.t
        pose = C.Pose(C.Frame.identity(), C.Frame(C.rotation_between(mpmath.matrix([1, 0, 0]), B - J), J))
        A, Bs = C.markers_world(g, pose)
        assert mpmath.norm(Bs[0] - B) < mpmath.mpf(10) ** -50      # B is an output of the truth
        with pytest.raises(C.ConstructionError, match="sample 0"):
            C.spherical21(g, [(A, Bs)], mpmath.mpf(1) / 2)
    chk = {c.name: c for c in get_derivation("counterexamples").checks}
    assert chk["spherical21_every_sample"].erratum == "E7" and not chk["spherical21_every_sample"].agrees
    assert all(c.ok for c in chk.values())


@pytest.mark.parametrize("case", NOT_LOCAL, ids=lambda c: f"{c[0]}{c[1]}{c[2]}")
@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10**6))
def test_every_non_identifiable_case_yields_a_verified_counterexample(case, seed):
    cx = C.witness(*case, seed=seed, n_samples=6)
    chk = cx.check()
    assert chk.ok and chk.truth <= chk.tolerance
    assert (cx.p, cx.q) == case[1:]
    assert not C.verify_dict(json.loads(json.dumps(cx.to_dict())))


def test_verification_rejects_a_tampered_counterexample():
    d = C.witness("spherical", 2, 1, seed=3, n_samples=4).to_dict()
    assert C.verify_dict(d) == []
    moved = json.loads(json.dumps(d))
    moved["samples"][1]["child"][0][2] = str(mpmath.mpf(moved["samples"][1]["child"][0][2]) + mpmath.mpf("1e-12"))
    assert any("misses a sample" in p for p in C.verify_dict(moved))
    same = json.loads(json.dumps(d))
    same["alternative"] = same["truth"]
    same["poses"] = same["truth_poses"]
    assert any("same marker distances" in p for p in C.verify_dict(same))
    no_truth = dict(d, truth_poses=None)
    assert any("no true poses" in p for p in C.verify_dict(no_truth))
    assert C.verify_dict({"format": "other"})


def test_identifiable_cases_have_no_continuous_counterexample():
    g, data, _ = _truth("spherical", 3, 1, 1)
    with pytest.raises(ValueError, match="locally identifiable"):
        C.construct(g, data, 1)
    with pytest.raises(ValueError, match="vacuous"):
        C.construct(C.random_geometry("revolute", 0, 0, random.Random(0)), [], 1)
