"""The derivatives of the whole chain's predicted markers, by blocks.

A marker depends on few of the unknowns: its own position on its segment, the constants of the joints
between its segment and the root, the effect terms that touch it, and per frame the root's pose and those
joints' angles. Markers of one segment touched by the same terms share all of these but their own
positions, so the Jacobian is kept as one block per such group (:class:`Group`): the group's markers'
derivatives with respect to its own per-frame and constant columns only. A 16-marker pair of legs has 82
constants, of which a shank marker touches 20 and a pelvis marker 3.

Rotation updates are applied on the left in the world frame (:func:`identcheck.bundle.model.apply_step`),
so the derivative of a marker at x with respect to a rotation ω about a point c is ``ω × (x − c)``: about
the root origin, or about the joint's centre for every marker downstream of the joint.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from identcheck.bundle.coupling import KronTerm, term_columns
from identcheck.bundle.model import (State, Terms, cross3, hinge_turns, n_const, second_axis, second_rotations,
                                     tangents, tilt_axis, turn_beta, turn_rate, world_motion)
from identcheck.geometry.rotations import hinge_matrix, left_jacobian_times, skew
from identcheck.skeleton import Skeleton


@dataclass(frozen=True)
class Group:
    """Markers of one segment touched by the same effect terms, and the columns they depend on.

    ``cols``: the markers (trial columns, (m,)); ``joints``: the joints from the root down to the segment;
    ``terms``: indices (``Terms.ordered()`` order) of the effect terms that touch them; ``frame_cols`` (kb,):
    their per-frame unknowns (the root's pose, then each joint's angles), and as :func:`runs`; ``const_cols``
    (pb,): their constants (the markers' own positions, 3 each, then each joint's, root first, then each term's).
    ``plain_at``: the positions in ``const_cols`` of the plain constants (those not a basis times a base direction:
    the columns of the block's G), ``plain_const_runs`` their columns in the whole system and ``plain_runs`` their
    places among :attr:`Layout.plain`, both as runs; ``kron_at``, the group's terms that are a basis times base
    directions, as indices of :attr:`Layout.kron`, in the order of their base directions in the block (their
    columns and their places among the coupling's bases follow from those:
    :func:`identcheck.bundle.normal.term_parts`)."""

    segment: str
    cols: np.ndarray
    joints: tuple
    terms: tuple
    frame_cols: np.ndarray
    const_cols: np.ndarray
    frame_runs: tuple
    plain_at: np.ndarray
    plain_const_runs: tuple
    plain_runs: tuple
    kron_at: tuple


def runs(cols: np.ndarray) -> tuple:
    """The stretches of consecutive columns in `cols`: ((first, end, position in cols), ...). Adding a block's
    products into the whole system stretch by stretch uses slices (views), not fancy indexing (copies)."""
    out, at = [], 0
    cols = [int(c) for c in cols]
    while at < len(cols):
        end = at + 1
        while end < len(cols) and cols[end] == cols[end - 1] + 1:
            end += 1
        out.append((cols[at], cols[end - 1] + 1, at))
        at = end
    return tuple(out)


@dataclass(frozen=True)
class Layout:
    """Where every unknown sits: ``k`` per-frame columns, ``P`` constant columns, and the groups; ``plain``, the
    constants that are not a basis times a base direction, and ``kron``, the terms that are
    (:class:`~identcheck.bundle.coupling.KronTerm`: skin, a translating centre, a hinge's second rotation)."""

    k: int
    P: int
    groups: tuple
    plain: np.ndarray = None
    kron: tuple = ()


def _ancestors(chain: Skeleton, segment: str) -> tuple:
    """The joints from the root down to `segment` (root first)."""
    joint_of = {chain.child[j]: j for j in chain.joints}
    out = []
    while segment in joint_of:
        j = joint_of[segment]
        out.append(j)
        segment = chain.parent[j]
    return tuple(reversed(out))


def _touched(chain: Skeleton, terms: Terms) -> list:
    """For each term (``Terms.ordered()`` order), the set of marker columns it moves."""
    out = [set(np.atleast_1d(c).tolist()) for c, _ in terms.markers]
    out += [set(chain.downstream[j].tolist()) for j, _ in terms.centres]
    out += [set(chain.downstream[j].tolist()) for j, _, _ in terms.rotations]
    out += [set(chain.downstream[j].tolist()) for j, _ in terms.screws]
    out += [set(np.atleast_1d(c).tolist()) for c, _ in terms.world]
    return out


def layout(chain: Skeleton, terms: Terms) -> Layout:
    """The columns of the chain's unknowns and the marker groups that share them (same segment, same terms)."""
    frame_start, col = {}, 6
    for j in chain.joints:
        frame_start[j] = col
        col += 3 if chain.types[j] == "spherical" else 1
    const_start, c = {}, 3 * chain.n_markers
    for j in chain.joints:
        const_start[j] = c
        c += 6 + (5 if chain.types[j] == "revolute" else 0)
    term_cols, kron, kron_of, offset = [], [], {}, 0
    n_mc = len(terms.markers) + len(terms.centres)
    for i, term in enumerate(terms.ordered()):
        if i < n_mc + len(terms.rotations):            # a basis times base directions (3, or one turn)
            basis = term[1]
            d = 3 if i < n_mc else 1
            kron_of[i] = len(kron)
            kron.append(KronTerm(c, d, offset, basis))
            offset += d
            size = d * basis.shape[1] + (0 if i < n_mc else 1)     # (a hinge's second rotation: its β, plain)
        else:
            size = 1
        term_cols.append(np.arange(c, c + size))
        c += size
    in_kron = np.zeros(c, dtype=bool)
    for t in kron:
        in_kron[t.cols] = True
    plain = np.flatnonzero(~in_kron)
    plain_index = np.cumsum(~in_kron) - 1
    touched = _touched(chain, terms)
    groups = []
    for seg in chain.segments:
        joints = _ancestors(chain, seg)
        fcols = np.concatenate([np.arange(6)] + [np.arange(frame_start[j], frame_start[j] + (
            3 if chain.types[j] == "spherical" else 1)) for j in joints]).astype(int)
        ccols = [np.arange(const_start[j], const_start[j] + 6 + (5 if chain.types[j] == "revolute" else 0))
                 for j in joints]
        by_terms: dict = {}
        for m in chain.seg_markers[seg]:
            key = tuple(i for i, t in enumerate(touched) if int(m) in t)
            by_terms.setdefault(key, []).append(int(m))
        for key, cols in by_terms.items():
            cols = np.array(cols, dtype=int)
            ccol = np.concatenate([(3 * cols[:, None] + np.arange(3)).ravel()] + ccols
                                  + [term_cols[i] for i in key]).astype(int)
            plain_at = np.flatnonzero(~in_kron[ccol])
            groups.append(Group(seg, cols, joints, key, fcols, ccol, runs(fcols), plain_at, runs(ccol[plain_at]),
                                runs(plain_index[ccol[plain_at]]), tuple(kron_of[i] for i in key if i in kron_of)))
    return Layout(col, n_const(chain, terms), tuple(groups), plain, tuple(kron))


@dataclass(frozen=True)
class Block:
    """One group's derivatives: ``J`` (F, m, 3, kb) per frame, in its columns; ``G`` (F, m, 3, len(plain_at)), its
    plain constants' (``Group.plain_at`` of its columns); ``base`` (F, m, 3, db), the base directions of the group's
    terms that are a basis times them (``Group.kron_at``): such a term's columns are its base times each basis
    function (:mod:`identcheck.bundle.coupling`) and are never written out (a hinge's second rotation with 82 basis
    functions had made a shank block's G 112 columns wide, 82 of them such; :func:`dense_jacobians` writes them for
    checks)."""

    group: Group
    J: np.ndarray
    G: np.ndarray
    base: np.ndarray | None = None


def jacobian_blocks(chain: Skeleton, terms: Terms, s: State, R: dict, centre: dict,
                    pred: np.ndarray, lazy: bool = False) -> tuple[Layout, list | Iterator]:
    """The derivatives of the predictions `pred` (F, M, 3) of state `s` (with the segments' rotations `R` and
    the joints' world centres `centre` of :func:`identcheck.bundle.model.forward`), one :class:`Block` per group:
    a list, or with `lazy` an iterator that forms each block when it is reached. `lazy` is for a caller that passes
    over the blocks once, as the fit's normal equations do (a second pass would find none: not
    :func:`~identcheck.bundle.normal.frames_eliminated`): there no more than two blocks are held at once, not all of
    them (53 MB on a 42-marker body at 1500 frames) beside the coupling B they are summed into."""
    lay = layout(chain, terms)
    F = pred.shape[0]
    n0, nw = terms.screws_start(), terms.world_start()
    lever = pred - world_motion(terms, s) if terms.world else pred    # lever arms: the rigid bodies' points
    runs_at = {nw + first: (cols, fields) for first, cols, fields in terms.world_runs()}
    turns = hinge_turns(chain, terms, s) if terms.rotations else {}
    hinge_w, rest_w, tilt_w = {}, {}, {}
    for j in chain.joints:
        if chain.types[j] != "revolute":
            continue
        P, ax, th = chain.parent[j], s.axis[j], s.theta[j]
        hinge_w[j] = R[P] @ ax
        rot = turns.get(j)
        rot = hinge_matrix(ax, th) if rot is None else rot
        rest_w[j] = [np.einsum("fij,fj->fi", R[P], rot[:, :, a]) for a in range(3)]
        tilt = []
        for b in tangents(ax):
            if any(r[0] == j for r in terms.rotations):
                wp = turn_rate(chain, terms, s, j, tilt_axis(j, b))      # the second axis moves with it
            else:
                wp = np.sin(th)[:, None] * b + (1 - np.cos(th))[:, None] * cross3(ax, b)
            tilt.append(np.einsum("fij,fj->fi", R[P], wp))
        tilt_w[j] = tilt
    n_mc = len(terms.markers) + len(terms.centres)
    second, vectors = {}, second_rotations(terms, s)
    for r, (j, basis, beta) in enumerate(terms.rotations):  # d/dψ: about R_P Rot(a, θ) J_l(v) u, through the centre
        u = second_axis(s.axis[j], beta + s.term_params[n_mc + r][-1, 0])
        P = chain.parent[j]
        # v, the hinge's whole second rotation, is along u when the hinge has one; with two (a ball joint's) it is
        # not, and u alone was wrong by O(|v|): fits crawled, 8-100 iterations at ρ ≈ 0.5 (a development knee as a ball)
        turn_u = left_jacobian_times(vectors[j], u)
        second[n_mc + r] = (np.einsum("fij,fjk,fk->fi", R[P], hinge_matrix(s.axis[j], s.theta[j]), turn_u),
                            np.einsum("fij,fj->fi", R[P], turn_rate(chain, terms, s, j, turn_beta(n_mc + r))))
    ordered = terms.ordered()
    screw = {}                                  # each hinge's screws, summed: (F,) mm along its axis
    for (j, profile), p in zip(terms.screws, s.term_params[n0:nw]):
        screw[j] = screw.get(j, 0.0) + p[0] * profile

    def block(grp: Group) -> Block:
        idx, m = grp.cols, len(grp.cols)
        J = np.zeros((F, m, 3, len(grp.frame_cols)))
        G = np.zeros((F, m, 3, len(grp.plain_at)))          # the plain constants' columns only
        J[..., 0:3] = -skew(lever[:, idx] - s.root_t[:, None])    # column a: e_a × lever (a turn about the root)
        J[..., 3:6] = np.eye(3)
        for i in range(m):                                   # each marker's own position: the segment's rotation
            G[:, i, :, 3 * i:3 * i + 3] = R[grp.segment]
        fc, cc, dx = 6, 3 * m, {}
        for j in grp.joints:
            P, C = chain.parent[j], chain.child[j]
            d = dx[j] = lever[:, idx] - centre[j][:, None]
            if chain.types[j] == "spherical":
                J[..., fc:fc + 3] = -skew(d)
                fc += 3
            else:
                J[..., fc] = cross3(hinge_w[j][:, None], d)
                fc += 1
            G[..., cc:cc + 3] = R[P][:, None]
            G[..., cc + 3:cc + 6] = -R[C][:, None]
            cc += 6
            if chain.types[j] == "revolute":
                for a in range(3):                          # rest rotation, pre-multiplied by Rot(a, θ) Exp(ψu)
                    G[..., cc + a] = cross3(rest_w[j][a][:, None], d)
                for a in range(2):                          # axis direction, tangent plane
                    G[..., cc + 3 + a] = cross3(tilt_w[j][a][:, None], d)
                    if j in screw:                          # a screw along the axis follows it
                        G[..., cc + 3 + a] += (screw[j][:, None] * np.einsum("fij,j->fi", R[P], tangents(
                            s.axis[j])[a]))[:, None]
                cc += 5
        base = []
        for ti in grp.terms:
            term = ordered[ti]
            if ti < len(terms.markers):                      # the markers' position on their segment
                base.append(np.broadcast_to(R[grp.segment][:, None], (F, m, 3, 3)))
            elif ti < n_mc:                                  # the joint centre in the parent
                j = term[0]
                base.append(np.broadcast_to(R[chain.parent[j]][:, None], (F, m, 3, 3)))
            elif ti < n0:                                    # a hinge's second rotation (its β column is plain)
                j = term[0]
                w_psi, w_beta = second[ti]
                turn = cross3(w_psi[:, None], dx[j])
                base.append(turn[..., None])
                G[..., cc] = cross3(w_beta[:, None], dx[j])
                cc += 1
            elif ti < nw:                                    # a screw: the hinge's centre along its axis
                j, profile = term
                G[..., cc] = (profile[:, None] * hinge_w[j])[:, None]
                cc += 1
            elif ti in runs_at:                              # fields in the world, a run of them at once
                cols, fields = runs_at[ti]
                where = {int(c): i for i, c in enumerate(cols)}
                G[..., cc:cc + fields.shape[-1]] = fields[:, [where[int(c)] for c in idx]]
                cc += fields.shape[-1]
        return Block(grp, J, G, np.concatenate(base, axis=3) if base else None)

    blocks = map(block, lay.groups)
    return lay, (blocks if lazy else list(blocks))


def dense_jacobians(lay: Layout, blocks: list, n_markers: int):
    """The blocks written out in full: per-frame J (F, M, 3, k) and constants' G (F, M, 3, P), the term columns each
    base direction times each basis function (for checks)."""
    F = blocks[0].J.shape[0] if blocks else 0
    J = np.zeros((F, n_markers, 3, lay.k))
    G = np.zeros((F, n_markers, 3, lay.P))
    for b in blocks:
        g = b.group
        for i, col in enumerate(g.cols):
            J[:, col][..., g.frame_cols] = b.J[:, i]
            G[:, col][..., g.const_cols[g.plain_at]] = b.G[:, i]
            off = 0
            for t in (lay.kron[at] for at in g.kron_at):
                G[:, col][..., t.cols] = term_columns(b.base[:, i, :, off:off + t.d], t.basis)
                off += t.d
    return J, G
