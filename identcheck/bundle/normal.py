"""The Gauss-Newton normal equations of the whole chain, built block by block.

With J the per-frame Jacobian, G the constants' Jacobian, r the residuals and w the per-sample weights:
A = JᵀWJ per frame (F, k, k), B = JᵀWG per frame (F, k, P), C = Σ_f GᵀWG (P, P), g = JᵀWr per frame
(F, k) and h = Σ_f GᵀWr (P,) (or per frame, (F, P): the scores of the sandwich covariance). Each
:class:`~identcheck.bundle.jacobian.Block` adds its products into its own rows and columns only, so the cost
grows with the columns each marker touches, not with all of them: the dense products multiplied 82-column
rows for markers that touch 9 to 20 of them.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from identcheck.bundle.coupling import Coupling, symmetric_from_upper, term_products, term_sums
from identcheck.bundle.jacobian import Layout


def _add(target: np.ndarray, rows: tuple, cols: tuple | None, x: np.ndarray) -> None:
    """``target[..., rows, cols] += x`` (``target[..., rows] += x`` when `cols` is None), rows and columns given
    as :func:`~identcheck.bundle.jacobian.runs`: slice by slice."""
    for r0, r1, a in rows:
        if cols is None:
            target[..., r0:r1] += x[..., a:a + r1 - r0]
            continue
        for c0, c1, b in cols:
            target[..., r0:r1, c0:c1] += x[..., a:a + r1 - r0, b:b + c1 - c0]


def term_parts(lay: Layout, grp) -> tuple[list, tuple, tuple]:
    """A group's terms that are a basis times base directions (``Group.kron_at``): each one's ``(offset, d, basis)``
    (its directions among its block's ``base``, as :func:`~identcheck.bundle.coupling.term_products` takes them);
    their columns in the whole system, and their directions among the coupling's bases, both as
    :func:`~identcheck.bundle.jacobian.runs` (positions among the terms' columns, and the block's directions)."""
    terms = [lay.kron[i] for i in grp.kron_at]
    at_d = np.cumsum([0] + [t.d for t in terms])
    at_size = np.cumsum([0] + [t.size for t in terms])
    parts = [(int(off), t.d, t.basis) for t, off in zip(terms, at_d)]
    cols = tuple((t.first, t.first + t.size, int(at)) for t, at in zip(terms, at_size))
    bases = tuple((t.offset, t.offset + t.d, int(off)) for t, off in zip(terms, at_d))
    return parts, cols, bases


def normal_equations(lay: Layout, blocks: Iterable, r: np.ndarray, w: np.ndarray, per_frame: bool = False):
    """(A, B, C, g, h) of the blocks with residuals `r` (F, M, 3) and weights `w` (F, M) (see the module), B as a
    :class:`~identcheck.bundle.coupling.Coupling` (its term columns a base times a basis, never written out). The
    gradients of many fields at once, without the products: :func:`field_gradients`. The blocks are passed over
    once (a list, or the fit's blocks formed as they are reached).

    C and h are built from the blocks' plain columns and their terms' base directions alone
    (:func:`~identcheck.bundle.coupling.term_products`), the term columns never written out: a hinge's second rotation
    with 82 basis functions had made a shank block's columns 112 wide, and that call (1584 frames) took 46-52 ms, 25-26
    ms now (best of 10, both in one run); diagnoses that try such rotations took a sixth less time (held-out draw
    79's extra-DOF trials, mean 27.4 → 22.7 CPU s), those with skin about as long as before."""
    F, k, P = r.shape[0], lay.k, lay.P
    plain_cols = lay.plain
    D = sum(t.d for t in lay.kron)
    A, C = np.zeros((F, k, k)), np.zeros((P, P))
    Bp, Bb = np.zeros((F, k, len(plain_cols))), np.zeros((F, k, D))
    g, h = np.zeros((F, k)), np.zeros((F, P) if per_frame else P)
    unit = bool(np.all(w == 1.0))        # every sample seen at unit weight (most trials): no weighted copies
    for b in blocks:
        grp = b.group
        idx, kb = grp.cols, b.J.shape[-1]
        fr = grp.frame_runs
        n = 3 * len(idx)
        Jf, Gf, rf = b.J.reshape(F, n, kb), b.G.reshape(F, n, -1), r[:, idx].reshape(F, n)
        base = None if not grp.kron_at else b.base.reshape(F, n, -1)
        if not unit:
            sw = np.repeat(np.sqrt(w[:, idx]), 3, axis=1)[..., None]                # (F, n, 1)
            Jf, Gf, rf = Jf * sw, Gf * sw, rf * sw[..., 0]
            base = None if base is None else base * sw
        Jt = np.ascontiguousarray(Jf.transpose(0, 2, 1))          # a contiguous Jᵀ: JᵀJ at BLAS speed
        G2 = Gf.reshape(F * n, -1)
        pr = grp.plain_const_runs
        _add(A, fr, fr, Jt @ Jf)
        _add(Bp, fr, grp.plain_runs, Jt @ Gf)
        _add(C, pr, pr, G2.T @ G2)
        _add(g, fr, None, (Jt @ rf[..., None])[..., 0])
        _add(h, pr, None, (Gf.transpose(0, 2, 1) @ rf[..., None])[..., 0] if per_frame else G2.T @ rf.reshape(-1))
        if base is None:
            continue
        parts, tr, bases = term_parts(lay, grp)
        _add(Bb, fr, bases, Jt @ base)
        base_t = base.transpose(0, 2, 1)
        pt, tt = term_products(base_t @ Gf, base_t @ base, parts)
        _add(C, pr, tr, pt)
        _add(C, tr, pr, pt.T)
        _add(C, tr, tr, symmetric_from_upper(tt))
        _add(h, tr, None, term_sums((base_t @ rf[..., None])[..., 0], parts, per_frame))
    return A, Coupling(Bp, plain_cols, Bb, lay.kron, P), C, g, h


def field_gradients(lay: Layout, blocks: list, V: np.ndarray, w: np.ndarray, per_frame: bool = False):
    """The gradients of Q fields at once, V (F, M, 3, Q) (the fields along the last axis) with weights `w` (F, M):
    ``g = JᵀWv`` per frame (F, k, Q) and ``h = Σ_f GᵀWv`` (P, Q) (per frame (F, P, Q)); what
    :func:`normal_equations` gives as g and h for each field as its residual, without the products A, B and C,
    which do not depend on it (a caller projecting many fields builds them once).

    Why together: one field at a time, each block's Jacobian is multiplied by a vector per frame (memory-bound); Q
    fields make it a product of matrices, and the weights go on the fields, so the Jacobians are not copied."""
    F, M, _, Q = V.shape
    flat = V.reshape(F, 3 * M, Q)
    g, h = np.zeros((F, lay.k, Q)), np.zeros((F, lay.P, Q) if per_frame else (lay.P, Q))
    unit = bool(np.all(w == 1.0))
    for b in blocks:
        grp = b.group
        idx, kb = grp.cols, b.J.shape[-1]
        n = 3 * len(idx)
        Vf = flat[:, (3 * np.asarray(idx)[:, None] + np.arange(3)).ravel()]          # (F, n, Q), a copy
        if not unit:
            Vf *= np.repeat(w[:, idx], 3, axis=1)[..., None]
        Jt = b.J.reshape(F, n, kb).transpose(0, 2, 1)
        _add_rows(g, grp.frame_runs, Jt @ Vf, axis=1)
        _add_constant_gradients(h, lay, b, Vf, per_frame)
    return g, h


def coupling_transposed_times(lay: Layout, blocks: list, X: np.ndarray, w: np.ndarray, per_frame: bool = False):
    """``Bᵀx`` for Q per-frame vectors at once, X (F, k, Q), from the blocks, B = JᵀWG (:func:`normal_equations`)
    never formed: ``Σ_f G_fᵀ W (J_f x_f)`` (P, Q), or per frame (F, P, Q). Each block's markers move by ``J x`` and
    their constants' gradient is taken of that move, so the cost is that of the columns each marker touches; B
    written out holds every per-frame column against every constant (a 42-marker body at 1500 frames: 88 MB, kept by
    the score tests' projection, :class:`~identcheck.bundle.score_test.RefitProjection`, through a whole round of
    detectors)."""
    F, _, Q = X.shape
    out = np.zeros((F, lay.P, Q) if per_frame else (lay.P, Q))
    unit = bool(np.all(w == 1.0))
    for b in blocks:
        grp = b.group
        idx, kb = grp.cols, b.J.shape[-1]
        n = 3 * len(idx)
        moved = b.J.reshape(F, n, kb) @ X[:, grp.frame_cols]                        # (F, n, Q)
        if not unit:
            moved *= np.repeat(w[:, idx], 3, axis=1)[..., None]
        _add_constant_gradients(out, lay, b, moved, per_frame)
    return out


def _add_constant_gradients(out: np.ndarray, lay: Layout, b, V: np.ndarray, per_frame: bool) -> None:
    """``out += Σ_f G_fᵀ V_f`` (P, Q), or each frame's (F, P, Q) with `per_frame`, for a block's rows' vectors V
    (F, n, Q) (weighted already): its plain constants' from its G, its terms' from their base directions
    (:func:`~identcheck.bundle.coupling.term_sums`)."""
    grp = b.group
    F, n, Q = V.shape
    Gf = b.G.reshape(F, n, -1)
    axis = 1 if per_frame else 0
    plain = Gf.transpose(0, 2, 1) @ V if per_frame else Gf.reshape(F * n, -1).T @ V.reshape(F * n, Q)
    _add_rows(out, grp.plain_const_runs, plain, axis)
    if grp.kron_at:
        parts, cols, _ = term_parts(lay, grp)
        y = b.base.reshape(F, n, -1).transpose(0, 2, 1) @ V                          # (F, d, Q)
        _add_rows(out, cols, term_sums(y, parts, per_frame), axis)


def _add_rows(target: np.ndarray, rows: tuple, x: np.ndarray, axis: int) -> None:
    """``target[rows] += x`` along `axis` (0 or 1), the rows given as :func:`~identcheck.bundle.jacobian.runs`."""
    for r0, r1, a in rows:
        if axis == 0:
            target[r0:r1] += x[a:a + r1 - r0]
        else:
            target[:, r0:r1] += x[:, a:a + r1 - r0]


def ridged(A: np.ndarray, floor: float | None = None) -> np.ndarray:
    """The per-frame blocks A (F, k, k) with a ridge of 1e-12 of their (at least the median, or `floor`) scale
    (trace / k): a frame whose markers leave its pose free, or that has no marker at all, stays solvable and
    contributes nothing. `floor`: the median of the whole trial's when A holds a chunk of its frames."""
    k = A.shape[1]
    scale = np.trace(A, axis1=1, axis2=2)[:, None, None] / k
    floor = np.median(scale) if floor is None else floor
    return A + 1e-12 * np.maximum(scale, floor + 1e-300) * np.eye(k)


ELIMINATION_CHUNK_ENTRIES = 1 << 21
"""Entries (float64, 16 MiB) of the coupling B, counted as k × P a frame (its term columns are kept as bases, fewer),
that a chunk of frames may hold in :func:`frames_eliminated`: a lower limb's rigid model (k 12, P 44) takes its 1500
frames in one chunk; both legs of walking2 with skin terms (k 14, P 450-775) 190-330 frames a chunk; a 42-marker
body 271."""


def frames_eliminated(lay: Layout, blocks: list, w: np.ndarray, r: np.ndarray | None = None,
                      per_frame: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S, reduced, A): what :func:`eliminate_frames` gives as S and the reduced gradient (with `per_frame`, each
    frame's) for the normal equations of the blocks with residuals `r` (zero when None; (F, M, 3)) and weights `w`
    (F, M), the blocks ridged (:func:`ridged`, the floor the whole trial's), and the per-frame blocks A (F, k, k) as
    built (unridged). The Schur complement and the reduced gradient are sums over the frames, so they are built a
    chunk of frames at a time (:data:`ELIMINATION_CHUNK_ENTRIES` of B): B is never held whole. For what needs no
    step back to the frames (the information, the per-frame scores, the score tests' projection); the fit's
    iterations keep B for theirs. A 42-marker body at 1500 frames: B is 88 MB, held with the derivatives (53 MB) it
    was built from, and the joints' covariance had been the peak of ``diagnose``."""
    F, k, P = len(w), lay.k, lay.P
    ridge_floor = float(np.median(_frame_traces(blocks, w))) / k       # ridged's median over every frame
    step = max(1, ELIMINATION_CHUNK_ENTRIES // max(k * P, 1))
    S, A_all = np.zeros((P, P)), np.empty((F, k, k))
    reduced = np.zeros((F, P) if per_frame else P)
    for f0 in range(0, F, step):
        c = slice(f0, min(f0 + step, F))
        part = replace(lay, kron=tuple(replace(t, basis=t.basis[c]) for t in lay.kron))
        chunk = [replace(b, J=b.J[c], G=b.G[c], base=None if b.base is None else b.base[c]) for b in blocks]
        rc = np.zeros((c.stop - f0,) + w.shape[1:] + (3,)) if r is None else r[c]
        A, B, C, g, h = normal_equations(part, chunk, rc, w[c], per_frame=per_frame)
        A_all[c] = A
        S_c, red_c, _ = eliminate_frames(ridged(A, ridge_floor), B, C, g, h)
        S += S_c
        if per_frame:
            reduced[c] = red_c
        else:
            reduced += red_c
    return S, reduced, A_all


def _frame_traces(blocks: list, w: np.ndarray) -> np.ndarray:
    """Each frame's trace of A = JᵀWJ (F,), from the blocks: the weighted sum of squares of each frame's derivatives
    (the diagonal of A sums them block by block)."""
    out = np.zeros(len(w))
    for b in blocks:
        out += np.einsum("fmcj,fmcj,fm->f", b.J, b.J, w[:, b.group.cols])
    return out


def lower_inverse(L: np.ndarray) -> np.ndarray:
    """The inverses (F, k, k) of lower-triangular matrices `L` (F, k, k) with a nonzero diagonal, by forward
    substitution row by row, each row for every frame at once: ``X_i = (e_i − L_i,<i X_<i) / L_ii``.

    Why not ``np.linalg.inv``: it factorises each of the F small matrices again (LU with pivoting, one LAPACK call
    per frame); k vectorised steps cost a third of that at k = 11 and F = 1500."""
    F, k, _ = L.shape
    X = np.zeros_like(L)
    for i in range(k):
        row = -np.einsum("fj,fjc->fc", L[:, i, :i], X[:, :i, :]) if i else np.zeros((F, k))
        row[:, i] += 1.0
        X[:, i, :] = row / L[:, i, i, None]
    return X


def eliminate_frames(A_damped: np.ndarray, B, C: np.ndarray, g: np.ndarray, h: np.ndarray):
    """The per-frame unknowns eliminated (Schur complement): ``S = C − Σ_f B_fᵀ A_f⁻¹ B_f`` (P, P) and the reduced
    gradient ``h − Σ_f B_fᵀ A_f⁻¹ g_f`` ((P,), or per frame (F, P) when `h` is), with `A_damped` (F, k, k) the
    per-frame blocks as the caller damps or ridges them and B a :class:`~identcheck.bundle.coupling.Coupling` (or
    an array (F, k, P)); and ``back(dc)``, the per-frame ``A_f⁻¹ (g_f + B_f dc)`` (F, k) that goes with a step `dc`
    of the constants.

    Through each block's Cholesky factor L (A = LLᵀ): ``Σ_f B_fᵀ A_f⁻¹ B_f`` is the coupling's
    :meth:`~identcheck.bundle.coupling.Coupling.schur` with L⁻¹, and ``A_f⁻¹ x = L⁻ᵀ L⁻¹ x``. A block that is not
    numerically positive definite (a pose the markers leave free, held by a tiny ridge) is solved as a general
    system instead."""
    B = B if isinstance(B, Coupling) else Coupling.from_dense(np.asarray(B))
    F, k, P = B.shape
    try:
        Linv = lower_inverse(np.linalg.cholesky(A_damped))
    except np.linalg.LinAlgError:
        Linv = None
    if Linv is None:
        Bd = B.dense()
        right = np.linalg.solve(A_damped, Bd)
        right_g = np.linalg.solve(A_damped, g[..., None])[..., 0]
        S = C - Bd.reshape(F * k, P).T @ right.reshape(F * k, P)
        reduced = h - B.transposed_times(right_g, per_frame=h.ndim == 2)
        return 0.5 * (S + S.T), reduced, lambda dc: right_g + right @ dc
    Linv_t = Linv.transpose(0, 2, 1)
    u = (Linv_t @ (Linv @ g[..., None]))[..., 0]                 # A⁻¹g (F, k)
    S = C - B.schur(Linv)
    reduced = h - B.transposed_times(u, per_frame=h.ndim == 2)
    back = lambda dc: u + (Linv_t @ (Linv @ B.times(dc)[..., None]))[..., 0]  # noqa: E731
    return 0.5 * (S + S.T), reduced, back
