"""Checks and linear solves shared by the exact-case solvers (one implementation each)."""
from __future__ import annotations

import mpmath
import numpy as np

from identcheck.errors import DegenerateError, InputError


def check_samples(xyz, n_min: int, name: str, case_label: str) -> np.ndarray:
    """``xyz`` as a float array of shape (N, 3) with N ≥ ``n_min`` finite samples, or a clear error."""
    xyz = np.asarray(xyz, dtype=float)
    if xyz.ndim != 2 or xyz.shape[-1] != 3:
        raise InputError(f"{name}: samples must have shape (n_samples, 3), got {xyz.shape}")
    if len(xyz) < n_min:
        raise InputError(f"{case_label} needs at least {n_min} samples, got {len(xyz)} for {name}")
    bad = np.flatnonzero(~np.all(np.isfinite(xyz), axis=1))
    if bad.size:
        raise DegenerateError(f"{name}: samples {bad.tolist()[:10]} are not finite (NaN or inf): drop occluded "
                              "frames first")
    return xyz


def column_scaled_lstsq(M: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Least-squares (or exact, when square) solution of M·Z = K with columns scaled to unit norm."""
    norm = np.linalg.norm(M, axis=0)
    norm = np.where(norm == 0, 1.0, norm)
    Z = np.linalg.lstsq(M / norm, K, rcond=None)[0]
    return Z / norm


def mp_solve(rows, rhs):
    """Solve a square (LU) or tall (QR least squares) mpmath system at the working precision."""
    A, b = mpmath.matrix(rows), mpmath.matrix(rhs)
    x = mpmath.lu_solve(A, b) if A.rows == A.cols else mpmath.qr_solve(A, b)[0]
    return [x[i] for i in range(A.cols)]
