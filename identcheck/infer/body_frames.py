"""Markers seen in the frame of a rigid body: how far they move there, and how much the body's own pose noise adds.

The grouping (:mod:`identcheck.infer.grouping`, :mod:`identcheck.infer.separated_groups`), the check for groups
that may be two segments (:mod:`identcheck.infer.two_segments`), the markers on joints
(:mod:`identcheck.infer.joint_markers`) and the tree's noise-only residuals (:mod:`identcheck.infer.tree`) all
pose some markers by least squares and look at others in that frame; this module does it once for all of them.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.stats import spearmanr

from identcheck.errors import InputError
from identcheck.estimate.joint import MIN_TRAVEL_MM
from identcheck.estimate.noise import MIN_SAMPLES_PER_PAIR
from identcheck.estimate.obrien import joint_location
from identcheck.geometry.poses import MIN_MARKERS, pose_noise_factor, segment_poses

DRIFT_RHO = 0.9
"""A single marker whose place along its path in a body's frame ranks with time at least this well (|Spearman's ρ|,
:func:`path_monotone`) drifts on that body: it slides on the skin or comes loose, where a joint's motion and skin
moving with a joint's angles go and return. On three development draws of the independent random-skeleton
generator: 0.95-1.00 for its 16 markers drifting 20-83 mm on a segment (in the frame where each moves least), at most
0.79 (in any segment's frame) for its 35 one-marker segments."""
STILL_DEG = 10.0
"""Two bodies whose relative rotation spreads less than this (degrees, the largest of O'Brien's rotation spreads:
about the RMS rotation about each direction) hardly rotate relative to each other in the trial. The still joints of
a functional trial sway by a few degrees; a joint that a trial exercises turns by tens."""
DEVIATION_PERCENTILE = 95.0
"""A marker's deviation in a body's frame: this percentile over frames of its distance from its median position."""


def evenly_spaced(xyz, n: int) -> np.ndarray:
    """At most `n` frames of `xyz` (frames first), evenly spread over the trial: the poses these checks need
    change slowly, and every frame would cost time without changing a verdict."""
    xyz = np.asarray(xyz, dtype=float)
    return xyz[np.linspace(0, len(xyz) - 1, n).astype(int)] if len(xyz) > n else xyz


def body_fixed(xyz: np.ndarray, body: list, cols: list):
    """The least-squares poses of the markers `body` (3 or more columns) in every frame, the markers `cols` in that
    frame, shape (F, k, 3) (NaN without a pose or the marker), and each one's median body-fixed place, (k, 3).

    Raises
    ------
    ValueError
        The body's markers are never all seen in one frame (:func:`identcheck.geometry.poses.segment_poses`).
    """
    poses = segment_poses(xyz[:, body])
    local = poses.to_local(xyz[:, cols])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)             # a marker never seen with the pose: NaN
        place = np.nanmedian(local, axis=0)
    return poses, local, place


def body_deviation(xyz: np.ndarray, body: list, cols: list) -> tuple[np.ndarray, np.ndarray]:
    """How far each marker of `cols` moves in the frame of the rigid body `body` (3 or more marker columns).

    Returns
    -------
    deviation : numpy.ndarray, shape (len(cols),)
        The 95th percentile (:data:`DEVIATION_PERCENTILE`) over frames of the marker's distance from its median
        body-fixed position, mm; inf when seen with the body's pose in fewer than
        :data:`~identcheck.estimate.noise.MIN_SAMPLES_PER_PAIR` frames, and for every marker when the body's
        markers are never all seen in one frame (no pose: no evidence that anything stays still in it).
    amplification : numpy.ndarray, shape (len(cols),)
        How much the body's own pose noise adds to a point there, as a factor on one marker's scatter:
        ``sqrt(1 + 1/n + tr([r]x J^-1 [r]x^T) / 3)`` for a point at r from the body's centroid, J the body's
        inertia tensor of its n markers (Kabsch's rotation covariance is σ² J⁻¹). Large where the body's markers
        are nearly collinear or far away.
    """
    try:
        poses, local, centre = body_fixed(xyz, body, cols)
    except ValueError:                                              # never seen whole (in these frames)
        return np.full(len(cols), np.inf), np.ones(len(cols))
    ok = np.isfinite(local).all(axis=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        dev = np.linalg.norm(local - centre, axis=2)
        out = np.nanpercentile(np.where(ok, dev, np.nan), DEVIATION_PERCENTILE, axis=0)
    out = np.where(ok.sum(axis=0) >= MIN_SAMPLES_PER_PAIR, out, np.inf)
    return out, np.sqrt(1.0 + pose_noise_factor(poses.local, np.nan_to_num(centre)) ** 2)


def path_monotone(path: np.ndarray) -> float:
    """|Spearman's ρ| between time and a point's place along its path (its positions (n, 3), in time order, NaN rows
    left out, projected on their first principal direction): 1 when it goes one way through the trial, near 0 when it
    goes and returns."""
    path = np.asarray(path, dtype=float)
    path = path[np.isfinite(path).all(axis=1)]
    if len(path) < 3:
        return 0.0
    centred = path - path.mean(axis=0)
    along = centred @ np.linalg.svd(centred, full_matrices=False)[2][0]
    rho = spearmanr(np.arange(len(along)), along)[0]
    return float(abs(rho)) if np.isfinite(rho) else 0.0


def is_drift(travel_mm: float, monotone: float) -> bool:
    """Whether a single marker that moves `travel_mm` (its largest coordinate range) in a body's frame, with
    :func:`path_monotone` `monotone` there, drifts on that body (:data:`DRIFT_RHO`): it goes one way through the
    trial, over at least :data:`~identcheck.estimate.joint.MIN_TRAVEL_MM`."""
    return bool(travel_mm >= MIN_TRAVEL_MM and monotone >= DRIFT_RHO)


def drifts_on(xyz: np.ndarray, body: list, marker: int) -> bool:
    """Whether the column `marker` drifts (:func:`is_drift`) in the frame of `body` (3 or more columns); False when
    the body is never seen whole or the marker is seen with it in fewer than
    :data:`~identcheck.estimate.noise.MIN_SAMPLES_PER_PAIR` frames (nothing to judge it by)."""
    if len(body) < MIN_MARKERS:
        return False
    try:
        path = body_fixed(xyz, body, [marker])[1][:, 0]
    except ValueError:
        return False
    seen = path[np.isfinite(path).all(axis=1)]
    return (len(seen) >= MIN_SAMPLES_PER_PAIR
            and is_drift(float(np.ptp(seen, axis=0).max()), path_monotone(seen)))


def is_rigid(xyz: np.ndarray, members: list, tolerance: float) -> bool:
    """Whether a set of four or more markers moves as one body: each member, seen in the frame of the others (a
    marker in the fit would pull the pose towards itself and hide its own motion), deviates by at most
    `tolerance` times that pose's amplification there (:func:`body_deviation`). Sets of three or fewer pass."""
    if len(members) <= MIN_MARKERS:
        return True
    for m in members:
        d, a = body_deviation(xyz, [o for o in members if o != m], [m])
        if not d[0] <= tolerance * a[0]:
            return False
    return True


def turn_deg(poses_a, poses_b) -> float:
    """How much one posed body turns in the frame of another (:class:`~identcheck.geometry.poses.Poses` each): the
    largest of the rotation spreads of O'Brien's joint fit between them
    (:func:`identcheck.estimate.obrien.joint_location`), degrees; NaN when the two are not posed together in enough
    frames. Below :data:`STILL_DEG` they hardly rotate relative to each other."""
    try:
        return float(np.max(joint_location(poses_a, poses_b).spread_deg))
    except InputError:
        return float("nan")


def relative_turn_deg(xyz: np.ndarray, body_a: list, body_b: list) -> float:
    """:func:`turn_deg` of the rigid bodies `body_a` and `body_b` (3 or more marker columns of `xyz` each); NaN when
    either has no pose."""
    try:
        return turn_deg(segment_poses(xyz[:, body_a]), segment_poses(xyz[:, body_b]))
    except ValueError:
        return float("nan")
