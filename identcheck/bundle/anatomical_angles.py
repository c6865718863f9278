"""Joint angles as a biomechanist reads them: flexion–extension, ab-/adduction and axial rotation of a ball
joint, a Cardan (Grood–Suntay) decomposition of its rotation in the joint's own frames; a hinge's flexion is its
hinge angle.

Why: the figures put a joint's motion on their axes, and a rotation-vector component (or the direction it
turned most, in a technical frame of three arbitrary markers) is not an angle anyone reads. A joint frame needs
three directions, all taken from the fit, none from a marker's name except the pelvis's:

- the long axis of the child segment: from its distal point to the joint centre (pointing proximally). The
  distal point is the next joint down: a hinge's axis point nearest the centre (the knee below a hip), else
  the centre of the next ball joint; a segment with no joint below uses the centroid of its markers.
- the medio-lateral axis of the child: the axis of a hinge below it (the knee's flexion axis for the thigh, as
  in functional femur frames), else the direction the joint itself turned most (its main rotation, which in
  gait and in functional trials is flexion), made perpendicular to the long axis.
- the parent's frame: the ISB pelvis frame when the parent carries the ASIS and posterior pelvis markers
  (:mod:`identcheck.geometry.pelvis`; then the angles are zero in the anatomical neutral pose and flexion is
  positive), else the child's frame at the trial's median pose (angles zero there).

Each frame's rows are (medio-lateral, antero-posterior, long) = (x, y, z), right-handed. The joint rotation
Q = P R_rel Cᵀ (P, C: the parent's and the child's frame rows in their segments' coordinates; R_rel the fitted
child-to-parent rotation) is decomposed as intrinsic x-y-z Cardan angles: flexion about the parent's
medio-lateral axis, ab-/adduction about the floating axis, axial rotation about the child's long axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.geometry.pelvis import pelvis_frame, pelvis_markers

ANGLE_NAMES = ("flexion–extension", "ab-/adduction", "axial rotation")


@dataclass(frozen=True)
class JointFrames:
    """A ball joint's two frames and where their axes came from.

    Attributes
    ----------
    parent, child : ndarray (3, 3)
        Rows: the medio-lateral, antero-posterior and long axes, in the parent's / the child's segment
        coordinates.
    medio_lateral : str
        Where the medio-lateral axis came from (``"knee_r's hinge axis"``, ``"its main rotation"``).
    zero : str
        Where the angles are zero (``"the ISB pelvis neutral"`` or ``"the median pose"``).
    """

    parent: np.ndarray
    child: np.ndarray
    medio_lateral: str
    zero: str


def cardan_angles(parent: np.ndarray, rel: np.ndarray, child: np.ndarray) -> np.ndarray:
    """Intrinsic x-y-z Cardan angles (F, 3), radians, of Q = parent @ rel @ childᵀ for rotations `rel` (F, 3, 3)
    and frame rows `parent`, `child` (3, 3): about x of the parent's frame, the floating y, then z of the
    child's."""
    Q = np.einsum("ij,fjk,lk->fil", parent, rel, child)
    return Rotation.from_matrix(Q).as_euler("XYZ")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _rows(medio_lateral: np.ndarray, long: np.ndarray) -> np.ndarray:
    """Frame rows (ML, AP, long) from a long axis and a medio-lateral direction not parallel to it."""
    z = _unit(long)
    x = _unit(medio_lateral - (medio_lateral @ z) * z)
    return np.stack([x, np.cross(z, x), z])


def _main_rotation(rel: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The direction (child coordinates at the median pose `ref`) about which the rotations `rel` turned most."""
    w = Rotation.from_matrix(rel @ ref.T).as_rotvec()
    _, _, vt = np.linalg.svd(w - w.mean(axis=0), full_matrices=False)
    return ref.T @ vt[0]


def _isb_rows(chain, state, segment: str) -> np.ndarray | None:
    """The ISB pelvis frame's rows (right, anterior, superior) in `segment`'s coordinates, when its markers
    include the ASIS and the posterior pelvis markers; else None."""
    names = pelvis_markers(chain.labels)
    if names is None:
        return None
    used = [names["right_asis"], names["left_asis"], *names["posterior"]]
    cols = [chain.labels.index(m) for m in used]
    if any(chain.marker_seg[c] != segment for c in cols):
        return None
    local = state.local[cols]
    R, _, _, _ = pelvis_frame(local[:1], local[1:2], np.mean(local[2:], axis=0)[None])
    x, y, z = R[0].T                                  # columns: anterior, superior, right
    return np.stack([z, x, y])


def joint_frames(fit, joint: str) -> JointFrames:
    """The frames of ball joint `joint` in the whole-tree fit `fit` (a :class:`~identcheck.bundle.chain.Fit` or
    anything with ``.fit``), built as the module says."""
    fit = getattr(fit, "fit", fit)
    chain, s = fit.chain, fit.state
    seg = chain.child[joint]
    centre = s.c_child[joint]
    rel = s.rel_R[joint]
    ref = Rotation.from_matrix(rel).mean().as_matrix()
    below = [k for k in chain.joints if chain.parent[k] == seg]
    hinge = next((k for k in below if chain.types[k] == "revolute"), None)
    if hinge is not None:
        a = s.axis[hinge]
        distal = s.c_parent[hinge] + ((centre - s.c_parent[hinge]) @ a) * a
    elif below:
        distal = s.c_parent[below[0]]
    else:
        cols = chain.seg_markers[seg]
        distal = s.local[cols].mean(axis=0) if len(cols) else None
    ml = s.axis[hinge] if hinge is not None else _main_rotation(rel, ref)
    source = f"{hinge}'s hinge axis" if hinge is not None else "its main rotation"
    long = centre - distal if distal is not None else None
    if long is None or np.linalg.norm(long) < 1e-6 or np.linalg.norm(np.cross(_unit(long), _unit(ml))) < 0.1:
        # no usable long axis (no joint below, no marker, or along the medio-lateral axis): the main rotation
        # gives the medio-lateral axis and any perpendicular direction the long one
        ml = _main_rotation(rel, ref)
        helper = np.eye(3)[int(np.argmin(np.abs(ml)))]
        long = np.cross(ml, helper)
        source = "its main rotation"
    child = _rows(ml, long)
    isb = _isb_rows(chain, s, chain.parent[joint])
    if isb is not None:
        in_parent = ref @ child.T                     # the child's axes in the parent, at the median pose
        if in_parent[:, 0] @ isb[0] < 0:              # point the medio-lateral axis to the right, as ISB does
            child = np.stack([-child[0], -child[1], child[2]])
        if (ref @ child[2]) @ isb[2] < 0:             # and the long axis superiorly
            child = np.stack([child[0], -child[1], -child[2]])
        return JointFrames(isb, child, source, "the ISB pelvis neutral")
    return JointFrames(child @ ref.T, child, source, "the median pose")


def anatomical_angles(fit, joint: str) -> tuple[np.ndarray, JointFrames]:
    """Ball joint `joint`'s flexion–extension, ab-/adduction and axial rotation per frame (F, 3), radians, with
    the frames they are measured in."""
    fit = getattr(fit, "fit", fit)
    frames = joint_frames(fit, joint)
    return cardan_angles(frames.parent, fit.state.rel_R[joint], frames.child), frames


ROM_SHARE = 0.95
"""The share of frames a range of motion spans (the central ones): a few frames whose pose the data barely fix (a
thigh showing one marker) can turn a fitted joint half a turn, and would make the whole range meaningless."""


def motion_ranges(fit, joint: str) -> list:
    """[(angle name, degrees)]: the range of each of the joint's angles over the central :data:`ROM_SHARE` of the
    frames: a hinge's flexion–extension; a ball joint's flexion–extension, ab-/adduction and axial rotation
    (:func:`anatomical_angles`), not rotation-vector components, which are no angles anyone reads and jump by
    2π where the rotation nears a half-turn. Each angle is measured about its circular mean, wrapped to a turn
    (unwrapping frame to frame would carry every flipped frame's jump into all frames after it)."""
    fit = getattr(fit, "fit", fit)
    if fit.chain.types[joint] == "revolute":
        names, angles = ANGLE_NAMES[:1], fit.state.theta[joint][:, None]
    else:
        names, angles = ANGLE_NAMES, anatomical_angles(fit, joint)[0]
    centre = np.angle(np.nanmean(np.exp(1j * angles), axis=0))              # each angle's circular mean
    about = np.angle(np.exp(1j * (angles - centre)))                           # wrapped to (-π, π] about it
    tail = 50.0 * (1.0 - ROM_SHARE)
    lo, hi = np.nanpercentile(about, [tail, 100.0 - tail], axis=0)
    return [(n, float(np.rad2deg(h - lw))) for n, lw, h in zip(names, lo, hi)]
