"""Every joint exact samples admit, for each locally identifiable revolute/spherical case.

The case is solved the way its row of the identifiability table certifies it: three markers on
a link fix that link's frame (spherical: the sphere of (3,1); revolute: the circle of (3,1)),
two on each use Pham's (2,1) and (2,2) solvers, and (p, q) with p < q is solved as (q, p) with
the links' roles exchanged (Remark 1). Joints are returned as their marker distances — the
gauge-invariant parameters: each marker's distance to the centre (spherical) or the hinge axis
(revolute), named A1.. (parent) and B1.. (child).
"""
from __future__ import annotations

import numpy as np

from identcheck.errors import DegenerateError, InputError
from identcheck.solve import revolute21, spherical22, spherical31
from identcheck.geometry.frames import pair_frame, parent_frame, to_local

ANGLE_TOL = 1e-6


def _names(prefix: str, k: int) -> list:
    return [f"{prefix}{i}" for i in range(1, k + 1)]


def _local_markers(parents: list) -> tuple:
    """Per-sample rotation and origin of the frame of markers A1, A2, A3, and their local coordinates."""
    a1, a2, a3 = parents[:3]
    rot, _ = parent_frame(a1, a2, a3 - a1)
    local = [to_local(rot, a1, a).mean(axis=0) for a in parents]
    return rot, a1, local


def _swap(dist: list) -> list:
    out = []
    for d in dist:
        out.append({("B" if k[0] == "A" else "A") + k[1:]: v for k, v in d.items()})
    return out


def _spherical_posed(parents, children) -> list:
    rot, a1, loc = _local_markers(parents)
    b = [to_local(rot, a1, c) for c in children]
    J = spherical31.identify(b[0]).joints[0].centre
    dist = {n: float(np.linalg.norm(p - J)) for n, p in zip(_names("A", len(parents)), loc)}
    dist.update({n: float(np.linalg.norm(bk - J, axis=1).mean()) for n, bk in zip(_names("B", len(children)), b)})
    return [dist]


def _best_plane(points) -> tuple:
    """(points (n, 3), their mean, the rows of their principal directions (3, 3), the last the plane's normal), for
    :func:`circle` and :func:`circle_fit`; DegenerateError when the points lie on a line."""
    P = np.asarray(points, dtype=float)
    c0 = P.mean(axis=0)
    _, s, vt = np.linalg.svd(P - c0, full_matrices=False)
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        raise DegenerateError("the samples are collinear: no circle (the hinge did not turn)")
    return P, c0, vt


def circle(points) -> tuple:
    """Centre, unit normal and radius of the circle through ≥ 3 points (least squares beyond 3): exact through 3, and
    beyond them the algebraic fit by mediating planes (each point's equal distance from the centre less the first's),
    which carries the first point's noise into every equation, so its residuals are not the least
    (:func:`circle_fit` gives the least-squares circle).

    Why kept for the hinge starts of ``fit`` and ``identify`` (:func:`identcheck.estimate.joint.posed_circle`): put
    in its place, the least-squares circle placed 5-15° hinges' starts a median 13 mm from the truth against 152 mm,
    but on a thigh posed along its own line (two markers and the hip) with one marker 30 ms late, ``diagnose`` then
    named an extra rotation of 61° before the delay, where from this start it names the delay alone: the whole-tree
    fit and its held-out calibrations rest on these starts, and a change of them needs a fresh validation."""
    P, c0, vt = _best_plane(points)
    n = vt[2]
    # centre: in the plane, equidistant from all points (mediating planes, least squares)
    A = np.vstack([2 * (P[1:] - P[0]), n])
    rhs = np.concatenate([np.sum(P[1:] ** 2, axis=1) - np.sum(P[0] ** 2), [n @ c0]])
    J = np.linalg.lstsq(A, rhs, rcond=None)[0]
    return J, n, float(np.linalg.norm(P - J, axis=1).mean())


CIRCLE_STEPS = 50
"""Gauss-Newton steps at most for a circle's geometric fit (:func:`circle_fit`); a few suffice from the algebraic start."""
CIRCLE_REACH = 100.0
"""A circle whose radius is more than this many times the extent of its points in their plane is a straight path
read as an arc (an arc of half a degree): the least-squares circle of a nearly straight noisy path heads for a line
(radii of 10⁷-10¹¹ mm on 2° arcs with 0.5 mm of noise), and no hinge is fixed by it (:func:`circle_fit` raises)."""


def circle_fit(points) -> tuple:
    """Centre, unit normal and radius of the circle through ≥ 3 points: exact through 3, and beyond them the least
    squares one, its plane the points' best (least-squares) plane and, in that plane, the circle whose distances to
    the projected points are least (Gauss-Newton from the algebraic fit about the points' mean, each step halved until
    it lowers the sum of squares). Raises DegenerateError for points on a line, or on an arc too straight to fix a
    circle (:data:`CIRCLE_REACH`).

    What ``skeleton`` measures a hinge's fit by (:func:`identcheck.infer.tree.small_fit`): the algebraic fit
    (:func:`circle`) carries its first point's noise into every equation, and a 350 mm arc of 90° with 0.5 mm of noise
    left it residuals of 10-17 mm RMS where the least-squares circle leaves 0.5."""
    P, c0, vt = _best_plane(points)
    n = vt[2]
    e1, e2 = vt[0], vt[1]
    uv = np.stack([(P - c0) @ e1, (P - c0) @ e2], axis=1)                  # the points in their plane, about the mean
    A = np.column_stack([2.0 * uv, np.ones(len(uv))])
    a, b, c = np.linalg.lstsq(A, np.sum(uv ** 2, axis=1), rcond=None)[0]   # |x|² = 2x·centre + c (Kåsa)
    centre = np.array([a, b])
    radius = float(np.sqrt(max(c + a * a + b * b, 0.0)))

    def cost(cen, r) -> float:
        return float(np.sum((np.linalg.norm(uv - cen, axis=1) - r) ** 2))

    now = cost(centre, radius)
    for _ in range(CIRCLE_STEPS):                                           # geometric: Σ(|x − centre| − r)² least
        d = uv - centre
        dist = np.linalg.norm(d, axis=1)
        if np.any(dist <= 0.0):
            break
        J = np.column_stack([-d / dist[:, None], -np.ones(len(uv))])        # ∂(|x − centre| − r)/∂(centre, r)
        step = np.linalg.lstsq(J, -(dist - radius), rcond=None)[0]
        t = 1.0
        while t >= 1.0 / 1024 and not cost(centre + t * step[:2], radius + t * float(step[2])) <= now:
            t /= 2.0
        if t < 1.0 / 1024:
            break                                                           # no step lowers it: a minimum
        centre, radius = centre + t * step[:2], radius + t * float(step[2])
        now = cost(centre, radius)
        if t * np.linalg.norm(step) <= 1e-12 * max(abs(radius), 1.0):
            break
    extent = float(np.max(np.ptp(uv, axis=0)))
    if abs(radius) > CIRCLE_REACH * extent:
        raise DegenerateError(f"the samples lie on a nearly straight path (a circle through them would have a radius "
                              f"{abs(radius):.3g}, over {CIRCLE_REACH:g} times their extent {extent:.3g}): no circle "
                              "(the hinge hardly turned)")
    J = c0 + centre[0] * e1 + centre[1] * e2
    return J, n, float(abs(radius))


def circle_deviations(points, centre, normal, radius: float | None = None) -> tuple:
    """(radial deviations (N,), out-of-plane deviations (N,), radius) of points (N, 3) from the circle about `centre`
    in the plane of unit `normal` (:func:`circle_fit`'s three values); `radius` None: the points' mean distance from
    the circle's axis. How far a path is from turning about one axis, in ``skeleton``'s small groups and in the
    one-axis test beside a two-marker segment (:func:`identcheck.bundle.practical.single_axis_by_circles`)."""
    w = np.asarray(points, dtype=float) - centre
    along = w @ normal
    radial = np.linalg.norm(w - along[:, None] * normal, axis=1)
    r = float(radial.mean()) if radius is None else float(radius)
    return radial - r, along, r


def _axis_distance(p, J, n) -> float:
    w = np.asarray(p) - J
    return float(np.linalg.norm(w - (w @ n) * n))


def _revolute_posed(parents, children) -> list:
    rot, a1, loc = _local_markers(parents)
    b = [to_local(rot, a1, c) for c in children]
    J, n, _ = circle(b[0])
    dist = {k: _axis_distance(p, J, n) for k, p in zip(_names("A", len(parents)), loc)}
    dist.update({k: float(np.mean([_axis_distance(x, J, n) for x in bk])) for k, bk in zip(_names("B", len(children)), b)})
    return [dist]


def _revolute21(a1, a2, b) -> list:
    local, h = pair_frame(a1, a2, b)
    res = revolute21.identify(local)
    return res.joints, float(np.mean(h))


def hinge_mismatch(j1, j2, sin=np.sin) -> tuple:
    """How far two markers' revolute (2,1) joints are from being one (2,2) joint.

    Returns (constants gap: max |Δd|, |Δr|, |Δα|; roll mismatch: max over samples |sin(Δθ/2)|;
    offset spread: max |sin((Δβ − Δβ₀)/2)|): a joint of both markers has the same (d, r, α), the same
    parent roll θ in every sample and a constant angle between the markers about the hinge.
    ``sin`` is ``numpy.sin`` for float joints or ``mpmath.sin`` for any-precision ones.
    """
    gap = max(abs(j1.d - j2.d), abs(j1.r - j2.r), abs(j1.alpha - j2.alpha))
    roll = max(abs(sin((a - b) / 2)) for a, b in zip(j1.theta, j2.theta))
    off = [b2 - b1 for b1, b2 in zip(j1.beta, j2.beta)]
    spread = max(abs(sin((o - off[0]) / 2)) for o in off)
    return gap, roll, spread


def _revolute2q(parents, children) -> list:
    """(2, q): each child marker's (2,1) joints; keep those that are one joint (:func:`hinge_mismatch`)."""
    per_marker = [_revolute21(parents[0], parents[1], c) for c in children]
    h = per_marker[0][1]
    out = []
    for j0 in per_marker[0][0]:
        chosen = [j0]
        for joints, _ in per_marker[1:]:
            match = None
            for j in joints:
                gap, roll, spread = hinge_mismatch(j0, j)
                if gap < ANGLE_TOL * (1 + h) and roll < ANGLE_TOL and spread < ANGLE_TOL:
                    match = j
            if match is None:
                break
            chosen.append(match)
        else:
            dist = {k: v for k, v in j0.marker_distances(h).items() if k != "B"}
            dist.update({f"B{i}": float(j.rho) for i, j in enumerate(chosen, 1)})
            out.append(dist)
    return out


def solve(joint: str, parents, children) -> list:
    """Every joint (as marker distances) that exact samples of a locally identifiable case admit.

    Parameters
    ----------
    joint : "revolute" | "spherical"
    parents, children : sequences of arrays (N, 3)
        World positions of each parent / child marker in N samples.
    """
    parents = [np.asarray(a, dtype=float) for a in parents]
    children = [np.asarray(b, dtype=float) for b in children]
    p, q = len(parents), len(children)
    if joint not in ("revolute", "spherical"):
        raise InputError(f"unknown joint type {joint!r} (revolute | spherical)")
    if p < q:
        return _swap(solve(joint, children, parents))
    if joint == "spherical":
        if p >= 3 and q >= 1:
            return _spherical_posed(parents, children)
        if (p, q) == (2, 2):
            l1, h = pair_frame(parents[0], parents[1], children[0])
            l2, _ = pair_frame(parents[0], parents[1], children[1])
            res = spherical22.identify(l1, l2)
            return [j.marker_distances(float(np.mean(h))) for j in res.joints]
    else:
        if p >= 3 and q >= 1:
            return _revolute_posed(parents, children)
        if p == 2 and q >= 1:
            return _revolute2q(parents, children)
    raise DegenerateError(f"{joint}({p},{q}) is not locally identifiable: no finite set of joints to solve for")
