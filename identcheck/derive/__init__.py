"""Symbolic derivations (SymPy only). Each returns a :class:`~identcheck.derive.base.Derivation`."""
from .base import Check, Derivation, Step

DERIVATIONS = {
    "revolute21": "identcheck.derive.revolute",
}


def get(name: str) -> Derivation:
    """Run (once, cached) and return the named derivation."""
    import importlib

    return importlib.import_module(DERIVATIONS[name]).derive()


def derive_all() -> list:
    """Every derivation, in canonical order."""
    return [get(n) for n in sorted(DERIVATIONS)]


__all__ = ["Check", "Derivation", "Step", "DERIVATIONS", "get", "derive_all"]
