"""The closed-form solvers' functions, printed from the derivations once and committed as code.

Each case (``revolute21``, ``spherical22``, ``spherical31``) has a module ``_<case>.py`` here, written by
``identcheck derive --regenerate`` (:mod:`identcheck.solve.generated.writer`) from the expressions
:mod:`identcheck.solve.formulas` names: plain NumPy and mpmath functions, SymPy's printed code. Loading
them needs neither SymPy nor a derivation, so ``fit`` and ``identify`` start without either.

Each module records the *derivation key* it was printed from: a hash of every source that determines its
text apart from SymPy's printers (:data:`KEY_SOURCES`: the derive package, the symbols, codegen, the
formulas and the writer). When those sources change (a derivation was edited) the key no longer
matches, and the functions are generated at run time from the derivation instead (SymPy, seconds), with
one :class:`~identcheck.errors.StaleCodeWarning` per process asking for ``identcheck derive --regenerate``.

The SymPy version that printed a module is recorded in it but is not part of the key: the committed code
is a valid rendering of the derivation whichever SymPy the user has, or none. Another SymPy may print the
same derivation differently; ``identcheck derive`` and the test suite compare the committed text with a
fresh print (the version line aside), so such a change is reported, never silent.
"""
from __future__ import annotations

import hashlib
import importlib
import sys
import warnings
from functools import lru_cache
from pathlib import Path

from identcheck.codegen import BACKENDS, NumericFunction
from identcheck.errors import StaleCodeWarning

CASES = ("revolute21", "spherical22", "spherical31")
SYMBOLIC = {"revolute21": ("revolute", 2, 1), "spherical22": ("spherical", 2, 2), "spherical31": ("spherical", 3, 1)}
PACKAGE = Path(__file__).resolve().parents[2]  # the identcheck package directory
# what a generated module's text depends on, besides SymPy (globs relative to PACKAGE)
KEY_SOURCES = ("derive/*.py", "symbols.py", "codegen.py", "solve/formulas.py", "solve/generated/writer.py")
_WARNED = []


@lru_cache(maxsize=1)
def derivation_key() -> str | None:
    """Hash (20 hex digits) of the sources in :data:`KEY_SOURCES`; None when the derive package's sources
    are not installed (nothing could be derived again: the committed modules are used as they are).
    Line endings are normalised, so a checkout with CRLF endings gets the same key."""
    files = sorted({f for pattern in KEY_SOURCES for f in PACKAGE.glob(pattern)})
    if not any(f.parent.name == "derive" for f in files):
        return None
    h = hashlib.sha256()
    for f in files:
        h.update(f.relative_to(PACKAGE).as_posix().encode() + b"\0")
        h.update(f.read_bytes().replace(b"\r\n", b"\n") + b"\0")
    return h.hexdigest()[:20]


def path(case: str) -> Path:
    """The committed module of ``case``."""
    _check_case(case)
    return Path(__file__).resolve().parent / f"_{case}.py"


def module(case: str):
    """The committed module of ``case``, imported; None when there is none."""
    _check_case(case)
    name = f"{__name__}._{case}"
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name != name:  # the module is there but needs something missing: say so
            raise
        return None


def is_current(case: str) -> bool:
    """Whether the committed module of ``case`` was printed from the present derivation sources."""
    mod, key = module(case), derivation_key()
    return mod is not None and (key is None or mod.KEY == key)


@lru_cache(maxsize=None)
def functions(case: str, backend: str = "numpy") -> dict:
    """``{name: NumericFunction}`` of ``case`` for ``backend``: the committed code when current, else
    generated from the derivation now (see the module docstring). One dict per process and backend."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
    if is_current(case):
        return {name: NumericFunction(f, groups, backend, name, n_values)
                for name, (f, groups, n_values) in module(case).FUNCTIONS[backend].items()}
    from identcheck import codegen

    return {name: codegen.numeric(spec.exprs, spec.groups, backend, name)
            for name, spec in _derived(case).functions.items()}


@lru_cache(maxsize=None)
def facts(case: str) -> dict:
    """The plain numbers the solver of ``case`` takes from its derivation (e.g. ``n_unknowns``)."""
    if is_current(case):
        return dict(module(case).FACTS)
    return dict(_derived(case).facts)


@lru_cache(maxsize=None)
def _derived(case: str):
    """The formulas of a stale case, derived now (SymPy; the derivations' disk cache is used)."""
    from identcheck.solve import formulas

    _warn_stale()
    return formulas.CASES[case]()


def _warn_stale() -> None:
    """Warn, once per process, which committed modules are stale."""
    if _WARNED:
        return
    _WARNED.append(True)
    stale = [c for c in CASES if not is_current(c)]
    warnings.warn(
        f"the generated solver code of {', '.join(stale)} (identcheck/solve/generated/) was printed from other "
        f"derivation sources than these (key {derivation_key()}): its functions are derived with SymPy at run time "
        "instead, which takes seconds. Run `identcheck derive --regenerate` to print them again.",
        StaleCodeWarning, stacklevel=4)


def reset() -> None:
    """Forget every loaded function and key (after the modules were rewritten, or in tests)."""
    for cache in (derivation_key, functions, facts, _derived):
        cache.cache_clear()
    _WARNED.clear()
    for case in CASES:
        sys.modules.pop(f"{__name__}._{case}", None)


def lazy_case(module_name: str, case: str):
    """A module ``__getattr__`` that gives ``CASE``, the :class:`identcheck.symbols.Case` of ``case``, when it
    is asked for: building it loads SymPy, which a solver's import must not."""
    def __getattr__(name):
        if name == "CASE":
            from identcheck.symbols import case as symbolic_case

            return symbolic_case(*SYMBOLIC[case])
        raise AttributeError(f"module {module_name!r} has no attribute {name!r}")
    return __getattr__


def _check_case(case: str) -> None:
    if case not in CASES:
        raise ValueError(f"no generated module for {case!r}; cases: {', '.join(CASES)}")
