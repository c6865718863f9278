"""Markers that move with both segments of a joint: on its axis or at its centre, their segment is a choice.

A marker on a hinge's axis (a femoral or humeral epicondyle) or at a ball joint's centre keeps its place in the
frames of both segments, however far the joint turns: only its skin motion and the noise move it. Motion cannot
say which segment carries it. The grouping gives it to one of them, so the written model is one reading of the
data and the report says so; the skeleton can still be settled, since the marker moves the same on either.
Measured on the independent full-body functional trials (development draw), every group that mixed markers from
both sides of a joint that moved held such markers: epicondyles 290-425 mm down the parent segment, an
olecranon 31 mm from the elbow's centre.

For every joint of the tree between two posed segments that turns by at least :data:`MOVING_DEG` (RMS spread of
the relative rotation about its main axis), each marker of either segment is seen in the frame of the other
(:func:`identcheck.infer.body_frames.body_deviation`, the 95th percentile of its distance from one body-fixed
place). It moves with both when that deviation is within a skin marker's range
(:data:`~identcheck.infer.separated_groups.MAX_SKIN_MM`) and at most :data:`BOTH_FACTOR` times its deviation in the
frame of its own segment's other markers (noise for a rigid marker, the skin's motion for a skin marker; a marker
50 mm off a hinge's axis moves 17 mm in the other frame for a 20 deg turn). In a segment of three markers a marker
has no other three to be posed on: then within :data:`NEAR_SHARE` of what its segment's median marker moves there.
"""
from __future__ import annotations

import numpy as np

from identcheck.geometry.poses import MIN_MARKERS
from identcheck.infer.body_frames import body_deviation, evenly_spaced
from identcheck.infer.grouping import MAX_GROUPING_FRAMES
from identcheck.infer.separated_groups import MAX_SKIN_MM

MOVING_DEG = 10.0
"""Joints turning less than this (RMS spread about their main axis, degrees) are not checked: every marker of two
segments that hardly move relative to each other stays still in both frames."""
BOTH_FACTOR = 2.0
"""A marker moves with the other segment when its deviation there is at most this many times its own ..."""
NEAR_SHARE = 0.15
"""... or, for a marker whose own deviation cannot be measured (one of three), at most this share of its segment's
median marker's there, and within :data:`~identcheck.infer.separated_groups.MAX_SKIN_MM`."""


def markers_on_joints(xyz, labels, segments: dict, joints: list) -> list:
    """The markers that move with both segments of a joint that turns.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm.
    labels : sequence of str
    segments : dict of str to sequence of str
        Segment → its markers.
    joints : list of dict
        The skeleton's joints (``parent``, ``child``, ``evidence.type.main_rotation_deg``).

    Returns
    -------
    list of dict
        ``{"marker", "segment", "also_with", "joint", "deviation_mm", "own_deviation_mm", "note"}``.
    """
    xyz = evenly_spaced(xyz, MAX_GROUPING_FRAMES)
    index = {m: i for i, m in enumerate(labels)}
    cols = {s: [index[m] for m in ms] for s, ms in segments.items()}
    own = {}
    out = []
    for j in joints:
        turn = (j.get("evidence", {}).get("type") or {}).get("main_rotation_deg")
        a, b = j["parent"], j["child"]
        if turn is None or not turn >= MOVING_DEG or len(cols.get(a, ())) < MIN_MARKERS \
                or len(cols.get(b, ())) < MIN_MARKERS:
            continue
        for seg, other in ((a, b), (b, a)):
            there, _ = body_deviation(xyz, cols[other], cols[seg])
            finite = there[np.isfinite(there)]
            typical = float(np.median(finite)) if len(finite) else float("nan")
            for k, m in enumerate(cols[seg]):
                if m not in own:
                    rest = [c for c in cols[seg] if c != m]
                    own[m] = float(body_deviation(xyz, rest, [m])[0][0]) if len(rest) >= MIN_MARKERS else float("nan")
                both = there[k] <= MAX_SKIN_MM and (there[k] <= BOTH_FACTOR * own[m] if np.isfinite(own[m])
                                                     else there[k] <= NEAR_SHARE * typical)
                if np.isfinite(there[k]) and both:
                    name = labels[m]
                    out.append({"marker": name, "segment": seg, "also_with": other, "joint": j["name"],
                                "deviation_mm": float(there[k]), "own_deviation_mm": own[m],
                                "note": f"{name} stays within {there[k]:.3g} mm of one place in {other}'s frame as "
                                        f"well as in {seg}'s ({own[m]:.3g} mm), although {j['name']} turns "
                                        f"{turn:.3g} deg: it lies near that joint's axis or centre, and which segment "
                                        f"carries it is a choice the motion cannot make"})
    return out
