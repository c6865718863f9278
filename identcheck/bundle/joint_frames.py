"""Joint geometry a lab can use: each joint's centre (a hinge: its axis) in the technical frames of the
parent and the child segment, with covariance.

A segment's technical frame is defined by its first three markers (model-file order): origin at the first,
x towards the second, z normal to the plane of the three (x × (third − first)), y = z × x; millimetres.
A segment with fewer than three markers has no technical frame of its own, and its side is left out.

For a ball joint the centre is reported; for a hinge, the point of the axis nearest the frame's origin and
the axis direction (a unit vector, sign as fitted). Covariances come from the whole-tree fit's constants'
covariance (the sandwich of :mod:`identcheck.bundle.uncertainty`), carried through by central differences
over the constants the quantity depends on.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import cross3, joint_offsets, tangents
from identcheck.geometry.rotations import rotvec_matrix

STEP = 1e-4     # mm (or rad) central-difference step


def _technical(local3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(origin (3,), rows = axes (3, 3)) of the frame of three points (3, 3), in the segment's fit frame."""
    o = local3[0]
    x = local3[1] - o
    x = x / np.linalg.norm(x)
    z = cross3(x, local3[2] - o)
    z = z / np.linalg.norm(z)
    return o, np.stack([x, cross3(z, x), z])


def _constants(state, chain, dc: np.ndarray, joint: str):
    """The constants the joint geometry uses, moved by a constants step dc (as the fit's own update)."""
    o = joint_offsets(chain)[joint]
    local = state.local + dc[:3 * chain.n_markers].reshape(-1, 3)
    cp = state.c_parent[joint] + dc[o:o + 3]
    cc = state.c_child[joint] + dc[o + 3:o + 6]
    axis = rest = None
    if chain.types[joint] == "revolute":
        rest = rotvec_matrix(dc[o + 6:o + 9])[0] @ state.rest[joint]
        b1, b2 = tangents(state.axis[joint])
        a = state.axis[joint] + dc[o + 9] * b1 + dc[o + 10] * b2
        axis = a / np.linalg.norm(a)
    return local, cp, cc, axis, rest


def _side_values(chain, state, dc, joint: str, side: int) -> np.ndarray | None:
    seg = chain.parent[joint] if side == 0 else chain.child[joint]
    cols = chain.seg_markers[seg]
    if len(cols) < 3:
        return None
    local, cp, cc, axis, rest = _constants(state, chain, dc, joint)
    o, T = _technical(local[cols[:3]])
    c = cp if side == 0 else cc
    if axis is None:
        return T @ (c - o)
    a = axis if side == 0 else rest.T @ axis
    a_t = T @ a
    p_t = T @ (c - o)
    p_t = p_t - (p_t @ a_t) * a_t             # the axis point nearest the technical origin
    return np.concatenate([p_t, a_t])


def joint_geometry(chain, state, cov, joint: str) -> dict:
    """``{"parent": {...}, "child": {...}, "frame": str}`` for one joint; each side holds ``centre`` (ball) or
    ``axis_point`` and ``axis_direction`` (hinge) with ``covariance`` (3×3 each), or is None when the segment
    has fewer than three markers."""
    P = len(cov.information)
    o = joint_offsets(chain)[joint]
    out = {"frame": "technical frame of the segment's first three markers: origin at the first, x towards the "
                    "second, z normal to their plane (x cross (third - first)), mm"}
    for side, name in ((0, "parent"), (1, "child")):
        seg = chain.parent[joint] if side == 0 else chain.child[joint]
        base = _side_values(chain, state, np.zeros(P), joint, side)
        if base is None:
            out[name] = None
            continue
        idx = [k for c in chain.seg_markers[seg][:3] for k in range(3 * c, 3 * c + 3)]
        idx += list(range(o, o + (11 if chain.types[joint] == "revolute" else 6)))
        G = np.zeros((len(base), P))
        for k in idx:
            dc = np.zeros(P)
            dc[k] = STEP
            G[:, k] = (_side_values(chain, state, dc, joint, side) - _side_values(chain, state, -dc, joint, side)) / (2 * STEP)
        C = G @ cov.sandwich @ G.T
        naive = G @ cov.naive @ G.T
        C = naive if np.trace(naive) > np.trace(C) else C          # never below white noise
        r = lambda v: [round(float(x), 4) for x in v]  # noqa: E731
        rc = lambda m: [[round(float(x), 6) for x in row] for row in m]  # noqa: E731
        if chain.types[joint] == "revolute":
            out[name] = {"segment": seg, "markers": [chain.labels[c] for c in chain.seg_markers[seg][:3]],
                         "axis_point": r(base[:3]), "axis_point_covariance": rc(C[:3, :3]),
                         "axis_direction": r(base[3:]), "axis_direction_covariance": rc(C[3:, 3:])}
        else:
            out[name] = {"segment": seg, "markers": [chain.labels[c] for c in chain.seg_markers[seg][:3]],
                         "centre": r(base), "centre_covariance": rc(C)}
    return out
