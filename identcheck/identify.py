"""Identify one joint of a model from a recorded or simulated trial with the exact-case solvers.

This is the structural-identifiability view of a real trial: the markers a joint's case uses
(revolute (2,1): two on the parent, one on the child; spherical (3,1): three and one, the
centre from each child marker; spherical (2,2): two and two), the samples taken to the
parent's marker frame, and every joint the samples admit, each with its marker distances. Statistical
fitting with uncertainty is ``identcheck fit`` (a separate capability).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from identcheck.errors import DegenerateError, InputError
from identcheck.io.jsonable import frozen, plain
from identcheck.io.model import Model
from identcheck.solve import revolute21, spherical22, spherical31
from identcheck.geometry.frames import pair_frame, parent_frame, to_local
from identcheck.trial import Trial


@dataclass(frozen=True)
class JointIdentification:
    """Every joint the trial's samples admit for one model joint.

    Attributes
    ----------
    joint, type, case : str
        The model's joint, its type and the exact case used (``"revolute(2,1)"``).
    markers : Mapping
        ``{"parent": (names), "child": (names)}``: the markers the case uses.
    n_samples : int
        Frames used.
    frames : tuple of int
        Their 0-based indices.
    parent_spread_mm : float
        Largest peak-to-peak change of a distance between parent markers (a rigidity check), mm.
    candidates : tuple of Mapping
        Every joint the samples admit (read-only), each with ``parameter_set``, ``mirror``,
        ``residual_mm``, ``marker_distances`` (mm) and the case's parameters (``d``, ``r``, ...).
    """

    joint: str
    type: str
    case: str
    markers: MappingProxyType
    n_samples: int
    frames: tuple
    parent_spread_mm: float
    candidates: tuple

    @property
    def unique(self) -> bool:
        return len(self.candidates) == 1

    @property
    def n_parameter_sets(self) -> int:
        return len({c["parameter_set"] for c in self.candidates})

    def to_dict(self) -> dict:
        """The joint as ``identcheck identify --json`` reports it: the best-fitting candidate's marker
        distances, the others as ``alternatives``."""
        best = min(self.candidates, key=lambda c: c["residual_mm"])
        return {
            "type": self.type, "case": self.case, "unique": self.unique,
            "candidates": len(self.candidates), "parameter_sets": self.n_parameter_sets,
            "marker_distances": plain(best["marker_distances"]),
            "alternatives": [plain(c) for c in self.candidates if c is not best],
            "rms_residual": best["residual_mm"], "n_samples": self.n_samples,
            "parent_marker_spread_mm": self.parent_spread_mm, "markers": plain(self.markers),
        }


@dataclass(frozen=True)
class IdentifyResult:
    """Every joint a trial's samples admit, for each joint asked (``identcheck identify``).

    Attributes
    ----------
    joints : tuple of JointIdentification
        In the order asked.
    """

    joints: tuple

    @property
    def unique(self) -> bool:
        """Every joint asked is determined uniquely."""
        return all(j.unique for j in self.joints)

    def __getitem__(self, name: str) -> JointIdentification:
        for j in self.joints:
            if j.joint == name:
                return j
        raise KeyError(name)

    def to_dict(self) -> dict:
        """``{"joints": {NAME: {...}}}`` as ``identcheck identify --json`` prints it."""
        return {"joints": {j.joint: j.to_dict() for j in self.joints}}


def identify(model: Model, trial: Trial, joints=None, frames=None, precision=None) -> IdentifyResult:
    """Identify ``joints`` of ``model`` (default: all, in the model's order) from ``trial``.

    Parameters
    ----------
    model : Model
    trial : Trial
    joints : iterable of str, optional
        Joint names; default every joint of the model.
    frames : iterable of int, optional
        0-based frame indices; default every frame where the joint's markers are all visible.
    precision : int, optional
        Decimal digits (mpmath) instead of float64.

    Raises
    ------
    InputError
        See :func:`identify_joint`.
    """
    names = list(joints) if joints else list(model.joint_order)
    frames = None if frames is None else list(frames)
    used = [m for n in names if n in model.joints for m in model.joint_markers(n)[0] + model.joint_markers(n)[1]]
    trial, unprefixed = trial.unprefixed(used)      # Vicon's 'Subject:Marker' labels (Trial.unprefixed)
    if unprefixed:
        warnings.warn(unprefixed, UserWarning, stacklevel=2)
    return IdentifyResult(tuple(identify_joint(model, trial, n, frames=frames, precision=precision) for n in names))


def identify_joint(model: Model, trial: Trial, joint: str, frames=None, precision=None) -> JointIdentification:
    """Identify ``joint`` of ``model`` from ``trial`` (all fully visible frames by default).

    Raises
    ------
    InputError
        Unknown joint, a marker case this verb does not cover, a marker missing from the trial, never
        visible or coinciding with another (:meth:`Trial.require_usable`), or fewer than 5 frames where all the
        joint's markers are visible.
    """
    if joint not in model.joints:
        raise InputError([f"unknown joint {joint!r}; the model has: {', '.join(model.joints) or 'none'}"],
                         source=model.source)
    jt = model.joints[joint]
    parent, child = model.joint_markers(joint)
    key = (jt.type, min(len(parent), 3) if jt.type == "spherical" else len(parent), len(child))
    if key not in _CASES and not (jt.type == "spherical" and key[0:2] == ("spherical", 3) and key[2] >= 1):
        raise InputError([f"joint {joint!r} is {jt.type} with ({len(parent)},{len(child)}) markers; identify covers "
                          "the exact cases of Pham et al.: revolute (2,1), spherical (3,q) and spherical (2,2) "
                          "(markers on the parent, on the child)"], source=model.source)
    label, n_min, solver = _CASES.get(key, _CASES[("spherical", 3, 1)])
    parent = list(parent)[:3] if jt.type == "spherical" else list(parent)
    names = list(parent) + list(child)
    model.require_markers_in(trial, names)
    frames = _frames(trial, names, frames, n_min, label)
    sel = trial.select(names).as_array()[frames]
    if solver is _spherical3q:
        _require_motion(sel, parent, list(child), _noise_sd(model, trial, joint), trial.source)
    cands = solver(sel, parent, list(child), precision)
    return JointIdentification(joint=joint, type=jt.type, case=label,
                               markers=frozen({"parent": list(parent), "child": list(child)}),
                               n_samples=len(frames), frames=tuple(map(int, frames)),
                               parent_spread_mm=_parent_spread(sel[:, :len(parent)]), candidates=frozen(cands))


def _frames(trial: Trial, names, frames, n_min: int, label: str) -> list:
    """The frames to use: all fully visible ones by default; requested ones must be visible."""
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
            seen = np.all(np.isfinite(xyz), axis=2)                                        # (F, markers)
            lines = [f"frame {f}: {', '.join(repr(n) for n, ok in zip(names, seen[f]) if not ok)} occluded there"
                     for f in hidden[:10]]
            more = f" (and {len(hidden) - 10} more frames)" if len(hidden) > 10 else ""
            raise InputError(lines[:-1] + [f"{lines[-1]}{more}; the joint needs {', '.join(map(repr, names))} in "
                                           "every frame used"], source=trial.source)
    if len(frames) < n_min:
        raise InputError([f"only {len(frames)} frames show all of {names}; {label} needs at least {n_min}"],
                         source=trial.source)
    return frames


MOTION_SIGMAS = 10.0
"""A ball joint's child markers must move in the parent's frame by this many times the trial's noise (the RMS spread
of the one that moves most, along its widest direction) for a sphere through their samples to mean anything: a marker
that stays put is fitted best by a tiny sphere around itself (a static hip trial gave a knee marker 0.00 mm from the
centre, the truth 402.5 mm, exit 0)."""


def _noise_sd(model: Model, trial: Trial, joint: str) -> float:
    """The trial's marker noise (mm per coordinate) from the distances within the joint's two segments
    (:func:`identcheck.estimate.noise.noise_floor`), 0 when no pair of their markers shows it."""
    from identcheck.estimate.noise import noise_floor      # (SciPy: only for the joints that need it)

    jt = model.joints[joint]
    segments = {s: [m for m in model.segments[s].markers if m in trial.labels] for s in (jt.parent, jt.child)}
    names = sorted({m for ms in segments.values() for m in ms})
    try:
        return float(noise_floor(trial.select(names).as_array(), names, segments).sigma_mm)
    except (InputError, ValueError):
        return 0.0


def _require_motion(sel: np.ndarray, parent, child, sigma: float, source) -> None:
    """Raise DegenerateError when no child marker moves in the parent's frame well beyond the noise
    (:data:`MOTION_SIGMAS`) and turns, seen from the parent markers' mean, by more than the tolerance ``fit`` and
    ``diagnose`` hold a joint's rotation to (:data:`identcheck.estimate.obrien.HINGE_TOL_DEG`): the joint hardly
    moved. The joint is judged by the marker that moves most (one near the centre barely moves however the joint
    turns). A subject standing still sways: on a real static pose a thigh marker moved 2.1 mm RMS in the pelvis's
    frame, 400 mm away, and its sphere put the hip 3.4 mm from it. (A joint that turns a few degrees more still leaves
    the exact solver's sphere biased small under noise: a hip turned ±5° under 0.5 mm of noise put the knee marker
    150-265 mm from the centre, truth 402.5 mm; ``fit`` judges that, ``identify`` does not.)"""
    from identcheck.estimate.obrien import HINGE_TOL_DEG as STILL_DEG    # (SciPy, as the noise estimate already)

    rot, _ = parent_frame(sel[:, 0], sel[:, 1], sel[:, 2] - sel[:, 0], names=(parent[0], parent[1], parent[2]))
    local = to_local(rot, sel[:, 0], sel)
    floor = max(sigma, 1e-6 * float(np.sqrt(np.mean(local[:, 3:] ** 2))))     # noise-free: float32 file precision
    hub = local[:, :3].mean(axis=(0, 1))
    moves = []
    for k, name in enumerate(child):
        xyz = local[:, 3 + k]
        widest = float(np.linalg.svd(xyz - xyz.mean(axis=0), compute_uv=False)[0] / np.sqrt(len(xyz)))
        turn = float(np.degrees(widest / max(float(np.linalg.norm(xyz.mean(axis=0) - hub)), 1e-12)))
        if widest >= MOTION_SIGMAS * floor and turn >= STILL_DEG:
            return
        moves.append((turn, widest, name))
    turn, widest, name = max(moves)
    raise DegenerateError(f"{source}: the joint hardly moves: {name}, the child marker that moves most in the frame of "
                          f"{', '.join(parent)}, spreads {widest:.3g} mm RMS along its widest direction, "
                          f"{turn:.2g} deg "
                          f"seen from those markers, against {floor:.2g} mm of noise and a {STILL_DEG:g} deg "
                          "tolerance: a point that stays put is fitted best by a small sphere around itself, so the "
                          "centre is not determined. Record the joint moving (flexion, abduction, rotation).")


def _parent_spread(parent_xyz: np.ndarray) -> float:
    """Largest peak-to-peak change of a distance between parent markers (rigidity check), mm."""
    n = parent_xyz.shape[1]
    spreads = [np.ptp(np.linalg.norm(parent_xyz[:, i] - parent_xyz[:, j], axis=-1))
               for i in range(n) for j in range(i + 1, n)]
    return float(max(spreads, default=0.0))


def _revolute21(sel, parent, child, precision) -> list:
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
    return cands


def _spherical3q(sel, parent, child, precision) -> list:
    """One sphere per child marker in the parent's frame F_GL; they must share the centre."""
    rot, _ = parent_frame(sel[:, 0], sel[:, 1], sel[:, 2] - sel[:, 0], names=(parent[0], parent[1], parent[2]))
    local = to_local(rot, sel[:, 0], sel)                     # (frames, markers, 3)
    centres, dist = [], {}
    for k, name in enumerate(child):
        j = spherical31.identify(local[:, 3 + k], precision=precision, rel_tol=np.inf).joints[0]
        centres.append(np.asarray(j.centre, dtype=float))
        dist[name] = float(j.rho)
    centre = np.mean(centres, axis=0)
    for i, name in enumerate(parent):
        dist[name] = float(np.mean(np.linalg.norm(local[:, i] - centre, axis=-1)))
    # every child marker's sphere should have the same centre; how far apart they are is the residual
    spread = max(float(np.linalg.norm(c - centre)) for c in centres)
    rebuilt = max(float(np.max(np.abs(np.linalg.norm(local[:, 3 + k] - centre, axis=-1) - dist[n])))
                  for k, n in enumerate(child))
    return [{"parameter_set": 0, "mirror": False, "centre_parent_frame": centre.tolist(),
             "residual_mm": max(spread, rebuilt), "marker_distances": dist}]


def _spherical22(sel, parent, child, precision) -> list:
    b, h = pair_frame(sel[:, :1], sel[:, 1:2], sel[:, 2:4])
    ident = spherical22.identify(b[:, 0], b[:, 1], precision=precision, rel_tol=np.inf) if precision is None \
        else spherical22.identify(b[:, 0].tolist(), b[:, 1].tolist(), precision=precision)
    out = []
    for j in ident.joints:
        dist = j.marker_distances(float(np.mean(h)))
        out.append({"parameter_set": 0, "mirror": False, "d": float(j.d), "r": float(j.r), "rho1": float(j.rho1),
                    "rho2": float(j.rho2), "residual_mm": float(j.residual),
                    "marker_distances": {parent[0]: dist["A1"], parent[1]: dist["A2"],
                                         child[0]: dist["B1"], child[1]: dist["B2"]}})
    return out


# (type, p, q) -> (case label, minimum samples, solver)
_CASES = {
    ("revolute", 2, 1): ("revolute(2,1)", revolute21.N_UNKNOWNS, _revolute21),
    ("spherical", 3, 1): ("spherical(3,1)", spherical31.N_UNKNOWNS, _spherical3q),
    ("spherical", 2, 2): ("spherical(2,2)", spherical22.n_unknowns(), _spherical22),
}
