"""THE forward kinematics of a skeleton: every segment's world pose from the root's pose and each joint's
relative rotation, with the joint centre the same point of both segments in every frame.

For a joint with centre ``c`` in its parent and ``e`` in its child and relative rotation ``rel`` (child to
parent frame)::

    R_child = R_parent · rel,     t_child = (R_parent c + t_parent) − R_child e

so a ball joint's centre, and a hinge's axis point, coincide exactly whatever the parameters. Written with
``@`` and broadcasting only, it runs on float64 arrays and on object arrays of ``mpmath.mpf`` alike (the
plan's witnesses are verified at 50 digits with the same function the fits use in float64).
"""
from __future__ import annotations

import numpy as np


def apply(R, v):
    """Per-frame rotation of a point: R (F, 3, 3) times v (3,) or (F, 3) -> (F, 3)."""
    v = np.asarray(v) if not isinstance(v, np.ndarray) else v
    return R @ v if v.ndim == 1 else (R @ v[..., None])[..., 0]


def chain_poses(joints, root: str, root_R, root_t, rel_R: dict, c_parent: dict, c_child: dict):
    """World-from-segment poses of every segment and each joint's centre in the world.

    Parameters
    ----------
    joints : iterable of (name, parent, child)
        Every joint, each parent's joint before its children's.
    root : str
    root_R : array, shape (n_frames, 3, 3)
    root_t : array, shape (n_frames, 3)
        The root's pose, mm.
    rel_R : dict
        joint -> relative rotation, child to parent frame, shape (n_frames, 3, 3).
    c_parent, c_child : dict
        joint -> its centre (a hinge: a point of its axis) in the parent / child frame, shape (3,) or
        (n_frames, 3) when it moves, mm.

    Returns
    -------
    R, t, centre : dict
        segment -> rotations (n_frames, 3, 3); segment -> translations (n_frames, 3); joint -> world
        centre (n_frames, 3).
    """
    R, t, centre = {root: root_R}, {root: root_t}, {}
    for name, par, chi in joints:
        cw = apply(R[par], c_parent[name]) + t[par]
        R[chi] = R[par] @ rel_R[name]
        t[chi] = cw - apply(R[chi], c_child[name])
        centre[name] = cw
    return R, t, centre


def place_markers(R, t, local):
    """Markers of one segment in the world: R (F, 3, 3), t (F, 3), local (m, 3) -> (F, m, 3)."""
    local = np.asarray(local) if not isinstance(local, np.ndarray) else local
    return local @ np.swapaxes(R, 1, 2) + t[:, None, :] if local.dtype != object else \
        np.stack([apply(R, p) + t for p in local], axis=1)
