"""The one set of rotation helpers for arrays: quaternions, axis-angle (Rodrigues) and rotation vectors.

``quaternion_matrix`` and ``axis_rotation`` are written with array operations only, so they run on float64
arrays and on object arrays of ``mpmath.mpf`` (the plan's witnesses are verified at 50 digits with them);
``rotvec_matrix`` is scipy's ``Rotation`` for float64 batches (the fits). Exact rational rotations
(half-angle tangents, rational quaternions) over any field are in :mod:`identcheck.exact.algebra`.
"""
from __future__ import annotations

import mpmath
import numpy as np
from scipy.spatial.transform import Rotation


def rotvec_matrix(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (F, 3, 3) of rotation vectors (F, 3) or (3,) (radians), float64."""
    return Rotation.from_rotvec(np.atleast_2d(w)).as_matrix()


def hinge_matrix(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rotations (F, 3, 3) about one unit axis (3,) by angles θ (F,), float64."""
    return rotvec_matrix(np.outer(theta, axis))


def elementwise(arr, name):
    """numpy's function `name` for float arrays, mpmath's (elementwise) for object arrays of mpf."""
    if arr.dtype == object:
        return np.vectorize(getattr(mpmath, name), otypes=[object])
    return getattr(np, name)


def quaternion_matrix(q):
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) = (w, x, y, z), normalised first."""
    n = elementwise(q, "sqrt")((q * q).sum(axis=-1))
    w, x, y, z = (q[..., i] / n for i in range(4))
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def axis_rotation(a, theta):
    """Rot(â, θ) for one direction a (3,) and angles θ (F,): (F, 3, 3), by Rodrigues."""
    a = a / elementwise(a, "sqrt")((a * a).sum())
    c, s = elementwise(theta, "cos")(theta), elementwise(theta, "sin")(theta)
    K = np.array([[0 * a[0], -a[2], a[1]], [a[2], 0 * a[0], -a[0]], [-a[1], a[0], 0 * a[0]]], dtype=a.dtype)
    K2 = K @ K
    eye = np.eye(3).astype(a.dtype)
    return eye[None] + s[:, None, None] * K[None] + (1 - c)[:, None, None] * K2[None]


def matrix_quaternion(R: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) = (w, x, y, z), w ≥ 0, of rotation matrices (..., 3, 3) (float64)."""
    xyzw = Rotation.from_matrix(R).as_quat()
    xyzw = np.where(xyzw[..., 3:] < 0, -xyzw, xyzw)          # w >= 0: nearby rotations, nearby quaternions
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)
