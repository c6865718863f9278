"""``extra_dof``: a joint declared a hinge also turns about another axis.

Two hypotheses, both for a hinge (a ball joint has nothing to add):

- **a second rotation** about one axis perpendicular to the hinge that turns with the child (a knee's
  varus/valgus or axial play), its angle any smooth function of time
  (:func:`~identcheck.bundle.hypothesis.time_basis`). Detector: the score test of that term at the rigid fit (what
  the refit would explain to first order, the hinge's and the other joints' angles and every constant free to take
  their part), about the best axis across the hinge and the best pivot along it (a 4° and 25 mm search; the fit
  then places both), with the knots of the angle's functions as far apart as the play allows (0.2 to 2 s, the one
  the estimate says gains most). What tells this from soft tissue is what moves: a rotation
  moves every child marker rigidly about the joint, skin moves markers one by one on their segment.
  Augmentation: :class:`~identcheck.bundle.model.Terms` ``rotations``, the angle's coefficients and the
  axis direction fitted with everything else, about the pivot the detector found (from the hinge's point nearest
  the markers, :func:`pivot_at_markers`). ``where`` gives the axis's angle to the child's long axis, the range and
  the knot spacing.
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
from identcheck.bundle.score_selection import choice_params
from identcheck.bundle.score_test import modulated_score_moments, quadratic_form
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


def pivot_at_markers(chain, state, joint: str, terms: Terms | None = None, shift_mm: float = 0.0):
    """The same rigid state with the hinge's point (``c_parent``, ``c_child``) moved along its axis to the point
    nearest the mean of both segments' markers (seen from the parent), and `shift_mm` further along the axis (where
    a detector found the play turns: :data:`PIVOT_SHIFTS_MM`): for a rigid hinge where on its axis
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
    along = float((np.concatenate(pts).mean(axis=0) - s.c_parent[joint]) @ a) + shift_mm
    s.c_parent[joint] = s.c_parent[joint] + along * a
    s.c_child[joint] = s.c_child[joint] + along * (s.rest[joint].T @ a)
    return s


PIVOT_SHIFTS_MM = np.arange(-150.0, 151.0, 25.0)
"""Where along the hinge the detector lets a second rotation turn, from the hinge's point nearest the markers
(:func:`pivot_at_markers`): a knee's play turns about the knee, and the markers' point can be a cluster's width to
its side. On a knee with slow varus/valgus play under AR(1) noise (held-out draw 66, trial 3) the single axis's
estimated gain read −69 about the markers' point and 260 50 mm medially, where the refit (which places the pivot
itself) gained 265."""
MAX_PLAY_DEG = 90.0
"""A hinge's fitted turn about a second axis ranging over more than this is not play about that axis (the widest a
human hinge allows, a flexed knee's axial rotation, is about half of it): the rotation's shape is taking up something
else, such as a single marker's skin motion on a segment its own markers cannot pose (the real right knee with one
shank marker: an axial 'play' of 130°)."""
KNOT_SPACINGS_S = (0.2, 0.5, 1.0, 2.0)
"""The knot spacings (s) of the second rotation's smooth angle the detector compares (the criterion's choice, by
its estimated gain): play as fast as the joint's own motion needs the finest, at 66 parameters on a 13 s trial; slow
play pays for no more than it uses (a knee's slow axial play of 4.7 mm under AR(1) noise, draw 65 trial 35, had
fitted at -184 with the finest alone, and a slip on a shank marker was named)."""
BETA_STEP_DEG = 4.0
"""The detector's search for the axis across the hinge: every this many degrees (the fit then places it)."""


def turn_carriers(hyp, joint: str, pivoted) -> tuple[list, np.ndarray]:
    """The marker displacements (F, M, 3 each) of a unit rotation about each of the two axes across the hinge, in
    the hinge's turned frame (a rotation added to one already fitted turns the child about ``J_l(v) e``, not e), about
    the joint's point in `pivoted`; and of the same rotations about a point 1 mm further along the hinge (their
    difference, the translation across the axis per unit angle): a pivot shifted by s moves each carrier by s times
    its difference. Every marker below the joint moves; the others do not."""
    ch = hyp.chain
    idx = ch.downstream[joint]
    _, _, centre, _ = forward(ch, hyp.terms, pivoted)
    frame = np.einsum("fij,fjk->fik", hyp.fit.seg_R[ch.parent[joint]],
                      hinge_matrix(pivoted.axis[joint], pivoted.theta[joint]))
    E = np.stack(tangents(pivoted.axis[joint]), axis=1)            # (3, 2): the plane, in the turning frame
    v = second_rotations(hyp.terms, pivoted).get(joint)
    if v is None:
        E = np.broadcast_to(E, (len(frame), 3, 2))
    else:
        E = np.stack([left_jacobian_times(v, e) for e in E.T], axis=2)             # (F, 3, 2)
    W = np.einsum("fij,fjk->fik", frame, E)                         # (F, 3, 2): the plane's axes in the world
    along = frame @ pivoted.axis[joint]                             # (F, 3): the hinge in the world
    offset = hyp.fit.pred[:, idx] - centre[joint][:, None]
    turns, shifts = [], []
    for e in range(2):
        for out, field in ((turns, np.cross(W[:, None, :, e], offset)),
                           (shifts, np.broadcast_to(-np.cross(W[:, :, e], along)[:, None], offset.shape))):
            full = np.zeros(hyp.data.shape)
            full[:, idx] = field
            out.append(full)
    return turns + shifts, W


def _at_shift(n, G, K: int, shift: float):
    """The moments (n, G) of the two turns about a pivot `shift` mm along the hinge, from those of
    :func:`turn_carriers`' four carriers (turns then shifts, K functions each): ``T n`` and ``T G Tᵀ`` with
    ``T = [[1, 0, shift, 0], [0, 1, 0, shift]] ⊗ I_K``, taken block by block. (Formed as a (2K, 4K) matrix, T cost
    K³ a shift: the functions' count grows with the trial's length, and on an 8000-frame trial, 400 functions at the
    finest knots, the 13 shifts had taken 1.7 of its 11.7 s.)"""
    turn, along = [slice(0, K), slice(K, 2 * K)], [slice(2 * K, 3 * K), slice(3 * K, 4 * K)]
    n_s = np.concatenate([n[t] + shift * n[a] for t, a in zip(turn, along)])
    G_s = np.block([[G[t, u] + shift * (G[a, u] + G[t, b]) + shift * shift * G[a, b]
                     for u, b in zip(turn, along)] for t, a in zip(turn, along)])
    return n_s, G_s


def _about_axis(n2, G2, K: int, betas: np.ndarray, absorbed=None):
    """The statistic ``nᵀ G⁺ n`` of one turn about each axis at angle β across the hinge (from the two axes'
    moments), for every β of `betas` at once; without the profile `absorbed` (K,) when given."""
    c, s = np.cos(betas), np.sin(betas)
    n = c[:, None] * n2[None, :K] + s[:, None] * n2[None, K:]
    G = (c ** 2)[:, None, None] * G2[:K, :K] + (c * s)[:, None, None] * (G2[:K, K:] + G2[K:, :K]) \
        + (s ** 2)[:, None, None] * G2[K:, K:]
    P = _without(absorbed, K)
    n, G = n @ P, P @ G @ P
    return np.einsum("bk,bkl,bl->b", n, np.linalg.pinv(G, rcond=1e-10, hermitian=True), n)


def _without(absorbed, K: int) -> np.ndarray:
    """The projection (K, K) of the angle's coefficients off the profile `absorbed` (the identity without one)."""
    if absorbed is None or not np.linalg.norm(absorbed) > 0:
        return np.eye(K)
    u = np.asarray(absorbed, dtype=float) / np.linalg.norm(absorbed)
    return np.eye(K) - np.outer(u, u)


def _fitted_rotations(hyp, joint: str) -> list:
    """(β as proposed, fitted parameters: the angle's coefficients then β's change) of each second rotation fitted
    for `joint`, in order."""
    n0 = len(hyp.terms.markers) + len(hyp.terms.centres)
    return [(b, p) for (j, _, b), p in zip(hyp.terms.rotations, hyp.fit.state.term_params[n0:]) if j == joint]


def fitted_profile(hyp, joint: str) -> np.ndarray:
    """The coefficients (K,) of the angle of the second rotation fitted for `joint` (the first, if several)."""
    return _fitted_rotations(hyp, joint)[0][1][:-1, 0]


def fitted_betas(hyp, joint: str) -> list:
    """The angles β of the second rotations already fitted for `joint`."""
    return [b + float(p[-1, 0]) for b, p in _fitted_rotations(hyp, joint)]


def _best_turns(ctx, hyp, moments, basis, carriers, shifts, betas, charged: int, absorbed=None) -> tuple:
    """The estimated gains of one turn (best axis) and of two, with angles in `basis`, about the pivot shift where two
    turns explain most, from the carriers' moments (:func:`turn_carriers`, :func:`modulated_score_moments`):
    ``((gain, shift, β), (gain, shift))``, each statistic counted at the share of the fitted turn's sum of squares the
    criterion keeps (:meth:`~identcheck.bundle.hypothesis.Context.kept_share`), each charged as its refit is (`charged`
    parameters beyond the angles' functions). (Where the knee turns is one place for either; the axis is searched
    there alone, every β at every shift having cost a second a round.) `absorbed`: coefficients (K,) of a profile
    the fit already takes up about every axis searched (a third rotation's, the second's own profile: turning it is
    the second's angle β), left out of the statistic (rounding leaves its eigenvalue above the cutoff, and its
    inverse had read a third rotation 100 times above what its refit gained)."""
    n, G = moments
    K = basis.shape[1]
    both = max((quadratic_form(*_at_shift(n, G, K, float(shift))), float(shift)) for shift in shifts)
    stats = _about_axis(*_at_shift(n, G, K, both[1]), K, betas, absorbed)
    k = int(np.argmax(stats))
    single = (float(stats[k]), both[1], float(betas[k]))

    def kept(stat, shift, directions):
        n2, G2 = _at_shift(n, G, K, shift)
        # (d·K, 2K): the turns' own fields (one turn's without the absorbed profile)
        T = np.kron(directions, _without(absorbed, K) if len(directions) == 1 else np.eye(K))
        coef = np.linalg.pinv(T @ G2 @ T.T, rcond=1e-10, hermitian=True) @ (T @ n2)
        angle = basis @ coef.reshape(-1, K).T @ directions          # (F, 2): the turn fitted about each axis
        turned = np.einsum("fe,efmi->fmi", angle, np.stack(carriers[:2]) + shift * np.stack(carriers[2:]))
        return stat * ctx.kept_share(turned, hyp.weights)

    stat, shift, beta = single
    gain = ctx.bic_gain(kept(stat, shift, np.array([[np.cos(beta), np.sin(beta)]])), K + 1 + charged)
    gain2 = ctx.bic_gain(kept(both[0], both[1], np.eye(2)), 2 * K + charged - 1)
    return (gain, shift, beta), (gain2, both[1])


def second_rotation_proposals(ctx, hyp, joint: str, name: str, taken: list = ()) -> list:
    """The second-rotation hypothesis for a hinge (see the module docstring), as a proposal whose strength is
    what the refit with it would gain to first order: the score test of the rotation's fields (a smooth angle,
    :func:`~identcheck.bundle.hypothesis.time_basis` with knots every one of :data:`KNOT_SPACINGS_S`, times the turn
    of every marker below the joint, :func:`~identcheck.bundle.score_test.modulated_score_moments`), about the best
    axis across the hinge (searched every :data:`BETA_STEP_DEG`; across the axis already `taken` when there is one)
    and the best pivot along it (:data:`PIVOT_SHIFTS_MM`; a hinge already turned keeps its pivot), the knot spacing
    the one whose estimate gains most (``where["knot_spacing_s"]``).

    The per-frame rotations the rigid fit leaves, regressed on the same functions, read 7 times less than the refit
    gained on draw 66's trial 3 (140 against 978 explained), and the rotation was never fitted: the hip's angles and
    the hinge's take up part of the play, and the part left is not the play's own size."""
    ch = hyp.chain
    pivoted = pivot_at_markers(ch, hyp.fit.state, joint, hyp.terms)
    carriers, W = turn_carriers(hyp, joint, pivoted)
    seen = int(np.any(hyp.weights[:, ch.downstream[joint]] > 0, axis=1).sum())
    # a third rotation's angle has the second's functions: the two axes then span the plane across the hinge, whatever
    # their angles (Terms.redundant)
    bases = [(None, next(b for j, b, _ in hyp.terms.rotations if j == joint))] if taken else \
        [(sp, time_basis(len(W), ctx.rate_hz, sp)) for sp in KNOT_SPACINGS_S]
    bases = [(spacing, b) for spacing, b in bases if b.shape[1] and seen > b.shape[1] + 10]
    if not bases:
        return []
    moments = modulated_score_moments(hyp.fit, hyp.weights, hyp.residuals(), carriers, [b for _, b in bases],
                                      hyp.projection)
    shifts = [0.0] if taken else PIVOT_SHIFTS_MM
    # a joint that already turns about one axis can take only the axis across it
    betas = np.array([taken[0] + np.pi / 2]) if taken else np.deg2rad(np.arange(0.0, 180.0, BETA_STEP_DEG))
    # the refit of one turn charges one parameter beyond its angle's functions and β (apply), and one more for the
    # knots chosen among several (the extended criterion's charge, score_selection.choice_params); a third rotation's
    # refit two fewer: with it the two axes' angles change no prediction (Terms.redundant)
    choice = choice_params(len(bases), 1, np.log(ctx.n_obs)) if len(bases) > 1 else 0
    absorbed = fitted_profile(hyp, joint) if taken else None
    found = [(_best_turns(ctx, hyp, m, b, carriers, shifts, betas, -1 if taken else 1 + choice, absorbed), sp, b)
             for m, (sp, b) in zip(moments, bases)]
    (gain, shift, beta), spacing, basis = max(((one, sp, b) for (one, _), sp, b in found), key=lambda x: x[0][0])
    # the rotation across one already adopted is a third: a place of its own (named alike, the two had been one
    # place, and a ball knee's third rotation was never tried once an oblique second had been adopted)
    where = {"joint": joint, "declared": ch.types[joint],
             "needs": "a third rotation" if taken else "a second rotation"}
    where.update(axis_description(ch, pivoted, joint, beta))
    if spacing is not None:
        where["knot_spacing_s"] = spacing
    out = [Proposal(name, where, gain, {"joint": joint, "basis": basis, "beta": beta, "shift_mm": shift,
                                        "choice_params": choice})] if gain > 0 else []
    if not taken:
        # both axes across the hinge at once, each with a smooth angle: a ball joint whose play is smooth. One axis at
        # a time, the best single axis can score below skin terms that take up the play about both (held-out draw
        # 45, a knee turning like a ball in gait: one axis 128 114, skin on the thigh cluster 133 895, the two axes
        # never fitted together)
        (gain2, shift2), spacing2, basis2 = max(((two, sp, b) for (_, two), sp, b in found), key=lambda x: x[0][0])
        if gain2 > 0:
            out.append(Proposal(name, {"joint": joint, "declared": ch.types[joint],
                                       "needs": "a second and a third rotation",
                                       "knot_spacing_s": spacing2},
                                gain2, {"joint": joint, "basis": basis2, "betas": [beta, beta + np.pi / 2],
                                        "shift_mm": shift2, "choice_params": choice}))
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
    """The ball's strength is a bound (all the residual below the joint), not an estimate of its score. The second
    rotation's had been read from the per-frame rotations the rigid fit left, after the hinge's axis and angles took
    their part (a knee's 11° varus/valgus wobble in gait under AR(1) noise: estimated 2 291, fitted 34 829, where
    skin on the thigh scored 23 933 and was named instead, the rotation never fitted); it is now a score test, but a
    first-order one: fitted, the pivot and the axis move."""

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
        screwed = {j for j, _ in hyp.terms.screws}
        for j in ch.joints:
            if ch.types[j] not in NEXT_TYPE:
                continue
            if turned.count(j) < 2:          # a second axis of play: the hinge is then a ball with smooth play
                out.extend(second_rotation_proposals(ctx, hyp, j, self.name, fitted_betas(hyp, j)))
            # a hinge whose centre moves along its axis (a screw) keeps the axis the screw runs along: its play is
            # looked for as second rotations (declared a ball, its screw had no axis left to run along)
            if j not in turned and j not in screwed:
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
                            state=pivot_at_markers(hyp.chain, hyp.fit.state, j, hyp.terms,
                                                   proposal.payload.get("shift_mm", 0.0)),
                            extra_params=proposal.payload.get("choice_params", 0), effect=proposal, max_iter=12)
            ranges = [round(float(np.rad2deg(np.ptp(t[1] @ _own_params(new, t)[:-1, 0]))), 1) for t in added]
            proposal.where["range_deg"] = ranges
            return new
        if "basis" in proposal.payload:
            term = (j, proposal.payload["basis"], proposal.payload["beta"])
            new = hyp.refit(terms=hyp.terms + Terms(rotations=[term]),
                            state=pivot_at_markers(hyp.chain, hyp.fit.state, j, hyp.terms,
                                                   proposal.payload.get("shift_mm", 0.0)),
                            extra_params=1 + proposal.payload.get("choice_params", 0), effect=proposal,
                            max_iter=12)
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

    def implausible(self, proposal) -> str:
        """A second (or third) rotation fitted over more than :data:`MAX_PLAY_DEG` is not play; a ball joint has no
        such bound (it is the joint's own motion)."""
        ranges = np.atleast_1d(proposal.where.get("range_deg", []))
        if not len(ranges) or float(np.max(ranges)) <= MAX_PLAY_DEG:
            return ""
        return (f"its second rotation ranges over {float(np.max(ranges)):.0f} deg (> {MAX_PLAY_DEG:g} deg): not play "
                f"about a second axis")

    def evidence(self, ctx, before, after, proposal) -> dict:
        j = proposal.payload["joint"]
        ch = before.chain
        if min(len(ch.seg_markers[ch.parent[j]]), len(ch.seg_markers[ch.child[j]])) < 3:
            return {}            # a segment its own markers cannot pose shows no hinge direction of its own
        off = off_axis_deg(before, j)
        return {"x": np.arange(len(off)), "x_label": "frame", "y": off,
                "y_label": f"{j}: hinge direction from thigh vs from shank (deg)".replace(
                    "thigh", before.chain.parent[j]).replace("shank", before.chain.child[j]), "kind": "series"}
