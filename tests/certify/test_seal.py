"""Standalone certificates carry a version (``/2``) and the hash of their content: sealing and unsealing give the
body back; any edit of any field is named as an edit of the sealed content; a rank certificate, a local
certificate and a counterexample sealed verify, and rejected once edited; ``/1`` files saved before the seal
still verify."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from identcheck.certify import counterexamples, jacobian, seal
from identcheck.certify.verify import verify

ROOT = Path(__file__).resolve().parents[2]
JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=6),
                    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                    max_leaves=12)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(seal.BODY_TO_SEALED)), st.dictionaries(st.text(min_size=1, max_size=6), JSON,
                                                                      min_size=1, max_size=5), st.data())
def test_sealing_round_trips_and_any_edit_breaks_the_hash(fmt, fields, data):
    body = {k: v for k, v in fields.items() if k not in ("format", "sha256")} | {"format": fmt}
    doc = seal.seal(body)
    assert doc["format"] == seal.BODY_TO_SEALED[fmt] and len(doc["sha256"]) == 64
    back, problems = seal.unseal(json.loads(json.dumps(doc)))
    assert back == json.loads(json.dumps(body)) and problems == []
    key = data.draw(st.sampled_from(sorted(doc)))
    edited = copy.deepcopy(doc)
    if key == "format":
        edited["sha256"] = "0" * 64                       # (another format would be another checker)
    else:
        edited[key] = data.draw(JSON.filter(lambda v: v != doc[key]))
    _, problems = seal.unseal(edited)
    assert problems and problems[0].startswith("sha256:")
    del edited["sha256"]
    assert "missing" in seal.unseal(edited)[1][0]


def test_a_sealed_local_certificate_verifies_and_an_edit_is_named():
    doc = jacobian.verdict("prismatic", 1, 1).sealed()
    assert doc["format"] == "identcheck.local-certificate/2"
    assert verify(doc).ok
    doc["statement"] = doc["statement"] + " (edited)"          # a field the replay itself does not compare
    res = verify(doc)
    assert not res.ok and res.problems[0].startswith("sha256:")


@pytest.mark.slow
def test_a_sealed_counterexample_verifies_and_an_edit_is_named():
    cx = counterexamples.witness("revolute", 1, 1, seed=0, n_samples=8)
    doc = cx.sealed()
    assert doc["format"] == "identcheck.counterexample/2" and verify(doc).ok
    doc["notes"] = doc["notes"] + ["edited"]
    res = verify(doc)
    assert not res.ok and res.problems[0].startswith("sha256:")


@pytest.mark.parametrize("name", ["rank_revolute_2_1.json", "rank_spherical_3_1.json"])
def test_certificates_saved_before_the_seal_still_verify(name):
    doc = json.loads((ROOT / "derivations" / "out" / name).read_text())
    assert doc["format"] == "identcheck.rank-certificate/1" and "sha256" not in doc
    assert verify(doc).ok
