"""The committed generated solver code: exactly what a fresh derivation prints, the same numbers as the
functions generated at run time, keyed by the derivation's sources, and derived again when stale."""
from __future__ import annotations

import difflib
import warnings
from functools import lru_cache

import hypothesis.extra.numpy as hnp
import mpmath
import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings, strategies as st

from identcheck import codegen
from identcheck.errors import StaleCodeWarning
from identcheck.solve import formulas, generated, spherical31
from identcheck.solve.generated import writer

FUNCTIONS = [(case, name) for case in generated.CASES
             for name in generated.module(case).FUNCTIONS["numpy"]]


@pytest.fixture(scope="module")
def fresh():
    """Every case's formulas from a fresh derivation (not the disk cache), derived once for this module."""
    return {case: formulas.CASES[case](disk_cache=False) for case in generated.CASES}


@pytest.fixture(scope="module")
def cached():
    """Every case's formulas as the solvers generated them before, from the derivations' disk cache."""
    return {case: formulas.CASES[case]() for case in generated.CASES}


@pytest.fixture
def clean():
    """Forget loaded functions before and after: a test that makes the modules stale leaves nothing behind."""
    generated.reset()
    yield
    generated.reset()


@pytest.mark.parametrize("case", generated.CASES)
def test_committed_module_is_the_fresh_print(case, fresh):
    """The cache cannot drift: a fresh derivation prints the committed text (the SymPy version line aside),
    under the key of the present sources. If this fails, run `identcheck derive --regenerate`."""
    committed, printed = generated.path(case).read_text(), writer.module_source(case)
    diff = "".join(list(difflib.unified_diff(committed.splitlines(True), printed.splitlines(True),
                                             "committed", "fresh print"))[:40])
    assert writer.same_code(committed, printed), f"{generated.path(case)} is stale: run `identcheck derive " \
        f"--regenerate`\n{diff}"
    assert generated.module(case).KEY == generated.derivation_key() and generated.is_current(case)
    assert generated.facts(case) == fresh[case].facts


def _groups(draw, groups, n, bound=50.0):
    return [draw(hnp.arrays(np.float64, (n, len(g)), elements=st.floats(-bound, bound, allow_subnormal=False)))
            for g in groups]


_PLAIN = {}  # SymPy's own lambdify of each function, made once


@pytest.mark.parametrize("case,name", FUNCTIONS)
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_generated_numpy_is_bit_identical_to_run_time_generation(case, name, fresh, data):
    """The committed function, codegen.numeric on the fresh derivation and a plain SymPy lambdify (the code
    generation every solver used before) give the same bits; the same call convention (broadcasting a
    single parameter row, NaN/inf through silently)."""
    spec = fresh[case].functions[name]
    committed = generated.functions(case, "numpy")[name]
    assert committed.groups == tuple(tuple(map(str, g)) for g in spec.groups)
    assert committed.__doc__ == codegen.numeric(spec.exprs, spec.groups, "numpy", name).__doc__
    args = _groups(data.draw, spec.groups, 7)
    args[-1] = args[-1][:1] if len(args) > 1 else args[-1]          # broadcasting: one row against seven
    got = committed(*args)
    assert got.shape == (7, len(spec.exprs)) and got.dtype == np.float64
    np.testing.assert_array_equal(got, codegen.numeric(spec.exprs, spec.groups, "numpy", name)(*args))
    if (case, name) not in _PLAIN:
        _PLAIN[case, name] = sp.lambdify([s for g in spec.groups for s in g], list(spec.exprs), modules=["numpy"],
                                         cse=True)
    plain = _PLAIN[case, name]
    with np.errstate(all="ignore"):
        cols = plain(*[np.broadcast_to(a[..., i], (7,)) for a in args for i in range(a.shape[-1])])
    np.testing.assert_array_equal(got, np.stack(np.broadcast_arrays(*[np.asarray(c, float) for c in cols]), -1))


@pytest.mark.parametrize("case,name", FUNCTIONS)
@settings(max_examples=10, deadline=None)
@given(data=st.data())
def test_generated_matches_the_cached_derivation(case, name, cached, data):
    """The derivations' disk cache (what the solvers generated from when its pickle was warm) prints some
    expressions in another but equal form (``(Q - Z2)/2`` against ``Q/2 - Z2/2``): equal to rounding
    (inputs of order 1, so that rounding is of order eps where terms cancel)."""
    spec = cached[case].functions[name]
    args = _groups(data.draw, spec.groups, 5, bound=3.0)
    got = generated.functions(case, "numpy")[name](*args)
    want = codegen.numeric(spec.exprs, spec.groups, "numpy", name)(*args)
    finite = np.isfinite(want) & (np.abs(want) < 1e12)
    np.testing.assert_allclose(got[finite], want[finite], rtol=1e-13, atol=1e-10)


@pytest.mark.parametrize("case", generated.CASES)
def test_generated_mpmath_is_identical_at_50_digits(case, fresh):
    rng = np.random.default_rng(3)
    committed = generated.functions(case, "mpmath")
    with mpmath.workdps(50):
        for name, spec in fresh[case].functions.items():
            args = [[mpmath.mpf(1) / 7 * v for v in rng.integers(1, 90, len(g))] for g in spec.groups]
            got = committed[name](*args)
            assert got == codegen.numeric(spec.exprs, spec.groups, "mpmath", name)(*args), name
            assert all(isinstance(v, (mpmath.mpf, int)) for v in got)


def test_stale_module_is_derived_at_run_time_with_one_warning(monkeypatch, clean):
    """A changed derivation (here: a changed key) makes the committed modules stale: the functions are
    generated from the derivation instead, the same numbers, with a single warning naming the remedy."""
    committed = generated.functions("spherical31", "numpy")
    facts = generated.facts("revolute21")
    generated.reset()
    monkeypatch.setattr(generated, "derivation_key", lru_cache(maxsize=1)(lambda: "0" * 20))
    assert not generated.is_current("spherical31")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        derived = generated.functions("spherical31", "numpy")
        assert generated.facts("revolute21") == facts
        generated.functions("spherical31", "mpmath")
    stale = [w for w in caught if issubclass(w.category, StaleCodeWarning)]
    assert len(stale) == 1 and "identcheck derive --regenerate" in str(stale[0].message)
    assert all(c in str(stale[0].message) for c in generated.CASES)
    assert derived is not committed and derived["m_row"]._f is not committed["m_row"]._f
    xyz = np.random.default_rng(0).normal(size=(20, 3))
    for name in committed:
        args = [xyz] if name == "m_row" else [np.random.default_rng(1).normal(size=(4, 4))] if name == "back" \
            else [np.ones(4), np.random.default_rng(2).normal(size=(3, 4))]
        np.testing.assert_array_equal(derived[name](*args), committed[name](*args))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaleCodeWarning)
        j = spherical31.identify(xyz / np.linalg.norm(xyz, axis=1, keepdims=True) * 2 + 1).joints[0]
    np.testing.assert_allclose(j.centre, [1, 1, 1], atol=1e-9)
    assert abs(j.rho - 2) < 1e-9


def test_key_follows_the_sources_not_their_line_endings(tmp_path, monkeypatch, clean):
    """The key hashes every source a module's text depends on: a changed derivation changes it, a CRLF
    checkout of the same sources does not."""
    files = sorted({f for pattern in generated.KEY_SOURCES for f in generated.PACKAGE.glob(pattern)})
    assert {f.name for f in files} >= {"revolute.py", "symbols.py", "codegen.py", "formulas.py", "writer.py"}
    for f in files:
        copy = tmp_path / f.relative_to(generated.PACKAGE)
        copy.parent.mkdir(parents=True, exist_ok=True)
        copy.write_bytes(f.read_bytes())
    key = generated.derivation_key()
    monkeypatch.setattr(generated, "PACKAGE", tmp_path)
    generated.derivation_key.cache_clear()
    assert generated.derivation_key() == key
    rev = tmp_path / "derive" / "revolute.py"
    rev.write_bytes(rev.read_bytes().replace(b"\n", b"\r\n"))
    generated.derivation_key.cache_clear()
    assert generated.derivation_key() == key
    rev.write_bytes(rev.read_bytes() + b"# changed\n")
    generated.derivation_key.cache_clear()
    assert generated.derivation_key() != key


def test_sync_reports_and_rewrites_a_stale_module(tmp_path, monkeypatch, fresh, clean):
    """``identcheck derive`` compares each module with the fresh print; ``--regenerate`` rewrites only the
    ones that differ (a different SymPy version line alone is no difference)."""
    targets = {c: tmp_path / f"_{c}.py" for c in generated.CASES}
    for c, t in targets.items():
        t.write_text(generated.path(c).read_text())
    targets["spherical31"].write_text("KEY = 'old'\n")
    text = targets["revolute21"].read_text()
    targets["revolute21"].write_text(writer._VERSION_LINE.sub("SYMPY = '0.0.1'  # another", text))
    monkeypatch.setattr(generated, "path", lambda case: targets[case])
    status = {s.case: s for s in writer.sync(write=False)}
    assert [status[c].ok for c in generated.CASES] == [True, True, False]
    assert targets["spherical31"].read_text() == "KEY = 'old'\n"
    status = {s.case: s for s in writer.sync(write=True)}
    assert status["spherical31"].written and not status["revolute21"].written and status["spherical31"].ok
    assert targets["spherical31"].read_text() == writer.module_source("spherical31")
    assert "0.0.1" in targets["revolute21"].read_text()                 # not rewritten for the version alone


def test_source_refuses_arguments_it_would_rename():
    x = sp.Symbol("x")
    with pytest.raises(ValueError, match="identifiers"):
        codegen.source([x], [(x, sp.Symbol("lambda"))])
    with pytest.raises(ValueError, match="identifiers"):
        codegen.source([x], [(x, x)])
