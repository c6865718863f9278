"""Derivations kept on disk between processes.

Deriving Pham's revolute (2,1) system takes SymPy seconds. The solvers run committed generated code
(:mod:`identcheck.solve.generated`) and need a derivation's results only when that code is stale (a
derivation was edited and not yet printed again): then they come from here. The results are pickled under
the user's cache directory (``$IDENTCHECK_CACHE``, else ``$XDG_CACHE_HOME/identcheck``, else
``~/.cache/identcheck``), keyed by a hash of every source file of :mod:`identcheck.derive`, of
:mod:`identcheck.symbols` and of the SymPy and Python (major.minor) versions, so that any change to a derivation
derives again. A cache that cannot be read or written is skipped (the derivation runs as
before); a file that fails to load is derived again and replaced. ``identcheck derive`` never uses it.

The package ships the files a fresh cache would hold after ``identcheck table`` (:data:`SEED`, written by
``identcheck derive --regenerate``: :mod:`identcheck.certify.seed`): a file missing from the user's cache is read
from there when one of the same name, that is of the same key, is shipped. A fresh install whose SymPy and Python
are those the seed was made with starts warm (the first ``identcheck table`` had derived everything again, 7-10 s
of SymPy); any other derives as before. ``IDENTCHECK_SEED=off`` skips the seed.
"""
from __future__ import annotations

import hashlib
import json
import os
import pickle
import sys
from functools import lru_cache
from pathlib import Path

from identcheck.io.atomic import atomic_write

_MEMO: dict = {}

SEED = Path(__file__).resolve().with_name("seed")
"""The shipped cache files (see the module's docstring)."""


def _seed_file(path: Path) -> Path | None:
    """The shipped file of the same name as the cache file `path`, or None (none shipped, or the seed is off)."""
    if os.environ.get("IDENTCHECK_SEED", "").strip().lower() in ("off", "0", "no", "false"):
        return None
    shipped = SEED / path.name
    return shipped if shipped.is_file() else None


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
    h.update(f"sympy {sympy.__version__} python {sys.version_info[:2]}".encode())
    return h.hexdigest()[:20]


def _load(path: Path):
    """The pickled value at `path`, or None when it cannot be read or unpickled."""
    try:
        with open(path, "rb") as fh:
            return pickle.load(fh)
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError, TypeError, ValueError):
        return None


def _save(path: Path, value) -> None:
    """Pickle `value` to `path` atomically (a temporary file replaced into place); skipped when it cannot be
    written."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, pickle.dumps(value))
    except OSError:
        pass


def cached(name: str, derive):
    """The derivation `name` from memory, else from disk, else from ``derive()`` (then saved)."""
    if name in _MEMO:
        return _MEMO[name]
    path = cache_dir() / f"{name}-{source_key()}.pickle"
    result = _load(path)
    if result is None and _seed_file(path) is not None:
        result = _load(_seed_file(path))
    if result is None:
        result = derive()
        _save(path, result)
    _MEMO[name] = result
    return result


def printed(name: str, render):
    """``render()`` (a JSON-able value: the printed forms of a derivation's expressions, which must come from a
    fresh derivation, see :func:`identcheck.derive.printed_forms`) from memory, else from disk, else computed and
    saved, under the same key as :func:`cached`. A file that cannot be read is computed again."""
    memo_key = ("printed", name)
    if memo_key in _MEMO:
        return _MEMO[memo_key]
    path = cache_dir() / f"{name}-{source_key()}.printed.json"
    value = None
    for where in (path, _seed_file(path)):           # the user's file, else the shipped one
        try:
            value = json.loads(where.read_text(encoding="utf-8")) if where is not None else None
        except (OSError, ValueError):
            value = None
        if value is not None:
            break
    if value is None:
        value = render()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write(path, json.dumps(value))
        except OSError:
            pass
    _MEMO[memo_key] = value
    return value


def files_key(paths) -> str:
    """Hash of these files' contents (line endings normalised) and the SymPy and Python versions: the key of a
    value computed with SymPy from what they define."""
    import sympy

    h = hashlib.sha256()
    for f in sorted(Path(p) for p in paths):
        h.update(f.name.encode() + b"\0" + f.read_bytes().replace(b"\r\n", b"\n") + b"\0")
    h.update(f"sympy {sympy.__version__} python {sys.version_info[:2]}".encode())
    return h.hexdigest()[:20]


def entry(name: str, key: str, item, compute):
    """``compute()`` for ``item`` of the dict kept on disk as ``name-key.pickle``: from memory, else from that
    file, else computed and the file rewritten with it (atomically; a file that cannot be read or written is
    skipped, the value computed as before)."""
    store = _MEMO.get(("entries", name, key))
    path = cache_dir() / f"{name}-{key}.pickle"
    if store is None:
        store = _load(path)
        if not isinstance(store, dict) and _seed_file(path) is not None:
            store = _load(_seed_file(path))
        store = dict(store) if isinstance(store, dict) else {}
        _MEMO[("entries", name, key)] = store
    if item not in store:
        store[item] = compute()
        _save(path, store)
    return store[item]
