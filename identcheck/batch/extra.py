"""The optional packages ``identcheck batch`` runs on (the ``batch`` extra), checked before any work so that a
missing one is a one-line message naming ``pip install 'identcheck[batch]'``, never a traceback."""
from __future__ import annotations

import importlib

PACKAGES = ("dask", "distributed", "pandas", "pyarrow", "tqdm")
"""Imported by the batch: the cluster (dask, distributed), the summary table (pandas, pyarrow for Parquet) and
the progress bar (tqdm)."""
INSTALL = "pip install 'identcheck[batch]'"


def missing() -> list:
    """The packages of :data:`PACKAGES` that cannot be imported (empty: the batch can run)."""
    gone = []
    for name in PACKAGES:
        try:
            importlib.import_module(name)
        except ImportError:
            gone.append(name)
    return gone


def problem() -> str:
    """Why the batch cannot run here ('' when it can)."""
    gone = missing()
    if not gone:
        return ""
    return f"identcheck batch runs on Dask and needs {', '.join(gone)}, not installed here: {INSTALL}"


def require() -> None:
    """Raise ``ImportError`` with :func:`problem`'s message when a package is missing."""
    msg = problem()
    if msg:
        raise ImportError(msg)
