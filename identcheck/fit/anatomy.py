"""The fitted hip centres beside the ones a lab would otherwise use: the ISB pelvis frame from the ASIS and PSIS
(or sacrum) markers, and Harrington et al.'s (2007) regression of the hip centre on the pelvis's width and
depth, with the distance between the functional centre and the regression's.

Why: a functional centre that lands 40 mm from the regression is either a finding about this subject or a sign
that the trial did not determine it; labs judge that with this very comparison. The ISB frame (Wu et al. 2002):
origin midway between the ASIS, z towards the right ASIS, y perpendicular to the plane of the ASIS and the
midpoint of the posterior markers (superior), x = y × z (anterior); millimetres. Harrington's regression:
x = −0.24 PD − 9.9, y = −0.30 PW − 10.9, z = ±(0.33 PW + 7.3), PW the inter-ASIS distance, PD the depth from
mid-ASIS to mid-PSIS. Davis et al.'s (1991) regression (as Plug-in Gait uses it) needs the subject's leg
length, which markers do not measure: it is computed when the model's ``[subject]`` table gives it
(``leg_length_mm`` or ``right_``/``left_leg_length_mm``, and ``marker_diameter_mm``, default 14).
With L the leg length, r the marker radius and W the inter-ASIS distance: C = 0.115 L − 15.3,
X_dis = 0.1288 L − 48.56, θ = 28.4°, β = 18°; in the ISB frame x = C cos θ sin β − (X_dis + r) cos β,
y = −C cos θ cos β − (X_dis + r) sin β, z = ±(W/2 − C sin θ).

Markers are recognised by their usual names (Plug-in Gait, ISB/biobuddy, OpenSim's examples, case ignored).
"""
from __future__ import annotations

import numpy as np

from identcheck.fit.export import joint_trajectories
from identcheck.geometry.pelvis import FRAME, pelvis_frame, pelvis_markers  # noqa: F401 (part of this module's API)


def harrington(width: float, depth: float, right: bool) -> np.ndarray:
    """Harrington et al. (2007): the hip centre in the ISB pelvis frame (mm)."""
    return np.array([-0.24 * depth - 9.9, -0.30 * width - 10.9, (1.0 if right else -1.0) * (0.33 * width + 7.3)])


DAVIS_THETA, DAVIS_BETA = np.deg2rad(28.4), np.deg2rad(18.0)
DEFAULT_MARKER_DIAMETER_MM = 14.0


def davis(leg_length: float, width: float, marker_radius: float, right: bool) -> np.ndarray:
    """Davis et al. (1991): the hip centre in the ISB pelvis frame (mm), from the leg length, the inter-ASIS
    distance and the radius of the ASIS markers (their centres sit that far off the skin)."""
    c = 0.115 * leg_length - 15.3
    reach = 0.1288 * leg_length - 48.56 + marker_radius
    x = c * np.cos(DAVIS_THETA) * np.sin(DAVIS_BETA) - reach * np.cos(DAVIS_BETA)
    y = -c * np.cos(DAVIS_THETA) * np.cos(DAVIS_BETA) - reach * np.sin(DAVIS_BETA)
    z = (1.0 if right else -1.0) * (width / 2 - c * np.sin(DAVIS_THETA))
    return np.array([x, y, z])


def leg_length(subject: dict, right: bool) -> float | None:
    """The leg length (mm) the model's ``[subject]`` gives for that side, or None."""
    return subject.get("right_leg_length_mm" if right else "left_leg_length_mm", subject.get("leg_length_mm"))


def anatomical_report(data: np.ndarray, labels, fit, subject: dict | None = None) -> dict | None:
    """The ``anatomical`` key of ``fit``: the pelvis frame and, for each ball joint of the segment carrying the
    pelvis markers, its fitted centre in that frame (median over frames), Harrington's centre for its side and
    the distance between them, and Davis's when `subject` (the model's ``[subject]``) gives that side's leg
    length. `data` (F, M, 3): the fitted trial's markers in `labels` order, in the fit's coordinates. None when
    the trial has no ASIS and posterior pelvis markers on one segment."""
    subject = subject or {}
    radius = subject.get("marker_diameter_mm", DEFAULT_MARKER_DIAMETER_MM) / 2
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
        right = bool(centre[2] > 0)
        reg = harrington(width, depth, right=right)
        joints[j] = {"functional_centre": [round(float(v), 2) for v in centre],
                     "harrington_2007": [round(float(v), 2) for v in reg],
                     "distance_mm": round(float(np.linalg.norm(centre - reg)), 2),
                     "side": "right" if right else "left"}
        leg = leg_length(subject, right)
        if leg is None:
            joints[j]["davis_1991"] = None
        else:
            dav = davis(leg, width, radius, right)
            joints[j]["davis_1991"] = [round(float(v), 2) for v in dav]
            joints[j]["davis_distance_mm"] = round(float(np.linalg.norm(centre - dav)), 2)
    return {"pelvis": {"segment": pelvis, "markers": names, "width_mm": round(width, 2), "depth_mm": round(depth, 2),
                       "frame": FRAME}, "hips": joints}
