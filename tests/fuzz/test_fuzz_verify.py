"""``identcheck verify`` on tampered and broken certificates: every field of a saved rank certificate changed,
given another type or removed; the file cut at any byte; binary content; JSON nested 100 000 deep.

A field the verifier rebuilds from the certificate's own data (the case, the parameters, the samples, the rank
and its flag, the minor) changed must be rejected (exit 1) naming it; a broken file is exit 2 naming the file;
nothing is ever a traceback or exit 3 (the ``run`` fixture)."""
from __future__ import annotations

import copy
import json

import pytest
from hypothesis import given, strategies as st

from fuzz_support import FUZZ

CHECKED = ("joint", "p", "q", "unknowns", "rank", "full_rank", "parameters", "samples", "pivot_rows",
           "pivot_columns", "minor_determinant")
"""Top-level fields ``verify`` recomputes or uses to recompute: changing one must reject the certificate."""

DERIVED = ("matrix", "statement", "numeric_rank", "min_samples", "n_samples", "seed", "unknown_exprs",
           "expansion", "deterministic", "exact")
"""Fields the rank certificate also stores, which ``verify`` rebuilds from its parameters and samples and
compares (the seed: by drawing them again)."""

LOOSE = {(("unknowns", 0), "change"), (("unknowns", 0), "retype"), (("full_rank",), "retype"),
         (("samples", 0, "t"), "change")}
"""Changes inside checked fields that ``verify`` once accepted: an unknown's name, a full_rank flag of another
type (taken for its truth value), a sample with an extra angle (ignored); now each is rejected."""


@pytest.fixture(scope="module")
def certificate(tmp_path_factory) -> dict:
    """A saved rank certificate of revolute (2,1) (``identcheck rank revolute 2 1 --save``)."""
    from identcheck import cli

    path = tmp_path_factory.mktemp("cert") / "cert.json"
    assert cli.main(["rank", "revolute", "2", "1", "--save", str(path)]) == 0
    return json.loads(path.read_text())


def _paths(doc, prefix=()):
    """Every field path of a JSON document (the first item of each list stands for its items)."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list) and doc:
        yield prefix + (0,)
        yield from _paths(doc[0], prefix + (0,))


def _tampered(doc, path, how):
    doc = copy.deepcopy(doc)
    target = doc
    for k in path[:-1]:
        target = target[k]
    value = target[path[-1]]
    if how == "remove":
        if isinstance(target, list):
            target.pop(path[-1])
        else:
            del target[path[-1]]
    elif how == "retype":
        target[path[-1]] = {"x": [1]} if not isinstance(value, dict) else "text"
    else:                                   # change: a value of the same type, different
        target[path[-1]] = (not value if isinstance(value, bool) else value + 1 if isinstance(value, int) else
                            value + "1" if isinstance(value, str) else value[:-1] + value[-1:] * 2
                            if isinstance(value, list) and value else {"extra": 1} if isinstance(value, dict) else 7)
    return doc


def test_every_field_tampered_is_never_a_traceback(run, certificate, tmp_path):
    """Every field of the saved (sealed) certificate changed, retyped or removed: exit 1 (rejected) or 2, with no
    traceback; rejected naming the content hash first (the file was edited) and then what failed."""
    assert certificate["format"] == "identcheck.rank-certificate/2" and len(certificate["sha256"]) == 64
    path = tmp_path / "tampered.json"
    for field in _paths(certificate):
        for how in ("change", "retype", "remove"):
            path.write_text(json.dumps(_tampered(certificate, field, how)))
            res = run(["verify", path])
            assert res.code in (1, 2), (field, how, res.out, res.err)
            assert res.code == 2 or ("REJECTED" in res.out and "sha256" in res.out), (field, how, res.out)


def test_the_body_of_a_sealed_certificate_is_checked_field_by_field(run, certificate, tmp_path):
    """The seal aside (the hash recomputed after the edit, as a forger would): every field the verifier checks
    is still rejected on its own."""
    from identcheck.certify import seal

    path = tmp_path / "resealed.json"
    for field in [(f,) for f in CHECKED + DERIVED if f in certificate]:
        doc = _tampered(certificate, field, "change")
        doc["sha256"] = seal.digest({k: v for k, v in doc.items() if k != "sha256"})
        path.write_text(json.dumps(doc))
        res = run(["verify", path])
        assert res.code in (1, 2) and "sha256" not in res.out, (field, res.out)


def test_a_changed_derived_field_is_rejected(run, certificate, tmp_path):
    path = tmp_path / "derived.json"
    failures = []
    for field, how in [((f,), "change") for f in DERIVED if f in certificate] + sorted(LOOSE):
        path.write_text(json.dumps(_tampered(certificate, field, how)))
        if run(["verify", path]).code == 0:
            failures.append((field, how))
    assert not failures, f"accepted with {failures}"


@FUZZ
@given(cut=st.floats(0, 0.999))
def test_a_certificate_cut_anywhere_is_named(run, certificate, tmp_path, cut):
    """The file cut at any byte: exit 2 naming the file and where the JSON stops."""
    text = json.dumps(certificate)
    path = tmp_path / "cut.json"
    path.write_text(text[:int(len(text) * cut)])
    res = run(["verify", path])
    assert res.code == 2 and res.names(path, "not JSON"), res.err


@pytest.mark.parametrize("content, words", [
    (bytes(range(256)) * 4, ["not UTF-8"]),
    (b"[" * 100_000 + b"]" * 100_000, ["nested too deeply"]),
    (b'{"format": "identcheck.rank-certificate/1", "x": ' + b"[" * 100_000 + b"]" * 100_000 + b"}", ["nested"]),
    (b"[1, 2, 3]", ["JSON object"]),
    (b'{"format": "nonsense/9"}', ["unknown certificate format"]),
])
def test_a_file_that_is_no_certificate_is_named(run, tmp_path, content, words):
    path = tmp_path / "not_a_certificate.json"
    path.write_bytes(content)
    res = run(["verify", path])
    assert res.code == 2 and res.names(path, *words), res.err
