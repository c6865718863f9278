"""What ``identcheck plan`` returns: the verdict for every joint of a marker plan, the explanation, and the
fewest markers to add."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from identcheck.io.jsonable import frozen, plain

OPTIONAL = ("suggestions_note", "suggestions_check", "suggestions_unique", "suggestions_unique_note", "undetermined",
            "robustness", "fewest_local", "shared_motion", "unfinished", "practical_suggestions",
            "practical_suggestions_note")
"""Top-level keys present only when the analysis ran (or had something to say)."""


@dataclass(frozen=True)
class PlanResult:
    """A marker plan's verdicts (read-only).

    Attributes
    ----------
    all_identifiable, all_local : bool
        Every joint is identifiable (uniquely) / locally identifiable.
    joints : Mapping
        Joint name -> its verdict, with the contract's keys (``identifiable``, ``local``, ``candidates``,
        ``case``, ``min_samples``, ``uses_virtual_markers``, ``reason``) and the explanation's
        (``parent``, ``child``, ``settled_by``, ``depends_on``, ``rejected_by``, ...; ``motion_needed``
        and ``alternative`` when those analyses ran).
    suggestions : tuple of Mapping
        The fewest markers to add, ``{"segment", "add_markers"}`` each, after which every joint is locally
        identifiable (whole-tree rank) and none is settled with several candidates; empty when none are
        needed or none were found (``suggestions_note`` then says so). ``suggestions_check`` says how
        their minimality was checked (every plan with one marker fewer fails).
    certificate : Mapping
        How the whole-tree verdict was computed (prime, frames, failure probability bound, seed).
    suggestions_note, suggestions_check, robustness, fewest_local, shared_motion
        Present (not None) when computed; as in the JSON.
    unfinished : Mapping
        Present when an analysis ran out of its time budget: the joints (``motion_needed``; their
        ``motion_needed`` is then null) and markers (``robustness``) the motion and robustness analyses left, the
        joints ``--witness`` did not search (``witness``), the joints the search for the fewest markers to add was
        settling when it stopped (``suggestions``; nothing is then suggested), ``suggestions_minimal`` False when the
        check that no plan with fewer markers passes stopped, and the ``reason``.
    suggestions_unique, suggestions_unique_note
        The fewest markers after which the propagation settles every joint uniquely, when they differ from
        ``suggestions`` (jointly identifiable joints' candidates are not counted).
    undetermined : Mapping
        Joint -> the quantities of that joint the whole tree leaves undetermined, for every joint that is
        not locally identifiable.
    practical_suggestions : tuple of Mapping
        With ``noise_mm`` and a named motion: one added marker on each segment, best first, with the
        millimetres it would save (:func:`identcheck.fit.marker_value.marker_value`); otherwise
        ``practical_suggestions_note`` says why not.
    root : str
        The model's root segment (for drawing the tree).
    markers : Mapping
        Segment -> its marker names (for drawing the tree).
    """

    all_identifiable: bool
    all_local: bool
    joints: Mapping
    suggestions: tuple
    certificate: Mapping
    root: str
    markers: Mapping
    suggestions_note: str | None = None
    suggestions_check: Mapping | None = None
    suggestions_unique: tuple | None = None
    suggestions_unique_note: str | None = None
    undetermined: Mapping | None = None
    robustness: Mapping | None = None
    fewest_local: Mapping | None = None
    shared_motion: str | None = None
    unfinished: Mapping | None = None
    practical_suggestions: tuple | None = None
    practical_suggestions_note: str | None = None

    @classmethod
    def from_dict(cls, doc: dict, root: str, markers: dict) -> "PlanResult":
        """A PlanResult from the ``plan`` JSON document (a read-only copy) and the model's tree."""
        return cls(all_identifiable=bool(doc["all_identifiable"]), all_local=bool(doc["all_local"]),
                   joints=frozen(doc["joints"]), suggestions=frozen(doc["suggestions"]),
                   certificate=frozen(doc["certificate"]), root=root,
                   markers=frozen({s: list(ms) for s, ms in markers.items()}),
                   **{k: frozen(doc[k]) for k in OPTIONAL if k in doc})

    def to_dict(self) -> dict:
        """The contract's ``plan`` JSON (plus the explanation, motion, robustness and the certificate)."""
        doc = {"all_identifiable": self.all_identifiable, "all_local": self.all_local,
               "joints": plain(self.joints), "suggestions": plain(self.suggestions)}
        for k in OPTIONAL:
            if getattr(self, k) is not None:
                doc[k] = plain(getattr(self, k))
        doc["certificate"] = plain(self.certificate)
        return doc
