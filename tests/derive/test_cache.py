"""Derivations kept on disk: the same results as deriving, a changed source derives again, an unusable
cache is skipped."""
from __future__ import annotations

import pickle

import sympy as sp

from identcheck.derive import cache


def test_disk_cache_round_trip_and_corruption(tmp_path, monkeypatch):
    monkeypatch.setenv("IDENTCHECK_CACHE", str(tmp_path / "c"))
    monkeypatch.setattr(cache, "_MEMO", {})
    calls = []

    def derive():
        calls.append(1)
        x = sp.Symbol("x")
        return {"poly": sp.expand((x + 1) ** 3)}

    first = cache.cached("demo", derive)
    files = list((tmp_path / "c").glob("demo-*.pickle"))
    assert len(files) == 1 and calls == [1]
    monkeypatch.setattr(cache, "_MEMO", {})
    again = cache.cached("demo", derive)
    assert calls == [1] and sp.simplify(again["poly"] - first["poly"]) == 0     # loaded, not derived
    files[0].write_bytes(b"not a pickle")
    monkeypatch.setattr(cache, "_MEMO", {})
    third = cache.cached("demo", derive)
    assert calls == [1, 1] and third["poly"] == first["poly"]                  # derived again, replaced
    assert pickle.loads(files[0].read_bytes())["poly"] == first["poly"]


def test_unwritable_cache_still_derives(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("IDENTCHECK_CACHE", str(blocker / "sub"))
    monkeypatch.setattr(cache, "_MEMO", {})
    assert cache.cached("demo2", lambda: {"v": 3}) == {"v": 3}


def test_key_follows_the_sources():
    """The key is a hash of the derive package and the symbols: stable within a run, 20 hex digits."""
    k = cache.source_key()
    assert k == cache.source_key() and len(k) == 20 and int(k, 16) >= 0


def test_entries_round_trip_corruption_and_unwritable(tmp_path, monkeypatch):
    """One dict per name and key on disk: an entry is computed once, loaded by a later process, computed
    again when the file is unreadable, and still computed when the directory cannot be written."""
    monkeypatch.setenv("IDENTCHECK_CACHE", str(tmp_path / "c"))
    monkeypatch.setattr(cache, "_MEMO", {})
    calls = []

    def compute(v):
        calls.append(v)
        return {"value": v}

    assert cache.entry("things", "k1", "a", lambda: compute(1)) == {"value": 1}
    assert cache.entry("things", "k1", "b", lambda: compute(2)) == {"value": 2}
    monkeypatch.setattr(cache, "_MEMO", {})
    assert cache.entry("things", "k1", "a", lambda: compute(9)) == {"value": 1} and calls == [1, 2]
    assert cache.entry("things", "k2", "a", lambda: compute(3)) == {"value": 3}     # another key: computed
    (tmp_path / "c" / "things-k1.pickle").write_bytes(b"garbage")
    monkeypatch.setattr(cache, "_MEMO", {})
    assert cache.entry("things", "k1", "a", lambda: compute(4)) == {"value": 4}
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("IDENTCHECK_CACHE", str(blocker / "sub"))
    monkeypatch.setattr(cache, "_MEMO", {})
    assert cache.entry("things", "k1", "a", lambda: compute(5)) == {"value": 5}


def test_the_table_from_the_disk_caches_equals_the_fresh_one(tmp_path, monkeypatch):
    """What ``identcheck table`` keeps on disk — the derivations' values and printed forms, the joint models
    and their compiled Jacobians — gives the same certificates as computing everything afresh: a rank
    certificate and a local certificate, computed in a cold cache, then again from the files alone."""
    from identcheck.certify import exact_rank, jacobian, joint_models
    from identcheck.derive import CASE_DERIVATION
    from identcheck.symbols import case as get_case

    def clear():
        monkeypatch.setattr(cache, "_MEMO", {})
        joint_models.model.cache_clear()
        jacobian.symbolic.cache_clear()
        jacobian._cached.cache_clear()

    monkeypatch.setenv("IDENTCHECK_CACHE", str(tmp_path / "c"))
    monkeypatch.setenv("IDENTCHECK_SEED", "off")        # cold: computed, not read from the shipped cache
    clear()
    cold = (exact_rank.rank("spherical", 2, 2, seed=3).to_dict(), jacobian.verdict("revolute", 2, 1, seed=3).to_dict(),
            jacobian.verdict("universal", 2, 3, seed=3).to_dict())
    assert {f.name.split("-")[0] for f in (tmp_path / "c").iterdir()} >= {"jacobians", "joint_models", "spherical22"}
    clear()
    warm = (exact_rank.rank("spherical", 2, 2, seed=3).to_dict(), jacobian.verdict("revolute", 2, 1, seed=3).to_dict(),
            jacobian.verdict("universal", 2, 3, seed=3).to_dict())
    assert warm == cold
    fresh = __import__("identcheck.derive", fromlist=["get"]).get(CASE_DERIVATION["spherical(2,2)"], disk_cache=False)
    assert cold[0]["unknown_exprs"] == [str(e) for e in fresh.result("Y")]
    assert exact_rank._printed(get_case("spherical", 2, 2))["Y"] == cold[0]["unknown_exprs"]
    for key in (("revolute", 2, 1), ("universal", 2, 3)):
        m = joint_models.model(*key)
        assert m == joint_models._build(*key)
        stored, computed = jacobian.symbolic(m), jacobian._differentiate(m)
        assert [[e.terms for e in row] for row in stored.J1] == [[e.terms for e in row] for row in computed.J1]
        assert [[e.terms for e in g] for g in stored.grads] == [[e.terms for e in g] for g in computed.grads]
