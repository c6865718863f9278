"""The derivations' cache the package ships (identcheck/derive/seed/): it serves the sources as they are, it holds
what SymPy computes afresh, and the cache reads it only for the files it was missing."""
from __future__ import annotations

import json
import pickle

import pytest
import sympy as sp
from hypothesis import given, settings, strategies as st

from identcheck.certify import seed
from identcheck.derive import cache


def _applies():
    st_ = seed.status()
    if not st_["applies"]:
        pytest.skip(f"the shipped cache was made with {st_['made_with']}, not this SymPy/Python "
                    f"{seed.versions()}: it does not apply here")
    return st_


def _shipped(name: str):
    with open(cache.SEED / name, "rb") as fh:
        return pickle.load(fh)


def _same_maths(a, b, where: str) -> None:
    """SymPy values equal as mathematics (a pickle round trip may reorder how an expression is written);
    containers and plain values equal item by item."""
    if isinstance(a, sp.Poly):
        assert sp.expand(a.as_expr() - b.as_expr()) == 0, where
    elif isinstance(a, (sp.MatrixBase, sp.Basic)):
        diff = sp.Matrix(a) - sp.Matrix(b) if isinstance(a, sp.MatrixBase) else a - b
        assert sp.simplify(sp.expand(diff)) == (sp.zeros(*diff.shape) if isinstance(diff, sp.MatrixBase) else 0), where
    elif isinstance(a, dict):
        assert set(a) == set(b), where
        for k in a:
            _same_maths(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same_maths(x, y, f"{where}[{i}]")
    else:
        assert a == b, where


def test_the_shipped_cache_serves_the_sources_as_they_are():
    """Every cache file the table reads under the present keys is shipped. If this fails, a derivation, a joint
    model or the symbols were edited since the seed was made: run `identcheck derive --regenerate`."""
    st_ = _applies()
    assert st_["current"], f"stale shipped cache, missing {st_['missing']}: run `identcheck derive --regenerate`"


@pytest.mark.slow
@pytest.mark.parametrize("name", seed.DERIVED)
def test_a_shipped_derivation_is_a_fresh_one(name, tmp_path, monkeypatch):
    """The shipped derivation's results and checks are a fresh derivation's, and its printed forms (what a
    certificate records) are a fresh render's, character for character."""
    import importlib

    from identcheck.certify import exact_rank
    from identcheck.derive import CASE_DERIVATION, DERIVATIONS
    from identcheck.symbols import case

    _applies()
    key = cache.source_key()
    shipped = _shipped(f"{name}-{key}.pickle")
    fresh = importlib.import_module(DERIVATIONS[name]).derive()
    assert [(c.name, c.agrees, c.ok) for c in shipped.checks] == [(c.name, c.agrees, c.ok) for c in fresh.checks]
    _same_maths(shipped.results, fresh.results, name)
    monkeypatch.setenv("IDENTCHECK_CACHE", str(tmp_path))
    monkeypatch.setenv("IDENTCHECK_SEED", "off")
    monkeypatch.setattr(cache, "_MEMO", {})
    label = next(k for k, v in CASE_DERIVATION.items() if v == name)
    joint, pq = label.split("(")
    p, q = (int(v) for v in pq.rstrip(")").split(","))
    printed = exact_rank._printed(case(joint, p, q))
    assert json.loads((cache.SEED / f"{name}-{key}.printed.json").read_text()) == printed


@settings(max_examples=6, deadline=None)
@given(st.data())
def test_shipped_joint_models_and_jacobians_are_fresh_ones(data):
    """Random entries of the shipped joint models and compiled Jacobians equal SymPy's fresh ones (the compiled
    polynomials term by term, exact rationals)."""
    from identcheck.certify import jacobian, joint_models

    _applies()
    models = _shipped(f"joint_models-{joint_models._models_key()}.pickle")
    key = data.draw(st.sampled_from(sorted(models)))
    shipped_model, fresh_model = models[key], joint_models._build(*key)
    assert shipped_model.key == fresh_model.key and shipped_model.constants == fresh_model.constants
    _same_maths(list(shipped_model.outputs), list(fresh_model.outputs), f"{key} outputs")
    jac = _shipped(f"jacobians-{jacobian._symbolic_key()}.pickle")
    if fresh_model.key in jac:
        shipped, fresh = jac[fresh_model.key], jacobian._differentiate(fresh_model)
        terms = lambda rows: [[c.terms for c in row] for row in rows]  # noqa: E731
        assert terms(shipped.J1) == terms(fresh.J1) and terms(shipped.grads) == terms(fresh.grads)
        assert (shipped.gens, shipped.n_const, shipped.n_var, shipped.row_degree, shipped.grad_degree) == \
            (fresh.gens, fresh.n_const, fresh.n_var, fresh.row_degree, fresh.grad_degree)


@settings(max_examples=20, deadline=None)
@given(shipped=st.dictionaries(st.text("abc", min_size=1, max_size=3), st.integers(), max_size=4),
       wanted=st.text("abcd", min_size=1, max_size=3), off=st.booleans())
def test_the_cache_reads_a_shipped_file_only_for_what_it_lacks(tmp_path_factory, shipped, wanted, off):
    """With an empty user cache an entry the seed holds is read from it, not computed; one it lacks is computed
    and saved to the user's cache (which then holds the seed's entries too); the seed is never written; with
    ``IDENTCHECK_SEED=off`` everything is computed."""
    tmp = tmp_path_factory.mktemp("seed")
    (tmp / "seed").mkdir()
    (tmp / "seed" / "things-k.pickle").write_bytes(pickle.dumps(shipped))
    before = (tmp / "seed" / "things-k.pickle").read_bytes()
    calls = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cache, "SEED", tmp / "seed")
        mp.setenv("IDENTCHECK_CACHE", str(tmp / "user"))
        mp.setenv("IDENTCHECK_SEED", "off" if off else "on")
        mp.setattr(cache, "_MEMO", {})
        value = cache.entry("things", "k", wanted, lambda: calls.append(1) or -1)
    from_seed = wanted in shipped and not off
    assert value == (shipped[wanted] if from_seed else -1) and calls == ([] if from_seed else [1])
    assert (tmp / "seed" / "things-k.pickle").read_bytes() == before
    if not from_seed:
        saved = pickle.loads((tmp / "user" / "things-k.pickle").read_bytes())
        assert saved == ({} if off else shipped) | {wanted: -1}


@settings(max_examples=10, deadline=None)
@given(shipped=st.lists(st.integers(), max_size=4), user=st.sampled_from(["none", "corrupt", "own"]),
       off=st.booleans())
def test_printed_forms_come_from_the_users_file_then_the_shipped_one(tmp_path_factory, shipped, user, off):
    """The printed forms: the user's file when it reads, else the shipped one (a missing or corrupt user file alike),
    else a fresh render saved to the user's cache; the shipped file is never written."""
    tmp = tmp_path_factory.mktemp("printed")
    (tmp / "seed").mkdir()
    (tmp / "user").mkdir()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cache, "SEED", tmp / "seed")
        mp.setenv("IDENTCHECK_CACHE", str(tmp / "user"))
        mp.setenv("IDENTCHECK_SEED", "off" if off else "on")
        mp.setattr(cache, "_MEMO", {})
        name = f"demo-{cache.source_key()}.printed.json"
        (tmp / "seed" / name).write_text(json.dumps(shipped))
        if user == "corrupt":
            (tmp / "user" / name).write_text("{not json")
        elif user == "own":
            (tmp / "user" / name).write_text(json.dumps(["own"]))
        value = cache.printed("demo", lambda: ["rendered"])
    expected = ["own"] if user == "own" else (["rendered"] if off else shipped)
    assert value == expected
    assert json.loads((tmp / "seed" / name).read_text()) == shipped
    if expected == ["rendered"]:
        assert json.loads((tmp / "user" / name).read_text()) == ["rendered"]
