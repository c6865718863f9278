"""Diagnose a trial: fit the rigid-joint model, and while the gap exceeds the noise floor (or an effect is
found decisively all the same), let every named effect propose where it acts, fit the proposals, and adopt
the one that earns its parameters best and keeps the joints identifiable (an error the data show without the joint
model, a label swap whose exchanged distances fit, comes before the rest once it earns its parameters: skin terms can
absorb part of a swap and be adopted first, after which the swap is never named); when none is left to adopt, drop the
earlier effects that later ones made unnecessary (:mod:`identcheck.diagnose.backward`) and, if any was dropped, search
on; report the effects in order with the gap before and after each. A proposal whose effect has a cheaper first fit
(:meth:`identcheck.effects.base.Effect.screen`: Newton on a delay until it settles) that scores below a tenth of the
round's best is left there, and fitted in full only if the round adopts nothing or a candidate well below its best
(:func:`choose`).
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from identcheck.skeleton import Skeleton
from identcheck.errors import (DegenerateError, GrossErrorWarning, InputError, SubjectPrefixWarning,
                               UnitsWarning)
from identcheck.io.jsonable import plain
from identcheck.io.model import left_out_reasons, refuse_exported_points, unposed_root
from identcheck.io.trc import centimetres_suspected, scaled_up_suspected
from identcheck.bundle.anatomical_angles import ROM_SHARE, motion_ranges
from identcheck.bundle.chain import fit_chain, information
from identcheck.bundle.stuck_frames import restarted_stuck_frames
from identcheck.bundle.gauge import turning_blocks
from identcheck.bundle.model import Terms, null_count
from identcheck.bundle.honest import assess, joint_answer, posed_by_itself
from identcheck.bundle.start import better_start, start_state
from identcheck.bundle.uncertainty import distance_gradients, gauge_free_inverse
from identcheck.effects.registry import EFFECTS
from identcheck.bundle.hypothesis import POLISH_ITER, Context, Hypothesis, consistency, score
from identcheck.diagnose.backward import Adopted, Redundant, redundant
from identcheck.estimate.noise import noise_floor
from identcheck.estimate.screen_findings import with_screen_findings
from identcheck.estimate.spikes import without_spikes
from identcheck.progress import Progress

log = logging.getLogger("identcheck")

MAX_STEPS = 4
SKIP_RATIO = 10.0
"""Proposals are fitted strongest first. Every effect's strongest place is fitted whenever its detector clears
the bar: effects are compared by their fitted scores, never by their detectors' estimates, which are not on one
scale (a hip centre pistoning in the pelvis: the markers' mean residual seen from the pelvis estimated 1 816
where the fit scored 22 930, and skin on the thigh, estimated 5 020, scored 20 013 and was named instead). An
effect's further places are not fitted this round when their strength is below 1/SKIP_RATIO of the best score
fitted so far, unless the effect leads (a delay's linearised detector cannot tell which segment lags when the
lag is several frames) or it or the proposal is marked ``always_fit`` (a swap's strength is read from distances,
not from the residual; a hinge's extra rotation's are a bound and a first-order reading; a marker's delay read from
its distances to its segment-mates). Once the best so far is at least :data:`SCREEN_FROM`, a proposal that is fitted
goes no further than its effect's screen (:meth:`identcheck.effects.base.Effect.screen`) while that scores below
1/SKIP_RATIO of the best (:data:`COMPLETE_SHARE` says when it is fitted in full after all)."""
BASE_ITER = 40         # the rigid fit of data an effect corrupts creeps on for long; its gap is settled by then
CREEP_ITER = 12
"""Iterations of the null refit each round: what a candidate's refit gains by iterating on, without its
effect, is not the effect's (:func:`creep`)."""
DECISIVE_GAIN = 50.0
"""A gap the consistency test passes may still hide an effect the criterion finds decisively (a slip under
strongly correlated noise: the test's allowance for the uncertain noise level is wide); an effect whose gain exceeds
this is adopted even then (the gain is 2 ln of a Bayes factor: 50 is far beyond 'very strong'). The bar is on the
fitted gain: a proposal of a nested effect (:attr:`identcheck.effects.base.Effect.nested`) is fitted whenever its
detector's estimate earns its parameters at all, since the estimates are first order and read low (a knee rolling
back 10.7 mm in gait, on a trial the test passed: estimated 25, fitted 247; a hip pistoning under correlated noise:
28 and 94). An effect acting on a few samples (:attr:`identcheck.effects.base.Effect.sparse`: gross errors) is held
to :data:`EQUIVALENT_GAIN` instead (:func:`bar_for`)."""
EQUIVALENT_GAIN = 10.0
EQUIVALENT_FRACTION = 0.02
"""Two effects whose scores differ by less than the larger of these (criterion units, fraction of the score)
explain the trial equally well: the report names both (``indistinguishable_from``)."""
MAX_SD_MM = 10.0
"""A joint whose marker distances have a standard error beyond this is not determined in practice."""
SD_GROWTH = 5.0
"""An adopted effect may not leave the joints' worst standard error more than this factor above the rigid fit's and
beyond :data:`MAX_SD_MM`: its parameters would be trading off against the joints'. The bar is the rigid fit's, not
the step before's, and it is checked on the candidate fitted on for 40 more iterations (:meth:`Hypothesis.polish`):
measured from the step before, the growth compounded (walking2: 0.37 mm rigid, then 4.7, 31, 128 mm as a knee turning
like a ball and skin on each thigh were adopted, each within five times the one before), and a candidate after its
few screening iterations can look determined where its converged fit is not (4.7 mm screened, 31 mm converged).
Fitted all the way, as the final model is (:meth:`Hypothesis.converged`), the check cost a sixth more time on
held-out draw 42 and let in a knee 28 mm off called determined (skin terms on single shank markers instead of the
refused cluster). A correction of the data that adds no term to the model (:func:`corrects_data_only`) is not held to
the bar; what the rigid model fitted to the corrected data leaves of the joints sets the bar for the effects after
it."""


@dataclass(frozen=True)
class Step:
    """One adopted effect: what, where, the gap before and after (mm), its score (the criterion's gain),
    the evidence for the figures, and the other candidates of its round as (name, where, score), less those that
    cannot be what they claim (:meth:`identcheck.effects.base.Effect.implausible`: a delay noise alone may have made
    is no explanation as good as the step's)."""

    name: str
    where: dict
    gap_before: float
    gap_after: float
    score: float
    evidence: dict = field(default_factory=dict)
    rejected: tuple = ()
    alike: tuple = ()

    def equivalents(self) -> list:
        """Other effects that the data cannot tell from this one. [(name, where)]: those of its round that explain
        the trial as well, within :data:`EQUIVALENT_GAIN` of its score (a skin cluster moving on the root segment
        with the hip's angles is the hip centre moving in the root, to the last marker), and those no data could
        tell from it (``alike``, :meth:`identcheck.effects.base.Effect.alike`: a knee's centre moving in the thigh
        moves the markers of a last segment as its skin cluster moving as one does). The same effect counts too
        where it acts on another segment, joint or set of markers (a thigh delayed 38 ms scored above the shank
        advanced 40 ms that was adopted, and the report had not said so), not where only its frames or sizes
        differ (a slip one frame later), nor where it only adds markers to the step's own on its segment (skin on
        every shank marker, scoring as skin on the ankle marker alone did, is that story again with more terms, not
        another one)."""
        out = [(n, w) for n, w, sc in self.rejected
               if (n != self.name or (acts_on(w) != acts_on(self.where) and not widens(w, self.where)))
               and sc >= self.score - max(EQUIVALENT_GAIN, EQUIVALENT_FRACTION * self.score)]
        return out + [(n, w) for n, w in self.alike
                      if n != self.name and place(n, w) not in {place(k, v) for k, v in out}]


@dataclass(frozen=True)
class Refused:
    """An effect that earned its parameters (``score`` in criterion units, over the hypothesis of its round) but
    would have left the joints undetermined: ``joint``'s marker distances with standard error ``sd_mm``, or
    ``free`` directions of the constants beyond the gauge (then ``joint`` is None and ``sd_mm`` infinite)."""

    name: str
    where: dict
    score: float
    joint: str | None
    sd_mm: float
    free: int

    def to_dict(self, where: dict, limit_mm: float) -> dict:
        reason = (f"{self.free} direction(s) of the joint parameters would be left free" if self.free else
                  f"{self.joint} would be determined to {self.sd_mm:.0f} mm (standard error of a marker distance), "
                  f"beyond the {limit_mm:.0f} mm an effect may leave")
        return {"name": self.name, "where": plain(where), "score": round(self.score, 1), "joint": self.joint,
                "worst_sd_mm": None if self.free else round(self.sd_mm, 2), "reason": reason}


@dataclass(frozen=True)
class Diagnosis:
    """Everything ``diagnose`` found (the result of ``identcheck diagnose``).

    Attributes
    ----------
    ctx : Context
        The model, the trial's data and the noise estimate (``ctx.noise.sigma_mm``, per coordinate).
    before, after : Hypothesis
        The rigid-joint fit, and the fit with every adopted effect (and each adopted delay's fraction of a frame
        fitted: :func:`with_choices_free`).
    steps : tuple of Step
        The adopted effects, in order (most important first).
    test_before, test_after : dict
        Whether the gap is consistent with noise: ``consistent``, ``ratio`` (gap²/floor²), ``limit``, ``dof``.
    offset : array (3,)
        What the trial was moved by before the fit (:meth:`identcheck.trial.Trial.recentred`): ``ctx``,
        ``before`` and ``after`` live in the moved frame, so a world position from them (a joint centre,
        a predicted marker) plus ``offset`` is in the file's own coordinates. Everything in :meth:`to_dict`
        is a distance and does not depend on it.
    first_frame : int
        The file's number of the trial's first row (TRC ``Frame#``, the C3D header's first frame): each effect's
        ``where`` gives its frames as row indices and, beside them, in the file's numbering (``file_frame``,
        ``file_frames``), as the capture software shows them.
    dropped : tuple of (name, where, gain)
        Effects adopted on the way and dropped once later ones explained what they did
        (:mod:`identcheck.diagnose.backward`), with what each still gained given the others (criterion units).
    progress : callable, optional
        Where the joints' judgment (:attr:`joints`) reports its stages.
    not_adopted : tuple of Refused
        Effects that earned their parameters but were not adopted because the joints would no longer be determined
        with them (the worst standard error beyond ``sd_limit_mm``, or a direction left free): what the data show
        and the model cannot take without giving up the joints. Best score first; the places adopted in the end are
        left out.
    sd_limit_mm : float
        The joints' worst standard error an adopted effect may leave (:data:`SD_GROWTH` times the rigid fit's, at
        least :data:`MAX_SD_MM`).
    left_out : dict
        joint -> (declared type, why) for the joints left out with the segments nothing poses (:class:`Unposed`):
        reported undetermined, with no distances.
    joint_order : tuple
        The model's joints, parents first: the order :attr:`joints` reports them in (the left-out ones included).
    warnings : tuple of dict
        Every warning said while the trial was read and diagnosed, as ``{"kind", "message"}`` (as ``fit``'s JSON
        gives them; set by :func:`identcheck.api.diagnose`).
    """

    ctx: Context
    before: Hypothesis
    after: Hypothesis
    steps: tuple
    test_before: dict
    test_after: dict
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    first_frame: int = 0
    dropped: tuple = ()
    progress: object = field(default=None, compare=False, repr=False)
    not_adopted: tuple = ()
    sd_limit_mm: float = MAX_SD_MM
    left_out: dict = field(default_factory=dict)
    joint_order: tuple = ()
    warnings: tuple = ()

    @cached_property
    def joints(self) -> dict:
        """Each joint as ``fit`` reports it, from the model with the adopted effects (:func:`joint_report`), and
        each joint left out (:attr:`left_out`) undetermined, without distances. Judged once, when first asked for:
        profile likelihoods and bootstrap refits can take up to a minute each for a weakly determined joint, and the
        JSON, the text and the HTML report all read the same answer."""
        out = joint_report(self.ctx, self.after, self.progress, self.steps)
        out |= {j: left_out_answer(kind, why) for j, (kind, why) in self.left_out.items()}
        return {j: out[j] for j in self.joint_order if j in out} | out        # in the model's order

    def numbered(self, where: dict) -> dict:
        """`where` with its row indices also in the file's numbering."""
        out = dict(where)
        if "frame" in where:
            out["file_frame"] = self.first_frame + int(where["frame"])
        if "frames" in where:
            out["file_frames"] = [self.first_frame + int(f) for f in where["frames"]]
        return out

    @property
    def gap_before(self) -> float:
        return self.before.gap(self.ctx)

    @property
    def gap_after(self) -> float:
        return self.after.gap(self.ctx)

    @property
    def noise_floor(self) -> float:
        return self.after.floor(self.ctx)

    @property
    def consistent(self) -> bool:
        """The gap left after the adopted effects is consistent with measurement noise."""
        return bool(self.test_after["consistent"])

    def to_dict(self) -> dict:
        """The contract's ``diagnose`` JSON, plus the noise estimate and the consistency tests."""
        return {
            "noise_floor": round(self.noise_floor, 4),
            "noise_floor_before": round(self.before.floor(self.ctx), 4),
            "noise_sigma_mm": round(self.ctx.noise.sigma_mm, 4),
            "gap_before": round(self.gap_before, 4),
            "gap_after": round(self.gap_after, 4),
            "consistent_before": plain(self.test_before), "consistent_after": plain(self.test_after),
            "effects": [{"name": s.name, "where": plain(self.numbered(s.where)), "gap_before": round(s.gap_before, 4),
                         "gap_after": round(s.gap_after, 4), "score": round(s.score, 1),
                         "indistinguishable_from": [{"name": n, "where": plain(self.numbered(w))}
                                                    for n, w in s.equivalents()]}
                        for s in self.steps],
            "dropped": [{"name": n, "where": plain(self.numbered(w)), "gain_given_the_others": round(g, 1)}
                        for n, w, g in self.dropped],
            "not_adopted": [r.to_dict(self.numbered(r.where), self.sd_limit_mm) for r in self.not_adopted],
            "joints": self.joints,
            "warnings": [dict(w) for w in self.warnings],
        }




# ---------------------------------------------------------------------- identifiability of a fit
def undetermined(h: Hypothesis) -> int:
    """Directions of the constants the data leave undetermined beyond the gauge (0: identifiable).

    Floating point on the fitted information matrix, scaled by the blocks a change of frames turns; a practical
    check that an adopted effect does not trade off against the joint parameters, not a structural certificate.
    """
    S = information(h.fit, h.data, h.weights)
    if not np.isfinite(S).all():
        return len(S)
    try:
        return gauge_free_inverse(S, null_count(h.chain, h.terms), blocks=turning_blocks(h.chain, h.terms))[1]
    except np.linalg.LinAlgError:
        return len(S)


# ---------------------------------------------------------------------- the loop
def _naming(files: str, call, *args):
    """``call(*args)``; an InputError it raises naming no file (the noise floor and the starting poses see
    arrays) is raised again naming `files`."""
    try:
        return call(*args)
    except InputError as exc:
        if exc.source is not None:
            raise
        raise exc.naming(files) from None


class Unposed(Exception):
    """The rigid fit cannot start because a segment below `joint` (its child) has no markers and its joints do not pose
    it: they lend fewer than three points (a foot without markers), or cannot be placed without its markers (a shank
    between two hinges); or its markers and the joints' points are too few because `joint` is a case no motion
    identifies (a ball knee on the hip centre and one thigh marker, one shank marker: spherical (2,1)); or its
    markers are seen together in fewer than three frames (a foot marker seen once). :func:`diagnose` leaves that joint
    and everything hanging from it out, as ``fit`` does, and says `why`
    (:attr:`identcheck.errors.DegenerateError.leave_out`). (Markers seen but not moving, a hinge that never turns in
    a static trial, stay a degenerate answer, as documented.)"""

    def __init__(self, joint: str, why: str):
        super().__init__(why)
        self.joint, self.why = joint, why


def start_leaving_out(model, trial, progress=None) -> tuple[Context, Hypothesis, dict]:
    """:func:`start`, leaving out each joint whose child segment cannot be posed (:class:`Unposed`) with everything
    below it, and starting again on the rest (once per joint at most): (context, rigid fit, {joint left out:
    (its declared type, why)}). The model in the context is the one without them. A root nothing poses (no marker,
    fewer than three joint points) is left out first with its joints, the subtree below it that holds joints
    diagnosed (:meth:`identcheck.io.model.Model.below_root`), as ``fit`` does; the trial is checked against the whole
    model first (a marker it never shows is refused, as ``fit`` refuses it)."""
    full = model
    unprefixed, _ = trial.unprefixed(model.markers)         # (start says so, once)
    refuse_exported_points(unprefixed, model.joints)
    model.require_markers_in(unprefixed)
    model, gone = model.below_root()
    if gone and not model.joints:
        raise InputError([f"segments.{full.root}.markers: none, and its joints lend fewer than three points: nothing "
                          "poses the model's root, and every joint hangs from it; give it markers"],
                         source=full.source)
    why = unposed_root(full, model, "diagnosed")
    left_out = {j: (full.joints[j].type, reason) for j, reason in left_out_reasons(gone, why, "diagnose").items()}
    if gone and progress:
        progress(f"leaving out {', '.join(gone)}: {why}")
    while True:
        try:
            ctx, h = start(model, trial, progress)
            return ctx, h, left_out
        except Unposed as exc:
            smaller, gone = model.without_subtrees([exc.joint])
            if not smaller.joints:
                raise InputError([f"joint {exc.joint}: {exc.why}; no joint would be left to diagnose"],
                                 source=full.source) from None
            left_out.update({j: (full.joints[j].type, reason)
                             for j, reason in left_out_reasons(gone, exc.why, "diagnose").items()})
            if progress:
                progress(f"leaving out {', '.join(gone)}: {exc.why}")
            model = smaller


def not_moving(data: np.ndarray) -> bool:
    """Whether every marker of `data` (F, M, 3) is where it was in every frame it is seen: a frozen or single-pose
    export, which ``fit`` answers as degenerate data (no motion), not a trial without noise."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)         # (a marker never seen: all-NaN)
        return bool(np.all(np.nan_to_num(np.nanmax(data, axis=0) - np.nanmin(data, axis=0)) == 0.0))


def start(model, trial, progress=None) -> tuple[Context, Hypothesis]:
    """Noise floor and the rigid-joint fit of `trial` (a subject prefix taken off its labels first, with a warning:
    :meth:`identcheck.trial.Trial.unprefixed`)."""
    trial, unprefixed = trial.unprefixed(model.markers)
    if unprefixed:
        warnings.warn(unprefixed, SubjectPrefixWarning, stacklevel=2)
    refuse_exported_points(trial, model.joints)
    model.require_markers_in(trial)
    for said in (centimetres_suspected(trial.as_array(), trial.source),
                 scaled_up_suspected(trial.select(model.markers).as_array(), trial.source)):
        if said:
            warnings.warn(said, UnitsWarning, stacklevel=2)
    data = trial.select(model.markers).as_array()
    seen = np.all(np.isfinite(data), axis=2)
    files = f"{trial.source} (model {model.source})"
    noise = _naming(files, noise_floor, data, model.markers, {s: model.segments[s].markers for s in model.segments})
    if noise.sigma_mm <= 0 and not_moving(data):
        raise DegenerateError(f"{trial.source}: every frame is the same: no marker moves, so no joint turns and none "
                              "can be located; record the joints' functional movement")
    if noise.sigma_mm <= 0:
        raise InputError(["the distances within every segment are exactly constant: no measurement noise to "
                          "scale the gap against (a noise-free synthetic trial?)"], source=trial.source)
    ctx = Context(model, tuple(model.markers), trial.rate_hz, data, noise, int(seen.sum()), trial.source)
    chain = Skeleton.from_model(model)
    if progress:
        progress(f"fitting the rigid-joint model to {trial.n_frames} frames")
    try:
        state = _naming(files, start_state, model, chain, data, trial.rate_hz, trial.source)
    except DegenerateError as exc:
        seg = exc.segment
        # a segment without markers that the start cannot pose: its joints lend fewer than three points, or lend
        # more that no closed form can place without its markers (a shank between a thigh and a foot, both hinges:
        # ``fit`` calls both not identifiable, and diagnose had stopped on degenerate data, blaming the trial)
        markerless = seg in model.segments and not model.segments[seg].markers
        above = model.parent_joint(seg) if seg in model.segments else None
        if markerless and above is not None:
            few = model.joint_points(seg) < 3
            raise Unposed(above.name, f"segments.{seg}.markers: none, and the joints beside it " + (
                "lend fewer than three points" if few else "cannot be placed without its markers to lend it points")
                + ": nothing poses the segment") from None
        if markerless:
            raise InputError([
                f"segments.{seg}.markers: none, and no joint points pose the segment, the model's root: every other "
                "segment is posed from it; give it markers"], source=model.source) from None
        if exc.leave_out and above is not None:     # markers seen too rarely, or a joint above no motion identifies
            raise Unposed(above.name, exc.leave_out) from None
        raise
    weights = seen.astype(float)
    fit = restarted_stuck_frames(fit_chain(chain, data, state, weights=weights, max_iter=BASE_ITER), data, weights)
    h = Hypothesis(chain, fit.terms, data, weights, fit)
    if not consistency(ctx, h)["consistent"]:
        # a gap above the noise may be a wrong minimum of the rigid model, not an effect: the other closed-form
        # starts ``fit`` uses are tried, and a lower fit from one is the rigid model's (:func:`better_start`)
        if progress:
            progress("the rigid-joint fit leaves a gap: trying the other closed-form starts")
        other = better_start(model, chain, data, weights, trial.rate_hz, ctx.start_margin, trial.source)
        if other is not None:              # fitted as far as the first (compared after the same iterations)
            again = restarted_stuck_frames(fit_chain(chain, data, other, weights=weights, max_iter=BASE_ITER), data,
                                           weights)
            if again.rss < fit.rss - ctx.start_margin:
                h = Hypothesis(chain, again.terms, data, weights, again)
                ctx = replace(ctx, every_start=True)
    return ctx, h


def creep(ctx: Context, h: Hypothesis, iterations: int = CREEP_ITER) -> float:
    """What refitting `h` as it is gains (`iterations` more, no effect added), in the criterion's units (≥ 0): the
    rigid fit of data an effect corrupts creeps on for long, and every candidate's refit takes that gain too, so each
    candidate's score is counted net of it."""
    return max(score(ctx, h.refit(max_iter=iterations), h), 0.0)


def widens(where: dict, of: dict) -> bool:
    """Whether `where` is the place `of` with markers added: the same segment, and every marker of `of` among its
    own (`of` names some)."""
    mine, theirs = set(where.get("markers") or ()), set(of.get("markers") or ())
    return bool(theirs) and where.get("segment") == of.get("segment") and theirs < mine


def acts_on(where: dict) -> tuple:
    """What an effect's `where` acts on: its segment, joint and markers (not its frames, nor any fitted size)."""
    return where.get("segment"), where.get("joint"), tuple(where.get("markers") or ())


def place(name: str, where: dict) -> tuple:
    """What makes an effect's place itself: its name and the non-numeric parts of `where` (joint, segment,
    markers, frames), leaving out fitted sizes (a delay in ms, an amplitude) and descriptions of the model
    (:data:`DESCRIPTIVE`). An effect adopted at a place
    is not proposed there again: the same terms a second time only repeat the first (a knee's translation adopted
    three times in a row, each refit creeping on a little further)."""
    def key(v):  # noqa: E306 - hashable, whatever `where` holds
        if isinstance(v, dict):
            return tuple(sorted((k, key(x)) for k, x in v.items()))
        if isinstance(v, (list, tuple, np.ndarray)):
            return tuple(key(x) for x in v)
        return v
    def size(v) -> bool:  # noqa: E306 - a fitted size, or a list of them (an extra rotation's ranges)
        if isinstance(v, (list, tuple, np.ndarray)):
            return len(v) > 0 and all(isinstance(x, (float, np.floating)) for x in v)
        return isinstance(v, (float, np.floating))
    return (name,) + tuple(sorted((k, key(v)) for k, v in where.items() if not size(v) and k not in DESCRIPTIVE))


DESCRIPTIVE = frozenset({"modelled", "functions", "fields", "degree", "knot_spacing_s"})
"""Keys of an effect's ``where`` that describe its model, not its place: a joint's translation is one place whichever
of its functions the data ask for, the volume's distortion one place whichever of its fields and of what degree
(:mod:`identcheck.bundle.score_selection`), a hinge's second rotation one place whatever the knots of its angle;
each adopted once, and a dropped one not proposed again in another form."""


def bar_for(effect, bar: float) -> float:
    """The fitted gain `effect` must exceed when the round's bar is `bar` (:data:`DECISIVE_GAIN` where the gap is
    consistent with noise, else 0), forward and in the backward check alike: that bar, or for an effect acting on a
    few samples (:attr:`identcheck.effects.base.Effect.sparse`) at most :data:`EQUIVALENT_GAIN`. Its samples have
    each failed a trial-wide bound and paid their own parameters, which the consistency test cannot judge; what is
    asked of it beyond that is to gain more than the margin within which two explanations are equal, so that a
    sample or two barely beyond the bound is no finding."""
    return min(bar, EQUIVALENT_GAIN) if effect.sparse else bar


def diagnose(model, trial, progress=None, max_steps: int = MAX_STEPS) -> Diagnosis:
    """Find, name and model what the rigid-joint model misses in `trial` (see the module docstring).

    The trial is fitted moved near the origin (:meth:`identcheck.trial.Trial.recentred`: float64 sums of squares
    of coordinates 100 m from the origin lose the millimetres); the result carries the move (``offset``)."""
    trial, spikes = without_spikes(trial)
    if spikes:
        warnings.warn(spikes["message"], GrossErrorWarning, stacklevel=2)
    trial, offset = trial.recentred()
    try:
        ctx, base, left_out = start_leaving_out(model, trial, progress)
    except InputError as exc:
        raise with_screen_findings(exc, [], spikes) from None
    for j, (_type, why) in left_out.items():
        warnings.warn(f"{trial.source}: joint {j} left out: {why}", UserWarning, stacklevel=2)
    test0 = consistency(ctx, base)
    h, steps, adopted_effects, dropped, dropped_steps = base, [], [], set(), []
    rigid_limit = max(SD_GROWTH * worst_sd(ctx, base), MAX_SD_MM)
    limit, free_floor = rigid_limit, 0             # the bar, and the directions the data (as corrected) leave free
    refused = {}                                   # place -> Refused, the latest round's
    trail = [base]                                 # the hypothesis after each adopted effect, from the rigid fit on
    # a round adopts an effect or, with none left to adopt, drops what the later effects made unnecessary and, if it
    # dropped any, lets the search go on; a place is dropped at most once, so the rounds are few
    for _round in range(4 * max_steps):
        adopted = None
        if len(steps) < max_steps:
            bar = DECISIVE_GAIN if consistency(ctx, h)["consistent"] else 0.0
            proposals = sorted(((p, eff) for eff in EFFECTS.values()
                                for p in eff.propose(ctx, h)[:eff.max_proposals]), key=lambda pe: -pe[0].strength)
            h.forget_projection()            # the detectors are done with it (an effect's apply builds it if it needs)
            tried, best, leader, drift, placed, screened = [], 0.0, None, None, set(), []
            # an adopted effect's place, and the places of the effects no data could tell from it (its ``alike``:
            # both adopted would model one motion twice)
            taken = {place(n, w) for st in steps for n, w in [(st.name, st.where), *st.alike]} | dropped
            for prop, eff in proposals:
                if prop.strength <= (0.0 if eff.nested else bar):
                    continue       # its detector's own estimate does not earn its parameters (or, for an effect that
                    # changes the data, clear the bar: Effect.nested)
                if place(eff.name, prop.where) in taken:
                    log.debug("%s %s skipped: adopted already", eff.name, prop.where)
                    continue
                if (eff.name in placed and prop.strength * SKIP_RATIO < best and eff is not leader
                        and not (eff.always_fit or prop.always_fit)):
                    # (each effect's first place, other places of the leader, and effects whose strength is no
                    # estimate of their score: always)
                    log.debug("%s %s skipped: its detector strength is far below the best fit", eff.name, prop.where)
                    continue
                placed.add(eff.name)
                if progress:
                    progress(f"step {len(steps) + 1}: trying {eff.name} {prop.where}")
                try:
                    first = eff.screen(ctx, h, prop) if best >= SCREEN_FROM else None
                    if first is not None:                 # (a best fitted already: drift is known)
                        estimate = score(ctx, first, h) - drift
                        if estimate * SKIP_RATIO < best:
                            log.debug("%s %s left at its screen (%.0f)", eff.name, prop.where, estimate)
                            screened.append((estimate, eff, prop))
                            continue
                    cand = eff.apply(ctx, h, prop)
                except (np.linalg.LinAlgError, ValueError) as exc:
                    log.debug("%s %s failed: %s", eff.name, prop.where, exc)
                    continue
                drift = creep(ctx, h) if drift is None else drift
                sc = score(ctx, cand, h) - drift
                tried.append((sc, eff, prop, cand))
                if not eff.implausible(prop) and sc > best:
                    best, leader = sc, eff
            h.forget_projection()
            bars = Bars(bar, best, limit, free_floor, rigid_limit)
            tried, adopted, limit, free_floor = choose(ctx, base, h, tried, screened, bars, refused, drift, progress,
                                                       len(steps) + 1)
        if adopted is not None:
            h = _adopt(ctx, h, adopted, tried, steps, progress)
            adopted_effects.append(Adopted(adopted[1], adopted[2]))
            trail.append(h)
            continue
        before = len(dropped_steps)
        while len(adopted_effects) > 1:       # each pass drops one effect or ends: bounded
            red = redundant(ctx, trail, adopted_effects, lambda without, a: needed(ctx, without, h, a), CREEP_ITER)
            if red is None:
                break
            gone = steps[red.index]
            dropped.add(place(gone.name, gone.where))
            dropped_steps.append((gone.name, gone.where, red.gain))
            if progress:
                progress(f"dropped {gone.name} {gone.where}: the later effects explain what it did (it gains "
                         f"{red.gain:.0f} given them)")
            steps, rebuilt = restated(ctx, base, red, [st for i, st in enumerate(steps) if i != red.index])
            adopted_effects, h, trail = list(red.kept), rebuilt[-1], [base] + rebuilt
            limit, free_floor = bar_on_corrected_data(ctx, base, h, rigid_limit)   # the corrections left, if any
        if len(dropped_steps) == before:
            break
    if progress:
        progress("fitting the final model to convergence")
    h = h.converged(progress)               # the model reported and judged is a maximum of the likelihood, or says not
    h = with_choices_free(ctx, h, progress)  # (and a delay's fraction of a frame is fitted: the joints move with it)
    if steps:
        steps[-1] = replace(steps[-1], gap_after=h.gap(ctx))
    kept = {place(st.name, st.where) for st in steps}
    not_adopted = sorted((r for key, r in refused.items() if key not in kept), key=lambda r: -r.score)
    return Diagnosis(ctx, base, h, tuple(steps), test0, consistency(ctx, h), offset, int(trial.frame_number(0)),
                     tuple(dropped_steps), progress, tuple(not_adopted), limit, left_out, tuple(model.joint_order))


SCREEN_FROM = 100.0
"""Proposals are screened (:meth:`identcheck.effects.base.Effect.screen`) only once the round's best fitted score is at
least this. A screened proposal whose full score came within the margin of equal explanations
(:data:`EQUIVALENT_GAIN`, :data:`EQUIVALENT_FRACTION`) of the candidate adopted would have been named
indistinguishable from it, or put ahead of it as the simpler of equals (:func:`simplest_among_equals`). A candidate
:func:`choose` adopts without fitting the screened ones scores at least :data:`COMPLETE_SHARE` of the best; from a
best of 100 that margin is at most a tenth of the best, so a screened proposal whose full score stays below half the
best cannot come within it. Measured (below), the full scores stayed below a quarter of the best."""
COMPLETE_SHARE = 0.6
"""A proposal left at its screen (:meth:`identcheck.effects.base.Effect.screen`, which scored below 1/SKIP_RATIO of the
round's best fit) is fitted in full before a candidate scoring below this share of the round's best is polished for
adoption, and before a round ends with nothing adopted: the round's choice then reaches scores that the full fit of
a screened proposal might have (it can move well above its screen: a delay several frames long, from a fresh start).
Adopting a candidate near the round's best, the screened ones are not needed. Measured with every screened delay
fitted in full beside (from any best above 0): on the 120 trials of held-out draw 82 (233 rounds), 48 delays were
left at their screen and none scored above 0.091 of its round's best in full (one had risen from a screen of −1 419
to 24 581, against 604 039); on the 120 of draw 83, drawn afterwards (249 rounds), 52 and none above 0.257 (a screen
of 125 828, in full 455 527, against 1 772 243; another at a best of 201: −112, then 40). One round of the 482 would
have fitted them in full (it adopted nothing). A screen of one Newton step had let through what a settled one does
not: a marker of a pelvis 4 frames late, its first step at −248, scored 669 in full against the round's 1 151 (draw
82, trial 59)."""


@dataclass(frozen=True)
class Bars:
    """What a round's candidate must clear to be adopted: ``bar`` on its score (0, or :data:`DECISIVE_GAIN` when the
    gap is consistent with noise), ``best`` the round's best plausible score, ``limit`` and ``free_floor`` on what it
    leaves of the joints (worst standard error, free directions), ``rigid_limit`` the rigid fit's limit."""

    bar: float
    best: float
    limit: float
    free_floor: int
    rigid_limit: float


def ranked(tried: list, h: Hypothesis, bar: float, logged: set | None = None) -> list:
    """The round's fitted candidates `tried` ((score, effect, proposal, hypothesis)) in the order they are considered
    for adoption, without those that cannot be what they claim: errors the data show without the joint model first
    among those that earn their parameters, then by score, the simplest of equals first
    (:func:`simplest_among_equals`). `logged`: the proposals (by id) whose refusal was logged already, to which those
    logged now are added (a round considered again does not repeat its log)."""
    logged = set() if logged is None else logged
    tried = sorted(tried, key=lambda x: (not (x[0] > bar_for(x[1], bar) and x[1].read_without_joints(x[2])), -x[0]))
    # what cannot be what it claims is never adopted, nor sets the margin of the explanations alike
    plausible = []
    for sc, eff, prop, cand in tried:
        why = eff.implausible(prop)
        if why and sc > bar_for(eff, bar) and id(prop) not in logged:
            logged.add(id(prop))
            log.info("%s at %s not adopted: %s", eff.name, prop.where, why)
        elif not why:
            plausible.append((sc, eff, prop, cand))
    return simplest_among_equals(plausible, h, bar)


def choose(ctx: Context, base: Hypothesis, h: Hypothesis, tried: list, screened: list, bars: Bars, refused: dict,
           drift: float | None, progress, step: int) -> tuple:
    """The round's adoption: (the candidates in the order considered, the adopted (score, effect, proposal,
    hypothesis) or None, the limit and free directions for the rounds after). Candidates are considered in
    :func:`ranked` order, the leading ones scored fitted on (:func:`contested`); each is fitted on
    (:meth:`Hypothesis.polish`) and adopted when it keeps the joints determined (or only corrects the data), else
    recorded in `refused`. The proposals left at their screen
    (`screened`, (estimate, effect, proposal)) are fitted in full, and the round considered again with them,
    when its choice reaches below :data:`COMPLETE_SHARE` of the round's best or ends with none; each candidate is
    fitted on once. The choice, the refusals and the candidates equivalent to the one adopted are then those of the
    round with every proposal fitted in full, provided each screened proposal's full score is below half the best
    (:data:`SCREEN_FROM`)."""
    polished, before, logged, screen = {}, dict(refused), set(), {}
    while True:
        refused.clear()
        refused.update(before)                     # (a second pass records its own refusals, as a single one would)
        screen.update({id(x[2]): x[0] for x in tried if id(x[2]) not in screen})   # each one's score after its screen
        tried = contested(ctx, h, ranked(tried, h, bars.bar, logged), tried, bars.bar, polished, progress, step)
        order = ranked(tried, h, bars.bar, logged)
        limit, free_floor = bars.limit, bars.free_floor
        adopted, closed = None, False
        for sc, eff, prop, cand in order:
            # the first candidate short of the round's bar closes the round to all but the sparse effects, held
            # to their own (bar_for): what follows scores less, or is a simpler explanation moved ahead of it
            closed = closed or sc <= bars.bar
            if sc <= bar_for(eff, bars.bar) or (closed and not eff.sparse):
                continue
            if screened and screen[id(prop)] < COMPLETE_SHARE * bars.best:
                break                              # (the screened proposals are fitted in full first; the share is of
                # the scores after the screen, the round's best's basis, whatever a contest fitted on since)
            if id(prop) not in polished:
                if progress:
                    progress(f"step {step}: fitting {eff.name} {prop.where} further, to check the joints stay "
                             f"determined")
                polished[id(prop)] = cand.polish()
            cand = polished[id(prop)]
            if corrects_data_only(h, cand):
                limit, free_floor = bar_on_corrected_data(ctx, base, cand, bars.rigid_limit)
                adopted = (sc, eff, prop, cand)
                break
            free = undetermined(cand)
            joint, sd = worst_joint(ctx, cand) if free <= free_floor else (None, float("inf"))
            if sd <= limit:
                adopted = (sc, eff, prop, cand)
                break
            if id(prop) not in logged:
                logged.add(id(prop))
                log.info("%s at %s not adopted: it leaves the joint parameters undetermined", eff.name, prop.where)
            refused[place(eff.name, prop.where)] = Refused(eff.name, prop.where, sc, joint, sd, free)
        if not screened or adopted is not None:     # (a candidate adopted: never one past the share)
            return order, adopted, limit, free_floor
        tried = tried + complete(ctx, h, screened, drift, progress, step)
        screened = []


CONTENDER_SHARE = 0.5
"""A round's plausible candidates scoring at least this share of its leader's score, after their few screening
iterations, are contenders: each is fitted on (:meth:`Hypothesis.polish`) and scored again before one is chosen
(:func:`contested`)."""
MAX_CONTENDERS = 4
"""At most this many contenders a round (the leader included)."""


def contested(ctx: Context, h: Hypothesis, order: list, tried: list, bar: float, polished: dict, progress,
              step: int) -> list:
    """The round's candidates `tried` with each contender's score and hypothesis those of its fit carried on
    (:meth:`Hypothesis.polish`, kept in `polished` by proposal), net of what `h` itself gains over as many more
    iterations (:func:`creep`, kept in `polished` as ``"creep"``); unchanged with fewer than two contenders. Of the
    candidates `order` (as :func:`ranked` puts them, the simplest of equals first) puts above the bar, each group of
    variants of one story (:func:`related`) is represented by its first; the contenders are the highest-scoring of
    those, at most :data:`MAX_CONTENDERS`, scoring at least :data:`CONTENDER_SHARE` of the round's best; none when
    `order` opens with an error the data show without the joint model (a swap: adopted ahead of any score). The other
    candidates keep their scores after the screen, and a report's scores mix the two bases: those below half the best
    are outside the margin within which two explanations are equal, but a variant a contender stands for may be above
    it, and if its stand-in is refused for the joints it is compared, unfitted, with contenders fitted on.

    Why: a candidate is scored after :data:`~identcheck.bundle.hypothesis.SCREEN_ITER` iterations from the round's
    hypothesis, and one with many parameters, or one that trades off with an effect adopted before it, is then
    further from its own minimum than a small one: skin on the four pelvis markers of the real walking2 trial's sparse
    legs (324 parameters) scored 43 582 after 6 iterations, 66 911 after 20 and 74 823 after 60, against a knee's
    translation at 63 793 (one parameter), which was adopted; a round later the skin scored 24, the trial's gap
    stayed 2.1 mm where the skin alone brings it to 0.53. Only the candidate about to be adopted had been fitted on.

    Two variants of one story (:func:`related`: skin on one shank marker or on all three, a pelvis cluster moving with
    the hip or the hip's centre moving) are not contested: the one after the screen's ranking stands for both. Fitted
    on, the more flexible one gains the more, and with it the more room to trade off with the joints: skin on all
    three shank markers outscored skin on the one that moved (9 532 against 9 121) and left the knee 66 mm off,
    unbounded; a pelvis cluster's skin outscored the hip translation it is, by 5 %, and the hip was claimed."""
    heads = [x for x in order if x[0] > bar_for(x[1], bar)]
    if len(heads) < 2 or heads[0][1].read_without_joints(heads[0][2]):
        return tried
    stand_ins = []
    for x in heads:                       # in ranked order: the simplest of equal variants stands for them
        if not any(related(x[2].where, c[2].where) for c in stand_ins):
            stand_ins.append(x)
    best = max(x[0] for x in heads)
    contenders = [x for x in sorted(stand_ins, key=lambda x: -x[0])[:MAX_CONTENDERS]
                  if x[0] >= CONTENDER_SHARE * best]
    if len(contenders) < 2:
        return tried
    if "creep" not in polished:     # (once a round; the screen's own drift counted CREEP_ITER iterations)
        polished["creep"] = creep(ctx, h, CREEP_ITER + POLISH_ITER)
    drift = polished["creep"]
    rescored = {}
    for sc, eff, prop, cand in contenders:
        if id(prop) not in polished:
            if progress:
                progress(f"step {step}: fitting {eff.name} {prop.where} further, to compare it with the round's "
                         f"other leading candidates")
            polished[id(prop)] = cand.polish()
        rescored[id(prop)] = (score(ctx, polished[id(prop)], h) - drift, eff, prop, polished[id(prop)])
    return [rescored.get(id(x[2]), x) for x in tried]


def related(where: dict, other: dict) -> bool:
    """Whether two places are variants of one story: the same segment, or a joint in common (the joint an effect is at
    or driven by). Markers in common are not enough: gross errors name every marker they flag, across segments, and
    are another story than skin on any one of them. Broad where a skin's driving joint is another segment's (skin on
    a shank driven by the hip is related to the hip's translation), and blind to a delay and a translation that move
    the same markers alike: a bound on what is contested, not the effects' own ``alike``."""
    joints = lambda w: {w.get("joint"), *(w.get("joints") or ())} - {None}    # noqa: E731
    seg, other_seg = where.get("segment"), other.get("segment")
    return bool((seg is not None and seg == other_seg) or joints(where) & joints(other))


def complete(ctx: Context, h: Hypothesis, screened: list, drift: float, progress, step: int) -> list:
    """The proposals left at their screen, fitted in full (:meth:`identcheck.effects.base.Effect.apply`, going on
    from the screen), as the round's candidates: (score net of `drift`, effect, proposal, hypothesis)."""
    out = []
    for _estimate, eff, prop in screened:
        if progress:
            progress(f"step {step}: trying {eff.name} {prop.where} in full")
        try:
            cand = eff.apply(ctx, h, prop)
        except (np.linalg.LinAlgError, ValueError) as exc:
            log.debug("%s %s failed: %s", eff.name, prop.where, exc)
            continue
        out.append((score(ctx, cand, h) - drift, eff, prop, cand))
    return out


def bar_on_corrected_data(ctx: Context, base: Hypothesis, h: Hypothesis, rigid_limit: float) -> tuple[float, int]:
    """(the joints' standard-error bar, the free directions tolerated) for the effects after `h`: what the rigid
    model (`base`'s chain, no terms) fitted to `h`'s corrected data and weights leaves of the joints, or the rigid
    fit's own bar `rigid_limit` and none free where `h` has corrected nothing. Measured on `h` itself, the terms
    adopted before a correction would raise the bar step by step (the real walking2 trial: outliers after two skin
    effects let the pelvis's skin in, gap 1.92 → 1.09 mm)."""
    if h.data is base.data and h.weights is base.weights:
        return rigid_limit, 0
    rigid = base.refit_corrected(ctx, h.data, h.weights, max_iter=BASE_ITER)
    free = undetermined(rigid)
    return (rigid_limit if free else max(rigid_limit, SD_GROWTH * worst_sd(ctx, rigid))), free


def corrects_data_only(h: Hypothesis, cand: Hypothesis) -> bool:
    """Whether `cand` is `h` fitted to corrected data (labels swapped back, a delay undone, samples set aside) with the
    same chain and terms: it adds no term to the model (its own parameters, a delay or the samples set aside, do not
    move the predictions the joints' constants could), so what it leaves of the joints (undetermined, or standard
    errors beyond :data:`SD_GROWTH`'s bar) is what the corrected data determine. It does not keep the correction out;
    the rigid model fitted to the corrected data sets the bar for the effects after it, and the final model's joints
    are judged by fit's rules. The rigid fit of corrupted data can look better determined than the truth: two pelvis
    markers swapped for 122 frames of a sit-to-stand, the rigid fit posing the pelvis on the swapped labels there,
    gave the joints a worst standard error of 0.07 mm; swapped back, the hip's is 36 mm, and the swap (2.1 million
    criterion units) had been refused and skin on a pelvis marker named instead (held-out draw 48, trial 28)."""
    return cand.terms is h.terms and cand.chain is h.chain


def simplest_among_equals(tried: list, h: Hypothesis, bar: float) -> list:
    """The round's candidates `tried` ((score, effect, proposal, hypothesis), in the order they are to be considered)
    with those at the head that explain the trial as well as the first (within :data:`EQUIVALENT_GAIN` or
    :data:`EQUIVALENT_FRACTION` of its score: the report names them with it, ``indistinguishable_from``) put in
    order of the parameters they add to `h`, fewest first; a swap the data show without the joint model keeps its
    place at the head.

    Why: scores that close are not told apart by the data, and the criterion's penalty is then smaller than the
    noise in what the richer hypothesis explains. A pelvis delayed 20 ms in gait (1 parameter) scored 3 895 and the
    hip's centre moving with its angles (31 parameters, the same marker motion when every other marker is below the
    hip) 3 916, and the translation was named. The parameters counted are the story's own
    (:meth:`identcheck.effects.base.Effect.own_params`): a pelvis delayed 4 frames had also been charged the 48 of
    the 16 samples its shift moves past the trial's end, and lost to the same translation at a higher score (held-out
    draw 46, trial 102: 145 413 against 145 133)."""
    if not tried or tried[0][0] <= bar_for(tried[0][1], bar) or (tried[0][1].read_without_joints(tried[0][2])):
        return tried
    top = tried[0][0]
    margin = max(EQUIVALENT_GAIN, EQUIVALENT_FRACTION * top)
    n = 1
    while n < len(tried) and tried[n][0] >= top - margin:
        n += 1
    head = sorted(tried[:n], key=lambda x: (x[1].own_params(x[2], h, x[3]), -x[0]))
    return head + tried[n:]


def rivals(tried: list, chosen, most: int = 8) -> tuple:
    """The round's candidates `tried` ((score, effect, proposal, hypothesis)) other than the `chosen` proposal, as
    (name, where, score), at most `most`, less those that cannot be what they claim
    (:meth:`identcheck.effects.base.Effect.implausible`): a delay noise alone may have made is no explanation as
    good as the one adopted, however close its score."""
    return tuple((e.name, p.where, s) for s, e, p, _ in tried if p is not chosen and not e.implausible(p))[:most]


def _adopt(ctx: Context, h: Hypothesis, adopted: tuple, tried: list, steps: list, progress) -> Hypothesis:
    """The round's chosen candidate (fitted to convergence already), recorded as the next step (with the round's
    other plausible candidates and the effects no data could tell from it), and announced."""
    sc, eff, prop, cand = adopted
    steps.append(Step(eff.name, prop.where, h.gap(ctx), cand.gap(ctx), sc, eff.evidence(ctx, h, cand, prop),
                      rivals(tried, prop),
                      tuple(eff.alike(h.chain, prop.where))))
    if progress:
        progress(f"adopted {eff.name} {prop.where}: gap {h.gap(ctx):.3g} -> {cand.gap(ctx):.3g} mm "
                 f"(floor {cand.floor(ctx):.3g})")
    return cand


def needed(ctx: Context, without: Hypothesis, full: Hypothesis, adopted: Adopted | None = None) -> tuple[float, bool]:
    """The forward step's rule, asked of an adopted effect given the others: (what `full` gains over `without`, the
    hypothesis without the effect; would the search adopt an effect gaining that much there?). Yes when it earns
    its parameters and the gap without it is not consistent with noise, when it gains decisively
    (:data:`DECISIVE_GAIN`; an effect acting on a few samples, :data:`EQUIVALENT_GAIN`: :func:`bar_for`) all the
    same, or when the joints need it to be determined: without it they are not, or their worst white-noise standard
    error grows beyond :data:`SD_GROWTH` times theirs with it and beyond :data:`MAX_SD_MM` (measured from the full
    model here, where the forward step measures from the rigid fit). The joints are then reported by fit's rules,
    which may still call them undetermined (a real knee whose ball joint was dropped for skin terms driven by its
    angle: ±20 mm). The gain must also stand clear of what noise alone gives the `adopted` effect
    (:meth:`identcheck.effects.base.Effect.stands_out`), as it had to when it was adopted."""
    gain = score(ctx, full, without)
    bar = DECISIVE_GAIN if consistency(ctx, without)["consistent"] else 0.0
    if adopted is not None:
        bar = bar_for(adopted.effect, bar)
    if gain > bar and (adopted is None or adopted.effect.stands_out(adopted.proposal, gain)):
        return gain, True
    limit = max(SD_GROWTH * worst_sd(ctx, full), MAX_SD_MM)
    return gain, bool(undetermined(without) > undetermined(full) or worst_sd(ctx, without) > limit)


def restated(ctx: Context, base: Hypothesis, red: Redundant, kept_steps: list) -> tuple[list, list]:
    """(the steps left after dropping an effect, the hypothesis after each). Those before it are as they were; those
    after it have the gaps before and after each and the evidence taken from the rebuilt hypotheses, fitted to
    convergence as the forward search fits what it adopts, and keep the score and the rival candidates of the round
    that adopted them."""
    k = red.index
    hyps = list(red.rebuilt[:k]) + [h.polish() for h in red.rebuilt[k:]]
    out = list(kept_steps[:k])
    for i in range(k, len(red.kept)):
        a, hyp, old = red.kept[i], hyps[i], kept_steps[i]
        prev = base if i == 0 else hyps[i - 1]
        out.append(Step(old.name, a.proposal.where, prev.gap(ctx), hyp.gap(ctx), old.score,
                        a.effect.evidence(ctx, prev, hyp, a.proposal), old.rejected, old.alike))
    return out, hyps


# ---------------------------------------------------------------------- the joints, as `fit` reports them
def marker_distances(ctx: Context, h: Hypothesis, S: np.ndarray | None = None) -> dict:
    """Each joint's adjacent markers' distances to its centre (ball) or axis (hinge), mm, with their
    white-noise standard errors (σ² times the gauge-free inverse of the information, through each
    distance's gradient): the yardstick the effect selection compares hypotheses by.
    {joint: {marker: (distance, sd)}}."""
    ch, s = h.chain, h.fit.state
    S = information(h.fit, h.data, h.weights) if S is None else S
    inverse = gauge_free_inverse(S, null_count(ch, h.terms), blocks=turning_blocks(ch, h.terms))[0]
    cov = ctx.noise.sigma_mm ** 2 * inverse
    return {j: {m: (d, float(np.sqrt(max(g @ cov @ g, 0.0)))) for m, (d, g) in per.items()}
            for j, per in distance_gradients(ch, s, len(S)).items()}


def worst_sd(ctx: Context, h: Hypothesis) -> float:
    """The largest standard error of any joint's marker distance, mm: how well the joints are determined."""
    return worst_joint(ctx, h)[1]


def worst_joint(ctx: Context, h: Hypothesis) -> tuple[str, float]:
    """(the joint whose marker distance has the largest standard error, that error in mm)."""
    return max(((j, sd) for j, per in marker_distances(ctx, h).items() for _, sd in per.values()),
               key=lambda js: js[1])


def scale_sd(h: Hypothesis) -> float:
    """The relative uncertainty of every length that the model's effects leave (the largest any of them says,
    :meth:`identcheck.effects.base.Effect.scale_sd`): a distorted capture volume's unseen uniform scale."""
    return max((EFFECTS[p.effect].scale_sd(p, h) for p in h.effects if getattr(p, "effect", None) in EFFECTS),
               default=0.0)


def modelled_motion(h: Hypothesis, steps: tuple = ()) -> tuple:
    """The motions with the joint angles the model's effects fit
    (:meth:`identcheck.effects.base.Effect.modelled_motion`: skin, a moving centre), and the same motions as read by
    the effects the data cannot tell from the adopted `steps` (:func:`equivalent_readings`), for the joints' model
    error."""
    own = tuple(m for p in h.effects if getattr(p, "effect", None) in EFFECTS
                for m in EFFECTS[p.effect].modelled_motion(p, h))
    return own + equivalent_readings(h, steps)


def equivalent_readings(h: Hypothesis, steps: tuple) -> tuple:
    """The motion each adopted step fits in `h`, as each effect the data cannot tell from it
    (:meth:`Step.equivalents`) would read it (:meth:`identcheck.effects.base.Effect.reading`, the step's largest
    motion): the joints are judged under every explanation the data leave open, not under the one named alone.

    Why: the same marker motion read as two effects moves the joints differently, and the data choose neither. A
    pelvis cluster moving as one with the hip's angles (10.6 mm) was named the hip's centre moving in the pelvis,
    the cluster listed as indistinguishable; the hip was then judged from the moving centre alone (its distances to
    the centre's mean place, ±4.2 mm) and called determined 32.5 mm from the truth, whose centre is fixed in the
    bone (held-out draw 80, trial 1). Read as the cluster, the motion counts as the joint displaced by the motion
    over the hip's excursion (:func:`identcheck.bundle.misfit.model_error_sd`)."""
    out = []
    for st in steps:
        here = place(st.name, st.where)
        fitted = [m for p in h.effects if getattr(p, "effect", None) == st.name and st.name in EFFECTS
                  and place(p.effect, p.where) == here for m in EFFECTS[st.name].modelled_motion(p, h)]
        if not fitted:
            continue
        rms = max(m.rms_mm for m in fitted)
        for name, where in st.equivalents():
            if name in EFFECTS:
                told = f"{said(name, where)}, which the data cannot tell from the {said(st.name, st.where)} adopted"
                out += [replace(m, reading=told) for m in EFFECTS[name].reading(h.chain, where, rms)]
    return tuple(out)


def said(name: str, where: dict) -> str:
    """An effect at a place in words, for a joint's reason: ``soft_tissue on pelvis (RASI, LASI, RPSI, LPSI
    together)``, ``joint_translation at hip``. Only the keys that make the place (segment, joint, markers), not
    :func:`identcheck.report.diagnose_figures.where_text`'s every key: a translation's ``where`` also holds a sentence
    on what is modelled, and the report layer is above this one."""
    out = name + (f" at {where['joint']}" if "joint" in where and "segment" not in where else "")
    out += f" on {where['segment']}" if "segment" in where else ""
    markers = [str(m) for m in where.get("markers") or ()]
    return out + (f" ({', '.join(markers)}{' together' if where.get('together') else ''})" if markers else "")


def left_out_answer(declared: str, why: str) -> dict:
    """The report of a joint diagnose left out (:class:`Unposed`): ``fit``'s keys, undetermined, no distance, no
    interval, no geometry, and why."""
    return {"type": declared, "declared_type": declared, "unique": False, "geometry": None, "marker_distances": {},
            "marker_distances_ci95": {}, "interval_method": {}, "uncertainty_mm": None, "alternatives": [],
            "rejected_candidates": [],
            "practical": {"verdict": "undetermined", "reason": f"left out: {why}", "tolerance_mm": None,
                          "weakest_direction_parent": None, "weakest_se_mm": None, "motion_advice": ""},
            "rms_residual": None, "excitation": {"ok": False, "reason": f"left out: {why}"}}


EXTRA_ROTATION_REFERENCE = (
    "the hinge's axis is placed in {child}'s frame where the trial's extra rotation is at its mean: a constant extra "
    "rotation is, to any data, the axis placed otherwise in {child}, so the distances of {child}'s markers are to the "
    "axis there (a convention, as a functional method's mean axis is)")
"""What a hinge's distances in its child refer to once the final model turns it about a second axis (``extra_dof``,
a second rotation with a smooth profile of time, :func:`identcheck.bundle.hypothesis.time_basis`, whose basis holds
no constant). Said because a profile with a mean away from zero is not wrong about the data: held-out draw 87,
trial 74 (varus/valgus play peaking at 6.3°), every thigh distance held the generator's, which is at zero play, and
the shank's three were 0.5-1.4 mm short of it at ±0.4-0.5 mm."""


def with_choices_free(ctx: Context, h: Hypothesis, progress=None) -> Hypothesis:
    """`h` refitted to convergence with what its effects fixed by a discrete choice left free
    (:meth:`identcheck.effects.base.Effect.judged_free`: a delay adopted as a whole number of frames), so that the
    joints judged from it carry that choice's uncertainty and sit where its continuous best puts them; `h` itself when
    its effects fixed nothing so. :func:`diagnose`'s final model (what it reports, judges, draws and exports).
    Its parameters count the freed ones on top of the effects' own charges (one a delay: the criterion has chosen by
    then, and the noise floor moves by a part in ten thousand).

    `h` itself, too, when a segment is not posed by its own markers
    (:func:`identcheck.bundle.honest.posed_by_itself`): the joints above it are judged from a refit without the
    markers below it (:func:`identcheck.bundle.incidental.without_incidental_rolls`), which a model with terms does
    not make, and a delay's remainder would switch it off; or when the refit fails (the delay then stays as adopted)."""
    owned = [(p, t) for p in h.effects if getattr(p, "effect", None) in EFFECTS
             for t in EFFECTS[p.effect].judged_free(ctx, h, p) if np.any(t[1])]   # (a field of zeros: a free parameter)
    if not owned or (not h.terms.ordered() and not all(posed_by_itself(h.chain, s, h.fit) for s in h.chain.segments)):
        return h
    if progress:
        progress("refitting the final model with the delays' fractions of a frame free")
    try:
        freed = h.refit(terms=h.terms + Terms(world=[t for _, t in owned])).converged(progress)
    except (np.linalg.LinAlgError, ValueError) as exc:
        log.debug("the delays' remainders not freed: %s", exc)
        return h
    values = freed.fit.state.term_params[len(freed.fit.state.term_params) - len(owned):]
    for p in {id(p): p for p, _ in owned}.values():                 # each effect told what its terms fitted
        EFFECTS[p.effect].freed(p, [float(np.ravel(v)[0]) for (q, _), v in zip(owned, values) if q is p])
    return freed


def joint_report(ctx: Context, h: Hypothesis, progress=None, steps: tuple = ()) -> dict:
    """Each joint as ``fit`` reports it, from the final model and by fit's rules (one estimator, one set of
    rules: :func:`identcheck.bundle.honest.assess`): marker distances with 95 % intervals from the sandwich
    covariance (correlated noise allowed), widened for markers that still move with the angles, profiled where
    wide, unbounded where the data leave the joint free; the largest standard error; the practical verdict;
    and, beside fit's keys, the declared type, the residual of the joint's markers and the range of motion. A joint
    whose own centre the final model moves claims no interval (:func:`identcheck.bundle.honest.with_moving_centre`).
    `progress` hears of the profiles and bootstrap refits, at most once a second. The model error counts the
    motions the effects fit as the adopted `steps` read them and as the effects the data cannot tell from them would
    (:func:`equivalent_readings`)."""
    ch = h.chain
    if progress:
        progress("judging the joints of the model with the effects (covariance, intervals)")
    judged = assess(h.fit, h.data, h.weights, progress=Progress(progress), rate_hz=ctx.rate_hz,
                    scale_sd=scale_sd(h), modelled=modelled_motion(h, steps))
    res = np.linalg.norm(np.where((h.weights > 0)[..., None], h.residuals(), np.nan), axis=2)
    turned = {j for j, _, _ in h.terms.rotations}            # hinges the final model turns about a second axis
    out = {}
    for j in ch.joints:
        P, C = ch.parent[j], ch.child[j]
        idx = np.concatenate([ch.seg_markers[P], ch.seg_markers[C]])
        rom = ", ".join(f"{name} {deg:.1f}" for name, deg in motion_ranges(h.fit, j))
        answer = joint_answer(judged, j)
        practical = answer["practical"]
        if j in turned:
            practical["axis_reference"] = EXTRA_ROTATION_REFERENCE.format(child=C)
            practical["reason"] += "; " + practical["axis_reference"]
        determined = practical["verdict"] == "determined"
        reason = "ok" if determined else (f"{practical['reason']}; range of motion over the central "
                                          f"{100 * ROM_SHARE:.0f} % of frames: {rom} deg"
                                          f"{'. ' + practical['motion_advice'] if practical['motion_advice'] else ''}")
        out[j] = {"type": ch.types[j], "declared_type": ctx.model.joints[j].type, "unique": determined, **answer,
                  "rms_residual": round(float(np.sqrt(np.nanmean(res[:, idx] ** 2))), 4),
                  "excitation": {"ok": determined, "reason": reason}}
    return out
