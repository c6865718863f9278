"""Derivations kept on disk between processes.

Deriving Pham's revolute (2,1) system takes SymPy seconds. The solvers run committed generated code
(:mod:`identcheck.solve.generated`) and need a derivation's results only when that code is stale (a
derivation was edited and not yet printed again): then they come from here. The results are pickled under
the user's cache directory (``$IDENTCHECK_CACHE``, else ``$XDG_CACHE_HOME/identcheck``, else
``~/.cache/identcheck``), keyed by a hash of every source file of :mod:`identcheck.derive`, of
:mod:`identcheck.symbols` and of the SymPy and Python versions, so that any change to a derivation derives
again. A cache that cannot be read or written is skipped (the derivation runs as
before); a file that fails to load is derived again and replaced. ``identcheck derive`` never uses it.
"""
from __future__ import annotations

import hashlib
import os
import pickle
import sys
import tempfile
from functools import lru_cache
from pathlib import Path

_MEMO: dict = {}


def cache_dir() -> Path:
    """Where the derivations are kept."""
    if os.environ.get("IDENTCHECK_CACHE"):
        return Path(os.environ["IDENTCHECK_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "identcheck"


@lru_cache(maxsize=1)
def source_key() -> str:
    """Hash of what a derivation's result depends on: the derive package, the symbols, SymPy, Python."""
    import sympy

    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(here.glob("*.py")) + [here.parent / "symbols.py"]:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    h.update(f"sympy {sympy.__version__} python {sys.version_info[:3]}".encode())
    return h.hexdigest()[:20]


def cached(name: str, derive):
    """The derivation `name` from memory, else from disk, else from ``derive()`` (then saved)."""
    if name in _MEMO:
        return _MEMO[name]
    path = cache_dir() / f"{name}-{source_key()}.pickle"
    result = None
    try:
        with open(path, "rb") as fh:
            result = pickle.load(fh)
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, TypeError, ValueError):
        result = None
    if result is None:
        result = derive()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, delete=False, suffix=".tmp") as tmp:
                pickle.dump(result, tmp)
            os.replace(tmp.name, path)
        except OSError:
            pass
    _MEMO[name] = result
    return result
