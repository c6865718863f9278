"""identcheck: certified identifiability of joint parameters from motion-capture markers, and the solvers
that fit them.

The public API, one function per verb of the ``identcheck`` command (each returns a frozen result whose
``to_dict()`` is the verb's JSON)::

    import identcheck as ic
    model = ic.load_model("examples/leg.toml")
    sim = ic.simulate(model, "leg.trc", seed=2, noise_mm=0.5)
    result = ic.fit(model, "leg.trc")          # FitResult: result.joints["knee_r"]["marker_distances"]
    ic.plan(model).all_identifiable            # PlanResult
    ic.diagnose(model, "leg.trc").steps        # Diagnosis
    ic.table(), ic.rank("revolute", 2, 1), ic.verify("cert.json")
    ic.batch("fit", ["trials/"], "results/", model=model)   # DataFrame, one row per trial x joint (Dask)

Names are imported on first use (PEP 562), so ``import identcheck`` stays light: no SymPy, no SciPy.
"""
from __future__ import annotations

import functools
import importlib

_API = ("load_model", "read_trial", "simulate", "fit", "diagnose", "plan", "table", "rank", "verify", "batch")
"""The verbs of :mod:`identcheck.api` offered here (``derive`` and ``identify`` stay in the api: their names are
the subpackages ``identcheck.derive`` and ``identcheck.identify``, which ``from identcheck import derive``
must keep giving)."""
_LAZY = {
    **{name: ("identcheck.api", name) for name in _API},
    "FitResult": ("identcheck.fit.result", "FitResult"),
    "Diagnosis": ("identcheck.diagnose.workflow", "Diagnosis"),
    "PlanResult": ("identcheck.plan.result", "PlanResult"),
    "TableResult": ("identcheck.certify.table", "TableResult"),
    "RankCertificate": ("identcheck.certify.exact_rank", "RankCertificate"),
    "VerifyResult": ("identcheck.certify.verify", "VerifyResult"),
    "IdentifyResult": ("identcheck.identify", "IdentifyResult"),
    "DeriveResult": ("identcheck.derive.result", "DeriveResult"),
    "Model": ("identcheck.io.model", "Model"),
    "Trial": ("identcheck.trial", "Trial"),
    "Simulation": ("identcheck.simulate.rigid", "Simulation"),
    "InputError": ("identcheck.errors", "InputError"),
    "DegenerateError": ("identcheck.errors", "DegenerateError"),
    "IdentifiabilityWarning": ("identcheck.errors", "IdentifiabilityWarning"),
}

__all__ = ["__version__", *_LAZY]

# The verbs fit, plan, diagnose, simulate and batch share their names with subpackages (whose __init__ only holds
# a docstring). Importing a subpackage binds its name here, the first time only: so they are imported now, and
# their names unbound, for __getattr__ to give the verb; later imports of their modules leave the name alone.
_SUBPACKAGES = ("fit", "plan", "diagnose", "simulate", "batch")
for _sub in _SUBPACKAGES:
    importlib.import_module(f"identcheck.{_sub}")
    del globals()[_sub]
del _sub


def _verb(function, package: str):
    """``function`` under the name of the subpackage it shadows: ``import identcheck.plan.analysis as a``
    looks ``plan`` up on this package and, not finding ``analysis`` on it, falls back to
    ``sys.modules[plan.__name__ + ".analysis"]``, which must be the subpackage's module."""
    @functools.wraps(function)
    def verb(*args, **kwargs):
        return function(*args, **kwargs)
    verb.__name__ = package
    return verb


def _version() -> str:
    """The installed distribution's version (package metadata), or ``0+unknown`` when not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("identcheck")
    except PackageNotFoundError:
        return "0+unknown"


def __getattr__(name: str):
    """Import a public name on first use and keep it (PEP 562)."""
    if name == "__version__":
        value = _version()
    elif name in _LAZY:
        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        if name in _SUBPACKAGES:
            value = _verb(value, f"identcheck.{name}")
    else:
        raise AttributeError(f"module 'identcheck' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))
