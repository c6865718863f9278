"""The gauge of a whole-chain fit, written out: the directions of the constants that change no fitted marker.

Each segment's body frame is a choice: moving it by t and turning it by ω moves the markers on it, the joint
points it carries and the hinge axes it holds by ``t + ω × x`` (axes by ``ω × a``), and the per-frame poses
undo it. A hinge adds two: sliding its point along its axis (both sides), and turning its rest rotation about
the axis while its angles take the turn back: :meth:`identcheck.skeleton.Skeleton.gauge` directions in all.
Effect terms (``diagnose``) turn with the frame they are written in: a marker's or a joint centre's offsets; a
hinge's screw runs along its axis and turns with it.

Why write them out rather than read them off the information's smallest eigenvalues: on sparse marker sets the
Schur complement's roundoff lifts gauge directions to 1e-8 of the largest (scaled) eigenvalue, among directions
the data determine poorly or not at all, and a cutoff between them falls on either side from one choice of
frames to the next (a one-marker thigh's knee had its weakest standard error move from 13 to 19 mm when the thigh's
frame was turned). Written out, the gauge is left out exactly, and the cutoff judges only what the data decide.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import Terms, joint_offsets, n_const, tangents


def gauge_basis(chain, state, n_params: int, terms: Terms | None = None) -> np.ndarray | None:
    """The gauge directions (P, :meth:`~identcheck.skeleton.Skeleton.gauge`) of the chain's constants in the fit's
    own update coordinates (:func:`identcheck.bundle.model.apply_step`: markers, then per joint the centre in parent
    and child, and for a hinge the rest rotation's left rotation vector and the axis' two tangent steps, then the
    effect terms' parameters). Of the effect terms, a marker's or a centre's offsets turn with their segment's frame
    (rows of B or D: ``ω × row``); a world field's scale and a screw's do not move (a screw runs along the hinge's
    axis, which turns); None when the fit carries a hinge's second rotation (its angle is measured from a tangent of
    the axis, whose gauge is not written out here) or when ``n_params`` is not the constants' count."""
    terms = terms or Terms()
    offsets = joint_offsets(chain)
    if terms.rotations or n_const(chain, terms) != n_params:
        return None
    columns = []
    for seg in chain.segments:
        for k in range(6):
            v = np.zeros(n_params)
            t, w = (np.eye(3)[k], np.zeros(3)) if k < 3 else (np.zeros(3), np.eye(3)[k - 3])
            for m in chain.seg_markers[seg]:
                v[3 * m:3 * m + 3] = t + np.cross(w, state.local[m])
            for j in chain.joints:
                o = offsets[j]
                if chain.parent[j] == seg:
                    v[o:o + 3] = t + np.cross(w, state.c_parent[j])
                    if chain.types[j] == "revolute":
                        v[o + 6:o + 9] = w                     # rest' = Rot(ω) rest
                        turn = np.cross(w, state.axis[j])
                        v[o + 9:o + 11] = [float(b @ turn) for b in tangents(state.axis[j])]
                if chain.child[j] == seg:
                    v[o + 3:o + 6] = t + np.cross(w, state.c_child[j])
                    if chain.types[j] == "revolute":
                        v[o + 6:o + 9] = -state.rest[j] @ w     # rest' = rest Rot(−ω) = Rot(−rest ω) rest
            _turn_offsets(chain, state, terms, seg, w, v)
            columns.append(v)
    for j in chain.joints:
        if chain.types[j] != "revolute":
            continue
        o, a = offsets[j], state.axis[j]
        slide = np.zeros(n_params)
        slide[o:o + 3], slide[o + 3:o + 6] = a, state.rest[j].T @ a
        offset = np.zeros(n_params)
        offset[o + 6:o + 9] = a                                # rest' = Rot(a, ε) rest, θ' = θ − ε
        columns += [slide, offset]
    return np.stack(columns, axis=1)


def _turn_offsets(chain, state, terms: Terms, segment: str, w: np.ndarray, v: np.ndarray) -> None:
    """Write into v the change ``ω × row`` of the offsets that a turn ω of `segment`'s frame brings to its markers'
    and its child joints' centres' effect terms (a world field's scale is not moved by any frame)."""
    c = n_const(chain, Terms())
    owners = [chain.marker_seg[int(np.atleast_1d(col)[0])] for col, _ in terms.markers]
    owners += [chain.parent[j] for j, _ in terms.centres]
    for owner, p in zip(owners, state.term_params):
        if owner == segment:
            v[c:c + p.size] = np.cross(w, p).ravel()
        c += p.size


def turning_blocks(chain, terms: Terms | None = None) -> list:
    """The constants' columns (index arrays, in :func:`gauge_basis`'s order) in the groups a change of a segment's
    body frame turns together, each by a rotation of its own coordinates: each marker's three coordinates, a joint's
    centre in parent and in child, a hinge's rest rotation (three) and its axis' two tangent steps, each row of a
    marker's or a centre's effect offsets; every other column (an extra rotation's profile, a world field's or a
    screw's scale) alone. Moving a frame's origin changes none of the constants' information (the per-frame poses
    take it up).

    What for: a cutoff on the eigenvalues of the information scaled with one scale a block
    (:func:`identcheck.bundle.uncertainty.block_scaled`) reads the same in every choice of frames, where scaling
    column by column does not (a one-marker knee's weakest direction read 9e-9 of the largest in the fit's own
    frames and 8e-12 to 4e-11 in turned ones, against a cutoff of 1e-9). Not with a hinge's second rotation
    (``terms.rotations``): its angle is measured from a fixed tangent of the axis, so a turn of the parent's frame
    mixes the axis' steps into it (:func:`gauge_basis` writes no gauge then either)."""
    terms = terms or Terms()
    offsets = joint_offsets(chain)
    blocks = [np.arange(3 * m, 3 * m + 3) for m in range(chain.n_markers)]
    for j in chain.joints:
        o = offsets[j]
        blocks += [np.arange(o, o + 3), np.arange(o + 3, o + 6)]
        if chain.types[j] == "revolute":
            blocks += [np.arange(o + 6, o + 9), np.arange(o + 9, o + 11)]
    c = n_const(chain, Terms())
    for p in terms.shapes():
        size = int(np.prod(p))
        if len(p) == 2 and p[1] == 3:
            blocks += [np.arange(c + 3 * k, c + 3 * k + 3) for k in range(p[0])]
        else:
            blocks += [np.array([c + k]) for k in range(size)]
        c += size
    return blocks
