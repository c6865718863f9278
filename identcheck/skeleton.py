"""The model's tree compiled once: segment and joint order (parents before children), each joint's
parent and child, each segment's marker columns, and the marker columns below every joint.

Everything that walks the tree (the whole-chain fit, the effects, the label screen) reads this one
structure instead of re-deriving the order from the model file.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Skeleton:
    """The model's tree as index arrays: which markers each segment and each joint moves.

    ``types`` may differ from the model's (``extra_dof`` refits a hinge as a ball joint).
    """

    segments: tuple          # segment names, parents before children
    root: str
    joints: tuple            # joint names, parents before children
    types: dict              # joint -> "spherical" | "revolute"
    parent: dict             # joint -> parent segment
    child: dict              # joint -> child segment
    labels: tuple            # marker names, trial column order
    seg_markers: dict        # segment -> marker column indices
    marker_seg: tuple        # column -> segment name
    downstream: dict         # joint -> column indices of every marker below the joint

    @classmethod
    def from_model(cls, model, types: dict | None = None, markers=None) -> "Skeleton":
        """The model's tree; ``types`` overrides joint types, ``markers`` (a set of names) keeps only
        those markers (a marker the trial never shows carries no information)."""
        types = {j: model.joints[j].type for j in model.joint_order} | dict(types or {})
        keep = (lambda m: True) if markers is None else (lambda m: m in markers)  # noqa: E731
        labels = tuple(m for m in model.markers if keep(m))
        col = {m: i for i, m in enumerate(labels)}
        seg_markers = {s: np.array([col[m] for m in model.segments[s].markers if keep(m)], dtype=int)
                       for s in model.segments}
        marker_seg = tuple(s for s in model.segments for m in model.segments[s].markers if keep(m))
        parent = {j: model.joints[j].parent for j in model.joint_order}
        child = {j: model.joints[j].child for j in model.joint_order}
        below = {}
        for j in reversed(model.joint_order):      # children's subtrees are complete first
            segs = {child[j]} | {s for k in model.joint_order if parent[k] == child[j] for s in below[k]}
            below[j] = segs
        downstream = {j: np.sort(np.concatenate([seg_markers[s] for s in below[j]])) for j in model.joint_order}
        order = [model.root] + [child[j] for j in model.joint_order]
        return cls(tuple(order), model.root, tuple(model.joint_order), types, parent, child, labels,
                   seg_markers, marker_seg, downstream)

    @property
    def n_markers(self) -> int:
        return len(self.labels)

    def frame_dof(self) -> int:
        """Unknowns per frame: the root pose plus each joint's angles."""
        return 6 + sum(3 if self.types[j] == "spherical" else 1 for j in self.joints)

    def joints_below(self, joint: str) -> list:
        """The joints in the subtree hanging from `joint` (not itself), parents first."""
        segs, out = {self.child[joint]}, []
        for k in self.joints:                      # parents before children
            if self.parent[k] in segs:
                out.append(k)
                segs.add(self.child[k])
        return out

    def frame_free(self) -> int:
        """Unknowns per frame that change no prediction, in the configurations where the tree's structure alone says so
        (markers in general position): a segment hung from a ball joint whose points all lie on one line through its
        centre turns about that line unseen, with what hangs below it by ball joints alone turning back (one marker and
        nothing below; no marker and one ball joint below), and with no marker and nothing below every angle of its
        joint is unseen; the root likewise (one marker and one ball joint below it, or no marker and one ball joint:
        its whole turn). A fit's parameter count leaves them out (:func:`identcheck.bundle.chain.fit_chain`): counted,
        a trial's gap was held to a noise floor one parameter a frame too low, and ``diagnose`` called clean trials of
        a hinge and a ball after two one-marker segments unexplained (gap²/floor² 1.24 against a limit of 1.17, the
        free turns' share of the degrees of freedom: 1 000 of 6 000)."""
        free = 0
        for seg in self.segments:
            up = [j for j in self.joints if self.child[j] == seg]
            down = [j for j in self.joints if self.parent[j] == seg]
            n = len(self.seg_markers[seg])
            balls_only = all(self.types[k] == "spherical" for k in down)
            kind = self.types[up[0]] if up else "root"
            if kind == "revolute":
                free += 1 if n == 0 and not down else 0
            elif not down:
                free += 3 if n == 0 else (1 if n == 1 else 0)
            elif balls_only and len(down) == 1:
                free += (3 if kind == "root" else 1) if n == 0 else (1 if n == 1 and kind == "root" else 0)
        return free

    def gauge(self) -> int:
        """Parameter directions that change no prediction: each segment frame (6), and each hinge's
        slide along its axis and angle offset (2)."""
        return 6 * len(self.segments) + 2 * sum(self.types[j] == "revolute" for j in self.joints)
