"""What every named effect provides: a detector that reads the residual structure and proposes where
the effect acts, and an augmentation that adds it to the model with its own parameters and refits."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np


def term_offsets(hyp, kind: str, basis) -> list:
    """[(key, offsets (F, 3))] of hypothesis `hyp`'s terms of `kind` (``"markers"``: key the marker column or
    columns, offsets on their segment; ``"centres"``: key the joint, offsets in its parent) built on `basis`, the very
    array an effect's ``apply`` gave them: ``basis @ params`` with the fitted parameters."""
    terms, params = hyp.terms, hyp.fit.state.term_params
    first = 0 if kind == "markers" else len(terms.markers)
    return [(key, b @ p) for (key, b), p in zip(getattr(terms, kind), params[first:]) if b is basis]


def scalar_coefficients(hyp, fields: list, kind: str = "world") -> list:
    """The fitted scalar of each of hypothesis `hyp`'s terms of `kind` (``"world"`` or ``"screws"``) whose field or
    profile is one of `fields` (the very arrays an effect's ``apply`` gave them), as [(index in `fields`,
    coefficient)]."""
    terms, params = hyp.terms, hyp.fit.state.term_params
    first = terms.world_start() if kind == "world" else terms.screws_start()
    out = []
    for (_, f), p in zip(getattr(terms, kind), params[first:]):
        out += [(k, float(p[0])) for k, g in enumerate(fields) if f is g]
    return out


def motion_rms_mm(offsets: np.ndarray) -> float:
    """How far offsets (F, 3) move: the RMS 3-D distance from their mean, mm (0 for none). Their mean is no motion
    (a term's linear functions of the angles are not centred, and their mean only moves the marker's place)."""
    if not len(offsets):
        return 0.0
    return float(np.sqrt(np.mean(np.sum((offsets - offsets.mean(axis=0)) ** 2, axis=1))))


def seen_mean(x: np.ndarray, axis) -> np.ndarray:
    """``np.nanmean(x, axis)`` without NumPy's warning for a slice with nothing seen (NaN there): in a diagnosis
    a frame where every marker of a segment is occluded is ordinary, and the warning reached the user's terminal
    as ``identcheck: warning: Mean of empty slice``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(x, axis=axis)


@dataclass
class Proposal:
    """A detector's guess: where the effect acts, how strongly the residuals point to it, and what the
    augmentation needs (bases, columns, frames)."""

    effect: str
    where: dict
    strength: float
    payload: dict = field(default_factory=dict)
    always_fit: bool = False
    """Fitted whatever the best score so far, as every proposal of an effect marked ``always_fit`` is: its strength
    is read another way than the effect's other proposals' (a delay read from distances), not on their scale."""


class Effect:
    """A named effect (one of the contract's names). Subclasses set ``name`` and implement both steps."""

    name = ""
    max_proposals = 1       # how many of the detector's best proposals are fitted each round
    always_fit = False
    """Fit this effect's proposals even when its detector's strength is far below the best score of the round:
    for detectors whose strength is not an estimate of the fitted score (a label swap's is read from distances
    within segments and fell 20x short of its score on a gait trial)."""

    nested = True
    """Whether this effect's hypothesis is the current model with parameters added, fitted to the same data (skin
    terms, a moving centre, a second rotation, a field, set-aside samples): its gain then has the null distribution
    the criterion assumes, and on a gap consistent with noise it is fitted whenever its detector's estimate earns
    its parameters. An effect that changes the data instead (a delay shifts a marker's samples, a swap exchanges
    labels) compares two different sets of residuals: on a clean trial under AR(1) noise (φ 0.87) one pelvis
    marker shifted a frame either way gained 87 and 92 in the prewhitened criterion while its plain sum of squares
    grew by 184 mm² one way. Such an effect is fitted there only when its estimate itself clears the decisive bar."""

    sparse = False
    """Whether this effect acts on a few samples, each paying for its own parameters (gross errors: three per sample
    set aside, five per brief burst). Every sample it sets aside has failed a trial-wide bound on its own (χ²₃ about 32
    on a 1500-frame leg, set for 0.5 % of noise-only trials; measured, a sample of a clean simulated leg fails it in
    about 1 trial in 9, through the departure test's scale pooled over markers) and is charged 3 ln N (about 31) in
    the score. The whole-trial consistency test cannot repeat that judgment: it sums a few gross samples into tens of
    thousands of ordinary ones (held-out draw 63, trial 43: eight 9 mm jumps under 1.2 mm of noise, χ²₃ 33-93 each,
    left its ratio at 0.99 under a limit of 1.15; set aside they gained 23, below the decisive bar, and nothing was
    named). Where that test passes, such an effect is held to a smaller bar
    (:func:`identcheck.diagnose.workflow.bar_for`)."""

    def propose(self, ctx, hyp) -> list:
        """Proposals, strongest first, from the residuals of hypothesis `hyp` (empty: no sign of it)."""
        raise NotImplementedError

    def apply(self, ctx, hyp, proposal: Proposal):
        """Hypothesis `hyp` with the effect added where `proposal` says, its parameters fitted."""
        raise NotImplementedError

    def screen(self, ctx, hyp, proposal: Proposal):
        """A first, cheaper fit of the proposal: a hypothesis whose score over `hyp` estimates the candidate's, or None
        when the effect has none (then :meth:`apply` is its only fit). :meth:`apply` goes on from it rather than
        repeating it. The search leaves a proposal at its screen when that scores below a tenth of the round's best
        (:func:`identcheck.diagnose.workflow.diagnose`), and fits it in full only if the round adopts nothing or a
        candidate well below its best (:func:`identcheck.diagnose.workflow.choose`)."""
        return None

    def alike(self, chain, where: dict) -> list:
        """Hypotheses of other effects that no data of this marker set could tell from this one at `where` (the
        same family of marker motions), as [(name, where)]; by default none."""
        return []

    def read_without_joints(self, proposal: Proposal) -> bool:
        """Whether the data show this effect at the proposal's place without the joint model (a label swap whose
        exchanged distances fit): an error in the data, which the search corrects, once it earns its parameters,
        before the effects the joint model is asked to explain. By default no."""
        return False

    def modelled_motion(self, proposal: Proposal, hyp) -> list:
        """The motions with the joint angles this effect's terms fit in hypothesis `hyp`, as
        :class:`~identcheck.bundle.misfit.ModelledMotion` (a marker moving on its segment, a centre moving in its
        parent): they count in the joints' model error as if seen (:func:`identcheck.bundle.misfit.model_error_sd`);
        none by default."""
        return []

    def reading(self, chain, where: dict, rms_mm: float) -> list:
        """The motions with the joint angles this effect at `where` would fit, as
        :class:`~identcheck.bundle.misfit.ModelledMotion`, were it given the motion (RMS `rms_mm`) that an adopted
        effect fits and the data cannot tell from this one (the adopted step's ``indistinguishable_from``). The same
        marker motion read as another effect moves the joints otherwise: a pelvis cluster moving as one with the hip's
        angles is, to first order, the hip centre displaced by the motion over the angles' excursion, where the same
        motion read as the centre moving only moves the centre about its mean place. None by default (an effect that
        fits no motion with the angles)."""
        return []

    def judged_free(self, ctx, hyp, proposal: Proposal) -> list:
        """World terms (columns, field (F, m, 3)) for what this effect, as hypothesis `hyp` holds it, fixed by a
        discrete choice that the joints' judgement must leave free: the joints' intervals then hold that choice's
        uncertainty. None by default: an effect's fitted sizes are in its terms already, and a label swap or a sample
        set aside has no continuous remainder."""
        return []

    def freed(self, proposal: Proposal, values: list) -> None:
        """Record in the proposal's ``where`` what the final model fitted for the terms :meth:`judged_free` gave (one
        fitted scalar a term, in their order); nothing by default."""

    def scale_sd(self, proposal: Proposal, hyp) -> float:
        """The relative standard deviation this effect, as hypothesis `hyp` fits it, leaves on every length the trial
        measures, which no fit can remove (a distortion of the capture volume says its calibration is off, and the
        uniform scale part of a calibration error is invisible to rigid bodies); 0 by default."""
        return 0.0

    def own_params(self, proposal: Proposal, before, after) -> float:
        """How many parameters this effect's story at `proposal` has, for ranking explanations the data cannot tell
        apart (fewest first): by default all that hypothesis `after` charges over `before`. An effect whose score
        also charges what is not its story (samples it had to set aside, noise its correction removes) says less."""
        return after.n_params() - before.n_params()

    def implausible(self, proposal: Proposal) -> str:
        """Why the fitted effect cannot be what it claims ('' if it can): e.g. a distortion too large for a
        calibrated capture volume is something else the field is absorbing."""
        return ""

    def stands_out(self, proposal: Proposal, gain: float) -> bool:
        """Whether `gain` (criterion units), what the fitted effect gains, stands clear of what noise alone would give
        this effect beyond the criterion's charge for its parameters: always, unless the effect knows its gain's
        spread under noise (a delay, :meth:`identcheck.effects.time_offset.TimeOffset.stands_out`). The backward
        check keeps an adopted effect by the forward rule and this."""
        return True

    def evidence(self, ctx, before, after, proposal: Proposal) -> dict:
        """Arrays that show the effect (for the figures): by default the proposal's own."""
        return dict(proposal.payload.get("evidence", {}))
