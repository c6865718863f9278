"""``spatial_distortion``: the capture volume is distorted by a smooth field (calibration error).

A rigid body moved through a distorted volume appears to stretch; the part of a smooth field that a
rigid motion cannot absorb is its strain. The field is modelled as ``f(u) = E u + Σ q_k m_k(u)``
over normalised coordinates ``u`` of the volume the markers occupy: E symmetric and traceless (a
rotation or uniform scale would be absorbed by the segments; 5 parameters), the 6 quadratic monomials
times 3-vectors (18) and the 10 cubic ones (30 more). Degree 3 holds the lens-like fields: a radial distortion
``|u − c|² (u − c)`` about any centre c is a cubic polynomial in u; over the metre or so a subject occupies, most of
what a lens changes in the segments' shapes is its strain. Of the 60 fields, only those the criterion asks for are
proposed (forward selection on the score test's moments, the choice charged: :mod:`identcheck.bundle.score_selection`),
each strain on its own and the quadratic and the cubic fields each as one family (:data:`UNITS`): a scale error along
any axis of the volume needs one field (:data:`SCALED_AXES`), a lens about a centre four (:data:`RADIAL`). Detector: the
score statistic of the fields, with what a rigid refit absorbs taken out (a segment's pose and constants absorb most
of a linear field over the little volume it sweeps), on the criterion's scale for a field as slow as the markers'
motion under correlated noise (:attr:`~identcheck.bundle.hypothesis.Context.smooth_share`; the
per-degree regressions before it read the plain residual). Augmentation: the fields added to every prediction, their
coefficients fitted with everything else. A smooth field moves every marker by where it is, a slip one marker
from one instant on: the two compete on that difference through the same criterion.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.score_test import score_moments_streamed
from identcheck.bundle.score_selection import forward_selection
from identcheck.bundle.model import Terms
from identcheck.effects.base import Effect, Proposal, motion_rms_mm, scalar_coefficients
from identcheck.effects.injection import MONOMIALS, Change, cannot, monomials

MAX_AMPLITUDE_MM = 25.0
"""A calibrated volume is not distorted by more than this; a larger fitted field is absorbing something
else (soft tissue on real data does this)."""

_STRAIN = [np.diag([1.0, -1.0, 0.0]), np.diag([1.0, 1.0, -2.0]) / np.sqrt(3),
           np.array([[0, 1.0, 0], [1, 0, 0], [0, 0, 0]]), np.array([[0, 0, 1.0], [0, 0, 0], [1, 0, 0]]),
           np.array([[0, 0, 0], [0, 0, 1.0], [0, 1, 0]])]
"""The five strains (symmetric, traceless) over the volume's normalised coordinates."""
SCALED_AXES = (0, 1, 2)
"""The axes along which a scale of the volume, less its uniform part, is also a field of its own (after the five
strains): ``(e eᵀ − I/3)(x − c)`` in millimetres, x along the axis e. A volume scaled along one of its axes is a
common calibration error (a wand or an L-frame off along one axis), and the normalised strains span it only in pairs
(their coordinates are scaled by the volume's half-extents, so a scale in millimetres along an axis is no one of
them): such a scale had paid two fields and their choice, and a held-out trial scaled 0.5 % along x (visible χ² 107)
fitted 47.6 with the one field the criterion chose, short of the 50 a trial the consistency test passes asks for.
The three sum to nothing (the uniform scale, which the segments absorb and no fit can tell, is in none of them)."""


def volume(data: np.ndarray):
    """Centre and half-extent (per axis, ≥ 1 mm) of the volume the visible markers occupy."""
    lo, hi = np.nanmin(data, axis=(0, 1)), np.nanmax(data, axis=(0, 1))
    return (lo + hi) / 2, np.maximum((hi - lo) / 2, 1.0)


_EXPONENTS = ((2, 0, 0), (0, 2, 0), (0, 0, 2), (1, 1, 0), (1, 0, 1), (0, 1, 1),            # MONOMIALS' order
              (3, 0, 0), (0, 3, 0), (0, 0, 3), (2, 1, 0), (2, 0, 1), (1, 2, 0), (0, 2, 1), (1, 0, 2), (0, 1, 2),
              (1, 1, 1))
"""The powers of x, y and z in each quadratic monomial (:data:`~identcheck.effects.injection.MONOMIALS`) and each
cubic one (x³, y³, z³, x²y, x²z, y²x, y²z, z²x, z²y, xyz), in the fields' order."""


def monomial(u: np.ndarray, index: int) -> np.ndarray:
    """The `index`-th monomial of :data:`_EXPONENTS` at points `u` (..., 3), shape (...): one product per field
    instead of every monomial of its degree (a trial's 53 fields had cost a 3-joint diagnosis 0.3 s that way)."""
    out = np.ones(u.shape[:-1])
    for axis, power in enumerate(_EXPONENTS[index]):
        for _ in range(power):
            out = out * u[..., axis]
    return out


FIELDS = {1: 8, 2: 26, 3: 56}
"""How many fields each degree has (each degree's fields begin with those of the degree below)."""
RADIAL = tuple(range(FIELDS[3], FIELDS[3] + 4))
"""After the polynomial fields, a lens about an estimated centre: ``k |u − c|² (u − c)`` over the normalised
coordinates, linearised in the centre c about the volume's: ``|u|² u`` (its strength k) and ``−(2 u_a u + |u|² e_a)``
for each axis a (k c_a). Four fields, one unit: the cubic family (30 fields) holds the first and the quadratic one
(18) the others, but a lens paid both families, 48 parameters and their choice, which a lens of a few millimetres does
not earn (held-out draw 87: a radial lens at visible χ² 267 named nothing); as one unit it pays four."""
N_FIELDS = RADIAL[-1] + 1
"""Every field: the polynomial ones (:data:`FIELDS`) and the lens's (:data:`RADIAL`)."""
_CUBIC = ("x^3", "y^3", "z^3", "x^2y", "x^2z", "y^2x", "y^2z", "z^2x", "z^2y", "xyz")
FIELD_NAMES = (["strain xx-yy", "strain xx+yy-2zz", "shear xy", "shear xz", "shear yz", "scale along x",
                "scale along y", "scale along z"]
               + [f"{m} along {d}" for m in MONOMIALS + _CUBIC for d in "xyz"]
               + ["radial", "radial centre x", "radial centre y", "radial centre z"])
"""The 60 fields' names, in :func:`field`'s order: the traceless strains and the scales along x, y and z less their
uniform parts (:data:`SCALED_AXES`), then each quadratic and cubic monomial of the volume's normalised coordinates
(:data:`_EXPONENTS`' order) along each axis, then the lens's four (:data:`RADIAL`)."""


def field(data: np.ndarray, k: int, box=None) -> np.ndarray:
    """The `k`-th distortion field (:data:`FIELD_NAMES`) at the positions `data` (F, M, 3), (F, M, 3) mm per unit
    coefficient (0 where `data` is NaN). `box`: the volume's (centre, half-extent) (:func:`volume`), when `data` is
    part of a trial (default: the volume of `data` itself)."""
    c, h = volume(data) if box is None else box
    u = np.nan_to_num((data - c) / h)
    if k < len(_STRAIN):
        return float(np.mean(h)) * np.einsum("ij,fmj->fmi", _STRAIN[k], u)
    if k < FIELDS[1]:
        scale = -np.eye(3) / 3.0
        scale[SCALED_AXES[k - len(_STRAIN)], SCALED_AXES[k - len(_STRAIN)]] += 1.0
        return np.einsum("ij,fmj->fmi", scale, np.nan_to_num(data - c))
    if k >= FIELDS[3]:
        r2 = np.sum(u * u, axis=-1, keepdims=True)
        if k == RADIAL[0]:
            return r2 * u
        a = k - RADIAL[1]
        out = -2.0 * u[..., a:a + 1] * u
        out[..., a] -= r2[..., 0]
        return out
    mono, d = divmod(k - FIELDS[1], 3)
    out = np.zeros_like(u)
    out[..., d] = monomial(u, mono)
    return out


def fields(data: np.ndarray, degree: int = 2, box=None) -> list:
    """The polynomial distortion fields of degree up to `degree` at the positions `data` (:func:`field`): the 8 strains
    of degree 1, 26 up to degree 2, 56 up to degree 3 (the lens's four, :data:`RADIAL`, come after them)."""
    box = volume(data) if box is None else box
    return [field(data, k, box) for k in range(FIELDS[degree])]


UNITS = ([[k] for k in range(FIELDS[1])] + [list(range(FIELDS[1], FIELDS[2])), list(range(FIELDS[2], FIELDS[3]))]
         + [list(RADIAL)])
"""What the selection of fields chooses among: each strain and each axis's scale on its own (a calibration can be off
along one axis, or sheared between two, alone), the 18 quadratic fields together, the 30 cubic ones together, and the
lens's four (:data:`RADIAL`) together. A monomial field alone
is no shape a calibration error takes, only a piece of a basis for one; chosen one by one, three or four of them
fitted what a few markers do where they happen to pass, and skin moving on a shank or thigh was named a distortion
(held-out draw 52, trials 1 and 81: 3–4 quadratic and cubic fields, scoring 139 against the shank skin's 54)."""
CHUNK_ROWS = 8192
"""Rows of the design matrix (marker coordinates) formed at a time by :func:`plain_gram`."""


def plain_gram(data: np.ndarray, weights: np.ndarray, box) -> np.ndarray:
    """``XᵀWX`` (60, 60) for X the 60 fields at the positions `data` (F, M, 3) as columns, 0 where NaN, and W the
    samples' `weights` (F, M; each marker's three coordinates alike): the plain part of the score test's Gram matrix
    (:func:`~identcheck.bundle.score_test.score_moments_streamed`). X (F·M·3 rows: 80 MB for a 42-marker body at 1500
    frames) is never formed whole, only chunks of frames."""
    F, M = weights.shape
    step = max(1, CHUNK_ROWS // max(3 * M, 1))
    out = np.zeros((N_FIELDS, N_FIELDS))
    for f0 in range(0, F, step):
        f = slice(f0, f0 + step)
        w = np.repeat(np.asarray(weights[f], dtype=float).reshape(-1), 3)
        X = np.stack([field(data[f], k, box).reshape(-1) for k in range(N_FIELDS)], axis=1)
        out += X.T @ (w[:, None] * X)
    return out


def where_fields_act(hyp) -> np.ndarray:
    """The positions the fields are evaluated at: the markers as hypothesis `hyp` predicts them (NaN where not
    seen), not as measured. A field evaluated at measured positions carries the noise itself (a linear field
    ``E x`` of ``x + e`` adds ``E e``), which its fit can use to take some of the noise out: on a held-out gait
    trial walked overground (a volume much longer than high) with serially correlated noise and nothing a
    distortion could explain, the strain scored 82 at measured positions and −47 at the noise-free ones."""
    return np.where((hyp.weights > 0)[..., None], hyp.fit.pred, np.nan)


class SpatialDistortion(Effect):
    name = "spatial_distortion"

    def inject(self, sim, rng) -> Change:
        """A smooth quadratic warp of the capture volume, x + f(x), with max |f| over the data A
        (8-15 mm); f is quadratic in the coordinates scaled to the data's bounding box."""
        x = sim.clean.as_array()
        if x.shape[1] == 0:
            raise cannot(self.name, "the model has no marker")
        centre, half = volume(x)
        mono = monomials((x - centre) / half)
        coef = rng.normal(size=(6, 3))
        size = rng.uniform(8.0, 15.0)
        peak = np.linalg.norm(mono @ coef, axis=-1).max()
        if not peak > 0:
            raise cannot(self.name, "every marker sits at one point")
        coef *= size / peak
        return Change(where={}, params={"amplitude_mm": size, "centre": centre, "half_extent": half,
                                         "coefficients": coef, "monomials": list(MONOMIALS)},
                       clean=x + mono @ coef)

    def propose(self, ctx, hyp) -> list:
        """One proposal: the fields the criterion asks for among the 60 (:func:`~identcheck.bundle.score_selection.
        forward_selection` on the score test's moments over :data:`UNITS`, the choice charged), its strength
        what a refit with them gains to first order, smooth in time like the markers' motion
        (:attr:`~identcheck.bundle.hypothesis.Context.smooth_share`); ``where["degree"]`` the highest degree among
        them, ``where["fields"]`` their names (:data:`FIELD_NAMES`). The three nested families (5, 23 and 53 fields)
        had been proposed whole: a calibration 0.8 % short along the vertical axis under correlated noise (held-out
        draw 50, trial 110) needs one strain field, and the 5 strains scored 47, short of the bar a trial the
        consistency test passes sets (50)."""
        if any(getattr(e, "effect", "") == self.name for e in hyp.effects):
            return []                        # the volume has its field already
        at = where_fields_act(hyp)          # NaN where weighted out: every field is 0 there
        box = volume(at)
        n, G = score_moments_streamed(hyp.fit, hyp.weights, hyp.residuals(),
                                      (field(at, k, box) for k in range(N_FIELDS)), plain_gram(at, hyp.weights, box),
                                      hyp.projection)
        chosen = forward_selection(n, G, UNITS,
                                   lambda stat, m: ctx.bic_gain(ctx.smooth_share * stat, m),
                                   per_param=np.log(ctx.n_obs))
        columns = list(chosen.columns)
        degree = next((d for d, k in FIELDS.items() if columns[-1] < k), 3)          # (the lens is cubic)
        where = {"degree": degree, "fields": [FIELD_NAMES[k] for k in columns]}
        # the fields are made again at these positions if it is applied
        return [Proposal(self.name, where, chosen.gain,
                         {"data": at, "columns": columns, "choice_params": chosen.choice_params})]

    def apply(self, ctx, hyp, proposal):
        cols = np.arange(hyp.chain.n_markers)
        at = proposal.payload["data"]
        box = volume(at)
        flds = [field(at, k, box) for k in proposal.payload["columns"]]
        terms = Terms(world=[(cols, f) for f in flds])
        new = hyp.refit(terms=hyp.terms + terms, effect=proposal, max_iter=10,
                        extra_params=proposal.payload["choice_params"])
        k = len(flds)
        coef = np.array([p[0] for p in new.fit.state.term_params[-k:]])
        disp = np.einsum("k,kfmi->fmi", coef, np.stack(flds))
        proposal.where["amplitude_mm"] = round(float(np.max(np.linalg.norm(disp, axis=2))), 2)
        proposal.payload["displacement"] = disp
        proposal.payload["fields"] = flds           # how scale_sd finds their terms in the final model
        return new

    def scale_sd(self, proposal, hyp) -> float:
        """The relative uncertainty of every length once the volume is found distorted: the field as hypothesis
        `hyp` fits it, its RMS displacement about its mean over the markers' RMS distance from the volume's centre
        (its typical strain).

        The fields leave out a uniform scale (:data:`_STRAIN` is traceless): a world scaled about any point is
        as rigid as the true one, so no fit of rigid segments can see that part of a calibration error, and every
        distance a fit reports carries it whole. A calibration that shows a strain ε in the part it can see has
        no reason to be exact in the part it cannot: the uniform part is taken as of the same size. On a held-out
        trial scaled by 0.74 % along one axis (uniform part 0.25 %), all 16 marker distances came out 0.16-0.33 %
        long, at 95 % intervals of ±0.1-0.4 mm that missed the truth 14 times in 16."""
        flds, at = proposal.payload.get("fields", []), proposal.payload.get("data")
        coefficients = scalar_coefficients(hyp, flds)
        seen = np.zeros((0,), bool) if at is None else np.all(np.isfinite(at), axis=-1)
        if not coefficients or not seen.any():
            return 0.0
        disp = sum(c * flds[k] for k, c in coefficients)
        centre = volume(at)[0]
        reach = float(np.sqrt(np.mean(np.sum((at[seen] - centre) ** 2, axis=-1))))
        moved = motion_rms_mm(disp[seen])           # a uniform shift is no strain: the poses take it up
        return moved / reach if reach > 0 else 0.0

    def implausible(self, proposal) -> str:
        amp = proposal.where.get("amplitude_mm", 0.0)
        return (f"the fitted distortion reaches {amp:.0f} mm (> {MAX_AMPLITUDE_MM:g} mm): not a calibration error"
                if amp > MAX_AMPLITUDE_MM else "")

    def evidence(self, ctx, before, after, proposal) -> dict:
        disp = proposal.payload.get("displacement")
        z = before.data[..., 2].reshape(-1)
        r = np.linalg.norm(np.nan_to_num(before.residuals()), axis=2).reshape(-1)
        return {"x": z, "x_label": "height in the volume, from the trial's median (mm)", "y": r,
                "y_after": None if disp is None else np.linalg.norm(disp, axis=2).reshape(-1),
                "y_label": "residual before (mm); fitted distortion (mm)", "kind": "scatter"}
