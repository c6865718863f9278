"""The linearised equations of a whole skeleton in generic frames, written segment by segment so that
each equation touches only one segment or one joint.

:mod:`identcheck.certify.tree_rank` asks which combinations of the constants (marker positions on
their segments, joint centres in their parents, hinge directions) the data determine: the subspace W
of constant-gradients ∇f such that [0 | ∇f] lies in the row space of the Jacobian of all marker
coordinates over all frames with respect to the per-frame unknowns and the constants.

W does not depend on how the per-frame unknowns are parametrised: any parametrisation whose tangent
space is the same gives the same projection of the null space onto the constants. Parametrised by
the root's pose and the joint angles, a marker's row involves every joint above it, so a 200-segment
chain gives dense rows of ~2000 columns. Here every segment's pose in every frame is an unknown
(ω_s, δt_s: rotation about the world axes, velocity of the segment's origin) and each joint adds the
linearisation of its constraint instead:

- a marker m of segment s, x = R_s m + t_s:       δx = −[R_s m]× ω_s + δt_s + R_s δm;
- joint j (parent P, child C), t_C = R_P c_j + t_P:  δt_C − δt_P + [R_P c_j]× ω_P − R_P δc_j = 0;
- and, for a hinge R_C = R_P Rot(a_j, θ):          ω_C − ω_P − R_P (a_j δθ + g_u ε_u + g_v ε_v) = 0,

where ε_u, ε_v move a_j along its tangents u, v and g = vee(∂Rot/∂ε · Rotᵀ). A ball joint's rotation
is free in every frame, so it adds no rotation equation; a joint held at one angle in every frame
(``frozen``) replaces δθ (or a ball joint's rotation vector) by a constant column. Every equation
then touches at most two segments, which is what lets :mod:`identcheck.certify.tree_elimination`
eliminate the unknowns leaf to root.

Columns are named by keys: ``("w", seg, frame, axis)``, ``("t", seg, frame, axis)``,
``("th", joint, frame)`` for the per-frame unknowns, and for the constants :func:`marker_keys`,
:func:`centre_keys`, :func:`tangent_keys`, :func:`frozen_keys` (by name, so that two plans that differ
in one marker share the keys, and the work, of everything else). A row is a dict key -> field element.
"""
from __future__ import annotations

from identcheck.exact.algebra import axis_rotation, mm, mv


CONSTANT_KINDS = frozenset("mcuz")


def marker_keys(marker: str) -> list:
    return [("m", marker, a) for a in range(3)]


def centre_keys(joint: str) -> list:
    return [("c", joint, a) for a in range(3)]


def tangent_keys(joint: str) -> list:
    return [("u", joint, b) for b in range(2)]


def frozen_keys(joint: str, n: int) -> list:
    return [("z", joint, a) for a in range(n)]


def cross_matrix(y) -> list:
    """[y]×, the matrix of v ↦ y × v."""
    return [[0, -y[2], y[1]], [y[2], 0, -y[0]], [-y[1], y[0], 0]]


def axis_rotation_derivative(a, u, c, s) -> list:
    """d Rot(a, θ) along a → a + ε u (u ⟂ a): s [u]× + (1 − c)(u aᵀ + a uᵀ)."""
    one = 1 - c
    skew = cross_matrix(u)
    return [[s * skew[i][j] + one * (u[i] * a[j] + a[i] * u[j]) for j in range(3)] for i in range(3)]


def tilt_rates(a, u, v, c, s) -> tuple:
    """(g_u, g_v): the rotation vectors, in the parent's frame, of tilting a hinge's axis along its tangents
    u and v at angle (c, s) — vee(∂Rot/∂ε · Rotᵀ), exact (the product is skew-symmetric)."""
    Q = axis_rotation(a, c, s)
    Qt = [[Q[j][i] for j in range(3)] for i in range(3)]
    out = []
    for t in (u, v):
        M = mm(axis_rotation_derivative(a, t, c, s), Qt)
        out.append([M[2][1], M[0][2], M[1][0]])
    return tuple(out)


def frame_pose(spec, k, draw, frozen_angles) -> tuple:
    """One generic frame: ({segment: (R, t)}, {joint: (Q, (cos, sin) or None)}), the root drawn at random,
    each joint at a random rotation (or its frozen one), parents before children. ``draw(*item)``: the
    random source of one item ("root",) or ("turn", joint)."""
    root = draw("root")
    pose = {spec.root: (root.rotation(), root.vector())}
    turns = {}
    for name, kind, par, chi in spec.joints:
        RP, tP = pose[par]
        if name in frozen_angles:
            Q, cs = frozen_angles[name]
        elif kind == "spherical":
            Q, cs = draw("turn", name).rotation(), None
        else:
            cs = draw("turn", name).angle()
            Q, cs = axis_rotation(k.a[name][0], *cs), cs
        pose[chi] = (mm(RP, Q), [x + y for x, y in zip(mv(RP, k.c[name]), tP)])
        turns[name] = (Q, cs)
    return pose, turns


def marker_rows(segment: str, frame: int, R, m_local, keys: list) -> list:
    """The three rows of one marker: −[R m]× ω + δt + R δm (``keys``: its position's three columns)."""
    y = mv(R, m_local)
    neg = cross_matrix([-v for v in y])
    rows = []
    for r in range(3):
        row = {("t", segment, frame, r): 1}
        for a in range(3):
            if neg[r][a] != 0:
                row[("w", segment, frame, a)] = neg[r][a]
            row[keys[a]] = R[r][a]
        rows.append(row)
    return rows


def joint_rows(joint: tuple, frame: int, RP, Q_cs, k, frozen: bool) -> list:
    """The rows of one joint's constraint in one frame (three for a ball joint, six for a hinge or a
    frozen joint)."""
    name, kind, par, chi = joint
    y = mv(RP, k.c[name])
    yx = cross_matrix(y)
    centre = centre_keys(name)
    rows = []
    for r in range(3):
        row = {("t", chi, frame, r): 1, ("t", par, frame, r): -1}
        for a in range(3):
            if yx[r][a] != 0:
                row[("w", par, frame, a)] = yx[r][a]
            row[centre[a]] = -RP[r][a]
        rows.append(row)
    if kind == "spherical" and not frozen:
        return rows
    if kind == "spherical":                                   # held at one rotation: ω_C = ω_P + R_P φ
        phi = frozen_keys(name, 3)
        for r in range(3):
            row = {("w", chi, frame, r): 1, ("w", par, frame, r): -1}
            for a in range(3):
                row[phi[a]] = -RP[r][a]
            rows.append(row)
        return rows
    a_, u_, v_ = k.a[name]
    gu, gv = tilt_rates(a_, u_, v_, *Q_cs[1])
    turn = mv(RP, a_)
    tilt_u, tilt_v = mv(RP, gu), mv(RP, gv)
    tu, tv = tangent_keys(name)
    angle_key = frozen_keys(name, 1)[0] if frozen else ("th", name, frame)
    for r in range(3):
        rows.append({("w", chi, frame, r): 1, ("w", par, frame, r): -1, angle_key: -turn[r],
                     tu: -tilt_u[r], tv: -tilt_v[r]})
    return rows
