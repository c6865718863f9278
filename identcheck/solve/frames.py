"""The frame F of two parent markers: A1 at the origin, A2 on +z (Pham et al., section II-A)."""
from __future__ import annotations

import numpy as np

from ..errors import DegenerateError


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


def triad_frame(a1, a2, a3, points):
    """Coordinates of ``points`` in the frame of three parent markers, frame by frame.

    The frame of Pham et al. V-A: origin A1, u1 along A1A2, u2 from orthonormalising A1A3
    against u1, u3 = u1 × u2. With three markers the parent is fully posed, so a point fixed
    on the parent has constant coordinates here.

    Returns
    -------
    local : array, shape (..., 3)
    basis : array, shape (..., 3, 3)
        Rows u1, u2, u3 per frame (world = a1 + local @ basis).
    """
    a1, a2, a3, points = (np.asarray(v, dtype=float) for v in (a1, a2, a3, points))
    e1, e2 = a2 - a1, a3 - a1
    n1 = np.linalg.norm(e1, axis=-1)
    cross = np.cross(e1, e2)
    area = np.linalg.norm(cross, axis=-1)
    scale = np.maximum(n1 * np.linalg.norm(e2, axis=-1), 1e-300)
    bad = np.flatnonzero(np.ravel(area <= 1e-9 * scale))
    if bad.size:
        raise DegenerateError(f"the three parent markers are collinear (frames {bad.tolist()[:10]}): they do not "
                              "pose the parent segment")
    u1 = e1 / n1[..., None]
    u3 = cross / area[..., None]
    u2 = np.cross(u3, u1)
    basis = np.stack([u1, u2, u3], axis=-2)
    local = np.einsum("...ij,...j->...i", basis, points - a1)
    return local, basis
