"""Paths and small helpers shared by the fuzz suite's tests (fixtures are in this folder's conftest.py)."""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parents[2]
LEG = ROOT / "examples" / "leg.toml"
KNEE = ROOT / "examples" / "knee_21.toml"
DIAGNOSE_LEG = ROOT / "examples" / "diagnose_leg.toml"


@dataclass(frozen=True)
class Outcome:
    """What one CLI run gave: its exit code, stdout and stderr."""

    code: int
    out: str
    err: str

    def names(self, *words) -> bool:
        """Whether stderr mentions every one of `words` (file, marker, line, field...)."""
        return all(str(w) in self.err for w in words)


def digest(path: Path) -> str:
    """The file's SHA-256 ('' when it is not a file): inputs must come out of every run unchanged."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""


FUZZ = settings(max_examples=6, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
"""Hypothesis settings of the suite: few examples, the same ones every run (2 cores, shared with benchmarks)."""
