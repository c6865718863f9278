"""The derivation of Pham eqs. (2)-(13): every printed form checked, errata recorded, proofs hold."""
import re
from pathlib import Path

import sympy as sp

from identcheck import cli
from identcheck.derive import get, printed
from identcheck.derive.algebra import equal, reduce_circle
from identcheck.derive.errata import ERRATA
from identcheck.symbols import c_alpha, s_alpha

ROOT = Path(__file__).resolve().parents[2]


def test_every_check_agrees_or_is_recorded():
    dv = get("revolute21")
    bad = [c.name for c in dv.checks if not c.ok]
    assert not bad, bad
    assert dv.ok


def test_printed_equations_that_are_right_agree_exactly():
    dv = get("revolute21")
    agree = {c.name for c in dv.checks if c.agrees}
    for name in ["O_theta", "eq2", "eq3", "eq4", "eq5", "cubic", "K", "identity_on_output_set",
                 "back_r", "back_alpha", "back_l", "back_rho"] + [f"M{i}" for i in range(1, 6)] + [f"Y{i}" for i in range(1, 6)]:
        assert name in agree, name


def test_root_structure_is_proved():
    roots = get("revolute21").results["roots"]
    assert roots["proved"], roots


def test_uniqueness_claim_is_flagged_as_erratum():
    dv = get("revolute21")
    byname = {c.name: c for c in dv.checks}
    assert byname["unique_joint"].erratum == "E1" and not byname["unique_joint"].agrees
    assert byname["alpha_branches"].erratum == "E2"


def test_errata_ids_are_documented():
    text = (ROOT / "derivations" / "ERRATA.md").read_text()
    for k in ERRATA:
        assert re.search(rf"^## {k}\b", text, re.M), k


def test_a_wrong_printed_coefficient_is_caught(monkeypatch):
    """If the print had a typo in (13), the derivation must disagree (exit 1 from derive)."""
    from identcheck.derive import revolute

    monkeypatch.setattr(printed, "CUBIC", printed.CUBIC + sp.Symbol("Q") * 2)
    revolute.derive.cache_clear()
    try:
        dv = revolute.derive()
        chk = {c.name: c for c in dv.checks}["cubic"]
        assert not chk.agrees and not chk.ok and not dv.ok
    finally:
        monkeypatch.undo()
        revolute.derive.cache_clear()


def test_reduce_circle_is_exact():
    e = (c_alpha**2 + s_alpha**2) ** 3 - 1
    assert reduce_circle(e, [(c_alpha, s_alpha)]) == 0
    assert not equal(s_alpha**2, 1, [(c_alpha, s_alpha)])


def test_derive_cli_writes_markdown(tmp_path):
    assert cli.main(["derive", "--out", str(tmp_path), "--json"]) == 0
    md = (tmp_path / "revolute21.md").read_text()
    assert "The cubic (13)" in md and "E1" in md
    assert (tmp_path / "README.md").exists()
