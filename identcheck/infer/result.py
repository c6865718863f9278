"""What ``identcheck skeleton`` returns: the segments, the tree and the joint types inferred from a trial, what the
data left open, and where the model was written."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from identcheck.io.jsonable import frozen, plain


@dataclass(frozen=True)
class SkeletonResult:
    """A skeleton inferred from a trial (read-only).

    Attributes
    ----------
    segments : Mapping
        Segment name → its markers: every rigid group (placed in the tree or not) and every one-marker segment.
    unassigned_markers : tuple
        Markers rigid with no other marker and attached to no segment.
    joints : tuple
        One mapping per joint, parents before children: ``name``, ``parent``, ``child``, ``type``, ``residual_mm``,
        ``confidence``, ``evidence``.
    runner_up : tuple
        Per joint, the best pair that could replace it and its residual.
    ambiguous : tuple
        Joints whose runner-up fits within the noise: both trees and the motion that would separate them.
    loops : tuple
        Pairs the tree does not join that fit a joint as well as a joint in it.
    cannot_place : tuple
        Groups of markers with no joint to the tree, with the reason.
    poor_joints : tuple
        Joints of the tree far worse than the others (two segments joined through something without a pose?).
    other : Mapping
        The rest of the JSON document (root, grouping, noise, playback, model path, warnings, ...).
    """

    segments: Mapping
    unassigned_markers: tuple = ()
    joints: tuple = ()
    runner_up: tuple = ()
    ambiguous: tuple = ()
    loops: tuple = ()
    cannot_place: tuple = ()
    poor_joints: tuple = ()
    other: Mapping = field(default_factory=lambda: MappingProxyType({}))

    KEYS = ("segments", "unassigned_markers", "joints", "runner_up", "ambiguous", "loops", "cannot_place",
            "poor_joints")

    @property
    def ok(self) -> bool:
        """The data settle the skeleton: some joint, none ambiguous or poor, every group of markers placed, every
        marker judged (a marker seen in too few frames to group, ``grouping.too_rarely_seen``, may be on a segment
        the model lacks: a pelvis seen in 5 frames had been left out of a trial called settled; a marker judged
        loose, fitting no joint, is an answer), and no group held together beyond the rigidity tolerance
        (``grouping.widened``) or moving inside beyond the noise (``may_be_two_segments``), which needs the marker
        noise: an inferred grouping whose noise could not be estimated (``noise`` null) is not settled. A marker
        that moves with both segments of a joint (``markers_on_joints``) leaves it settled: whichever segment
        carries it, it moves the same."""
        grouping = self.other.get("grouping") or {}
        unchecked = self.other.get("noise") is None and grouping.get("source") == "inferred"
        return (bool(self.joints) and not self.ambiguous and not self.cannot_place and not self.poor_joints
                and not grouping.get("too_rarely_seen") and not grouping.get("widened")
                and not self.other.get("may_be_two_segments") and not unchecked)

    @classmethod
    def from_dict(cls, doc: dict) -> "SkeletonResult":
        """A SkeletonResult from its JSON document (a read-only copy)."""
        rest = {k: v for k, v in doc.items() if k not in cls.KEYS}
        return cls(**{k: frozen(doc.get(k, {} if k == "segments" else [])) for k in cls.KEYS}, other=frozen(rest))

    def to_dict(self) -> dict:
        """The ``skeleton`` JSON document."""
        return {**{k: plain(getattr(self, k)) for k in self.KEYS}, **plain(self.other), "ok": self.ok}
