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

With it: the weakest direction of the joint centre (or of the hinge's position across its axis) relative to the
parent's markers (:func:`centre_in_parent`: not in the fit's own frame, which is a choice) and its standard error,
and the motion that would help (:func:`_motion`). What that advice says of the motion is only what the markers
measure: the fitted angles of a joint beside a segment with fewer than three
markers of its own follow from the joint's fitted geometry, which is what the data leave open when the advice is
given (a static knee trial with one shank marker near the fitted axis had "moved 346 deg about its hinge"). There,
the other segment's markers' movement in the frame of the one posed by its own markers is reported instead, in mm.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.bundle.model import joint_offsets
from identcheck.geometry.poses import MIN_MARKERS, pose_noise_factor, poses_segment
from identcheck.geometry.rotations import skew

TOLERANCE_MM = 10.0
"""A joint is determined when every marker distance's 95 % interval is within ± this many mm."""
Z95 = 1.959964
MIN_SECOND_AXIS_DEG = 15.0   # a ball joint's rotation needs this RMS spread about a second axis
MIN_HINGE_ROM_DEG = 30.0     # a hinge's range of motion below which more range is the first advice
SECOND_AXIS_NOISE_RATIO = 3.0
"""A ball joint's RMS turn about its second axis must exceed this many times the RMS noise of its fitted
relative rotation for the second axis to count as motion (:func:`single_axis`)."""
HARDLY_MOVED_NOISE = 4.0
"""A joint hardly moved when the markers of one segment stay within this many times their noise of one place in
the frame of the other (95th percentile of their distance from it, :func:`excursion_mm`; pure noise of σ per
coordinate reaches 2.8 σ)."""
HARDLY_MOVED_MM = 5.0
"""... or within this many mm: a marker that sweeps less than that in the other segment's frame traces too short an
arc to place a joint, whatever the noise (a knee turning 5 deg moves a marker 50 mm from its axis by 4 mm)."""


def judge(chain, fit, cov, joint: str, distances: dict, n_alternatives: int = 0, unbounded: str | None = None) -> dict:
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
    unbounded : str, optional
        Why the intervals do not bound the joint, when they do not (the profile likelihood's finding): the joint
        is then ``undetermined`` for that reason, whatever the quadratic standard errors say, unless a free
        direction, one axis of rotation or a joint that hardly moved already says why.
    """
    from identcheck.bundle.uncertainty import distance_gradients

    free = free_markers(cov, distance_gradients(chain, fit.state, len(cov.information))[joint])
    worst_marker, (worst_d, worst_se) = max(distances.items(), key=lambda kv: kv[1][1]) if distances else (None, (0, 0))
    weak = weakest(chain, fit, cov, joint)
    seen = _motion_seen(chain, fit, joint, cov.sigma_mm)
    motion = _motion(chain, fit, joint, weak, seen)
    one_axis, second_deg, noise_deg = single_axis(chain, fit, cov.sigma_mm, joint)
    still = seen[1] if seen[0] == "hardly" else None
    if free:
        verdict = "undetermined"
        why = (f"the data leave {joint} free: the distances of {', '.join(free)} can change without changing "
               "any fitted marker")
    elif one_axis:
        verdict = "undetermined"
        why = (f"{joint} turned about one axis only: {second_deg:.2f} deg RMS about a second axis, within "
               f"{SECOND_AXIS_NOISE_RATIO:g}x the {noise_deg:.2f} deg of its noise, so its centre is "
               "free along that axis")
    elif still:
        verdict = "undetermined"
        why = (f"{still}: a joint that did not move is not determined by the trial, however narrow the curvature of "
               "the likelihood (a marker that stays put is fitted best by a small sphere or circle around itself)")
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
    if unbounded and not (free or one_axis or still):    # those say why the likelihood does not bound it
        verdict, why = "undetermined", unbounded
    return {"verdict": verdict, "reason": why, "tolerance_mm": TOLERANCE_MM,
            "weakest_direction_parent": None if weak[0] is None else [round(float(x), 4) for x in weak[0]],
            "weakest_se_mm": None if weak[1] is None else round(weak[1], 3),
            "motion_advice": motion if verdict != "determined" else ""}


def free_markers(cov, grads: dict) -> list:
    """Which of a joint's adjacent markers (``grads``: marker -> (distance, gradient), one joint's entry of
    :func:`~identcheck.bundle.uncertainty.distance_gradients`) have distances that move along a direction the data
    leave free (beyond the gauge): no standard error means anything for them, and no interval bounds them."""
    return [m for m, (_, g) in grads.items() if cov.free(g)]


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


def rotation_spread_rad(fit, joint: str) -> np.ndarray:
    """A ball joint's fitted relative rotation's RMS spread about its principal axes (rad, ascending): the
    rotation vectors of each frame's rotation away from their mean, and the square roots of their covariance's
    eigenvalues."""
    rel = fit.state.rel_R[joint]
    rv = Rotation.from_matrix(rel @ Rotation.from_matrix(rel).mean().as_matrix().T).as_rotvec()
    return np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(rv.T)), 0.0)) if len(rv) > 2 else np.zeros(3)


def single_axis(chain, fit, sigma_mm: float, joint: str) -> tuple[bool, float, float]:
    """Whether a ball joint turned about one axis only in this trial: (verdict, RMS turn about its second axis
    in deg, RMS noise of its fitted rotation in deg). Its centre is then not determined along that axis, however
    small the quadratic standard error: the fitted rotations' wobble about the other axes is noise, and a fit
    that moves the centre to follow it is fitting the noise (a floating-point guide on measured data, with the
    threshold :data:`SECOND_AXIS_NOISE_RATIO`). False for a hinge. Beside a segment with fewer than three markers,
    whose fitted rotation is not measured by its own markers (two markers nearly in line with the centre leave its
    roll to the noise), the motion is read from its two markers' paths instead (:func:`single_axis_by_circles`), when
    the other segment has three or more; otherwise the test cannot tell (False)."""
    if chain.types[joint] != "spherical":
        return False, float("nan"), float("nan")
    if any(len(chain.seg_markers[s]) < 3 for s in (chain.parent[joint], chain.child[joint])):
        return single_axis_by_circles(chain, fit, sigma_mm, joint)
    spread = rotation_spread_rad(fit, joint)
    noise = rotation_noise_rad(chain, fit, sigma_mm, joint)
    second = float(spread[-2])
    return bool(second <= SECOND_AXIS_NOISE_RATIO * noise), float(np.rad2deg(second)), float(np.rad2deg(noise))


def single_axis_by_circles(chain, fit, sigma_mm: float, joint: str) -> tuple[bool, float, float]:
    """:func:`single_axis` for a ball joint between a segment posed by three markers or more and one with two: each
    marker of the two, as the fit places it in the other's frame, moves on a circle about one axis
    when the joint turns about one axis only. The verdict is whether the marker farthest from its least-squares
    circle (:func:`identcheck.solve.minimal.circle_fit`; the 3-D distance, out of its plane too) stays within
    :data:`SECOND_AXIS_NOISE_RATIO` times the markers' noise σ, RMS; the degrees are that RMS distance and σ as angles
    seen from the joint's centre at that marker's distance. A path too straight or too short to fix a circle tells
    nothing (False), nor does a joint without one such pair of segments. Not beside a segment of one marker: the short
    path of a single marker turning 8 deg about three axes 80 mm from the centre (1.5 mm of noise) lies within 2.4 σ
    of a circle, which would call the joint turned about one axis where its path is only too short to tell (the rules
    for a joint that hardly moved, and its intervals, judge it).

    Why: two thigh markers 180 and 325 mm from a hip that only flexed (41 deg; 0.5 deg of abduction, 0.1 of
    rotation, 1.4 mm of AR(1) noise, 3000 frames) were fitted with the centre 76 mm along the flexion axis from the
    truth and called determined at ±8.6 mm, in 5 of 9 noise draws (an independent session's simulator): the
    likelihood at the truth was 25 χ² units above the fit's, the estimate biased by the per-frame rotations fitted to
    noise, which no interval from the likelihood holds. Their markers lie within 1.8-2.7 σ of circles; of that
    session's hips that turned about several axes, none nearer than 3.0 σ (small clusters 34-85 mm from the centre:
    3.0-3.2 σ, every other 5.2 σ and above).

    The noise counted is the markers' own, not what the posed segment's pose noise adds at the marker, which the
    3-marker rule counts (:func:`rotation_noise_rad`): counted, that session's hips turning about several axes came
    within 1.7-3.0 of it (five of the eight called determined, all holding the truth), where the wrong ones stayed
    at 0.75-1.1. Uncounted, a far marker (a knee marker 460 mm from a three-marker pelvis: 2.7 mm off its circle at
    1 mm of noise) can read a one-axis hip as turning about two, and the joint is then judged as before: the
    simulator's one-axis hips with a greater trochanter and a thigh wand marker were read as one axis in 6 of 12
    (1 mm, 600 frames), its two- and three-axis hips never (24 of 24 at 5.7 σ and above)."""
    from identcheck.errors import DegenerateError
    from identcheck.solve.minimal import circle_deviations, circle_fit

    nan = float("nan")
    P, C = chain.parent[joint], chain.child[joint]
    posed = [s for s in (P, C) if len(chain.seg_markers[s]) >= 3]
    sparse = [s for s in (P, C) if len(chain.seg_markers[s]) == 2]
    if len(posed) != 1 or len(sparse) != 1 or not (sigma_mm > 0):
        return False, nan, nan
    R, t = fit.seg_R[posed[0]], fit.seg_t[posed[0]]
    centre = fit.state.c_parent[joint] if posed[0] == P else fit.state.c_child[joint]
    worst, reach = float("nan"), 1.0
    for k in chain.seg_markers[sparse[0]]:
        path = np.einsum("fji,fj->fi", R, fit.pred[:, k] - t)          # the marker in the posed segment's frame
        path = path[np.isfinite(path).all(axis=1)]
        if len(path) < 4:
            return False, nan, nan
        try:
            middle, normal, radius = circle_fit(path)
        except (DegenerateError, np.linalg.LinAlgError, ValueError):
            return False, nan, nan
        radial, out, _ = circle_deviations(path, middle, normal, radius)
        rms = float(np.sqrt(np.mean(radial ** 2 + out ** 2)))
        if not np.isfinite(rms):
            return False, nan, nan
        if not rms / sigma_mm <= worst:                 # (the first, or a marker farther from its circle)
            worst = rms / sigma_mm
            reach = max(float(np.sqrt(np.mean(np.sum((path - centre) ** 2, axis=1)))), 1e-9)
    return (bool(worst <= SECOND_AXIS_NOISE_RATIO), float(np.rad2deg(worst * sigma_mm / reach)),
            float(np.rad2deg(sigma_mm / reach)))


def weakest(chain, fit, cov, joint: str) -> tuple[np.ndarray | None, float | None]:
    """Unit direction (in the parent's fit frame) in which the joint's centre (a hinge: its position across the
    axis) is least determined relative to the parent segment, and its standard error in mm; the error is None when
    the data leave the centre free along that direction (beyond the gauge: no error means anything there), and both
    are None when the parent carries nothing to place the centre against (:func:`centre_in_parent`)."""
    grad, free = centre_in_parent(chain, fit.state, joint, len(cov.information))
    if grad is None:
        return None, None
    block = grad @ cov.sandwich @ grad.T
    naive = grad @ cov.naive @ grad.T
    block = naive if np.trace(naive) > np.trace(block) else 0.5 * (block + block.T)   # never below white noise
    if chain.types[joint] == "revolute":
        free = np.column_stack([free, fit.state.axis[joint]])
    if free.shape[1]:
        u, s, _ = np.linalg.svd(free, full_matrices=False)
        u = u[:, s > 1e-9 * max(s[0], 1e-300)]
        P = np.eye(3) - u @ u.T
        block = P @ block @ P
        grad = P @ grad
    if any(cov.free(row) for row in grad):                   # free along a direction the data leave open
        return np.linalg.svd(grad @ cov.null)[0][:, 0], None
    w, V = np.linalg.eigh(block)
    return V[:, -1], float(np.sqrt(max(w[-1], 0.0)))


def centre_in_parent(chain, state, joint: str, n_params: int) -> tuple[np.ndarray | None, np.ndarray]:
    """The gradient (3, P) over the constants of the joint's centre relative to its parent segment, and the
    directions (3, k) in which the parent leaves it free.

    Why: the fit's body frame of a segment is a choice (a gauge: moving and turning it, with the markers, joint
    points and poses it carries, changes no fitted marker), and the centre's covariance in it measures the frame as
    much as the joint (moving the frames' origins to their markers had moved biobuddy's knee's weakest standard
    error from 38.8 to 63.1 mm). Relative to the segment means: in the frame that the least-squares fit of the
    segment's points to their fitted places holds still, its markers, or when they are fewer than three or in a
    line, its markers and the centres of its other ball joints. The centre's change is ``δc − δt − δω × (c − p̄)``,
    with δt the points' mean change and δω their least-squares turn about their centroid p̄; a turn the points do
    not fix (about their line, or any turn about a single point) moves the centre along ``n × (c − p̄)``, which no
    data can tell, and those directions are returned to be left out. None when the parent carries no point."""
    offsets = joint_offsets(chain)
    seg = chain.parent[joint]
    cols = [3 * m for m in chain.seg_markers[seg]]
    points = [state.local[m] for m in chain.seg_markers[seg]]
    if len(points) < 3 or np.linalg.matrix_rank(np.array(points) - np.mean(points, axis=0), tol=1e-6) < 2:
        for j in chain.joints:
            if j != joint and chain.types[j] == "spherical" and seg in (chain.parent[j], chain.child[j]):
                side = 0 if chain.parent[j] == seg else 1
                cols.append(offsets[j] + 3 * side)
                points.append(state.c_parent[j] if side == 0 else state.c_child[j])
    if not points:
        return None, np.zeros((3, 0))
    q = np.array(points) - np.mean(points, axis=0)
    inertia = np.sum(q * q) * np.eye(3) - q.T @ q
    w, V = np.linalg.eigh(inertia)
    fixed = w > 1e-9 * max(w[-1], 1e-300)
    turn = (V[:, fixed] / w[fixed]) @ V[:, fixed].T           # δω = turn @ Σ q_k × δp_k
    arm = state.c_parent[joint] - np.mean(points, axis=0)
    grad = np.zeros((3, n_params))
    o = offsets[joint]
    grad[:, o:o + 3] = np.eye(3)
    for col, qk in zip(cols, q):
        grad[:, col:col + 3] += -np.eye(3) / len(q) + skew(arm) @ turn @ skew(qk)
    free = np.stack([np.cross(n, arm) for n in V[:, ~fixed].T], axis=1) if (~fixed).any() else np.zeros((3, 0))
    return grad, free


def own_pose(chain, segment: str, fit=None) -> bool:
    """Whether a segment carries markers enough (three) to be posed in every frame by them alone, so that its
    motion relative to a neighbour is measured, whatever the joint between them; with `fit`, also not on one line
    (their fitted places on the segment, :func:`~identcheck.geometry.poses.poses_segment`): a frame posed by three
    markers within a millimetre of a line turns about it with the noise, and a knee that moved 60° below such a thigh
    was said to have hardly moved (its shank markers 170 mm from one place in the thigh's frame, within the noise
    that frame's roll amplified)."""
    idx = chain.seg_markers[segment]
    if len(idx) < MIN_MARKERS:
        return False
    return fit is None or poses_segment(fit.state.local[idx][None])


def excursion_mm(chain, fit, frame_segment: str, moving_segment: str) -> tuple[np.ndarray, np.ndarray]:
    """How far each marker of `moving_segment` moves in the frame of `frame_segment` (posed by its own markers): the
    95th percentile over frames of its distance from its median place there, mm (as fitted, which is the measured
    markers up to the residual); and the noise of the marker there, as a factor on the markers' noise σ: its own
    and the frame's pose noise (:func:`identcheck.geometry.poses.pose_noise_factor`), ``sqrt(1 + f²)``; a static
    trial's markers move by about 2.8 σ times that. Empty arrays for a segment without markers."""
    idx = chain.seg_markers[moving_segment]
    if not len(idx):
        return np.zeros(0), np.zeros(0)
    R, t = fit.seg_R[frame_segment], fit.seg_t[frame_segment]
    local = np.einsum("fji,fkj->fki", R, fit.pred[:, idx] - t[:, None])
    place = np.median(local, axis=0)
    moved = np.percentile(np.linalg.norm(local - place, axis=2), 95.0, axis=0)
    own = fit.state.local[chain.seg_markers[frame_segment]]
    return moved, np.sqrt(1.0 + pose_noise_factor(own, place) ** 2)


def cross_spread_mm(fit, a: list, b: list) -> np.ndarray:
    """How much each distance between a marker of `a` and one of `b` varies over the trial: the 95th percentile
    over frames of its departure from its median, shape (len(a), len(b)), mm (as fitted, which is the measured
    markers up to the residual; noise of σ per coordinate alone gives about 2.8 σ)."""
    d = np.linalg.norm(fit.pred[:, list(a)][:, :, None] - fit.pred[:, list(b)][:, None], axis=3)
    return np.percentile(np.abs(d - np.median(d, axis=0)), 95.0, axis=0)


def hardly_moved(chain, fit, sigma_mm: float, joint: str) -> str | None:
    """What shows that a joint hardly moved in the trial, or None.

    Beside a segment not posed by its own markers the fitted rotations are not measured, so neither
    :func:`single_axis` nor a range of angles can tell; what the markers do show is how far the other segment's
    markers move in the posed segment's frame (:func:`excursion_mm`). Within :data:`HARDLY_MOVED_NOISE` times their
    noise there, or :data:`HARDLY_MOVED_MM`, the trial holds the joint still, and no place of it is determined: on
    a static simulated trial (3 pelvis, 1 thigh, 1 shank marker, 1 mm noise) the hip was 'determined' with its
    thigh marker 5.9 +- 1.2 mm from the centre, 510 mm in truth (the incidental roll of the one-marker thigh lets a
    small sphere absorb the noise). Between two segments neither of which is posed by its own markers, three or
    more markers on the two together that keep every distance across the joint (:func:`cross_spread_mm`, within
    :data:`HARDLY_MOVED_NOISE` times a distance's noise σ√2, or :data:`HARDLY_MOVED_MM`) move as one rigid body: the
    joint did not move (a static ankle between a two-marker shank and a two-marker foot had been 'determined'
    111-196 mm off). Between two segments both posed by their own markers the same test in the parent's frame
    applies: a static knee between three-marker thigh and shank had been 'determined' 300 mm off at +-9 mm (AR(1)
    noise, 405 frames)."""
    kind, text = _motion_seen(chain, fit, joint, sigma_mm)
    return text if kind == "hardly" else None


def _still_in_frame(joint: str, frame: str, other: str, each: np.ndarray, amplification: np.ndarray,
                    sigma_mm: float) -> str | None:
    """'joint hardly moved: ...' when every marker of `other` stays within :data:`HARDLY_MOVED_MM` or
    :data:`HARDLY_MOVED_NOISE` times its noise of one place in the frame of `frame` (`each`, `amplification`:
    :func:`excursion_mm`), else None."""
    if np.all(each <= np.maximum(HARDLY_MOVED_MM, HARDLY_MOVED_NOISE * sigma_mm * amplification)):
        return (f"{joint} hardly moved: {other}'s markers stay within {float(np.max(each)):.2g} mm of one place in "
                f"{frame}'s frame")
    return None


def _motion_seen(chain, fit, joint: str, sigma_mm: float) -> tuple[str, str]:
    """What the markers themselves show of the joint's motion: (kind, text), kind one of ``"measured"`` (both
    segments posed by their own markers and the joint moved; no text), ``"hardly"`` (:func:`hardly_moved`),
    ``"moved"`` (one segment posed, the other's markers move in its frame, by how much the text says) and
    ``"unmeasured"`` (neither posed and not shown still, or the other segment carries no marker)."""
    parent, child = chain.parent[joint], chain.child[joint]
    posed = [s for s in (parent, child) if own_pose(chain, s, fit)]
    n = {s: len(chain.seg_markers[s]) for s in (parent, child)}
    counts = f"{parent} carries {n[parent]} marker{'s' * (n[parent] != 1)}, {child} {n[child]}"
    lined = [s for s in (parent, child) if n[s] >= MIN_MARKERS and s not in posed]
    if lined:
        counts += f"; {' and '.join(lined)}'s lie on one line"
    if not posed:
        if n[parent] and n[child] and n[parent] + n[child] >= MIN_MARKERS:
            spread = cross_spread_mm(fit, chain.seg_markers[parent], chain.seg_markers[child])
            if np.all(spread <= max(HARDLY_MOVED_MM, HARDLY_MOVED_NOISE * np.sqrt(2.0) * sigma_mm)):
                return "hardly", (f"{joint} hardly moved: every distance between {parent}'s and {child}'s markers "
                                  f"stays within {float(np.max(spread)):.2g} mm of one value")
        return "unmeasured", (
            f"{joint}'s rotation is not measured by the markers ({counts}: neither is posed by its own markers, and "
            f"the fitted angles follow the joint's geometry, which this trial leaves open): add markers to bring "
            f"{parent} or {child} to three, off one line")
    frame = posed[0]                        # the parent when both are posed
    other = child if frame == parent else parent
    each, amplification = excursion_mm(chain, fit, frame, other)
    if not len(each):
        return "unmeasured", (f"{joint}'s rotation is seen only through the joints beyond it ({other} carries no "
                              f"marker): add markers on {other}")
    still = _still_in_frame(joint, frame, other, each, amplification, sigma_mm)
    if still:
        return "hardly", still
    if len(posed) == 2:
        return "measured", ""
    return "moved", (f"{other}'s markers move up to {float(np.max(each)):.0f} mm in {frame}'s frame, but {other} is "
                     f"not posed by its own markers ({counts}), so how far {joint} turned depends on its geometry, "
                     f"which this trial leaves open: add markers to bring {other} to three, off one line, or markers "
                     "farther from the joint on it")


def _motion(chain, fit, joint: str, weak, seen: tuple) -> str:
    """What to record to determine the joint better, from the motion the trial shows (module docstring: only what
    the markers measure; `seen` is :func:`_motion_seen`'s finding)."""
    kind, text = seen
    if kind == "hardly":
        return "record the joint's movement through its range"
    if chain.types[joint] == "revolute":
        if kind != "measured":
            return text
        rom = float(np.rad2deg(np.ptp(np.unwrap(fit.state.theta[joint]))))
        if rom < MIN_HINGE_ROM_DEG:
            return f"flex {joint} through a larger range (this trial: {rom:.0f} deg about the hinge)"
        return (f"{joint} moved {rom:.0f} deg about its hinge: add frames, or markers farther from the hinge axis, "
                "on the segments that carry few")
    where = (f"along ({', '.join(f'{x:+.2f}' for x in weak[0])}) in {chain.parent[joint]}'s frame"
             if weak[0] is not None else f"relative to {chain.parent[joint]}, which carries no marker to place it by")
    generic = (f"{joint}'s centre is least determined {where}: a larger range of motion, more frames or more markers "
               "on the segments that carry few")
    if kind != "measured":
        return f"{text}; {generic}" if kind == "moved" else text
    second = float(np.rad2deg(rotation_spread_rad(fit, joint)[-2]))
    if second < MIN_SECOND_AXIS_DEG:
        return (f"{joint} turned mostly about one axis (second axis {second:.0f} deg RMS): its centre is least "
                f"determined {where}; add rotation about the other axes "
                "(e.g. abduction and circumduction of a hip that only flexed)")
    return generic
