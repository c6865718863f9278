"""The fitted hip centres beside the ones a lab would otherwise use: the ISB pelvis frame from the ASIS and PSIS
(or sacrum) markers, and Harrington et al.'s (2007) regression of the hip centre on the pelvis's width and
depth, with the distance between the functional centre and the regression's.

Why: a functional centre that lands 40 mm from the regression is either a finding about this subject or a sign
that the trial did not determine it; labs judge that with this very comparison. The ISB frame (Wu et al. 2002):
origin midway between the ASIS, z towards the right ASIS, y perpendicular to the plane of the ASIS and the
midpoint of the posterior markers (superior), x = y × z (anterior); millimetres. Harrington's regression:
x = −0.24 PD − 9.9, y = −0.30 PW − 10.9, z = ±(0.33 PW + 7.3), PW the inter-ASIS distance, PD the depth from
mid-ASIS to mid-PSIS. Davis et al.'s (1991) regression needs the subject's leg length, which markers do not
measure, so it is not computed.

Markers are recognised by their usual names (Plug-in Gait, ISB/biobuddy, OpenSim's examples, case ignored).
"""
from __future__ import annotations

import numpy as np

from identcheck.fit.export import joint_trajectories

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


def harrington(width: float, depth: float, right: bool) -> np.ndarray:
    """Harrington et al. (2007): the hip centre in the ISB pelvis frame (mm)."""
    return np.array([-0.24 * depth - 9.9, -0.30 * width - 10.9, (1.0 if right else -1.0) * (0.33 * width + 7.3)])


def anatomical_report(data: np.ndarray, labels, fit) -> dict | None:
    """The ``anatomical`` key of ``fit``: the pelvis frame and, for each ball joint of the segment carrying the
    pelvis markers, its fitted centre in that frame (median over frames), Harrington's centre for its side and
    the distance between them. `data` (F, M, 3): the fitted trial's markers in `labels` order, in the fit's
    coordinates. None when the trial has no ASIS and posterior pelvis markers on one segment."""
    names = pelvis_markers(labels)
    chain = fit.chain
    if names is None:
        return None
    col = {m: i for i, m in enumerate(labels)}
    used = [names["right_asis"], names["left_asis"], *names["posterior"]]
    segs = {chain.marker_seg[chain.labels.index(m)] for m in used if m in chain.labels}
    if len(segs) != 1:
        return None
    pelvis = segs.pop()
    R, o, width, depth = pelvis_frame(data[:, col[names["right_asis"]]], data[:, col[names["left_asis"]]],
                                      np.mean([data[:, col[p]] for p in names["posterior"]], axis=0))
    points = joint_trajectories(fit)
    joints = {}
    for j in chain.joints:
        if chain.parent[j] != pelvis or chain.types[j] != "spherical":
            continue
        local = np.einsum("fji,fj->fi", R, points[f"{j}.centre"] - o)
        centre = np.nanmedian(local, axis=0)
        reg = harrington(width, depth, right=bool(centre[2] > 0))
        joints[j] = {"functional_centre": [round(float(v), 2) for v in centre],
                     "harrington_2007": [round(float(v), 2) for v in reg],
                     "distance_mm": round(float(np.linalg.norm(centre - reg)), 2),
                     "side": "right" if centre[2] > 0 else "left"}
    return {"pelvis": {"segment": pelvis, "markers": names, "width_mm": round(width, 2), "depth_mm": round(depth, 2),
                       "frame": FRAME}, "hips": joints}
