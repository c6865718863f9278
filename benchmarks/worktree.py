"""An earlier commit of this repository checked out beside the working tree, for benchmarks that time the
same work with the current code and with a baseline in one run."""
from __future__ import annotations

import contextlib
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def checkout(commit: str):
    """Yield the path of a temporary ``git worktree`` at ``commit`` (removed afterwards). Run the baseline's
    code with PYTHONPATH and the working directory both set to it: ``python -m`` puts the working directory
    ahead of PYTHONPATH."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "baseline"
        subprocess.run(["git", "worktree", "add", "--detach", str(path), commit], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            yield path
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(path)], cwd=ROOT, capture_output=True)


def head() -> str:
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
