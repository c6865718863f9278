"""Where the tests find real recordings: the repository's own copies first (``examples/real/``, small and openly
licensed, see its README), then the shared folder of larger ones (``IDENTCHECK_REAL_DATA``, default
``../shared/data/real`` beside the repository), which may be absent: tests that need a file there skip.

Also the ``real_file`` fixture of ``tests/conftest.py``."""
from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPO = ROOT / "examples" / "real"
"""Recordings shipped in the repository."""
SHARED = Path(os.environ.get("IDENTCHECK_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))
"""The shared folder of real recordings (not in the repository)."""
TRIAL_SUFFIXES = (".trc", ".c3d")


def real_file(name: str) -> Path:
    """The recording `name`: the repository's copy when there is one, else the shared folder's (which may not
    exist: check ``.exists()``)."""
    own = REPO / name
    return own if own.exists() else SHARED / name


def real_files() -> list[Path]:
    """Every real recording found (TRC and C3D), once per name, the repository's copy first."""
    found = {}
    for folder in (REPO, SHARED):
        if folder.is_dir():
            for p in sorted(folder.iterdir()):
                if p.suffix.lower() in TRIAL_SUFFIXES:
                    found.setdefault(p.name, p)
    return sorted(found.values(), key=lambda p: p.name)
