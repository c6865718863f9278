"""The fitted skeleton as an OpenSim model (``fit --export-osim OUT.osim``), written with OpenSim's own Python
package (the optional extra ``identcheck[osim]``), so that a lab can run OpenSim's inverse kinematics on the
joints this trial determined.

One body per segment, its frame the whole-tree fit's segment frame; the root hangs from the ground by a free
joint; a ball joint becomes a ``BallJoint`` and a hinge a ``PinJoint`` whose joint frames put their z axis on
the fitted hinge axis, located at the fitted centre (a hinge: the fit's point of its axis) in both segments;
every marker sits on its body at its fitted body-fixed position. Lengths in metres, as OpenSim wants. With
every coordinate at zero the model stands in the pose of the fit's reference (root at the ground's origin, each
hinge at its rest rotation, each ball joint's segments aligned), and each pin's coordinate is the fit's hinge
angle θ. The masses and inertias are placeholders (1 kg, 0.01 kg m²): the model is kinematic, for marker-based
inverse kinematics, not for dynamics.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.bundle.model import tangents
from identcheck.errors import InputError
from identcheck.io.atomic import replacing

MM = 1e-3        # metres per millimetre


def opensim_missing() -> str:
    """Why OpenSim's Python package cannot be used ('' when it can): what to install."""
    try:
        import opensim  # noqa: F401
    except ImportError:
        return "needs OpenSim's Python package, which is not installed: pip install 'identcheck[osim]'"
    return ""


INVALID_CHARACTERS = "\\*+ \t/"
"""Characters OpenSim refuses in a component's name (its error: 'contains invalid characters of: \\*+ \\t/'): a body,
joint or marker named with one stopped OpenSim after the whole fit, with a traceback and then a crash of the process
(a segment "fore arm", a joint "hip r", a marker "R*KNEE")."""


def name_problems(model) -> list[str]:
    """What in `model` (an :class:`identcheck.io.model.Model`) OpenSim cannot name: each segment, joint and marker
    whose name holds one of :data:`INVALID_CHARACTERS`, or none ([]). Checked before the fit."""
    shown = {" ": "a space", "\t": "a tab"}
    out = []
    for kind, names in (("segment", list(model.segments)), ("joint", list(model.joints)), ("marker", model.markers)):
        for name in names:
            bad = sorted({c for c in name if c in INVALID_CHARACTERS})
            if bad:
                which = ", ".join(shown.get(c, repr(c)) for c in bad)
                out.append(f"{kind} {name!r}: OpenSim does not allow {which} in a name; rename it in the model file "
                           "to export it with --export-osim")
    return out


def hinge_frames(axis: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pin joint's frame in the parent (columns: its axes, z on the hinge axis) and in the child, such that
    ``F_p · Rot(z, θ) · F_cᵀ = Rot(axis, θ) · rest``, the fit's relative rotation at hinge angle θ."""
    b1, b2 = tangents(axis)
    F_p = np.column_stack([b1, b2, axis])
    return F_p, rest.T @ F_p


def _opensim():
    """OpenSim's module, its log kept off the user's disk: by default it appends to ``opensim.log`` in whatever
    folder the user runs from, which a library must not do."""
    import opensim as osim

    osim.Logger.removeFileSink()
    return osim


def _vec(v) -> "object":
    import opensim as osim

    v = np.asarray(v, dtype=float)
    return osim.Vec3(float(v[0]), float(v[1]), float(v[2]))


def _euler(F: np.ndarray):
    """OpenSim's orientation of a frame (body-fixed x-y-z angles) from its rotation matrix."""
    return _vec(Rotation.from_matrix(F).as_euler("XYZ"))


def build_model(fit, name: str = "identcheck"):
    """The opensim.Model of a whole-chain fit (see the module docstring)."""
    osim = _opensim()

    chain, s = fit.chain, fit.state
    model = osim.Model()
    model.setName(name)
    bodies = {}
    for seg in chain.segments:
        bodies[seg] = osim.Body(seg, 1.0, osim.Vec3(0), osim.Inertia(0.01, 0.01, 0.01))
        model.addBody(bodies[seg])
    root = osim.FreeJoint(f"ground_{chain.root}", model.getGround(), osim.Vec3(0), osim.Vec3(0),
                          bodies[chain.root], osim.Vec3(0), osim.Vec3(0))
    for i, what in enumerate(("rx", "ry", "rz", "tx", "ty", "tz")):
        root.upd_coordinates(i).setName(f"{chain.root}_{what}")
    model.addJoint(root)
    for j in chain.joints:
        parent, child = bodies[chain.parent[j]], bodies[chain.child[j]]
        at_parent, at_child = _vec(MM * s.c_parent[j]), _vec(MM * s.c_child[j])
        if chain.types[j] == "spherical":
            joint = osim.BallJoint(j, parent, at_parent, osim.Vec3(0), child, at_child, osim.Vec3(0))
            for i, what in enumerate(("rx", "ry", "rz")):
                joint.upd_coordinates(i).setName(f"{j}_{what}")
        else:
            F_p, F_c = hinge_frames(s.axis[j], s.rest[j])
            joint = osim.PinJoint(j, parent, at_parent, _euler(F_p), child, at_child, _euler(F_c))
            joint.upd_coordinates(0).setName(f"{j}_angle")
        model.addJoint(joint)
    for i, label in enumerate(chain.labels):
        model.addMarker(osim.Marker(label, bodies[chain.marker_seg[i]], _vec(MM * s.local[i])))
    model.finalizeConnections()
    return model


def export_osim(path, fit, name: str = "identcheck") -> None:
    """Write the OpenSim model of a whole-chain fit to `path` (.osim)."""
    problem = opensim_missing()
    if problem:
        raise InputError([f"--export-osim {path}: {problem}"])
    if fit.terms.size():
        raise InputError([f"--export-osim {path}: the fit carries effect terms, which an OpenSim model of rigid "
                          "joints cannot hold"])
    model = build_model(fit, name)
    try:
        with replacing(path) as tmp:
            if model.printToXML(str(tmp)) is False or not tmp.stat().st_size:
                raise OSError("OpenSim wrote nothing")
    except (RuntimeError, OSError) as exc:          # OpenSim says a failed write with a RuntimeError of its own
        why = getattr(exc, "strerror", None) or str(exc).strip().splitlines()[0]
        raise InputError([f"--export-osim {path}: cannot write the model ({why})"]) from None
