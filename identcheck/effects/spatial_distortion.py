"""``spatial_distortion``: the capture volume is distorted by a smooth field (calibration error).

A rigid body moved through a distorted volume appears to stretch; the part of a smooth field that a
rigid motion cannot absorb is its strain. The field is modelled as ``f(u) = E u + Σ q_k m_k(u)``
over normalised coordinates ``u`` of the volume the markers occupy: E symmetric and traceless (a
rotation or uniform scale would be absorbed by the segments; 5 parameters), the 6 quadratic monomials
times 3-vectors (18) and the 10 cubic ones (30 more). Three hypotheses, each degree's fields beginning with
the degree below: the strain alone (5), up to degree 2 (23) and up to degree 3 (53); the criterion decides
which earns its parameters. Degree 3 holds the lens-like fields: a radial distortion ``|u − c|² (u − c)``
about any centre c is a cubic polynomial in u; over the metre or so a subject occupies, most of what a lens
changes in the segments' shapes is its strain, which the 5-field hypothesis names at a tenth of the cost.
Detector: the residuals regressed on the fields; for the strain, the score statistic with what a rigid refit
absorbs taken out (:func:`strain_explained`). Augmentation: the fields added to every prediction, their
coefficients fitted with everything else. A smooth field moves every marker by where it is, a slip one marker
from one instant on: the two compete on that difference through the same criterion.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.chain import score_statistic
from identcheck.bundle.model import Terms
from identcheck.effects.base import Effect, Proposal, motion_rms_mm, world_coefficients
from identcheck.effects.injection import MONOMIALS, Change, cannot, monomials

MAX_AMPLITUDE_MM = 25.0
"""A calibrated volume is not distorted by more than this; a larger fitted field is absorbing something
else (soft tissue on real data does this)."""

_STRAIN = [np.diag([1.0, -1.0, 0.0]), np.diag([1.0, 1.0, -2.0]) / np.sqrt(3),
           np.array([[0, 1.0, 0], [1, 0, 0], [0, 0, 0]]), np.array([[0, 0, 1.0], [0, 0, 0], [1, 0, 0]]),
           np.array([[0, 0, 0], [0, 0, 1.0], [0, 1, 0]])]


def volume(data: np.ndarray):
    """Centre and half-extent (per axis, ≥ 1 mm) of the volume the visible markers occupy."""
    lo, hi = np.nanmin(data, axis=(0, 1)), np.nanmax(data, axis=(0, 1))
    return (lo + hi) / 2, np.maximum((hi - lo) / 2, 1.0)


def cubic_monomials(u: np.ndarray) -> np.ndarray:
    """The 10 cubic monomials (x³, y³, z³, x²y, x²z, y²x, y²z, z²x, z²y, xyz) of points (..., 3), (..., 10)."""
    x, y, z = u[..., 0], u[..., 1], u[..., 2]
    return np.stack([x ** 3, y ** 3, z ** 3, x * x * y, x * x * z, y * y * x, y * y * z, z * z * x, z * z * y,
                     x * y * z], axis=-1)


def fields(data: np.ndarray, degree: int = 2, box=None) -> list:
    """The distortion fields at the positions `data` (F, M, 3), each (F, M, 3) mm per unit coefficient: the 5
    strains of degree 1, 23 up to degree 2, 53 up to degree 3 (each degree's fields begin with those of the degree
    below). `box`: the volume's (centre, half-extent) (:func:`volume`), when `data` is part of a trial (default: the
    volume of `data` itself)."""
    c, h = volume(data) if box is None else box
    u = np.nan_to_num((data - c) / h)
    scale = float(np.mean(h))
    out = [scale * np.einsum("ij,fmj->fmi", E, u) for E in _STRAIN]
    if degree < 2:
        return out
    mono_all = monomials(u) if degree < 3 else np.concatenate([monomials(u), cubic_monomials(u)], axis=-1)
    for k in range(mono_all.shape[-1]):
        mono = mono_all[..., k]
        for d in range(3):
            f = np.zeros_like(u)
            f[..., d] = mono
            out.append(f)
    return out


FIELDS = {1: 5, 2: 23, 3: 53}
"""How many fields each degree has."""
CHUNK_ROWS = 8192
"""Rows of the design matrix (marker coordinates) formed at a time by :func:`explained`."""


def explained(data: np.ndarray, seen: np.ndarray, res: np.ndarray) -> dict:
    """For each degree, the squared norm of the least-squares fit of the residuals `res` (F, M, 3; 0 where not
    `seen`) by that degree's fields (0 where not seen): ``{degree: ‖X c‖²}`` with ``c = lstsq(X, res)``, X the
    fields as columns.

    X (F·M·3 rows, 53 columns: 80 MB for a 42-marker body at 1500 frames) is never formed whole: its QR factor R
    is accumulated over chunks of frames (each chunk's rows stacked under the R so far and factored again), with
    Qᵀres beside it. The fields of degrees 1 and 2 being the first 5 and 23 columns, R's leading blocks and
    Qᵀres's leading entries give those degrees' fits too; the small problems are solved by the same least squares
    with the cut-off a whole X would have had (``rcond`` = machine epsilon × rows), so singular directions are
    dropped as before."""
    F, M = seen.shape
    box = volume(data)
    step = max(1, CHUNK_ROWS // max(3 * M, 1))
    R, z = np.zeros((0, FIELDS[3])), np.zeros(0)
    for f0 in range(0, F, step):
        f = slice(f0, f0 + step)
        X = np.stack([np.where(seen[f, :, None], fld, 0.0).reshape(-1) for fld in fields(data[f], 3, box)], axis=1)
        Q, R = np.linalg.qr(np.vstack([R, X]))
        z = Q.T @ np.concatenate([z, res[f].reshape(-1)])
    rcond = np.finfo(float).eps * max(3 * F * M, FIELDS[3])
    out = {}
    for degree, k in FIELDS.items():
        Rk = R[:k, :k]
        coef = np.linalg.lstsq(Rk, z[:k], rcond=rcond)[0]
        out[degree] = float(np.sum((Rk @ coef) ** 2))
    return out


def where_fields_act(hyp) -> np.ndarray:
    """The positions the fields are evaluated at: the markers as hypothesis `hyp` predicts them (NaN where not
    seen), not as measured. A field evaluated at measured positions carries the noise itself (a linear field
    ``E x`` of ``x + e`` adds ``E e``), which its fit can use to take some of the noise out: on a held-out gait
    trial walked overground (a volume much longer than high) with serially correlated noise and nothing a
    distortion could explain, the strain scored 82 at measured positions and −47 at the noise-free ones."""
    return np.where((hyp.weights > 0)[..., None], hyp.fit.pred, np.nan)


def strain_explained(hyp, res: np.ndarray, at: np.ndarray | None = None) -> float:
    """What a refit with the 5 strain fields (degree 1, made at the positions `at`, by default
    :func:`where_fields_act`) would explain of the residual `res` of hypothesis `hyp`, to first order: the score
    statistic ``nᵀ G⁺ n`` with ``n_i = f_iᵀ W res`` and G the Gram matrix of the fields' parts the rigid refit
    cannot absorb (:func:`~identcheck.bundle.chain.unabsorbed_gram`).

    Regressing the residual on the fields themselves (:func:`explained`) understates it: a segment's pose and
    constants absorb most of a linear field over the little volume it sweeps, and that part is already gone from
    the residual. On a held-out trial a single-axis scale error of 4 mm read as 0 this way, while the refit with
    the strain gained 491 in the criterion's units."""
    flds = fields(where_fields_act(hyp) if at is None else at, 1)
    return score_statistic(hyp.fit, hyp.weights, res, flds)


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

    max_proposals = 3

    def propose(self, ctx, hyp) -> list:
        if any(getattr(e, "effect", "") == self.name for e in hyp.effects):
            return []                        # the volume has its field already
        w = hyp.weights > 0
        res = np.where(w[..., None], np.nan_to_num(hyp.residuals()), 0.0)
        at = where_fields_act(hyp)
        out = []
        found = explained(at, w, res)
        # at a converged fit the score statistic is never below the plain regression; short of it, keep the larger
        found[1] = max(found[1], strain_explained(hyp, res, at))
        for degree, fit_mm2 in found.items():
            gain = ctx.bic_gain(fit_mm2, FIELDS[degree])
            if gain > 0:                          # the fields are made again at these positions if it is applied
                out.append(Proposal(self.name, {"degree": degree}, gain, {"data": at}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        cols = np.arange(hyp.chain.n_markers)
        flds = fields(proposal.payload["data"], proposal.where["degree"])
        terms = Terms(world=[(cols, f) for f in flds])
        new = hyp.refit(terms=hyp.terms + terms, effect=proposal, max_iter=10)
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
        coefficients = world_coefficients(hyp, flds)
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
