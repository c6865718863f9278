"""The frame F of two parent markers: A1 at the origin, A2 on +z (Pham et al., section II-A)."""
from __future__ import annotations

import numpy as np

from identcheck.errors import DegenerateError


def pair_frame(a1, a2, points):
    """Coordinates of ``points`` in the frame of the parent markers A1, A2, frame by frame.

    The roll about A1A2 is arbitrary (it is the per-sample θ of the derivation); x is taken
    from the world axis least aligned with A1A2 so the frame is well defined.

    Parameters
    ----------
    a1, a2 : array, shape (..., 3)
    points : array, shape (..., 3)

    Returns
    -------
    local : array, shape (..., 3)
    h : array, shape (...)
        |A1A2| per frame (A2 sits at (0, 0, h)).
    """
    a1, a2, points = (np.asarray(v, dtype=float) for v in (a1, a2, points))
    e = a2 - a1
    h = np.linalg.norm(e, axis=-1)
    tiny = h <= 1e-12 * max(1.0, float(np.nanmax(np.abs(a1))))
    if np.any(tiny):
        frames = np.flatnonzero(np.ravel(tiny)).tolist()[:10]
        raise DegenerateError(f"A1 and A2 coincide (frames {frames}): their axis is undefined")
    ez = e / h[..., None]
    ref = np.eye(3)[np.argmin(np.abs(ez), axis=-1)]
    ex = ref - np.sum(ref * ez, axis=-1, keepdims=True) * ez
    ex /= np.linalg.norm(ex, axis=-1, keepdims=True)
    ey = np.cross(ez, ex)
    rel = points - a1
    local = np.stack([np.sum(rel * ex, -1), np.sum(rel * ey, -1), np.sum(rel * ez, -1)], axis=-1)
    return local, h


MIN_SINE = 1e-6
"""Smallest sine of the angle between A1A2 and the in-plane direction of a frame."""


def parent_frame(a1, a2, toward, names=("A1", "A2", "toward")) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame rotation into the frame with origin A1, z = u1 along A1A2, x = u2 toward `toward`.

    u2 is `toward` made orthogonal to u1 (Gram-Schmidt) and y = u3 = u1 × u2: the frames F_GL
    (``toward = A3 - A1``) and F_S22 (``toward`` = a fixed vector v) of Pham et al., section
    V-A. Built on :func:`~identcheck.geometry.frames.pair_frame` (A2 on +z), rolled about z so
    that `toward` lies in the half-plane x > 0, y = 0.

    Parameters
    ----------
    a1, a2 : array, shape (n_frames, 3)
    toward : array, shape (n_frames, 3) or (3,)
        A direction (not a point) per frame, or one for all frames.
    names : tuple of 3 str
        Names of a1, a2 and toward for messages.

    Returns
    -------
    rot : numpy.ndarray, shape (n_frames, 3, 3)
        ``local = rot @ (p - a1)``; ``p = a1 + rot.T @ local``. Rows are u2, u3, u1.
    h : numpy.ndarray, shape (n_frames,)
        |A1A2| per frame.

    Raises
    ------
    DegenerateError
        A1 and A2 coincide, or `toward` is parallel to A1A2, in some frame (frames listed).
    """
    a1, a2 = np.asarray(a1, dtype=float), np.asarray(a2, dtype=float)
    toward = np.broadcast_to(np.asarray(toward, dtype=float), a1.shape)
    h = np.linalg.norm(a2 - a1, axis=-1)
    scale = max(1.0, float(np.max(np.abs(a1))))
    if np.any(h <= 1e-9 * scale):
        bad = np.flatnonzero(h <= 1e-9 * scale).tolist()
        raise DegenerateError(f"{names[0]} and {names[1]} coincide in frames {bad[:10]}"
                              f"{' ...' if len(bad) > 10 else ''}: their axis is undefined")
    probe = a1[:, None, :] + np.eye(3)[None]
    cols, _ = pair_frame(a1[:, None, :], a2[:, None, :], probe)   # cols[f, j] = R e_j
    rot = np.swapaxes(cols, 1, 2)
    t = np.einsum("fij,fj->fi", rot, toward)
    perp = np.hypot(t[:, 0], t[:, 1])
    norm = np.linalg.norm(toward, axis=-1)
    bad = np.flatnonzero(~(perp > MIN_SINE * norm))
    if len(bad):
        raise DegenerateError(f"{names[2]} is parallel to {names[0]}{names[1]} in frames "
                              f"{bad[:10].tolist()}{' ...' if len(bad) > 10 else ''}: "
                              "the frame's second axis is undefined")
    c, s = t[:, 0] / perp, t[:, 1] / perp
    roll = np.zeros_like(rot)
    roll[:, 0, 0], roll[:, 0, 1], roll[:, 1, 0], roll[:, 1, 1] = c, s, -s, c
    roll[:, 2, 2] = 1.0
    return roll @ rot, h


def to_local(rot, a1, points) -> np.ndarray:
    """Points, shape (n_frames, 3) or (n_frames, k, 3), in the frames of :func:`parent_frame`."""
    points = np.asarray(points, dtype=float)
    if points.ndim == 2:
        return np.einsum("fij,fj->fi", rot, points - a1)
    return np.einsum("fij,fkj->fki", rot, points - a1[:, None])


def to_world(rot, a1, local) -> np.ndarray:
    """Inverse of :func:`to_local` for points, shape (n_frames, 3) or (3,) (same in every frame)."""
    local = np.broadcast_to(np.asarray(local, dtype=float), a1.shape)
    return a1 + np.einsum("fji,fj->fi", rot, local)
