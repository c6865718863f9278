"""``extra_dof``: a joint declared a hinge also turns about another axis.

Two hypotheses, both for a hinge (a ball joint has nothing to add):

- **a second rotation** about one axis perpendicular to the hinge that turns with the child (a knee's
  varus/valgus or axial play), its angle any smooth function of time
  (:func:`~identcheck.bundle.hypothesis.time_basis`). Detector: in every frame, the small rotation about
  the joint's centre that best explains the residual of the markers below the joint, seen in the hinge's
  own frame with its component about the hinge removed; their smooth part (in time) about each direction
  across the hinge, weighted by how far that direction moves the markers, picks the axis (a 2° search,
  then the axis is fitted). What tells this from soft tissue is what moves: a rotation
  moves every child marker rigidly about the joint, skin moves markers one by one on their segment.
  Augmentation: :class:`~identcheck.bundle.chain.Terms` ``rotations``, the angle's coefficients and the
  axis direction fitted with everything else, about the hinge's point nearest the markers
  (:func:`pivot_at_markers`). ``where`` gives the axis's angle to the child's long axis and the range.
  A second proposal for the same joint takes the axis across the first (two smooth axes of play: ``needs`` a
  third rotation, a place of its own); both axes across the hinge can also be proposed at once (``needs`` a second
  and a third rotation: a ball joint whose play is smooth, scored on the smooth rotations about the whole plane).
- **a ball joint**: the joint re-declared as the next type up, keeping its fitted motion as the starting
  point (two more angles per frame: it earns them only when the extra rotation is too rough for a smooth
  profile).

The selection makes either earn its parameters, and the joint must stay identifiable.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import convert_joint
from identcheck.errors import DegenerateError
from identcheck.bundle.model import Terms, forward, second_axis, second_rotations, tangents
from identcheck.bundle.hypothesis import time_basis
from identcheck.effects.base import Effect, Proposal
from identcheck.geometry.rotations import hinge_matrix, left_jacobian_times
from identcheck.simulate.rigid import smooth_profile
from identcheck.effects.injection import Change, cannot, extra_rotation_world, pick, rotations, subtree, subtree_columns, unit

NEXT_TYPE = {"revolute": "spherical"}


def off_axis_deg(h, joint: str) -> np.ndarray:
    """Angle between the hinge direction as carried by the parent and by the child, per frame (deg),
    from the segments' own rigid poses: zero for a true hinge."""
    from identcheck.estimate.obrien import joint_location
    from identcheck.bundle.chain import segment_frames
    frames = segment_frames(h.chain, h.data, only=(h.chain.parent[joint], h.chain.child[joint]))
    P, C = frames[h.chain.parent[joint]], frames[h.chain.child[joint]]
    fit = joint_location(P, C, hinge=True)
    a = np.einsum("fij,j->fi", P.R, fit.axis_parent)
    b = np.einsum("fij,j->fi", C.R, fit.axis_child)
    return np.rad2deg(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))


def pivot_at_markers(chain, state, joint: str, terms: Terms | None = None):
    """The same rigid state with the hinge's point (``c_parent``, ``c_child``) moved along its axis to the point
    nearest the mean of both segments' markers (seen from the parent): for a rigid hinge where on its axis
    the point sits is a free choice, but a second rotation turns about it, and a knee's play is about the knee,
    not about wherever the hinge fit left its point (hundreds of millimetres away along the axis). A hinge that
    already turns about a second axis (in `terms`) keeps its point: the fit has placed it, and moving it would move
    the markers."""
    s = state.copy()
    if terms is not None and any(j == joint for j, _, _ in terms.rotations):
        return s
    P, C = chain.parent[joint], chain.child[joint]
    a = s.axis[joint]
    rel = hinge_matrix(a, s.theta[joint]) @ s.rest[joint]
    pts = [s.local[chain.seg_markers[P]]] if len(chain.seg_markers[P]) else []
    if len(chain.seg_markers[C]):
        child = np.einsum("fij,mj->fmi", rel, s.local[chain.seg_markers[C]] - s.c_child[joint])
        pts.append((child.mean(axis=0) + s.c_parent[joint]))
    if not pts:
        return s
    along = float((np.concatenate(pts).mean(axis=0) - s.c_parent[joint]) @ a)
    s.c_parent[joint] = s.c_parent[joint] + along * a
    s.c_child[joint] = s.c_child[joint] + along * (s.rest[joint].T @ a)
    return s


def frame_rotations(hyp, joint: str, pivoted=None) -> tuple[np.ndarray, np.ndarray]:
    """In every frame, the small rotation (rad, world) about the joint's centre that best explains the
    residual of the markers below it, ω = L⁻¹ Σ d × r with L = Σ (|d|² I − d dᵀ), d each marker's offset
    from the centre and r its residual; and L itself (how strongly each rotation moves the markers).
    (F, 3) and (F, 3, 3); ω is zero where fewer than two such markers are seen. `pivoted`: the state from
    :func:`pivot_at_markers`, when the caller has it already."""
    ch = hyp.chain
    idx = ch.downstream[joint]
    pivoted = pivot_at_markers(ch, hyp.fit.state, joint, hyp.terms) if pivoted is None else pivoted
    _, _, centre, _ = forward(ch, hyp.terms, pivoted)
    seen = (hyp.weights[:, idx] > 0) & np.all(np.isfinite(hyp.data[:, idx]), axis=2)
    r = np.where(seen[..., None], np.nan_to_num(hyp.residuals()[:, idx]), 0.0)
    d = np.where(seen[..., None], hyp.fit.pred[:, idx] - centre[joint][:, None], 0.0)
    L = np.einsum("fm,ij->fij", np.sum(d * d, axis=2), np.eye(3)) - np.einsum("fmi,fmj->fij", d, d)
    b = np.sum(np.cross(d, r), axis=1)
    ok = seen.sum(axis=1) >= 2
    out = np.zeros_like(b)
    out[ok] = np.linalg.solve(L[ok] + 1e-9 * np.eye(3), b[ok][..., None])[..., 0]
    L[~ok] = 0.0
    return out, L


def fitted_betas(hyp, joint: str) -> list:
    """The angles β of the second rotations already fitted for `joint`."""
    n0 = len(hyp.terms.markers) + len(hyp.terms.centres)
    return [b + float(p[-1, 0]) for (j, _, b), p in zip(hyp.terms.rotations, hyp.fit.state.term_params[n0:]) if j == joint]


def second_rotation_proposals(ctx, hyp, joint: str, name: str, taken: list = ()) -> list:
    """The second-rotation hypothesis for a hinge (see the module docstring), as a proposal whose strength is
    the BIC gain of the smooth part of the per-frame rotations about the best axis in the plane perpendicular
    to the hinge (searched every 2°, each direction weighted by how far it moves the markers; across the axis
    already `taken` when there is one)."""
    ch = hyp.chain
    s = pivot_at_markers(ch, hyp.fit.state, joint, hyp.terms)
    omega, L = frame_rotations(hyp, joint, s)
    frame = np.einsum("fij,fjk->fik", hyp.fit.seg_R[ch.parent[joint]], hinge_matrix(s.axis[joint], s.theta[joint]))
    E = np.stack(tangents(s.axis[joint]), axis=1)                   # (3, 2): the plane, in the turning frame
    v = second_rotations(hyp.terms, s).get(joint)
    if v is None:
        E = np.broadcast_to(E, (len(frame), 3, 2))
    else:                   # a rotation added to one already fitted turns the child about J_l(v) e, not e
        E = np.stack([left_jacobian_times(v, e) for e in E.T], axis=2)             # (F, 3, 2)
    W = np.einsum("fij,fjk->fik", frame, E)                         # (F, 3, 2): the plane's axes in the world
    plane = np.einsum("fji,fj->fi", W, omega)                       # (F, 2)
    lever = np.einsum("fji,fjk,fkl->fil", W, L, W)                   # (F, 2, 2)
    moved = np.any(omega != 0, axis=1)
    basis = time_basis(len(plane), ctx.rate_hz)
    if moved.sum() <= basis.shape[1] + 10:
        return []
    coef = np.linalg.lstsq(basis[moved], plane[moved] - plane[moved].mean(axis=0), rcond=None)[0]
    smooth = basis @ coef                                           # (F, 2)
    # a joint that already turns about one axis can take only the axis across it
    betas = np.array([taken[0] + np.pi / 2]) if taken else np.deg2rad(np.arange(0.0, 180.0, 2.0))
    e = np.stack([np.cos(betas), np.sin(betas)], axis=1)            # (B, 2)
    explained = np.einsum("fb,fij,bi,bj->b", (smooth @ e.T) ** 2, lever, e, e)
    k = int(np.argmax(explained))
    beta = float(betas[k])
    gain = ctx.bic_gain(float(explained[k]) * ctx.smooth_share, basis.shape[1] + 1)
    # the rotation across one already adopted is a third: a place of its own (named alike, the two had been one
    # place, and a ball knee's third rotation was never tried once an oblique second had been adopted)
    where = {"joint": joint, "declared": ch.types[joint],
             "needs": "a third rotation" if taken else "a second rotation"}
    where.update(axis_description(ch, s, joint, beta))
    out = [Proposal(name, where, gain, {"joint": joint, "basis": basis, "beta": beta})] if gain > 0 else []
    if not taken:
        # both axes across the hinge at once, each with a smooth angle: a ball joint whose play is smooth. One axis at
        # a time, the best single axis can score below skin terms that take up the play about both (held-out draw
        # 45, a knee turning like a ball in gait: one axis 128 114, skin on the thigh cluster 133 895, the two axes
        # never fitted together)
        both = float(np.einsum("fi,fij,fj->", smooth, lever, smooth))
        gain2 = ctx.bic_gain(both * ctx.smooth_share, 2 * basis.shape[1])
        if gain2 > 0:
            out.append(Proposal(name, {"joint": joint, "declared": ch.types[joint],
                                       "needs": "a second and a third rotation"},
                                gain2, {"joint": joint, "basis": basis, "betas": [beta, beta + np.pi / 2]}))
    return out


def axis_description(chain, state, joint: str, beta: float) -> dict:
    """Where the second rotation's axis points: its angle to the child's long axis (the pivot to the child's
    markers' mean, across the hinge), and the name that angle suggests."""
    s = pivot_at_markers(chain, state, joint)
    a = s.axis[joint]
    child = chain.seg_markers[chain.child[joint]]
    if not len(child):
        return {}
    long_axis = s.rest[joint] @ (s.local[child].mean(axis=0) - s.c_child[joint])
    long_axis = long_axis - (long_axis @ a) * a
    tilt = float(np.degrees(np.arccos(min(abs(second_axis(a, beta) @ long_axis)
                                          / max(np.linalg.norm(long_axis), 1e-12), 1.0))))
    return {"about": "the child's long axis (axial rotation)" if tilt < 30 else
            "an axis across the child's long axis (varus/valgus)" if tilt > 60 else "an oblique axis",
            "angle_to_long_axis_deg": round(tilt, 1)}


def _own_params(hyp, term) -> np.ndarray:
    """The fitted parameters of hypothesis `hyp`'s term `term` (the very tuple an ``apply`` gave it)."""
    return next(q for t, q in zip(hyp.terms.ordered(), hyp.fit.state.term_params) if t is term)


class ExtraDof(Effect):
    name = "extra_dof"
    max_proposals = 3
    always_fit = True
    """Neither strength estimates the fitted score: the ball's is a bound (all the residual below the joint), and
    the second rotation's reads the per-frame rotations the rigid fit left, after the hinge's axis and angles took
    their part (a knee's 11° varus/valgus wobble in gait under AR(1) noise: estimated 2 291, fitted 34 829, where
    skin on the thigh scored 23 933 and was named instead, the rotation never fitted)."""

    def inject(self, sim, rng) -> Change:
        """A hinge also turns about an axis b perpendicular to its own (in the parent frame), by a
        smooth angle of 12-25 deg peak to peak; the child subtree turns about the joint centre."""
        model = sim.model
        hinges = [j for j in model.joint_order if model.joints[j].type == "revolute"]
        if not hinges:
            raise cannot(self.name, "it adds a second rotation to a revolute joint, and the model has none")
        options = [j for j in hinges if subtree_columns(sim, model.joints[j].child)]
        if not options:
            raise cannot(self.name, "no revolute joint has a marker on its child segment or below it")
        joint = pick(rng, options)
        hinge = sim.truth.joints[joint].axis_parent
        b = rng.normal(size=3)
        b = unit(b - (b @ hinge) * hinge)
        rom = rng.uniform(12.0, 25.0)
        psi = rom * smooth_profile(rng, sim.clean.times, 1)[:, 0]
        turn = extra_rotation_world(rotations(sim, model.joints[joint].parent), b, psi)
        pivot = sim.truth.centre_world(joint)[:, None]
        clean = sim.clean.as_array()
        cols = subtree_columns(sim, model.joints[joint].child)
        clean[:, cols] = pivot + np.einsum("fij,fmj->fmi", turn, clean[:, cols] - pivot)
        return Change(where={"joint": joint},
                       params={"extra_rom_deg": rom, "axis_parent": b, "angle_deg": psi,
                               "moved_segments": subtree(model, model.joints[joint].child)},
                       clean=clean)

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        res = np.where((hyp.weights > 0)[..., None], hyp.residuals(), 0.0)
        out = []
        turned = [j for j, _, _ in hyp.terms.rotations]
        for j in ch.joints:
            if ch.types[j] not in NEXT_TYPE:
                continue
            if turned.count(j) < 2:          # a second axis of play: the hinge is then a ball with smooth play
                out.extend(second_rotation_proposals(ctx, hyp, j, self.name, fitted_betas(hyp, j)))
            if j not in turned:
                # at most all the residual below the joint, less two angles per frame
                rss = float(np.sum(res[:, ch.downstream[j]] ** 2)) / ctx.noise.sigma_mm ** 2
                bound = rss - 2 * int(np.any(hyp.weights[:, ch.downstream[j]] > 0, axis=1).sum()) * np.log(ctx.n_obs)
                out.append(Proposal(self.name, {"joint": j, "declared": ch.types[j], "needs": NEXT_TYPE[ch.types[j]]},
                                    bound, {"joint": j}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        j = proposal.payload["joint"]
        if "betas" in proposal.payload:
            # two axes at once: they span the plane across the hinge whatever their angles (Terms.redundant leaves
            # those two directions out of the count), so no axis is chosen and nothing more is charged
            added = [(j, proposal.payload["basis"], b) for b in proposal.payload["betas"]]
            new = hyp.refit(terms=hyp.terms + Terms(rotations=added),
                            state=pivot_at_markers(hyp.chain, hyp.fit.state, j, hyp.terms), effect=proposal,
                            max_iter=12)
            ranges = [round(float(np.rad2deg(np.ptp(t[1] @ _own_params(new, t)[:-1, 0]))), 1) for t in added]
            proposal.where["range_deg"] = ranges
            return new
        if "basis" in proposal.payload:
            term = (j, proposal.payload["basis"], proposal.payload["beta"])
            new = hyp.refit(terms=hyp.terms + Terms(rotations=[term]),
                            state=pivot_at_markers(hyp.chain, hyp.fit.state, j, hyp.terms),
                            extra_params=1, effect=proposal, max_iter=12)
            p = _own_params(new, term)
            proposal.where["range_deg"] = round(float(np.rad2deg(np.ptp(term[1] @ p[:-1, 0]))), 1)
            proposal.where.update(axis_description(new.chain, new.fit.state, j, term[2] + float(p[-1, 0])))
            return new
        chain, _ = convert_joint(hyp.chain, hyp.fit.state, j, NEXT_TYPE[hyp.chain.types[j]])
        # a fresh start: the hinge fit bent every constant to absorb the missing rotation
        new = hyp.restarted(ctx, chain=chain, effect=proposal, max_iter=12)
        if new is None:
            raise DegenerateError(f"joint {j!r} as {chain.types[j]}: its samples cannot start a fit")
        return new

    def evidence(self, ctx, before, after, proposal) -> dict:
        j = proposal.payload["joint"]
        ch = before.chain
        if min(len(ch.seg_markers[ch.parent[j]]), len(ch.seg_markers[ch.child[j]])) < 3:
            return {}            # a segment its own markers cannot pose shows no hinge direction of its own
        off = off_axis_deg(before, j)
        return {"x": np.arange(len(off)), "x_label": "frame", "y": off,
                "y_label": f"{j}: hinge direction from thigh vs from shank (deg)".replace(
                    "thigh", before.chain.parent[j]).replace("shank", before.chain.child[j]), "kind": "series"}
