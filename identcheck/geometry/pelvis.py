"""The ISB pelvis frame (Wu et al. 2002) from the usual pelvis markers: which labels are the ASIS and the
posterior markers (Plug-in Gait, ISB/biobuddy, OpenSim's examples, case ignored), and the frame they span.
Origin midway between the ASIS, z towards the right ASIS, y perpendicular to the plane of the ASIS and the
midpoint of the posterior markers (superior), x = y × z (anterior); millimetres.

Used by ``fit``'s comparison with Harrington's regression (:mod:`identcheck.fit.anatomy`) and by the joint
angles of the figures (:mod:`identcheck.bundle.anatomical_angles`).
"""
from __future__ import annotations

import numpy as np

RIGHT_ASIS = ("RASI", "RASIS", "R.ASIS", "R_ASIS", "RIAS", "R.ASI")
LEFT_ASIS = ("LASI", "LASIS", "L.ASIS", "L_ASIS", "LIAS", "L.ASI")
POSTERIOR = (("RPSI", "LPSI"), ("RPSIS", "LPSIS"), ("R.PSIS", "L.PSIS"), ("R_PSIS", "L_PSIS"), ("SACR",),
             ("V.SACRAL",), ("SACRUM",), ("S1",))
FRAME = ("ISB pelvis frame: origin midway between the ASIS, z towards the right ASIS, y superior (normal to the "
         "plane of the ASIS and the posterior markers' midpoint), x anterior; mm")


def _find(labels, names) -> str | None:
    upper = {label.upper(): label for label in labels}
    return next((upper[n] for n in names if n in upper), None)


def pelvis_markers(labels) -> dict | None:
    """``{"right_asis", "left_asis", "posterior": [...]}``: the trial's labels for the ISB frame, or None."""
    r, l = _find(labels, RIGHT_ASIS), _find(labels, LEFT_ASIS)
    for names in POSTERIOR:
        post = [_find(labels, (n,)) for n in names]
        if r and l and all(post):
            return {"right_asis": r, "left_asis": l, "posterior": post}
    return None


def pelvis_frame(right: np.ndarray, left: np.ndarray, posterior: np.ndarray):
    """Per frame: the ISB pelvis frame's rotation (F, 3, 3; columns x, y, z in the world) and origin (F, 3), and
    the pelvis width and depth (medians over frames, mm), from the markers' trajectories (F, 3)."""
    o = (right + left) / 2
    z = right - left
    z = z / np.linalg.norm(z, axis=1, keepdims=True)
    y = np.cross(z, o - posterior)
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, z)
    width = float(np.nanmedian(np.linalg.norm(right - left, axis=1)))
    depth = float(np.nanmedian(np.linalg.norm(o - posterior, axis=1)))
    return np.stack([x, y, z], axis=2), o, width, depth
