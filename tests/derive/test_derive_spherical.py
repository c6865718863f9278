import pytest
"""Derivations of Pham IV-A (sphere, (3,1)) and IV-C (eqs. 14-17, (2,2)): proofs hold, errata recorded."""
import json
import random

import sympy as sp
from hypothesis import given, strategies as st

from identcheck.certify import exact_rank as certify
from identcheck import cli
from identcheck.derive import get, printed
from identcheck.derive.algebra import equal
from identcheck.derive.errata import ERRATA
from identcheck.symbols import case, d, r, rho1, rho2


def test_every_spherical_check_agrees_or_is_recorded():
    for name in ("spherical31", "spherical22"):
        dv = get(name)
        assert dv.ok, [c.name for c in dv.checks if not c.ok]


def test_eq14_and_15_agree_with_the_print_and_vanish_on_the_output_set():
    byname = {c.name: c for c in get("spherical22").checks}
    for n in ("H", "G", "eq14", "eq14_on_output_set", "rigid_link", "identity_on_output_set", "back_substitution"):
        assert byname[n].agrees, n


def test_printed_unknowns_miss_d_squared_erratum_e4():
    dv = get("spherical22")
    chk = {c.name: c for c in dv.checks}["Y17_covers_expansion"]
    assert not chk.agrees and chk.erratum == "E4" and "E4" in ERRATA
    assert chk.witness["missing"] == ["d**2"]
    # the d² column really is there: its coefficient in the expansion of (14) is not zero
    exp = dv.results["expansion"]
    col = exp["M"][exp["unknowns"].index(d**2)]
    assert sp.expand(col) != 0
    # and no printed unknown is d² (so M·Y = K with (17) cannot hold)
    assert not any(equal(y, d**2) for y in printed.Y17)


def test_expansion_columns_have_one_relation_on_the_output_set_erratum_e5():
    dv = get("spherical22")
    exp = dv.results["expansion"]
    assert len(exp["unknowns"]) == 10 and len(exp["relations"]) == 1
    assert {c.name: c for c in dv.checks}["expansion_rank"].erratum == "E5"
    # check the relation on random exact points of the output set (independently of the derivation's proof)
    cs = case("spherical", 2, 2)
    rng = random.Random(11)
    params = certify.draw_parameters(cs, rng)
    L2 = params["rho1"] ** 2 + params["rho2"] ** 2 - 2 * params["rho1"] * params["rho2"] * certify.half_angle(params["t_gamma"])[0]
    rel = [sp.sympify(c).subs(exp["L2_symbol"], L2) for c in exp["relations"][0]]
    for ts in certify.draw_angles(cs, rng, 3):
        pt = dict(zip(cs.sample, certify.sample_point(cs, params, ts)))
        assert sum(c * m.xreplace(pt) for c, m in zip(rel, exp["M"])) == 0


def test_reduced_unknowns_give_parameters_linearly():
    back = get("spherical22").results["back"]
    Y = get("spherical22").results["Y"]
    truth = dict(zip(back["Z"], Y))
    assert equal(back["d"].subs(truth), d)
    assert equal(back["r2"].subs(truth), r**2)
    assert equal(back["rho1_2"].subs(truth), rho1**2) and equal(back["rho2_2"].subs(truth), rho2**2)


@pytest.mark.slow
@given(st.integers(0, 10**6))
def test_rank_certificates_are_full_and_replay(seed):
    for joint, p, q, n in (("spherical", 3, 1, 4), ("spherical", 2, 2, 9)):
        cert = certify.rank(joint, p, q, seed=seed % 50)
        assert cert.rank == n and cert.full_rank and cert.min_samples == n
        assert certify.verify(cert.to_dict()).ok


def test_tampered_spherical_certificate_is_rejected():
    cert = certify.rank("spherical", 2, 2, seed=1).to_dict()
    cert["samples"][0]["xyz"][0] = str(sp.Rational(cert["samples"][0]["xyz"][0]) + 1)
    assert not certify.verify(cert).ok


def test_too_few_samples_give_a_lower_bound_only():
    cert = certify.rank("spherical", 2, 2, n_samples=8, seed=0)
    assert cert.rank == 8 and not cert.full_rank and not cert.deterministic


def test_cli_rank_spherical_json(capsys):
    assert cli.main(["rank", "spherical", "2", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rank"] == 9 and out["full_rank"] and out["exact"] is True and len(out["unknowns"]) == 9
    assert out["expansion"]["rank"] == 9 and len(out["expansion"]["unknowns"]) == 10
    assert cli.main(["rank", "spherical", "3", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rank"] == 4 and out["full_rank"] and out["unknowns"] == ["Y1", "Y2", "Y3", "Y4"]


def test_cli_rank_unknown_case_is_a_clear_error(capsys):
    assert cli.main(["rank", "spherical", "1", "1"]) == 2
    assert "no derivation for spherical (1,1)" in capsys.readouterr().err


def test_coplanar_degeneracy_is_proved():
    dv = get("spherical31")
    assert dv.results["coplanar_line"]
    assert {c.name for c in dv.checks if c.agrees} >= {"mediating_planes", "radius_from_centre", "identity_on_output_set"}


def test_derive_writes_every_derivation(tmp_path, capsys):
    assert cli.main(["derive", "--out", str(tmp_path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert {d_["name"] for d_ in rep["derivations"]} == {"revolute21", "spherical31", "spherical22", "counterexamples"}
    assert "E7" in (tmp_path / "counterexamples.md").read_text()
    text = (tmp_path / "spherical22.md").read_text()
    assert "E4" in text and "E5" in text
