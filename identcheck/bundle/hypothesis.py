"""A hypothesis about a trial: the rigid-joint chain plus the effects adopted so far, fitted.

Effects change a hypothesis in one of four ways: extra terms in the chain (:class:`~.chain.Terms`),
corrected data (labels swapped back, a delay undone), weights (gross errors dropped), or a joint
re-declared. Every hypothesis is scored on the same measured samples, so that they compare: a sample
an effect sets aside counts as three parameters spent, not as a sample removed.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.skeleton import Skeleton
from identcheck.bundle.anatomical_angles import anatomical_angles
from identcheck.bundle.chain import fit_chain
from identcheck.bundle.converge import converged_fit
from identcheck.bundle.model import Fit, State, Terms, forward
from identcheck.bundle.score_test import RefitProjection
from identcheck.bundle.start import PICK_ITER, better_start, start_state
from identcheck.errors import DegenerateError, InputError
from identcheck.estimate.noise import NoiseFloor

SCREEN_ITER = 6          # LM iterations when screening a candidate (warm start)
POLISH_ITER = 40         # LM iterations a candidate is fitted on for to be compared and checked (Hypothesis.polish)
CONSISTENCY_MARGIN = 0.02
"""Allowance on gap²/floor² beyond its sampling spreads before the residual counts as unexplained
(1 % of the gap): the floor's model of noise (white, isotropic, the same on every marker) is never
exact."""


@dataclass(frozen=True)
class Context:
    """What every step of a diagnosis shares: the model, the raw trial, the noise and its sample count."""

    model: object
    labels: tuple
    rate_hz: float
    raw: np.ndarray              # (F, M, 3) as measured, NaN = occluded
    noise: NoiseFloor
    n_samples: int               # visible marker samples of the raw trial
    source: str = ""
    every_start: bool = False
    """Fresh starts (:meth:`Hypothesis.restarted`) are taken from the best of the closed-form combinations
    (:func:`~identcheck.bundle.start.better_start`), not the first: set when the rigid fit's first combination
    settled above another's by more than :attr:`start_margin` (the first is then known to lead this trial's fits
    astray)."""

    @property
    def n_obs(self) -> int:
        return 3 * self.n_samples

    @property
    def start_margin(self) -> float:
        """mm²: how much lower one start's fit must end than another's to count as another minimum (the noise's
        variance times one parameter's charge, ``ln 3N``); starts that reach one minimum differ by 1e-10 of it."""
        return float(self.noise.sigma_mm ** 2 * np.log(self.n_obs))

    def rss(self, h: "Hypothesis") -> float:
        """What a hypothesis leaves unexplained, as the noise model sees it: its residual sum of squares
        prewhitened with the noise's lag-1 coefficient (:func:`whitened_rss`; the plain RSS for white noise)."""
        return h.rss if self.noise.lag1 <= 0 else whitened_rss(h.residuals(), h.weights, self.noise.lag1)

    def rss_terms(self, h: "Hypothesis") -> np.ndarray:
        """The terms of :meth:`rss` of each sample (F, M) (:func:`whitened_terms`)."""
        return whitened_terms(h.residuals(), h.weights, max(float(self.noise.lag1), 0.0))

    @property
    def smooth_share(self) -> float:
        """The share of a smooth residual's sum of squares that :meth:`rss` counts: ``(1 − φ)/(1 + φ)`` under
        serially correlated noise of lag-1 coefficient φ (prewhitening keeps that much of a slow component), 1
        under white noise. A detector that estimates what a smooth effect explains from the plain residual
        scales its estimate by this to put it on the criterion's scale."""
        phi = max(float(self.noise.lag1), 0.0)
        return (1.0 - phi) / (1.0 + phi)

    def kept_share(self, field: np.ndarray, weights: np.ndarray) -> float:
        """The share of a displacement field's weighted sum of squares (F, M, 3) that :meth:`rss` counts: 1 under
        white noise, :attr:`smooth_share` for a field constant in time, more for one that changes faster. A detector
        that estimates what a change explains from the plain residual scales its estimate by this share of the change
        it would fit."""
        w = np.asarray(weights, dtype=float)
        plain = float(np.sum(np.where((w > 0)[..., None], w[..., None] * np.nan_to_num(field) ** 2, 0.0)))
        if self.noise.lag1 <= 0 or plain <= 0:
            return 1.0
        return whitened_rss(np.nan_to_num(field), weights, self.noise.lag1) / plain

    def bic_gain(self, explained_mm2: float, n_params: int) -> float:
        """Bayesian information criterion gain with the noise known: the squared residual a change
        explains over σ², less ln(3N) per parameter it costs; > 0 means it earns its parameters."""
        return float(explained_mm2 / self.noise.sigma_mm ** 2 - n_params * np.log(self.n_obs))


@dataclass
class Hypothesis:
    """The chain, its terms, the (corrected) data and weights it is fitted to, and the fit."""

    chain: Skeleton
    terms: Terms
    data: np.ndarray
    weights: np.ndarray
    fit: Fit
    extra_params: float = 0      # discrete choices, set-aside samples and charges, counted as parameters
    effects: list = field(default_factory=list)

    @property
    def rss(self) -> float:
        return self.fit.rss

    def n_params(self) -> int:
        return self.fit.n_params + self.extra_params

    def gap(self, ctx: Context) -> float:
        """RMS 3-D distance over every measured sample (set-aside samples count as explained), mm."""
        return float(np.sqrt(self.rss / ctx.n_samples))

    def floor(self, ctx: Context) -> float:
        return ctx.noise.floor(ctx.n_samples, self.n_params())

    def residuals(self) -> np.ndarray:
        """Measured minus predicted, (F, M, 3), NaN where occluded (uses the corrected data)."""
        return self.data - self.fit.pred

    @cached_property
    def projection(self) -> RefitProjection:
        """What a refit of this hypothesis absorbs of a field of marker displacements (the score tests' projection,
        :mod:`identcheck.bundle.score_test`), built when first asked for: the detectors of a round of ``diagnose`` all
        ask at the round's hypothesis (a delay's, a distortion's, a moving centre's and each hinge's second rotation),
        and each had built its own, 0.06 s at 1500 frames, where one gives the same. A hypothesis's fit and weights are
        not replaced once made (:meth:`refit` and :func:`dataclasses.replace` make new ones)."""
        return RefitProjection(self.fit, self.weights)

    def forget_projection(self) -> None:
        """Let go of :attr:`projection` (built again if asked for): it holds the fit's derivatives and the frames'
        inverse factors (a 42-marker body at 1500 frames: 53 and 13 MB), which the candidates' refits and the
        hypotheses kept for later rounds do not need (a delay's share of the noise is read in its proposal)."""
        self.__dict__.pop("projection", None)

    def refit(self, terms: Terms | None = None, data=None, weights=None, chain: Skeleton | None = None,
              state: State | None = None, extra_params: int = 0, effect=None,
              max_iter: int = SCREEN_ITER) -> "Hypothesis":
        """A new hypothesis with the given changes, fitted from this one's state (warm start)."""
        terms = self.terms if terms is None else terms
        state = (state or self.fit.state).copy()
        state.term_params = carry_params(self.terms, self.fit.state.term_params, terms)
        data = self.data if data is None else data
        weights = self.weights if weights is None else weights
        chain = chain or self.chain
        fit = fit_chain(chain, data, state, terms, weights, max_iter=max_iter)
        return Hypothesis(chain, terms, data, weights, fit, self.extra_params + extra_params,
                          self.effects + ([effect] if effect is not None else []))

    def restarted(self, ctx: Context, data: np.ndarray | None = None, weights: np.ndarray | None = None,
                  chain: Skeleton | None = None, max_iter: int = SCREEN_ITER, **changes) -> "Hypothesis | None":
        """This hypothesis (terms and their parameters) refitted to `data` and `weights` (default: its own), on
        `chain` (default: its own), from a fresh start of the poses and constants
        (:func:`~identcheck.bundle.start.start_state` on the samples of weight > 0, or the best combination of the
        closed-form starts when :attr:`Context.every_start`), or None when they cannot start one. `changes`: as
        :meth:`refit` takes them (``extra_params``, ``effect``)."""
        data = self.data if data is None else data
        weights = self.weights if weights is None else weights
        chain = chain or self.chain
        seen = np.where((weights > 0)[..., None], data, np.nan)
        state = better_start(ctx.model, chain, seen, weights, ctx.rate_hz, ctx.start_margin, ctx.source) \
            if ctx.every_start else None
        if state is not None:
            # fitted as far as the combinations were compared before the caller's short refit (a candidate screened
            # in 8 iterations): from the bare start it would be judged where it is still highest
            state = fit_chain(chain, data, state, weights=weights, max_iter=PICK_ITER).state
        try:
            state = state if state is not None else start_state(ctx.model, chain, seen, ctx.rate_hz, ctx.source)
        except (DegenerateError, InputError):
            return None
        return self.refit(data=data, weights=weights, chain=chain, state=state, max_iter=max_iter, **changes)

    def refit_corrected(self, ctx: Context, data: np.ndarray, weights: np.ndarray, max_iter: int = SCREEN_ITER,
                        **changes) -> "Hypothesis":
        """This hypothesis refitted to corrected `data` and `weights` (labels swapped back, a delay undone) from its
        own state and from a fresh start (:meth:`restarted`), whichever leaves less unexplained (:meth:`Context.rss`).

        Why both: this hypothesis's state is bent to what the correction undid, and a fresh start may fall into
        another minimum. A thigh 4 frames late in gait: the rigid fit had turned the hip and knee angles to the lag;
        refitted from it with the lag undone, 8 iterations ended at 262 000 mm² and scored 145 000 criterion units
        below the fit a fresh start reached in 8 (12 400 mm², the noise's share; held-out draw 48, trial 36). Two
        pelvis markers swapped in a sit-to-stand (anatomical markers, two on the shank): from a fresh start the
        swap-corrected fit stopped at 140 000 mm² and scored below the rigid fit, from the rigid fit's state at
        48 000 (held-out draw 49, trial 63)."""
        warm = self.refit(data=data, weights=weights, max_iter=max_iter, **changes)
        try:
            fresh = self.restarted(ctx, data, weights, max_iter=max_iter, **changes)
        except (np.linalg.LinAlgError, ValueError):       # a fresh start that fails leaves the warm fit
            fresh = None
        return warm if fresh is None or ctx.rss(fresh) >= ctx.rss(warm) else fresh

    def polish(self, max_iter: int = POLISH_ITER) -> "Hypothesis":
        """The same hypothesis fitted on for at most `max_iter` iterations: near convergence, as the search
        needs to compare candidates (the final model is taken all the way by :meth:`converged`)."""
        fit = fit_chain(self.chain, self.data, self.fit.state, self.terms, self.weights, max_iter=max_iter)
        return replace(self, fit=fit)

    def converged(self, progress=None) -> "Hypothesis":
        """The same hypothesis fitted to convergence by ``fit``'s rule
        (:func:`~identcheck.bundle.converge.converged_fit`: restarted within a time budget; a fit that still has
        not converged is no maximum of the likelihood, and its joints claim no interval)."""
        fit = converged_fit(self.chain, self.data, self.fit.state, progress, self.weights, self.terms)
        return replace(self, fit=fit)


def carry_params(old: Terms, params: list, new: Terms) -> list:
    """Parameters for `new` terms: those it shares with `old` (the same term objects) keep their values."""
    by_id = {id(t): p for t, p in zip(old.ordered(), params)}
    return [np.array(by_id[id(t)]) if id(t) in by_id else np.zeros(shape)
            for t, shape in zip(new.ordered(), new.shapes())]


def whitened_rss(resid: np.ndarray, weights: np.ndarray, phi: float) -> float:
    """Σ over every marker coordinate's series of ``(e_t − φ e_{t−1})² / (1 − φ²)`` (a run's first sample:
    ``e_t²``), e the residual (F, M, 3) times √weight, a gap or a set-aside sample ending the run.

    Minus twice the AR(1) log-likelihood up to constants, in the units of an RSS (its expectation under
    noise alone is σ² per sample, as for white noise), so that BIC with correlated noise is the plain
    formula with this in place of the RSS. Smooth residual is worth (1 − φ)/(1 + φ) of its plain sum of
    squares, so slow correlated noise no longer passes for soft tissue or a translating joint, while a
    spike or a step is worth as much as before or more."""
    return float(np.sum(whitened_terms(resid, weights, phi)))


def whitened_terms(resid: np.ndarray, weights: np.ndarray, phi: float) -> np.ndarray:
    """The terms of :func:`whitened_rss` summed over each sample's three coordinates (F, M): where in the trial, and
    on which marker, a change of the fit gains or loses (``phi`` 0: the weighted squared residual)."""
    w = np.asarray(weights, dtype=float)
    e = np.where((w > 0)[..., None], resid * np.sqrt(np.maximum(w, 0.0))[..., None], np.nan)
    prev = np.concatenate([np.full_like(e[:1], np.nan), e[:-1]])
    innov = np.where(np.isfinite(prev), e - phi * prev, np.sqrt(1 - phi ** 2) * e)
    return np.nansum(innov ** 2, axis=2) / (1 - phi ** 2)


def score(ctx: Context, new: Hypothesis, old: Hypothesis) -> float:
    """:meth:`Context.bic_gain` of going from ``old`` to ``new``: ΔRSS/σ² − ΔP·ln(3N), the RSS prewhitened
    for correlated noise (:meth:`Context.rss`)."""
    return ctx.bic_gain(ctx.rss(old) - ctx.rss(new), new.n_params() - old.n_params())


def consistency(ctx: Context, h: Hypothesis) -> dict:
    """The stated test that the residual is noise: RSS/σ² (prewhitened, :meth:`Context.rss`) is χ²(ν), ν = 3N − P, so gap²/floor² ≈ 1 with
    spread √(2/ν); σ itself is estimated with relative standard error s, which moves the ratio by 2s.
    Consistent when ratio ≤ 1 + 3√(2/ν) + 4s + :data:`CONSISTENCY_MARGIN` (about 3 and 2 standard
    errors). A trial that fails it only by chance still adopts nothing unless an effect earns its
    parameters (:func:`score`)."""
    nu = max(ctx.n_obs - h.n_params(), 1)
    ratio = ctx.rss(h) / (nu * ctx.noise.sigma_mm ** 2) if ctx.noise.sigma_mm > 0 else np.inf
    limit = 1 + 3 * np.sqrt(2 / nu) + 4 * ctx.noise.rel_se + CONSISTENCY_MARGIN
    return {"ratio": float(ratio), "limit": float(limit), "dof": int(nu), "consistent": bool(ratio <= limit)}


# ---------------------------------------------------------------------- joint angles
def joint_angles(h) -> dict:
    """Each joint's angles from the fit of a :class:`Hypothesis` or a :class:`~identcheck.bundle.chain.Fit`:
    a hinge's angle (F, 1); a ball joint's rotation vector relative to its median pose, in the parent frame
    (F, 3); radians."""
    fit = getattr(h, "fit", h)
    s, chain = fit.state, fit.chain
    out = {}
    for j in chain.joints:
        if chain.types[j] == "revolute":
            out[j] = s.theta[j][:, None]
        else:
            rel = s.rel_R[j]
            ref = Rotation.from_matrix(rel).mean().as_matrix()
            out[j] = Rotation.from_matrix(rel @ ref.T).as_rotvec()
    return out


DRIVING_SMOOTHING_S = 0.04
"""Standard deviation (s) of the Gaussian that smooths the fitted joint angles before a translating joint's and
skin's smooth functions of them are built (:func:`driving_angles`, :func:`smoothed_in_time`'s local quadratic): it
passes the motion (at 1 Hz 99.9 % of the amplitude, at 2 Hz 99 %) and takes out most of the frame-to-frame noise
the fitted angles carry (white noise at 100 Hz: to 0.37 of its standard deviation, none of it the frame's own)."""


MAX_NOISE_GAIN = 1.0
"""The most noise a frame's smoothed value may carry, relative to one sample's (white noise): a quadratic or a line
fitted to neighbours on one side only extrapolates (a frame at an end: 1.17 for the quadratic at 4 frames; beyond a
long gap with three neighbours 14-16 frames off: 275), and then a lower order is fitted; the weighted mean of the
neighbours never passes more than one sample's."""


def smoothed_in_time(x: np.ndarray, width_frames: float) -> np.ndarray:
    """`x` (F, ...) smoothed along axis 0: at each frame, the value at that frame of a quadratic fitted to the frames
    around it, weighted by a Gaussian of standard deviation `width_frames` (at least half a frame; cut at four of
    them), the frame's own sample left out. NaN (or infinite) frames are left out of their neighbours' fits and left
    NaN; where the quadratic would pass more of the noise than one sample carries (:data:`MAX_NOISE_GAIN`: neighbours
    on one side, or at fewer than three offsets) a line is fitted instead, or else their weighted mean, and a frame
    with no neighbour keeps its own value.

    Why its own sample out: what is smoothed is fitted per frame (a joint's angle), and its noise is that frame's
    measurement noise; functions of it fitted to the same frame's markers fit that noise, however small its share
    (a centre weight of 0.1 at 4 frames). Left out, white noise has no part in the frame's own value, and noise
    correlated in time (AR(1), φ 0.9) less. Skin on a shank's three markers each its own way, beside a knee
    translating with its angle (the simulator's, seed 3; white noise, 1 500 frames), fitted to convergence: 1 416
    criterion units more with functions of the fitted angles than with the same functions of the true angles, 121
    less with these. Why a quadratic: a weighted mean of the neighbours lags a motion near an end or a gap, where
    they lie on one side, and flattens its peaks everywhere (by 3.5 % at 1 Hz and 13 % at 2 Hz at 0.04 s), and a
    smooth function of the flattened angle misses the same function of the angle: skin moving 9 mm with gait-like
    angles (1 and 2 Hz), fitted on functions of the smoothed angles, missed by 0.23 mm RMS (2.1 mm at worst, at an
    end) with the Gaussian mean, 0.27 (3.9) with the mean of the neighbours, 0.042 with this quadratic (2.0 at a
    first or last frame, where a line is fitted: a quadratic there passes more noise than the sample); away
    from the ends it passes 0.37 of white noise's standard deviation (the Gaussian mean 0.27), at most 1."""
    from scipy.ndimage import correlate1d

    width = max(float(width_frames), 0.5)
    reach = max(int(4.0 * width + 0.5), 1)
    k = np.arange(-reach, reach + 1, dtype=float)
    w = np.exp(-0.5 * (k / width) ** 2)
    w[reach] = 0.0                                        # each frame's own sample out of its fit
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    xv, okv = np.where(ok, x, 0.0), ok.astype(float)
    S = [correlate1d(okv, w * k ** p, axis=0, mode="constant") for p in range(5)]       # Σ w kᵖ over the neighbours
    Q = [correlate1d(okv, w * w * k ** p, axis=0, mode="constant") for p in range(5)]   # Σ w² kᵖ: the noise passed
    T = [correlate1d(xv, w * k ** p, axis=0, mode="constant") for p in range(3)]        # Σ w kᵖ x(t + k)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # each fit's value at 0 is Σ w(k) (a₀ + a₁k + a₂k²) x(t + k), a the first row of its normal matrix's inverse
        # (cofactors over the determinant); the noise it passes, relative to one sample's, is √(Σ w² (a·kᵖ)²)
        cof = [S[2] * S[4] - S[3] ** 2, S[2] * S[3] - S[1] * S[4], S[1] * S[3] - S[2] ** 2]
        det3 = S[0] * cof[0] + S[1] * cof[1] + S[2] * cof[2]
        a3 = [c / det3 for c in cof]
        det2 = S[0] * S[2] - S[1] ** 2
        a2 = [S[2] / det2, -S[1] / det2]
        fits = []
        for a, det, scale in ((a3, det3, S[0] * S[2] * S[4]), (a2, det2, S[0] * S[2]), ([1.0 / S[0]], S[0], 1.0)):
            value = sum(a[i] * T[i] for i in range(len(a)))
            gain = sum(a[i] * a[j] * Q[i + j] for i in range(len(a)) for j in range(len(a)))
            solvable = det > 1e-9 * np.maximum(scale, 1e-300)         # neighbours at as many offsets as it has terms
            fits.append((value, solvable & np.isfinite(value) & (gain <= MAX_NOISE_GAIN ** 2)))
    (quad, quad_ok), (line, line_ok), (mean, _) = fits          # (the mean passes at most one sample's noise)
    at_zero = np.select([quad_ok, line_ok, S[0] > 0], [quad, line, mean], default=x)
    return np.where(ok, at_zero, np.nan)


def driving_angles(h, rate_hz: float) -> dict:
    """:func:`joint_angles` smoothed in time, each frame's own angle left out (:func:`smoothed_in_time`,
    :data:`DRIVING_SMOOTHING_S`): the angles a translating joint's fields and skin's functions are built from
    (:mod:`identcheck.effects.joint_translation`, :mod:`identcheck.effects.soft_tissue`).

    Why smoothed: the fitted angles carry the measurement noise of the frames they are fitted to. Where a joint
    barely turns about an axis, that component is mostly noise (a hip in gait: 7.5° of axial rotation against 0.4°
    of noise; a hip that only flexed: all noise), and the translation's fields linear in it are kept exactly
    because no centre shift absorbs noise. The refit then explains noise with them: on rigid data with white noise
    a hip's centre moving with its angles gained 502 criterion units (31 parameters) in a held-out gait trial, 900
    to 1 450 in five of eight single-axis hips, and −185 to −300 with the angles smoothed (−285 with the true
    angles). Skin terms (:mod:`identcheck.effects.soft_tissue`) are built from them too: with the fitted angles a
    skin term fits the noise the rigid fit left in them, with ever larger vectors as it is fitted on (a knee centre
    translating 9 mm in gait, held-out draw 93, trial 100: a shank cluster's skin scored 1 458 after 10 iterations and
    1 512 after 40, the shank's markers each their own way 1 197, 1 584 and 2 494 after 10, 40 and 200, its vectors
    300 mm long and the knee's axis turned 10°, against 1 469 for the true translation; with these angles: the
    cluster 1 355, each its own way 1 196 and 1 267, settled by 40, and the translation, 1 426, named). The local
    quadratic of :func:`smoothed_in_time` keeps a motion's peaks (it passes 99.9 % of a 1 Hz motion at 0.04 s)."""
    return {j: smoothed_in_time(a, DRIVING_SMOOTHING_S * rate_hz) for j, a in joint_angles(h).items()}


def main_angle(h, joint: str) -> tuple[np.ndarray, str]:
    """The angle a figure puts on its axis for `joint` (F,) in degrees, and its label: a hinge's own angle (its
    flexion); a ball joint's flexion–extension in its joint frames (:mod:`identcheck.bundle.anatomical_angles`:
    about the medio-lateral axis a hinge below it gives, in the ISB pelvis frame below a pelvis), not one
    component of a rotation vector."""
    fit = getattr(h, "fit", h)
    if fit.chain.types[joint] == "revolute":
        return np.rad2deg(fit.state.theta[joint]), f"{joint} flexion–extension: its hinge angle (deg)"
    angles, frames = anatomical_angles(fit, joint)
    return (np.rad2deg(angles[:, 0]),
            f"{joint} flexion–extension (deg)\nabout {frames.medio_lateral}; 0 at {frames.zero}")


def rescale(values: np.ndarray, low: float = -1.0) -> np.ndarray:
    """Each column of `values` mapped linearly from its [min, max] to [low, 1] (a column that does not move
    maps to `low`): the one angle scaling of the soft-tissue and joint-translation models, used both to
    inject them and to detect them."""
    lo, hi = values.min(axis=0), values.max(axis=0)
    unit = (values - lo) / np.where(hi > lo, hi - lo, 1.0)
    return low + (1.0 - low) * np.where(hi > lo, unit, 0.0)


def angle_basis(angles: np.ndarray, linear: bool = True, cubic: bool = False) -> np.ndarray:
    """Smooth functions of a joint's angles (F, n), each angle scaled to [-1, 1]: the angles themselves
    (unless `linear` is False), every product of two of them and, with `cubic`, each angle's cube, centred;
    (F, n + n(n+1)/2 [+ n]) or (F, n(n+1)/2 [+ n]). The shape of soft-tissue motion and of a translating
    joint."""
    a = np.where(np.ptp(angles, axis=0) > 0, rescale(angles, low=-1.0), 0.0)   # an angle that does not move: no term
    i, j = np.triu_indices(a.shape[1])
    parts = [a] if linear else []
    parts.append(a[:, i] * a[:, j])
    if cubic:
        parts.append(a ** 3)
    out = np.concatenate(parts, axis=1)
    return out - out.mean(axis=0) * (np.arange(out.shape[1]) >= (a.shape[1] if linear else 0))


TIME_KNOT_S = 0.2
"""Knot spacing of the smooth functions of time (cubic B-splines: motion up to about 2 Hz)."""


def time_basis(n_frames: int, rate_hz: float, spacing_s: float = TIME_KNOT_S) -> np.ndarray:
    """Smooth functions of time (F, K): cubic B-splines with knots every `spacing_s`, centred, one dropped so
    that no combination is constant (a constant is a change of the constants, not a motion). The shape of
    a joint's extra rotation when nothing says what drives it."""
    from scipy.interpolate import BSpline

    n_knots = max(int(np.ceil(n_frames / max(spacing_s * rate_hz, 1.0))), 1)
    inner = np.linspace(0.0, n_frames - 1.0, n_knots + 1)
    knots = np.concatenate([[inner[0]] * 3, inner, [inner[-1]] * 3])
    B = BSpline.design_matrix(np.arange(n_frames, dtype=float), knots, 3).toarray()
    B = B[:, 1:] - B[:, 1:].mean(axis=0)
    return B


def segment_residuals(h: Hypothesis) -> np.ndarray:
    """Each marker's residual in its own segment's frame, (F, M, 3), NaN where occluded or weighted out."""
    r = h.residuals()
    out = np.full_like(r, np.nan)
    for seg in h.chain.segments:
        idx = h.chain.seg_markers[seg]
        out[:, idx] = np.einsum("fji,fkj->fki", h.fit.seg_R[seg], r[:, idx])
    out[h.weights <= 0] = np.nan
    return out


def centre_world(h: Hypothesis, joint: str) -> np.ndarray:
    """The joint's centre (a hinge: its point nearest the parent frame's origin) in the world, (F, 3)."""
    _, _, centre, _ = forward(h.chain, h.terms, h.fit.state)
    return centre[joint]
