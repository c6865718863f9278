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
