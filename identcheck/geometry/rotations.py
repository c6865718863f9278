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


def left_jacobian_times(v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``J_l(v) u`` (F, 3) for rotation vectors v (F, 3) and vectors u (3,) or (F, 3): how ``Exp(v)`` turns as v moves
    along u, as a left perturbation (``Exp(v + εu) ≈ Exp(ε J_l(v) u) Exp(v)``: a rotation vector in the frame Exp(v)
    maps into), with ``J_l(v) = I + (1 − cos φ)/φ² [v]× + (φ − sin φ)/φ³ [v]×²``, φ = |v|. It is u itself only when v
    is along u. Below φ = 1e-2 the two coefficients are their Taylor series to φ⁴ (φ − sin φ loses digits there)."""
    v = np.asarray(v, dtype=float)
    u = np.broadcast_to(np.asarray(u, dtype=float), v.shape)
    phi2 = np.einsum("fi,fi->f", v, v)
    phi = np.sqrt(phi2)
    small = phi < 1e-2
    safe = np.where(small, 1.0, phi)
    a = np.where(small, 0.5 - phi2 / 24 + phi2 ** 2 / 720, (1 - np.cos(safe)) / safe ** 2)
    b = np.where(small, 1 / 6 - phi2 / 120 + phi2 ** 2 / 5040, (safe - np.sin(safe)) / safe ** 3)
    vxu = np.cross(v, u)
    return u + a[:, None] * vxu + b[:, None] * np.cross(v, vxu)


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]× (..., 3, 3) of vectors (..., 3): ``skew(v) @ x == v × x``; float64."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


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


# ---------------------------------------------------------------------- the least-squares rotation (Kabsch)
DEGENERATE_GAP = 1e-6
"""Relative size of the eigenvector's adjugate below which the largest eigenvalue of Horn's matrix counts as
(nearly) repeated: the rotation is then taken from the SVD instead (collinear points, a zero matrix)."""


def best_rotations(H: np.ndarray, bound: np.ndarray | None = None) -> np.ndarray:
    """The rotations R (F, 3, 3) maximising tr(Rᵀ H_f), H (F, 3, 3) = Σ p lᵀ of centred points: the Kabsch
    rotation with the reflection guard, the same as ``U diag(1, 1, det(U Vᵀ)) Vᵀ`` from the SVD of H.

    Why not the SVD: numpy's batched 3×3 SVD is a LAPACK call per frame, and poses of every segment in every
    frame are most of a joint fit's start. This is Horn's quaternion method (J. Opt. Soc. Am. A 4, 1987)
    solved as Theobald's QCP (Acta Cryst. A 61, 2005), with array operations only: the largest eigenvalue of
    Horn's symmetric 4×4 matrix by Newton's method on its characteristic polynomial
    ``λ⁴ − 2‖H‖²λ² − 8 det(H) λ + det(N)`` from an upper bound (``bound``, e.g. (Σ|p|² + Σ|l|²)/2 per frame,
    close to the root for a good fit; by default √3‖H‖), then the eigenvector from the adjugate of
    ``N − λI``. Where that eigenvalue is (nearly) repeated the eigenvector is ill-defined and the SVD is used.
    """
    H = np.asarray(H, dtype=float)
    xx, yx, zx = H[:, 0, 0], H[:, 0, 1], H[:, 0, 2]
    xy, yy, zy = H[:, 1, 0], H[:, 1, 1], H[:, 1, 2]
    xz, yz, zz = H[:, 2, 0], H[:, 2, 1], H[:, 2, 2]
    N = [[xx + yy + zz, yz - zy, zx - xz, xy - yx],
         [yz - zy, xx - yy - zz, xy + yx, zx + xz],
         [zx - xz, xy + yx, -xx + yy - zz, yz + zy],
         [xy - yx, zx + xz, yz + zy, -xx - yy + zz]]
    _, det_n = _adjugate4(N)
    f2 = np.einsum("fij,fij->f", H, H)
    det_h = (xx * (yy * zz - zy * yz) - yx * (xy * zz - zy * xz) + zx * (xy * yz - yy * xz))
    lam = np.sqrt(3.0 * f2) if bound is None else np.minimum(np.asarray(bound, dtype=float), np.sqrt(3.0 * f2))
    scale = np.maximum(np.sqrt(3.0 * f2), 1e-300)
    for _ in range(100):                     # from above the largest root, Newton's steps fall monotonically
        l2 = lam * lam
        p = (l2 - 2.0 * f2) * l2 - 8.0 * det_h * lam + det_n
        dp = 4.0 * lam * (l2 - f2) - 8.0 * det_h
        step = np.where(dp > 0, p / np.where(dp > 0, dp, 1.0), 0.0)
        lam = lam - step
        if not np.any(np.abs(step) > 1e-15 * scale):
            break
    b, _ = _adjugate4([[N[i][j] - lam if i == j else N[i][j] for j in range(4)] for i in range(4)])
    cols = np.array([[b[i][j] for i in range(4)] for j in range(4)])          # (column, entry, F)
    norms = np.sqrt(np.einsum("jif,jif->jf", cols, cols))
    k = np.argmax(norms, axis=0)
    frames = np.arange(len(H))
    q = cols[k, :, frames]                                                      # (F, 4)
    size = norms[k, frames]
    ok = size > 0
    R = quaternion_matrix(np.where(ok[:, None], q / np.where(ok, size, 1.0)[:, None], np.array([1.0, 0.0, 0.0, 0.0])))
    bad = ~(size > DEGENERATE_GAP * scale ** 3) | ~np.isfinite(R).all(axis=(1, 2))
    if bad.any():
        U, _, Vt = np.linalg.svd(H[bad])
        D = np.ones((int(bad.sum()), 3))
        D[:, 2] = np.sign(np.linalg.det(U @ Vt))
        R[bad] = np.einsum("fij,fj,fjk->fik", U, D, Vt)
    return R


def _adjugate4(a):
    """Adjugate (as nested lists of arrays) and determinant of 4×4 matrices given entry by entry (arrays)."""
    (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = a
    s0, s1, s2 = a00 * a11 - a10 * a01, a00 * a12 - a10 * a02, a00 * a13 - a10 * a03
    s3, s4, s5 = a01 * a12 - a11 * a02, a01 * a13 - a11 * a03, a02 * a13 - a12 * a03
    c5, c4, c3 = a22 * a33 - a32 * a23, a21 * a33 - a31 * a23, a21 * a32 - a31 * a22
    c2, c1, c0 = a20 * a33 - a30 * a23, a20 * a32 - a30 * a22, a20 * a31 - a30 * a21
    det = s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0
    adj = [[a11 * c5 - a12 * c4 + a13 * c3, -a01 * c5 + a02 * c4 - a03 * c3,
            a31 * s5 - a32 * s4 + a33 * s3, -a21 * s5 + a22 * s4 - a23 * s3],
           [-a10 * c5 + a12 * c2 - a13 * c1, a00 * c5 - a02 * c2 + a03 * c1,
            -a30 * s5 + a32 * s2 - a33 * s1, a20 * s5 - a22 * s2 + a23 * s1],
           [a10 * c4 - a11 * c2 + a13 * c0, -a00 * c4 + a01 * c2 - a03 * c0,
            a30 * s4 - a31 * s2 + a33 * s0, -a20 * s4 + a21 * s2 - a23 * s0],
           [-a10 * c3 + a11 * c1 - a12 * c0, a00 * c3 - a01 * c1 + a02 * c0,
            -a30 * s3 + a31 * s1 - a32 * s0, a20 * s3 - a21 * s1 + a22 * s0]]
    return adj, det
