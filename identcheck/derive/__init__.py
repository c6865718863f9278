"""Symbolic derivations (SymPy only). Each returns a :class:`~identcheck.derive.base.Derivation`."""
from identcheck.derive.base import Check, Derivation, Step

DERIVATIONS = {
    "revolute21": "identcheck.derive.revolute",
    "spherical31": "identcheck.derive.spherical31",
    "spherical22": "identcheck.derive.spherical22",
    "counterexamples": "identcheck.derive.counterexamples",
}


def get(name: str, disk_cache: bool = True) -> Derivation:
    """The named derivation: run once per process (each module caches it), and, for callers that only need
    its results, kept on disk between processes (:mod:`identcheck.derive.cache`). The solvers need neither:
    they run committed generated code (:mod:`identcheck.solve.generated`) and derive, from the disk cache,
    only when that code is stale. ``identcheck derive``, the code generator and the certificates pass
    ``disk_cache=False``: they derive again or print the derived expressions, whose printed form a pickle
    round trip can change (``(2*d**2 + r**2)/2`` came back as ``d**2 + r**2/2``)."""
    import importlib

    if disk_cache:
        from identcheck.derive.cache import cached

        return cached(name, lambda: importlib.import_module(DERIVATIONS[name]).derive())
    return importlib.import_module(DERIVATIONS[name]).derive()


CASE_DERIVATION = {"revolute(2,1)": "revolute21", "spherical(3,1)": "spherical31",
                   "spherical(2,2)": "spherical22"}


def for_case(case, disk_cache: bool = True) -> Derivation:
    """The derivation that yields the linear form M·Y = K of a case (see :func:`get` for ``disk_cache``)."""
    try:
        return get(CASE_DERIVATION[case.key], disk_cache=disk_cache)
    except KeyError:
        raise RuntimeError(f"no derivation of the linear form for {case.key} yet") from None


def printed_forms(name: str, render) -> object:
    """``render(derivation)`` of a fresh derivation ``name`` — the printed text of some of its expressions, as
    a certificate records them — kept on disk between processes beside :func:`get`'s results, under the same
    key. The pickled expressions are the same mathematics but may print differently, so what a certificate
    prints comes from here and what it computes from :func:`get`."""
    from identcheck.derive.cache import printed as cached_printed

    return cached_printed(name, lambda: render(get(name, disk_cache=False)))


def derive_all() -> list:
    """Every derivation, in canonical order."""
    return [get(n, disk_cache=False) for n in sorted(DERIVATIONS)]


__all__ = ["Check", "Derivation", "Step", "DERIVATIONS", "get", "for_case", "printed_forms", "derive_all"]
