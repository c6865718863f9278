"""The derivations' cache as the package ships it (:data:`identcheck.derive.cache.SEED`): written, and checked.

``table``, ``rank``, ``verify`` and ``plan`` take SymPy's results (the derivations, their printed forms, the joint
models and their compiled Jacobians) from the user's disk cache. :func:`write` fills an empty cache by running the
table in a fresh process, as a new user's first ``identcheck table`` would, and ships its files with an index of the
SymPy, Python and python-flint versions they were made with. :func:`status` says whether the shipped files serve the
sources as they are now: when the running versions are the seed's, every cache file the current keys name must be
shipped (a derivation or a joint model edited since is a stale seed); under other versions the seed does not apply,
and the cache derives as before.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from identcheck.derive import CASE_DERIVATION
from identcheck.derive.cache import SEED, source_key

INDEX = "index.json"
DERIVED = tuple(sorted(set(CASE_DERIVATION.values())))   # the derivations the table reads, and prints


def versions() -> dict:
    """The versions a cache key holds besides the sources: SymPy's, Python's major.minor, and python-flint's (whose
    rationals the compiled Jacobians hold)."""
    import flint
    import sympy

    return {"sympy": sympy.__version__, "python": f"{sys.version_info[0]}.{sys.version_info[1]}",
            "flint": flint.__version__}


def expected() -> list:
    """The names of the cache files the table reads under the current keys."""
    from identcheck.certify.jacobian import _symbolic_key
    from identcheck.certify.joint_models import _models_key

    key = source_key()
    return sorted([f"{n}-{key}.pickle" for n in DERIVED] + [f"{n}-{key}.printed.json" for n in DERIVED]
                  + [f"jacobians-{_symbolic_key()}.pickle", f"joint_models-{_models_key()}.pickle"])


def status() -> dict:
    """``{"applies", "current", "missing", "made_with"}``: whether the running versions are the seed's, whether
    every file the current keys name is shipped, and which are not."""
    try:
        made_with = json.loads((SEED / INDEX).read_text(encoding="utf-8")).get("versions", {})
    except (OSError, ValueError):
        made_with = {}
    applies = made_with == versions()
    missing = [n for n in expected() if not (SEED / n).is_file()] if applies else []
    return {"applies": applies, "current": applies and not missing, "missing": missing, "made_with": made_with}


def write(timeout_s: float = 900.0) -> dict:
    """Fill an empty cache with the table's SymPy work (a fresh process, the seed off) and ship its files in
    place of the seed's; the new :func:`status`. Raises RuntimeError when the table fails or a file the current
    keys name was not made."""
    if status()["current"]:
        return status()         # pickles are not byte for byte the same from run to run: a current seed is kept
    with tempfile.TemporaryDirectory() as tmp:
        package = str(Path(__file__).resolve().parents[2])       # this package's, whatever the caller's folder
        env = dict(os.environ, IDENTCHECK_CACHE=tmp, IDENTCHECK_SEED="off",
                   PYTHONPATH=os.pathsep.join(filter(None, [package, os.environ.get("PYTHONPATH")])))
        done = subprocess.run([sys.executable, "-c", "from identcheck.certify.table import table; table()"],
                              env=env, capture_output=True, text=True, timeout=timeout_s)
        if done.returncode != 0:
            raise RuntimeError(f"the table failed while the seed was made:\n{done.stderr[-2000:]}")
        made = sorted(p.name for p in Path(tmp).iterdir() if p.is_file())
        lacking = [n for n in expected() if n not in made]
        if lacking:
            raise RuntimeError(f"the table made no {', '.join(lacking)}: the seed would not serve it")
        SEED.mkdir(parents=True, exist_ok=True)
        for old in SEED.iterdir():
            if old.is_file():
                old.unlink()
        for name in made:
            shutil.copyfile(Path(tmp) / name, SEED / name)
    (SEED / INDEX).write_text(json.dumps({"versions": versions(), "files": made}, indent=1) + "\n",
                              encoding="utf-8")
    return status()
