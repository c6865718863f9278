"""Containers every derivation returns: the steps (for rendering), the checks of printed
against derived forms, and the named results that certify and codegen consume."""
from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp


@dataclass
class Step:
    """One rendered step: prose plus labelled equations (SymPy objects or LaTeX strings)."""

    title: str
    text: str = ""
    equations: list = field(default_factory=list)  # [(label, expr_or_latex)]


@dataclass
class Check:
    """A printed equation or claim of the paper, compared with the derivation.

    ``agrees`` is decided by exact algebra. When it is False, ``erratum`` names the entry of
    derivations/ERRATA.md that records the disagreement and ``witness`` gives a point where
    printed and derived forms differ.
    """

    name: str
    where: str
    printed: object
    derived: object
    agrees: bool
    erratum: str | None = None
    witness: dict | None = None
    note: str = ""

    @property
    def ok(self) -> bool:
        """True when the print agrees, or disagrees exactly as ERRATA.md records."""
        from identcheck.derive.errata import ERRATA

        return self.agrees or self.erratum in ERRATA


@dataclass
class Derivation:
    """A finished derivation: ``results`` holds the SymPy objects later stages use."""

    name: str
    title: str
    source: str
    steps: list = field(default_factory=list)
    checks: list = field(default_factory=list)
    results: dict = field(default_factory=dict)

    def result(self, key: str):
        """A named result; raises rather than return something stale or missing."""
        try:
            return self.results[key]
        except KeyError:
            raise RuntimeError(f"derivation {self.name!r} has no result {key!r}; call derive() first") from None

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks)

    def add_check(self, **kw) -> Check:
        chk = Check(**kw)
        self.checks.append(chk)
        return chk


def as_latex(obj) -> str:
    """LaTeX for a SymPy object, or a string passed through."""
    return obj if isinstance(obj, str) else sp.latex(obj)
