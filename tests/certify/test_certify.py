"""Exact rank over the rationals, and replayable certificates."""
import json
import time

import sympy as sp
from hypothesis import given, settings, strategies as st

from identcheck.certify import exact_rank as certify
from identcheck import cli
from identcheck.derive import get
from identcheck.symbols import case


@given(st.integers(0, 10**6))
def test_rank_is_five_on_random_exact_samples(seed):
    cert = certify.rank("revolute", 2, 1, seed=seed)
    assert cert.rank == 5 and cert.full_rank and cert.exact and cert.deterministic
    assert sp.Rational(cert.minor_determinant) != 0
    assert cert.numeric_rank == 5  # floats agree here, but only guide
    assert certify.verify(cert.to_dict()).ok


@given(st.integers(0, 10**6))
def test_sample_points_lie_exactly_on_the_output_set(seed):
    """M·Y = K holds exactly at the certificate's points with the stated parameters."""
    cert = certify.rank("revolute", 2, 1, seed=seed)
    cs = case("revolute", 2, 1)
    dv = get("revolute21")
    p = {k: sp.Rational(v) for k, v in cert.parameters.items()}
    ca, sa = certify.half_angle(p["t_alpha"])
    sub = {sp.Symbol("d", real=True): p["d"], sp.Symbol("r", positive=True): p["r"],
           sp.Symbol("l", real=True): p["l"], sp.Symbol("rho", positive=True): p["rho"],
           cs.constant_angles[0].cos: ca, cs.constant_angles[0].sin: sa}
    Y = [y.xreplace(sub) for y in dv.result("Y")]
    rows, rhs = certify.m_rows(cs, [[sp.Rational(c) for c in s["xyz"]] for s in cert.samples])
    for row, k in zip(rows, rhs):
        assert sum(m * y for m, y in zip(row, Y)) == k


def test_fewer_samples_than_unknowns_is_not_full_rank():
    cert = certify.rank("revolute", 2, 1, n_samples=4, seed=1)
    assert cert.rank == 4 and not cert.full_rank and not cert.deterministic


def test_tampered_certificate_is_rejected():
    cert = certify.rank("revolute", 2, 1, seed=2).to_dict()
    for mutate in (lambda c: c.update(rank=4),
                   lambda c: c["samples"][1]["xyz"].__setitem__(2, "7/3"),
                   lambda c: c.update(minor_determinant="1")):
        c = json.loads(json.dumps(cert))
        mutate(c)
        assert not certify.verify(c).ok


def test_rank_cli_json_has_contract_keys(tmp_path, capsys):
    path = tmp_path / "cert.json"
    assert cli.main(["rank", "revolute", "2", "1", "--json", "--seed", "5", "--save", str(path)]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("joint", "p", "q", "unknowns", "rank", "full_rank", "exact"):
        assert key in out
    assert out["rank"] == 5 and out["exact"] is True and out["seed"] == 5 and len(out["samples"]) == 5
    assert cli.main(["verify", str(path)]) == 0
    bad = json.loads(path.read_text())
    bad["rank"] = 3
    path.write_text(json.dumps(bad))
    assert cli.main(["verify", str(path)]) == 1


def test_rank_cli_bad_input_exits_2(tmp_path, capsys):
    assert cli.main(["rank", "hinge", "2", "1"]) == 2
    assert "unknown joint type 'hinge'" in capsys.readouterr().err
    assert cli.main(["rank", "revolute", "1", "1"]) == 2
    (tmp_path / "x.json").write_text("{not json")
    assert cli.main(["verify", str(tmp_path / "x.json")]) == 2


def test_samples_beyond_the_distinct_tangents_are_refused_before_any_work(capsys):
    """The samples' tangents are distinct and come from a finite set: asking for more used to loop for ever.
    The command line's limit is that set's size, and the library refuses more with the reason."""
    import pytest

    from identcheck.errors import InputError

    assert cli.MAX_RANK_SAMPLES == certify.distinct_tangents() == 675
    with pytest.raises(InputError, match="at most 675"):
        certify.rank("revolute", 2, 1, n_samples=676)
    assert cli.main(["rank", "revolute", "2", "1", "--samples", "676"]) == 2
    assert "--samples 676" in capsys.readouterr().err
    draws = certify.draw_angles(case("revolute", 2, 1), __import__("random").Random(3), 675)
    assert all(len(set(col)) == 675 for col in zip(*draws))


def _numeric_paths(doc, path=()):
    """The paths of the text fields of `doc` that read as exact numbers."""
    from fractions import Fraction

    if isinstance(doc, dict):
        return [p for k, v in doc.items() for p in _numeric_paths(v, path + (k,))]
    if isinstance(doc, list):
        return [p for i, v in enumerate(doc) for p in _numeric_paths(v, path + (i,))]
    if isinstance(doc, str):
        try:
            Fraction(doc)
            return [path]
        except (ValueError, ZeroDivisionError):
            return []
    return []


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6), st.integers(4001, 10**12),
       st.sampled_from(["1e{}", "-3E+{}", "2.5e{}/7", "1/1e{}", "1e-{}", "DIGITS{}"]))
def test_a_number_with_a_huge_power_of_ten_is_rejected_by_field_at_once(pick, power, form):
    """A number no certificate holds (more than 4000 digits, or a power of ten beyond 1e4000) is named by its field
    and rejected before any arithmetic: 1e100000000 in a sample had kept verify computing past any time limit, and
    1e4300 had been rejected with Python's own message."""
    if form == "DIGITS{}":
        form = "7" * min(power, 6000) + "/3"
    from identcheck.certify.verify import verify

    cert = certify.rank("revolute", 2, 1, seed=3).to_dict()
    paths = _numeric_paths(cert)
    path = paths[pick % len(paths)]
    node = cert
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = form.format(power) if "{}" in form else form
    started = time.process_time()
    result = verify(cert)
    assert not result.ok and time.process_time() - started < 5.0
    named = "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in path).lstrip(".")
    assert any(f"field {named}:" in p for p in result.problems)
