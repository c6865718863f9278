"""Identify one joint of a model from a recorded or simulated trial with the exact-case solvers.

This is the structural-identifiability view of a real trial: the markers a joint's case uses
(revolute (2,1): two on the parent, one on the child), the samples taken to the parent's
marker frame, and every joint the samples admit, each with its marker distances. Statistical
fitting with uncertainty is ``identcheck fit`` (a separate capability).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .io.model import Model
from .solve import revolute21
from .solve.frames import pair_frame
from .trial import Trial


@dataclass
class JointIdentification:
    """Every joint the trial's samples admit for one model joint."""

    joint: str
    type: str
    case: str
    markers: dict
    n_samples: int
    frames: list
    parent_spread_mm: float
    candidates: list  # [{"d","r","alpha","l","rho","mirror","parameter_set","residual_mm","marker_distances"}]

    @property
    def unique(self) -> bool:
        return len(self.candidates) == 1

    @property
    def n_parameter_sets(self) -> int:
        return len({c["parameter_set"] for c in self.candidates})


def identify_joint(model: Model, trial: Trial, joint: str, frames=None, precision=None) -> JointIdentification:
    """Identify ``joint`` of ``model`` from ``trial`` (all fully visible frames by default).

    Raises
    ------
    InputError
        Unknown joint, a marker case this verb does not cover, a marker missing from the trial,
        or fewer than 5 frames where all the joint's markers are visible.
    """
    if joint not in model.joints:
        raise InputError([f"unknown joint {joint!r}; the model has: {', '.join(model.joints) or 'none'}"],
                         source=model.source)
    jt = model.joints[joint]
    parent, child = model.joint_markers(joint)
    if (jt.type, len(parent), len(child)) != ("revolute", 2, 1):
        raise InputError([f"joint {joint!r} is {jt.type} with ({len(parent)},{len(child)}) markers; "
                          "identify covers the revolute (2,1) case of Pham et al. so far "
                          "(two markers on the parent segment, one on the child)"], source=model.source)
    names = list(parent) + list(child)
    xyz = trial.select(names).as_array()
    visible = np.all(np.isfinite(xyz), axis=(1, 2))
    if frames is None:
        frames = np.flatnonzero(visible).tolist()
    else:
        bad = [f for f in frames if not (0 <= f < trial.n_frames)]
        if bad:
            raise InputError([f"frames {bad} are outside the trial (0..{trial.n_frames - 1})"], source=trial.source)
        hidden = [f for f in frames if not visible[f]]
        if hidden:
            raise InputError([f"frames {hidden}: a marker of {names} is occluded there"], source=trial.source)
    if len(frames) < revolute21.N_UNKNOWNS:
        raise InputError([f"only {len(frames)} frames show all of {names}; revolute (2,1) needs at least "
                          f"{revolute21.N_UNKNOWNS}"], source=trial.source)
    sel = xyz[frames]
    local, h = pair_frame(sel[:, 0], sel[:, 1], sel[:, 2])
    if precision is None:
        ident = revolute21.identify(local, rel_tol=np.inf)
    else:
        ident = revolute21.identify(local, precision=precision, rel_tol=np.inf)
    hbar = float(np.mean(h))
    cands = []
    for j in ident.joints:
        dist = j.marker_distances(hbar)
        cands.append({
            "parameter_set": j.root, "mirror": j.mirror,
            "d": float(j.d), "r": float(j.r), "alpha": float(j.alpha), "l": float(j.l), "rho": float(j.rho),
            "residual_mm": float(j.residual),
            "marker_distances": {parent[0]: dist["A1"], parent[1]: dist["A2"], child[0]: dist["B"]},
        })
    return JointIdentification(joint=joint, type=jt.type, case="revolute(2,1)",
                               markers={"parent": list(parent), "child": list(child)},
                               n_samples=len(frames), frames=list(map(int, frames)),
                               parent_spread_mm=float(np.ptp(h)), candidates=cands)
