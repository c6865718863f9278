"""What ``identcheck fit`` returns: every joint's parameters from a recorded trial, with uncertainty,
excitation and the warnings (label swaps left out, estimator warnings, model misfit)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from identcheck.io.jsonable import frozen, plain


@dataclass(frozen=True)
class FitResult:
    """A trial's joints as fitted (read-only).

    Attributes
    ----------
    joints : Mapping
        Joint name -> its fit with the contract's keys: ``type``, ``unique``, ``marker_distances``
        (marker -> mm: to the centre of a ball joint, to the axis of a hinge), ``alternatives`` (the other
        joints that explain the trial equally well), ``rms_residual`` (mm), ``uncertainty_mm``,
        ``excitation`` (``ok``, ``reason``), and ``case``, ``estimator``, ``identifiable`` and the rest
        ``identcheck fit --json`` prints.
    warnings : tuple
        Every warning of the fit, in the order found (a subject prefix removed from the labels and the label
        screen's findings first).
    noise : Mapping or None
        The estimated noise model, when the fit reports one.
    other : Mapping
        Any further top-level keys of the ``fit`` JSON.
    """

    joints: Mapping
    warnings: tuple = ()
    noise: Mapping | None = None
    other: Mapping = field(default_factory=lambda: MappingProxyType({}))

    @property
    def ok(self) -> bool:
        """Every joint is identifiable from these markers and determined uniquely by this trial."""
        return all(j["unique"] and j["identifiable"] for j in self.joints.values())

    @classmethod
    def from_dict(cls, doc: dict) -> "FitResult":
        """A FitResult from the ``fit`` JSON document (a read-only copy)."""
        rest = {k: v for k, v in doc.items() if k not in ("joints", "warnings", "noise")}
        return cls(joints=frozen(doc["joints"]), warnings=frozen(list(doc.get("warnings", []))),
                   noise=frozen(doc["noise"]) if "noise" in doc else None, other=frozen(rest))

    def to_dict(self) -> dict:
        """The contract's ``fit`` JSON."""
        doc = {"joints": plain(self.joints), "warnings": plain(self.warnings), **plain(self.other)}
        if self.noise is not None:
            doc["noise"] = plain(self.noise)
        return doc
