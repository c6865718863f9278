"""Practical identifiability: what this motion and this noise determine of each joint.

The structural verdict (``identcheck table`` / ``plan``) says whether noise-free generic data determine a
joint. A trial is neither noise-free nor generic: a hip that only flexes leaves its centre free along the
flexion axis, a knee fitted through one marker leaves a 100 mm family of hinges nearly as good. So each
joint gets a verdict from the covariance of the whole-tree fit:

- ``undetermined``: the information leaves a direction of the joint free, a ball joint turned about one
  axis only (:func:`single_axis`: its spread about a second axis is no more than the noise of the fitted
  rotations, so whatever curvature the likelihood has along that axis is the noise's, not the motion's), or
  some marker distance's 95 % interval is wider than ±:data:`TOLERANCE_MM`;
- ``ambiguous``: another candidate joint explains the trial as well (not rejected by the likelihood ratio);
- ``determined``: neither.

With it: the weakest direction of the joint centre (or of the hinge's position across its axis) in the
parent's frame and its standard error, and the motion that would help.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.bundle.uncertainty import joint_offsets

TOLERANCE_MM = 10.0
"""A joint is determined when every marker distance's 95 % interval is within ± this many mm."""
Z95 = 1.959964
MIN_SECOND_AXIS_DEG = 15.0   # a ball joint's rotation needs this RMS spread about a second axis
MIN_HINGE_ROM_DEG = 30.0     # a hinge's range of motion below which more range is the first advice
SECOND_AXIS_NOISE_RATIO = 3.0
"""A ball joint's RMS turn about its second axis must exceed this many times the RMS noise of its fitted
relative rotation for the second axis to count as motion (:func:`single_axis`)."""


def judge(chain, fit, cov, joint: str, distances: dict, n_alternatives: int = 0) -> dict:
    """The ``practical`` JSON object of one joint (see the module docstring).

    Parameters
    ----------
    chain : Skeleton
    fit : bundle.chain.Fit
    cov : bundle.uncertainty.Covariance
    joint : str
    distances : dict
        marker -> (distance mm, standard error mm) of the joint's adjacent markers.
    n_alternatives : int
        Other candidates the likelihood ratio could not reject.
    """
    from identcheck.bundle.uncertainty import distance_gradients

    grads = distance_gradients(chain, fit.state, len(cov.information))[joint]
    free = [m for m, (_, g) in grads.items() if cov.free(g)]
    worst_marker, (worst_d, worst_se) = max(distances.items(), key=lambda kv: kv[1][1]) if distances else (None, (0, 0))
    weak = _weakest(chain, fit, cov, joint)
    motion = _motion(chain, fit, joint, weak)
    one_axis, second_deg, noise_deg = single_axis(chain, fit, cov.sigma_mm, joint)
    if free:
        verdict = "undetermined"
        why = (f"the data leave {joint} free: the distances of {', '.join(free)} can change without changing "
               "any fitted marker")
    elif one_axis:
        verdict = "undetermined"
        why = (f"{joint} turned about one axis only: {second_deg:.2f} deg RMS about a second axis, within "
               f"{SECOND_AXIS_NOISE_RATIO:g}x the {noise_deg:.2f} deg noise of its fitted rotation, so its centre is "
               "free along that axis")
    elif Z95 * worst_se > TOLERANCE_MM:
        verdict = "undetermined"
        why = (f"{worst_marker}'s distance is {worst_d:.1f} ± {Z95 * worst_se:.1f} mm (95 %), wider than "
               f"±{TOLERANCE_MM:g} mm")
    elif n_alternatives:
        verdict = "ambiguous"
        why = f"{n_alternatives} other joint(s) explain the trial as well (likelihood ratio, 95 % level)"
    else:
        verdict = "determined"
        why = f"every marker distance within ±{Z95 * worst_se:.2g} mm (95 %)"
    return {"verdict": verdict, "reason": why, "tolerance_mm": TOLERANCE_MM,
            "weakest_direction_parent": [round(float(x), 4) for x in weak[0]], "weakest_se_mm": round(weak[1], 3),
            "motion_advice": motion if verdict != "determined" else ""}


def rotation_noise_rad(chain, fit, sigma_mm: float, joint: str) -> float:
    """RMS noise (rad, per axis) of a joint's fitted relative rotation from marker noise σ: each segment's
    rotation is known to about σ / (√n · r), n its markers and r their RMS distance from their centroid across
    an axis (√(2/3) of the 3-D RMS distance); the relative rotation carries both segments'."""
    var = 0.0
    for seg in (chain.parent[joint], chain.child[joint]):
        local = fit.state.local[chain.seg_markers[seg]]
        if len(local) < 2:
            return float("inf")
        r2 = (2.0 / 3.0) * float(np.mean(np.sum((local - local.mean(axis=0)) ** 2, axis=1)))
        var += sigma_mm ** 2 / (len(local) * max(r2, 1e-12))
    return float(np.sqrt(var))


def single_axis(chain, fit, sigma_mm: float, joint: str) -> tuple[bool, float, float]:
    """Whether a ball joint turned about one axis only in this trial: (verdict, RMS turn about its second axis
    in deg, RMS noise of its fitted rotation in deg). Its centre is then not determined along that axis, however
    small the quadratic standard error: the fitted rotations' wobble about the other axes is noise, and a fit
    that moves the centre to follow it is fitting the noise (a floating-point guide on measured data, with the
    threshold :data:`SECOND_AXIS_NOISE_RATIO`). False for a hinge, and beside a segment with fewer than three
    markers (its rotation is not measured by its own markers: the test cannot tell)."""
    if chain.types[joint] != "spherical":
        return False, float("nan"), float("nan")
    if any(len(chain.seg_markers[s]) < 3 for s in (chain.parent[joint], chain.child[joint])):
        # a segment posed through its joints, not by its own markers: its fitted rotation's wobble is not a
        # measurement of the motion, so this test cannot tell (the rules for such segments decide instead)
        return False, float("nan"), float("nan")
    rel = fit.state.rel_R[joint]
    rv = Rotation.from_matrix(rel @ Rotation.from_matrix(rel).mean().as_matrix().T).as_rotvec()
    spread = np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(rv.T)), 0.0)) if len(rv) > 2 else np.zeros(3)
    noise = rotation_noise_rad(chain, fit, sigma_mm, joint)
    second = float(spread[-2])
    return bool(second <= SECOND_AXIS_NOISE_RATIO * noise), float(np.rad2deg(second)), float(np.rad2deg(noise))


def _weakest(chain, fit, cov, joint: str) -> tuple[np.ndarray, float]:
    """Unit direction (parent frame) in which the joint's centre (a hinge: its position across the axis)
    is least determined, and its standard error in mm."""
    o = joint_offsets(chain)[joint]
    block = cov.sandwich[o:o + 3, o:o + 3]
    naive = cov.naive[o:o + 3, o:o + 3]
    block = naive if np.trace(naive) > np.trace(block) else 0.5 * (block + block.T)   # never below white noise
    if chain.types[joint] == "revolute":
        a = fit.state.axis[joint]
        P = np.eye(3) - np.outer(a, a)
        block = P @ block @ P
    w, V = np.linalg.eigh(block)
    return V[:, -1], float(np.sqrt(max(w[-1], 0.0)))


def _motion(chain, fit, joint: str, weak) -> str:
    """What to record to determine the joint better, from the motion the trial shows."""
    s = fit.state
    if chain.types[joint] == "revolute":
        rom = float(np.rad2deg(np.ptp(np.unwrap(s.theta[joint]))))
        if rom < MIN_HINGE_ROM_DEG:
            return f"flex {joint} through a larger range (this trial: {rom:.0f} deg about the hinge)"
        return (f"{joint} moved {rom:.0f} deg about its hinge: add frames, or markers farther from the hinge axis, "
                "on the segments that carry few")
    rel = s.rel_R[joint]
    rv = Rotation.from_matrix(rel @ Rotation.from_matrix(rel).mean().as_matrix().T).as_rotvec()
    spread = np.sqrt(np.linalg.eigvalsh(np.cov(rv.T))) if len(rv) > 2 else np.zeros(3)
    second = float(np.rad2deg(spread[-2]))
    d = ", ".join(f"{x:+.2f}" for x in weak[0])
    if second < MIN_SECOND_AXIS_DEG:
        return (f"{joint} turned mostly about one axis (second axis {second:.0f} deg RMS): its centre is least "
                f"determined along ({d}) in {chain.parent[joint]}'s frame; add rotation about the other axes "
                "(e.g. abduction and circumduction of a hip that only flexed)")
    return (f"{joint}'s centre is least determined along ({d}) in {chain.parent[joint]}'s frame: a larger range of "
            "motion, more frames or more markers on the segments that carry few")
