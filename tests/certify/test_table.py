"""The identifiability table: contract, certificates, Remark 1, and recovery of random truths."""
import json
import random
import warnings

import mpmath
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from identcheck.certify import counterexamples as C
from identcheck.certify import jacobian
from identcheck.certify import table as T
from identcheck import cli
from identcheck.errors import DegenerateError
from identcheck.certify.joint_models import JOINTS
from identcheck.solve import minimal

KEYS = {"joint", "p", "q", "identifiable", "local", "candidates", "min_samples", "certificate"}


@pytest.fixture(scope="module")
def doc():
    return T.table().to_dict()


@pytest.fixture(scope="module")
def rows(doc):
    return {(r["joint"], r["p"], r["q"]): r for r in doc["cases"]}


def test_every_case_once_with_the_contract_keys(doc, rows):
    assert len(doc["cases"]) == len(rows) == len(JOINTS) * 16
    for r in doc["cases"]:
        assert KEYS <= set(r)
        assert isinstance(r["identifiable"], bool) and isinstance(r["local"], bool)
        assert r["candidates"] is None or (isinstance(r["candidates"], int) and r["candidates"] >= 1)
        if r["identifiable"]:
            assert r["local"] and r["candidates"] == 1 and r["min_samples"] >= 1
        if not r["local"]:
            assert r["candidates"] is None and r["min_samples"] is None and not r["identifiable"]
        assert r["certificate"]["kind"] and r["certificate"]["statement"]


def test_paper_cases(rows):
    assert {k: rows[("revolute", 2, 1)][k] for k in ("identifiable", "local", "candidates", "min_samples")} == \
        {"identifiable": False, "local": True, "candidates": 4, "min_samples": 5}
    assert rows[("spherical", 3, 1)]["identifiable"] and rows[("spherical", 3, 1)]["min_samples"] == 4
    assert rows[("spherical", 2, 2)]["identifiable"] and rows[("spherical", 2, 2)]["min_samples"] == 9
    for key in (("revolute", 1, 1), ("spherical", 2, 1)):
        assert not rows[key]["local"] and rows[key]["certificate"]["kind"] == "counterexample"
    assert rows[("revolute", 2, 2)]["candidates"] == 1          # new: the second child marker decides
    assert rows[("spherical", 1, 3)]["certificate"]["follows_from"] == "spherical(3,1)"


def test_symmetric_in_p_q(rows):
    for (j, p, q), r in rows.items():
        s = rows[(j, q, p)]
        for k in ("identifiable", "local", "candidates", "min_samples", "local_min_samples"):
            assert r[k] == s[k], (j, p, q, k)


def test_monotone_in_markers(rows):
    for (j, p, q), r in rows.items():
        for bigger in ((j, p + 1, q), (j, p, q + 1)):
            if bigger in rows:
                assert rows[bigger]["local"] >= r["local"], bigger
                if r["identifiable"]:
                    assert rows[bigger]["identifiable"], bigger
                if r["local"] and rows[bigger]["local"] and r["candidates"] and rows[bigger]["candidates"]:
                    assert rows[bigger]["candidates"] <= r["candidates"]


def test_engine_agrees_with_the_certificates(rows):
    for (j, p, q), r in rows.items():
        c = jacobian.verdict(j, p, q)
        assert c.local == r["local"], (j, p, q)
        if r["local"]:
            assert r["local_min_samples"] <= r["min_samples"]
        if j in ("universal", "prismatic"):
            assert r["verdict_kind"] == "local" and r["certificate"]["kind"] == "local_jacobian"
            assert r["identifiable_decided"] == (not r["local"])


def at_key(doc, joint, p, q) -> int:
    return next(i for i, r in enumerate(doc["cases"]) if (r["joint"], r["p"], r["q"]) == (joint, p, q))


def test_deterministic_and_verifiable(doc):
    again = [r for j in ("revolute", "spherical") for r in T._joint_rows.__wrapped__(0, j)]
    assert json.dumps([r for r in doc["cases"] if r["joint"] in ("revolute", "spherical")], sort_keys=True) == \
        json.dumps(list(again), sort_keys=True)
    small = {"format": T.FORMAT, "seed": 0, "cases": [r for r in doc["cases"] if (r["joint"], r["p"], r["q"]) in
                                                      {("revolute", 2, 1), ("spherical", 2, 1), ("spherical", 1, 2),
                                                       ("revolute", 3, 1), ("universal", 2, 2)}]}
    small["sha256"] = T.content_hash(small["cases"])
    # five rows of a table: each verifies, and the rows left out are named (a table answers every p, q)
    partial = T._coverage(small["cases"])
    assert [p.split(":")[0] for p in partial] == ["joint 'revolute'", "joint 'spherical'", "joint 'universal'"]
    assert T.verify(small) == partial
    assert T.verify({k: v for k, v in small.items() if k != "sha256"}) == [
        "sha256: missing (a saved table carries the digest of its rows)"] + partial
    reseeded = dict(small, seed=5)                  # another seed draws other points: every row differs
    assert all(p.split(":")[0] in {"revolute(2,1)", "spherical(2,1)", "spherical(1,2)", "revolute(3,1)",
                                   "universal(2,2)"} for p in T.verify(reseeded) if p not in partial)
    assert len(T.verify(reseeded)) > len(partial)
    shown = json.loads(json.dumps(small))            # a displayed number, the hash recomputed: still caught
    shown["cases"][at_key(shown, "revolute", 3, 1)]["min_samples"] = 2
    shown["sha256"] = T.content_hash(shown["cases"])
    assert "revolute(3,1): field min_samples: 2 differs from the recomputed 3" in T.verify(shown)
    at = {(r["joint"], r["p"], r["q"]): i for i, r in enumerate(small["cases"])}
    bad = json.loads(json.dumps(small))
    bad["cases"][at[("spherical", 2, 1)]]["certificate"]["counterexample"]["poses"][0]["child"]["t"][0] = "0"
    assert any("spherical(2,1)" in p for p in T.verify(bad))
    bad = json.loads(json.dumps(small))
    bad["cases"][at[("spherical", 1, 2)]]["local"] = True
    assert any("follows from" in p or "does not match" in p for p in T.verify(bad))


def test_cli_table_json_and_text(capsys):
    assert cli.main(["table", "--json", "--joint", "prismatic"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [(r["p"], r["q"]) for r in out["cases"]] == [(p, q) for p in range(4) for q in range(4)]
    assert cli.main(["table", "--joint", "revolute"]) == 0
    text = capsys.readouterr().out
    rows = {tuple(line.split()[:2]): line.split()[2:] for line in text.splitlines() if line.startswith("revolute")}
    assert rows[("revolute", "2,1")][:3] == ["no", "yes", "4"]             # identifiable, local, candidates
    assert text.splitlines()[1].startswith("---")                           # a rule under the header


def _world(data, i, parent=True):
    return np.array([[float(x) for x in (A if parent else B)[i]] for A, B in data])


def _solve(joint, p, q, data):
    P = [_world(data, i) for i in range(p)]
    Q = [_world(data, i, parent=False) for i in range(q)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return minimal.solve(joint, P, Q)


LOCAL = [("revolute", 2, 1), ("revolute", 1, 2), ("revolute", 2, 2), ("revolute", 3, 1), ("revolute", 1, 3),
         ("revolute", 3, 3), ("spherical", 3, 1), ("spherical", 2, 2), ("spherical", 2, 3), ("spherical", 3, 3)]


@pytest.mark.parametrize("case", LOCAL, ids=lambda c: f"{c[0]}{c[1]}{c[2]}")
@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10**6))
def test_identifiable_cases_recover_their_truth_from_min_samples(rows, case, seed):
    r = rows[case]
    rng = random.Random(seed)
    g = C.random_geometry(*case, rng)
    data, _ = C.simulate(g, r["min_samples"], rng)
    truth = {k: float(v) for k, v in g.marker_distances().items()}
    try:
        found = _solve(*case, data)
    except DegenerateError:          # a random draw close to a degenerate configuration
        return
    assert len(found) == r["candidates"]
    scale = max(truth.values())
    assert min(max(abs(s[k] - truth[k]) for k in truth) for s in found) < 1e-5 * scale


@pytest.mark.parametrize("case", [("revolute", 3, 1), ("revolute", 2, 2), ("spherical", 3, 1), ("spherical", 2, 2)],
                         ids=lambda c: f"{c[0]}{c[1]}{c[2]}")
def test_removing_any_marker_from_a_minimal_case_breaks_it(rows, case):
    """Every one-marker-smaller case is non-identifiable, shown on data: a verified counterexample,
    or several joints reproducing the same samples."""
    with mpmath.workdps(C.DPS + C.GUARD):
        _remove_each_marker(rows, case)


def _remove_each_marker(rows, case):
    j, p, q = case
    assert rows[case]["identifiable"]
    rng = random.Random(17)
    g = C.random_geometry(j, p, q, rng)
    data, poses = C.simulate(g, 6, rng)
    for side, k in [("parent", i) for i in range(p)] + [("child", i) for i in range(q)]:
        keep_p = [i for i in range(p) if not (side == "parent" and i == k)]
        keep_q = [i for i in range(q) if not (side == "child" and i == k)]
        smaller = (j, len(keep_p), len(keep_q))
        assert not rows[smaller]["identifiable"], smaller
        sub = C.JointGeometry(j, [g.parent_markers[i] for i in keep_p], [g.child_markers[i] for i in keep_q],
                              g.parent_joint, g.child_joint)
        sub_data = [([A[i] for i in keep_p], [B[i] for i in keep_q]) for A, B in data]
        if rows[smaller]["local"]:
            found = _solve(j, len(keep_p), len(keep_q), sub_data)
            assert len(found) > 1
        else:
            cx = C.construct(sub, sub_data, C.mpf(1) / 64)
            cx.truth_poses = poses
            assert cx.check().ok


def test_engine_rows_universal_and_prismatic(rows):
    """The README's summary of the engine-only rows."""
    for p in range(4):
        for q in range(4):
            assert rows[("universal", p, q)]["local"] == (p >= 2 and q >= 2), (p, q)
            assert rows[("prismatic", p, q)]["local"] == (p >= 1 and q >= 1 and p + q >= 3), (p, q)


FORGEABLE = ("identifiable", "local", "candidates")


def _forge(value):
    """Another value of the same field: a verdict flipped, a count moved."""
    if isinstance(value, bool):
        return not value
    if value is None:
        return 1
    return value + 1 if value != 1 else 2


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_forged_verdict_is_rejected_naming_its_row_and_field(doc, data):
    """Any row's identifiable, local or candidates changed (alone, or together with its mirror row (q, p)
    so that the symmetry check cannot catch it) makes the table fail verification, with the row named and
    the field named. The rows of a few cases are re-checked in full (the certificate arithmetic is
    re-verified elsewhere); the verdict checks need no recomputation."""
    cases = doc["cases"]
    i = data.draw(st.integers(0, len(cases) - 1), label="row")
    field = data.draw(st.sampled_from(FORGEABLE), label="field")
    mirror = data.draw(st.booleans(), label="mirror too")
    bad = json.loads(json.dumps(cases))
    row = bad[i]
    key = f"{row['joint']}({row['p']},{row['q']})"
    row[field] = _forge(row[field])
    rows = [row]
    if mirror:
        for r in bad:
            if (r["joint"], r["p"], r["q"]) == (row["joint"], row["q"], row["p"]) and r is not row:
                r[field] = row[field]
                rows.append(r)
    problems = [p for r in rows for p in T.meaning(r)] + T._symmetry(bad)
    for r in rows:
        if r["certificate"]["kind"] == "remark1":       # a Remark 1 row answers to the row it follows from
            src = next(s for s in bad if f"{s['joint']}({s['p']},{s['q']})" == r["certificate"]["follows_from"])
            if (src["identifiable"], src["local"], src["candidates"]) != (r["identifiable"], r["local"], r["candidates"]):
                problems.append(f"{key}: does not match the row it follows from")
    assert problems, (key, field, row[field])
    assert any(key in p or field in p for p in problems), problems


def test_the_papers_wrong_claim_does_not_verify(doc):
    """Revolute (2,1) and (1,2) both set identifiable while they carry their four candidates (Pham's claim,
    ERRATA E1), and revolute (1,1) set identifiable while it carries its own counterexample: rejected, with
    the rows and the fields named."""
    bad = {"format": T.FORMAT, "cases": json.loads(json.dumps(
        [r for r in doc["cases"] if (r["joint"], r["p"], r["q"]) in {("revolute", 2, 1), ("revolute", 1, 2),
                                                                    ("revolute", 1, 1)}]))}
    for r in bad["cases"]:
        r["identifiable"] = True
    problems = T.verify(bad)
    assert any(p.startswith("revolute(2,1): identifiable") for p in problems), problems
    assert any(p.startswith("revolute(1,2)") and "candidates" in p for p in problems), problems
    assert any(p.startswith("revolute(1,1): identifiable") for p in problems), problems


def test_a_counterexamples_displayed_numbers_are_recomputed(doc):
    """Editing the alternative's displayed distances, δ or the 50-digit summary of a counterexample (its
    geometry untouched) is rejected, naming the field."""
    row = next(r for r in doc["cases"] if (r["joint"], r["p"], r["q"]) == ("revolute", 1, 1))
    good = row["certificate"]["counterexample"]
    assert C.verify_dict(good) == []
    for field, edit in (("marker_distances_alternative", lambda d: d.update(A1="40.0")),
                        ("delta", None), ("check_50_digits", lambda d: d.update(largest_distance_change="1.0"))):
        bad = json.loads(json.dumps(good))
        if edit is None:
            bad[field] = str(mpmath.mpf(bad[field]) * 2)
        else:
            edit(bad[field])
        problems = C.verify_dict(bad)
        assert any(p.startswith(field.split(".")[0]) or field in p for p in problems), (field, problems)


def test_a_saved_table_carries_its_maker_and_a_hash_of_its_rows(doc):
    """The saved table names its maker and the SHA-256 of its rows; editing any field, even prose that no
    other check reads, is reported under sha256."""
    assert doc["made_by"].startswith("identcheck ") and len(doc["sha256"]) == 64
    assert doc["sha256"] == T.content_hash(doc["cases"])
    bad = json.loads(json.dumps(doc))
    bad["cases"][0]["certificate"]["statement"] += " (edited)"
    assert T.content_hash(bad["cases"]) != bad["sha256"]
    small = {k: v for k, v in bad.items() if k != "cases"} | {"cases": bad["cases"][:1]}
    small["sha256"] = T.content_hash(doc["cases"][:1])
    assert any(p.startswith("sha256") for p in T.verify(small))


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_a_table_with_its_hash_recomputed_must_still_hold_every_case_once(doc, data):
    """The hash is of the rows, so whoever edits the rows can recompute it: a table emptied, with a row left out
    or a row listed twice (its hash made again) is still rejected, naming what is missing or repeated."""
    cases = json.loads(json.dumps(doc["cases"]))
    how = data.draw(st.sampled_from(["empty", "drop", "duplicate"]))
    i = data.draw(st.integers(0, len(cases) - 1))
    row = cases[i]
    if how == "empty":
        cases = []
    elif how == "drop":
        cases.pop(i)
    else:
        cases.insert(data.draw(st.integers(0, len(cases))), json.loads(json.dumps(row)))
    forged = {k: v for k, v in doc.items() if k != "cases"} | {"cases": cases, "sha256": T.content_hash(cases)}
    said = T._coverage(cases)
    assert said, how
    key = f"({row['p']},{row['q']})"
    expect = {"empty": "no row", "drop": f"no row for p, q = {key}", "duplicate": "listed 2 times"}[how]
    assert any(expect in p for p in said), said
    if how == "empty":
        assert any(expect in p for p in T.verify(forged))
