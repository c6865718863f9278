"""Score tests of the fitted chain: what a refit with more terms would explain of the residual, to first order,
without refitting.

At a least-squares fit the residual r is orthogonal to everything the model's own unknowns (every per-frame pose
and angle, every constant) can absorb, so the first-order gain of adding fields of marker displacements v_i is the
score statistic ``nᵀ G⁺ n``: ``n_i = v_iᵀ W r`` and G the Gram matrix of the fields' parts the refit does not absorb
(the per-frame unknowns eliminated frame by frame, the constants through the Schur complement, as in the fit:
:mod:`identcheck.bundle.chain`). Regressing the residual on the fields themselves understates it whenever the
model's own unknowns take up part of each field. The detectors of :mod:`identcheck.effects` read their strengths
from these moments. Each function takes the projection as `proj` when the caller has it already (a hypothesis keeps
its own: :attr:`identcheck.bundle.hypothesis.Hypothesis.projection`), else builds it.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.jacobian import jacobian_blocks
from identcheck.bundle.model import Fit, forward
from identcheck.bundle.normal import (coupling_transposed_times, field_gradients, frames_eliminated, lower_inverse,
                                     ridged)


class RefitProjection:
    """What a refit of the model at `fit` absorbs of a field of marker displacements, linearised (every unknown,
    per frame and constant; the per-frame unknowns eliminated as in the fit, Schur complement).
    :meth:`pieces_many` takes fields (F, M, 3, Q) to their pieces ``(v0, z, reduced)``, v0 the fields with NaN and
    unweighted samples set to 0; :meth:`gram` takes them to the inner products of the fields' unabsorbed parts,
    ``v0ᵀWu0 − z_v·z_u − reduced_vᵀ S⁺ reduced_u`` (S⁺ the pseudo-inverse of the constants' Schur complement,
    ``S_plus``, the gauge left free). Built once (a whole normal-equation build and the Schur complement); the
    fields then cost a gradient pass over the blocks they move, and one over every block for their coupling to the
    constants (:func:`~identcheck.bundle.normal.coupling_transposed_times`: B itself is not kept)."""

    def __init__(self, fit: Fit, weights: np.ndarray):
        s = fit.state
        self.w = w = np.array(weights, dtype=float)           # a copy: the caller's array may change later
        R, _t, centre, pred = forward(fit.chain, fit.terms, s)
        self.lay, self.blocks = jacobian_blocks(fit.chain, fit.terms, s, R, centre, pred)
        S, _, A = frames_eliminated(self.lay, self.blocks, w)      # B's products come from the blocks: not kept
        A = ridged(A)
        self.S_plus = np.linalg.pinv(S, rcond=1e-12, hermitian=True)                # the gauge stays free
        self.Linv = lower_inverse(np.linalg.cholesky(A))                            # A⁻¹ = L⁻ᵀL⁻¹

    def pieces_many(self, V: np.ndarray, per_frame: bool = False, owned: bool = False) -> tuple:
        """Q fields V (F, M, 3, Q) (the fields along the last axis, :func:`stacked`) to ``(V0, Z, reduced)`` (see the
        class): V0 (F, M, 3, Q), Z (F, k, Q) and reduced (P, Q), or with `per_frame` (F, P, Q), frame by frame, its
        sum over the frames the plain one (fields scaled frame by frame, :func:`modulated_score_moments`, weight
        it). Their gradients are taken together (:func:`~identcheck.bundle.normal.field_gradients`), and so are the
        per-frame solves. `owned`: V is the caller's to overwrite (a stack of :func:`stacked`), and becomes V0."""
        w = self.w
        keep = (w[..., None, None] > 0) & np.isfinite(V)
        if owned:
            V0 = V
            V0[~keep] = 0.0
        else:
            V0 = np.where(keep, V, 0.0)
        del keep
        moved = np.any(V0 != 0, axis=(0, 2, 3))          # a block whose markers no field moves would add zeros
        g, h = field_gradients(self.lay, [b for b in self.blocks if moved[b.group.cols].any()], V0, w, per_frame)
        z = self.Linv @ g                                                           # L_f⁻¹ g_f (F, k, Q)
        back = self.Linv.transpose(0, 2, 1) @ z                                     # L_f⁻ᵀ z_f
        return V0, z, h - coupling_transposed_times(self.lay, self.blocks, back, w, per_frame)   # h − Σ_f B_fᵀ A_f⁻¹g_f

    def gram(self, V0: np.ndarray, Z: np.ndarray, reduced: np.ndarray) -> np.ndarray:
        """The Gram matrix (Q, Q) of the unabsorbed parts of Q fields, given their :meth:`pieces_many` (not per
        frame): ``v0ᵀWu0 − z_v·z_u − reduced_vᵀ S⁺ reduced_u`` between every two (see the class)."""
        Q = V0.shape[-1]
        X = V0.reshape(-1, Q)
        Zf = Z.reshape(-1, Q)
        plain = X.T @ X if self.unit else (X * np.repeat(self.w.reshape(-1), 3)[:, None]).T @ X
        G = plain - Zf.T @ Zf - reduced.T @ self.S_plus @ reduced
        return (G + G.T) / 2

    @property
    def unit(self) -> bool:
        """Every sample at unit weight (most trials): the plain inner products need no weighted copy."""
        return bool(np.all(self.w == 1.0))


def unabsorbed(fit: Fit, weights: np.ndarray, fields, proj: RefitProjection | None = None) -> list:
    """For each field of marker displacements v (F, M, 3; NaN, and samples of weight 0, count as 0; any iterable,
    so that a caller with many fields can make each as it is used), its weighted squared norm less the part a
    refit of the model absorbs (every unknown, per frame and constant, linearised at `fit`): ``vᵀWv − bᵀN⁺b``
    with N the Gauss-Newton normal matrix and ``b = JᵀWv``, the per-frame unknowns eliminated as in the fit
    (Schur complement): the diagonal of :meth:`RefitProjection.gram`, stack by stack.

    What a displacement of that shape still leaves in the model's residual: the denominator of a detector that
    regresses the residual on it. At the fit the residual is orthogonal to what a refit absorbs, so the numerator
    needs no projection. A lag is the case: the joint angles take up most of a lagging limb segment's displacement,
    a segment's pose and a marker's own position most of a single marker's (its mean speed times the lag is a
    constant offset), and regressing on the whole field read a 40 ms lag of one pelvis marker as 0.5 ms."""
    proj = proj if proj is not None else RefitProjection(fit, weights)
    out = []
    for V in stacked(fields):
        out.extend(np.diag(proj.gram(*proj.pieces_many(V, owned=True))))
    return [float(x) for x in out]


FIELD_CHUNK_ENTRIES = 1 << 21
"""Entries (float64, 16 MiB) of the fields :func:`stacked` puts together at most, beyond a single field: the score
tests' fields are projected that many at a time (:meth:`RefitProjection.pieces_many`). A stack in work costs about
twice that (the stack, masked in place, and its blocks' weighted copies; with `per_frame`, (F, P, Q) arrays more); a
caller that keeps every stack's pieces (:func:`score_moments`) keeps the fields themselves, as it always had to for
their plain Gram matrix."""


def stacked(fields):
    """The fields (any iterable of (F, M, 3) arrays of one shape, read once) stacked along a last axis, (F, M, 3, Q),
    at most :data:`FIELD_CHUNK_ENTRIES` entries a stack (one field a stack where one field is larger); each stack a
    new array, filled as the fields come and grown by doubling (the fields already stacked are not held twice, and a
    few small fields do not take a whole stack's memory). An item may also be a unit of fields, (F, M, 3, q), whose q
    fields stay in one stack, in their order (a slip's three steps, whose 3 × 3 Gram block is read per marker:
    :func:`identcheck.effects.marker_slip.refit_gain`)."""
    buf, q, cap = None, 0, 1
    for item in fields:
        v = np.asarray(item, dtype=float)
        v = v[..., None] if v.ndim == 3 else v
        k = v.shape[-1]
        if buf is not None and v.shape[:-1] != buf.shape[:-1]:
            raise ValueError(f"a field of shape {np.shape(item)} among fields of shape {buf.shape[:-1]}")
        if buf is not None and q + k > cap:                  # the unit does not fit: the stack goes as it is
            yield buf[..., :q] if q == buf.shape[-1] else buf[..., :q].copy()
            buf = None
        if buf is None:
            cap = max(k, FIELD_CHUNK_ENTRIES // max(v[..., 0].size, 1))
            buf, q = np.empty(v.shape[:-1] + (min(cap, max(4, k)),)), 0
        if q + k > buf.shape[-1]:
            grown = np.empty(buf.shape[:-1] + (min(cap, max(2 * buf.shape[-1], q + k)),))
            grown[..., :q] = buf[..., :q]
            buf = grown
        buf[..., q:q + k] = v
        q += k
        if q == cap:
            yield buf
            buf = None
    if buf is not None and q:
        yield buf[..., :q] if q == buf.shape[-1] else buf[..., :q].copy()


def _all_pieces(proj: "RefitProjection", fields, per_frame: bool = False) -> tuple | None:
    """:meth:`RefitProjection.pieces_many` of every field of `fields`, stack by stack, put together along the last
    axis (None for no field)."""
    parts = [proj.pieces_many(V, per_frame, owned=True) for V in stacked(fields)]
    if not parts:
        return None
    if len(parts) == 1:
        return parts[0]
    out = []
    while parts[0]:                                     # one piece at a time, each stack's copy let go as it is joined
        out.append(np.concatenate([p[0] for p in parts], axis=-1))
        parts = [p[1:] for p in parts]
    return tuple(out)


def unabsorbed_gram(fit: Fit, weights: np.ndarray, fields: list, proj: RefitProjection | None = None
                    ) -> np.ndarray:
    """The Gram matrix (k, k) of the parts of k fields a refit of the model at `fit` does not absorb (what
    :func:`unabsorbed` gives on its diagonal): the normal matrix of a score test that the residual is not
    explained by any combination of the fields, ``explained = nᵀ G⁺ n`` with ``n_i = v_iᵀ W r`` at the fit."""
    proj = proj if proj is not None else RefitProjection(fit, weights)
    parts = _all_pieces(proj, fields)
    return np.zeros((0, 0)) if parts is None else proj.gram(*parts)


def score_statistic(fit: Fit, weights: np.ndarray, residual: np.ndarray, fields: list) -> float:
    """What a refit with `fields` (each (F, M, 3) marker displacements per unit coefficient) added to the model
    would explain of `residual` (F, M, 3, the fit's; NaN and weight-0 samples count as 0), to first order: the
    score statistic ``nᵀ G⁺ n``, ``n_i = v_iᵀ W r`` and G the Gram matrix of the fields' unabsorbed parts
    (:func:`unabsorbed_gram`), in mm² (divide by σ² for a χ²).

    A detector that regresses the residual on the fields themselves understates this whenever the model's own
    unknowns take up part of each field (the joint angles, a shifted centre or axis, the segments' poses): that
    part is already gone from the residual, and the field's full norm in the denominator counts it again."""
    return quadratic_form(*score_moments(fit, weights, residual, [fields])[0])


def score_moments(fit: Fit, weights: np.ndarray, residual: np.ndarray, field_sets,
                  proj: RefitProjection | None = None) -> list:
    """For each set of fields in `field_sets` (any iterable of lists of fields, read once: a generator keeps one set
    in memory at a time; the refit's projection is built once for them all, at the cost of a whole normal-equation
    build and the Schur complement, and each field costs a gradient pass), the score test's moments ``(n, G)``:
    ``n_i = v_iᵀ W r`` and G the Gram matrix of the fields' unabsorbed parts. Any subset S of a set's
    fields has the statistic ``n_Sᵀ G_SS⁺ n_S`` (:func:`quadratic_form`) without another pass over the data: what a
    detector that chooses among its fields (:mod:`identcheck.bundle.score_selection`) needs."""
    w = np.asarray(weights, dtype=float)[..., None]
    r = np.where((w > 0) & np.isfinite(residual), residual, 0.0)
    proj = proj if proj is not None else RefitProjection(fit, weights)
    wr = (w * r).reshape(-1)
    out = []
    for fields in field_sets:
        parts = _all_pieces(proj, fields)
        if parts is None:
            out.append((np.zeros(0), np.zeros((0, 0))))
            continue
        out.append((parts[0].reshape(-1, parts[0].shape[-1]).T @ wr, proj.gram(*parts)))
    return out


def score_moments_streamed(fit: Fit, weights: np.ndarray, residual: np.ndarray, fields, plain_gram: np.ndarray,
                           proj: RefitProjection | None = None):
    """:func:`score_moments` of one set of fields read a stack at a time (any iterable of (F, M, 3) arrays,
    :func:`stacked`), their plain Gram matrix ``vᵀWu`` given (`plain_gram`, accumulated by the caller over chunks of
    frames): only what a refit absorbs of each field is kept, never the fields themselves. For families of dense
    fields over every marker (a distortion's 53 on a 42-marker body at 1500 frames: 80 MB, and as much again zeroed
    where unweighted)."""
    w = np.asarray(weights, dtype=float)[..., None]
    r = np.where((w > 0) & np.isfinite(residual), residual, 0.0)
    proj = proj if proj is not None else RefitProjection(fit, weights)
    wr = (w * r).reshape(-1)
    n, Z, reduced = [], [], []
    for V in stacked(fields):
        V0, z, red = proj.pieces_many(V, owned=True)
        n.append(V0.reshape(-1, V0.shape[-1]).T @ wr)
        Z.append(z.reshape(-1, z.shape[-1]).T)
        reduced.append(red.T)
    if not n:
        return np.zeros(0), np.zeros((0, 0))
    n, Z, reduced = np.concatenate(n), np.concatenate(Z), np.concatenate(reduced)
    G = np.asarray(plain_gram, dtype=float) - Z @ Z.T - reduced @ proj.S_plus @ reduced.T
    return n, (G + G.T) / 2


def quadratic_form(n: np.ndarray, G: np.ndarray) -> float:
    """``nᵀ G⁺ n``, the score statistic of moments ``(n, G)`` (:func:`score_moments`); 0 for no fields. With `n` a
    matrix (k, w), the sum of the statistic over its w columns, ``trace(nᵀ G⁺ n)``: the moments of k functions each
    with a free w-vector when every one of the w directions shares the Gram matrix `G` (k, k) — the statistic of the
    kw fields ``nᵀ (G ⊗ I_w)⁺ n`` with the w-fold smaller matrix."""
    if not len(n):
        return 0.0
    return float(np.sum(n * (np.linalg.pinv(G, rcond=1e-10, hermitian=True) @ n)))


def modulated_score_moments(fit: Fit, weights: np.ndarray, residual: np.ndarray, carriers: list,
                            bases: list, proj: RefitProjection | None = None) -> list:
    """For each basis of `bases` (each (F, K), functions of the frame), :func:`score_moments` of the fields
    ``basis[:, k] · carriers[e]`` for every function k and every carrier e (each (F, M, 3)), ordered carrier by carrier
    (field ``e·K + k``), from one gradient pass per carrier for them all: the K·E fields are never formed. A term
    whose size in every frame is a smooth function of time times a displacement that changes from frame to frame (a
    joint's second rotation: the angle's coefficients times the turn of every marker below it) has such fields, and
    their moments are sums over the frames of each carrier's per-frame pieces weighted by the functions:
    ``G[ek, e'l] = Σ_f b_k b_l (⟨u_e, u_e'⟩_f − z_e·z_e'|_f) − ρ_ekᵀ S⁺ ρ_e'l`` with ``ρ_ek = Σ_f b_k(f) ρ_e(f)``, the
    constants' per-frame parts."""
    proj = proj if proj is not None else RefitProjection(fit, weights)
    w = proj.w[..., None]
    r = np.where((w > 0) & np.isfinite(residual), residual, 0.0)
    stack = _all_pieces(proj, carriers, per_frame=True)
    parts = [] if stack is None else [tuple(x[..., e] for x in stack) for e in range(stack[0].shape[-1])]
    E = len(parts)
    per_frame = np.empty((len(r), E, E))           # ⟨u_e, u_e'⟩ less the per-frame unknowns' part, frame by frame
    for a, (va, za, _) in enumerate(parts):
        for b, (vb, zb, _) in enumerate(parts[a:], start=a):
            per_frame[:, a, b] = per_frame[:, b, a] = np.sum(w * va * vb, axis=(1, 2)) - np.sum(za * zb, axis=1)
    along = [np.sum(w * v0 * r, axis=(1, 2)) for v0, _, _ in parts]                # ⟨u_e, r⟩ frame by frame
    out = []
    for basis in bases:
        basis = np.asarray(basis, dtype=float)
        G = np.block([[(basis * per_frame[:, a, b, None]).T @ basis for b in range(E)] for a in range(E)])
        rho = np.concatenate([basis.T @ red for _, _, red in parts])                 # (E·K, P)
        G = G - rho @ proj.S_plus @ rho.T
        out.append((np.concatenate([basis.T @ x for x in along]), (G + G.T) / 2))
    return out
