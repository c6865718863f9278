"""The coupling ``B_f = J_fᵀ W G_f`` between each frame's unknowns and the constants, kept by its structure.

An effect term's constants are K functions of time (its basis) times d base directions: skin moves its marker (or
its cluster) on the segment by ``basis_f @ D`` (D K × 3), so the term's K·d columns of G at frame f are the
marker's own position columns (the segment's rotation) times ``basis[f, kk]``; a translating joint's centre moves
its parent-side centre's columns times the basis; a hinge's second rotation, one turn column (d = 1) times it.
Their columns of B are therefore base columns of B times the basis: ``B_f[:, (kk, a)] = base_f[:, a] basis[f, kk]``.

Written out, those columns are most of B: a pair of legs has 82 plain constants, and 450-775 columns in all once
skin terms are in. The Schur complement ``Σ_f B_fᵀ A_f⁻¹ B_f`` then costs F·k·P² (k unknowns per frame) and
was 60 % of ``diagnose``'s time on a real gait trial. Kept as base ⊗ basis, with ``V = L⁻¹ base`` (A = LLᵀ) the
block of two terms t, u is ``Σ_f (V_tᵀ V_u)_f ⊗ basis_t,f basis_u,fᵀ``: k·d_t·d_u + d_t·d_u·K_t·K_u per frame
instead of k·d_t·K_t·d_u·K_u, a k-fold saving (k is 10-20), and B is never held with its term columns.

Columns of a term are ordered basis function first, direction second: column ``first + d·kk + a``, as
:func:`identcheck.bundle.jacobian.layout` places them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHUNK_ENTRIES = 1 << 19
"""Entries (float64, 4 MiB) of each frame-chunk's intermediate products formed at a time when the frames are
eliminated: the Schur complement sums over frames, so it is built chunk by chunk and L⁻¹B is never held whole.
(32 MiB chunks raised the peak of `fit` on a 42-marker body from 341 to 407 MiB.)"""


@dataclass(frozen=True)
class KronTerm:
    """One term's columns: the constants ``first .. first + d·K`` (basis function kk, direction a at
    ``first + d·kk + a``), their base columns ``offset .. offset + d`` of :attr:`Coupling.bases`, and the basis
    (F, K)."""

    first: int
    d: int
    offset: int
    basis: np.ndarray

    @property
    def size(self) -> int:
        return self.d * self.basis.shape[1]

    @property
    def cols(self) -> np.ndarray:
        return np.arange(self.first, self.first + self.size)


@dataclass(frozen=True)
class Coupling:
    """B (F, k, P) as its plain columns written out (``plain`` (F, k, P0) at the constants ``plain_cols``) and its
    term columns as ``bases`` (F, k, D) times each :class:`KronTerm`'s basis."""

    plain: np.ndarray
    plain_cols: np.ndarray
    bases: np.ndarray
    terms: tuple
    P: int

    @classmethod
    def from_dense(cls, B: np.ndarray) -> "Coupling":
        """A dense B (F, k, P) as a coupling without terms."""
        F, k, P = B.shape
        return cls(B, np.arange(P), np.zeros((F, k, 0)), (), P)

    @property
    def shape(self) -> tuple:
        return self.plain.shape[0], self.plain.shape[1], self.P

    def dense(self) -> np.ndarray:
        """B written out (F, k, P): for checks, and for the rare frame whose block has no Cholesky factor."""
        F, k, _ = self.plain.shape
        out = np.zeros((F, k, self.P))
        out[..., self.plain_cols] = self.plain
        for t in self.terms:
            out[..., t.first:t.first + t.size] = term_columns(self.bases[..., t.offset:t.offset + t.d], t.basis)
        return out

    def times(self, dc: np.ndarray) -> np.ndarray:
        """``B_f dc`` for every frame (F, k)."""
        out = np.einsum("fkp,p->fk", self.plain, dc[self.plain_cols])
        for t in self.terms:
            coef = t.basis @ dc[t.first:t.first + t.size].reshape(-1, t.d)      # (F, d)
            out += np.einsum("fkd,fd->fk", self.bases[..., t.offset:t.offset + t.d], coef)
        return out

    def transposed_times(self, u: np.ndarray, per_frame: bool = False) -> np.ndarray:
        """``Σ_f B_fᵀ u_f`` (P,) for u (F, k); with `per_frame`, each frame's ``B_fᵀ u_f`` (F, P). (Of many vectors a
        frame, from the blocks without B: :func:`identcheck.bundle.normal.coupling_transposed_times`.)"""
        F = u.shape[0]
        out = np.zeros((F, self.P) if per_frame else self.P)
        out[..., self.plain_cols] = np.einsum("fkp,fk->fp" if per_frame else "fkp,fk->p", self.plain, u)
        if self.terms:
            y = np.einsum("fkd,fk->fd", self.bases, u)                          # (F, D)
            cols = np.concatenate([t.cols for t in self.terms])
            out[..., cols] = term_sums(y, [(t.offset, t.d, t.basis) for t in self.terms], per_frame)
        return out

    def schur(self, Linv: np.ndarray) -> np.ndarray:
        """``Σ_f (L_f⁻¹B_f)ᵀ(L_f⁻¹B_f)`` (P, P) for the per-frame inverse factors `Linv` (F, k, k): the part of the
        Schur complement the frames take away, summed over chunks of frames (:data:`CHUNK_ENTRIES`)."""
        F, k, P0 = self.plain.shape
        D = self.bases.shape[2]
        T = sum(t.size for t in self.terms)
        S_pp, S_pt, S_tt = np.zeros((P0, P0)), np.zeros((P0, T)), np.zeros((T, T))
        step = max(1, CHUNK_ENTRIES // max(k * (P0 + D), P0 * max(D, 1), D * D, 1))
        for f0 in range(0, F, step):
            L = Linv[f0:f0 + step]
            Vp = L @ self.plain[f0:f0 + step]                                    # (c, k, P0)
            Vp2 = Vp.reshape(-1, P0)
            S_pp += Vp2.T @ Vp2
            if not self.terms:
                continue
            Vb = L @ self.bases[f0:f0 + step]                                    # (c, k, D)
            M = Vb.transpose(0, 2, 1) @ Vp                                       # (c, D, P0)
            N = Vb.transpose(0, 2, 1) @ Vb                                       # (c, D, D)
            pt, tt = term_products(M, N, [(t.offset, t.d, t.basis[f0:f0 + step]) for t in self.terms])
            S_pt += pt
            S_tt += tt
        P = self.P
        if not T and P0 == P:
            return S_pp
        out = np.zeros((P, P))
        term_cols = np.concatenate([t.cols for t in self.terms]) if T else np.zeros(0, dtype=int)
        out[np.ix_(self.plain_cols, self.plain_cols)] = S_pp
        out[np.ix_(self.plain_cols, term_cols)] = S_pt
        out[np.ix_(term_cols, self.plain_cols)] = S_pt.T
        out[np.ix_(term_cols, term_cols)] = symmetric_from_upper(S_tt)
        return out


def term_columns(base: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """A term's columns written out (F, r, K·d) from its base directions (F, r, d) and its basis (F, K), column
    ``d·kk + a`` the direction a times basis function kk: for checks and the rare dense solve; the products take them
    from the directions (:func:`term_products`, :func:`term_sums`)."""
    F, r, d = base.shape
    return (base[:, :, None, :] * basis[:, None, :, None]).reshape(F, r, basis.shape[1] * d)


def term_products(M: np.ndarray, N: np.ndarray, parts: list) -> tuple[np.ndarray, np.ndarray]:
    """The sums over frames of products that involve term columns (a basis times base directions), from the
    products of the base directions alone: with M (c, D, p) each frame's products of the D base directions with p
    plain columns and N (c, D, D) those of the base directions with each other, and `parts` each term's
    ``(offset, d, basis)`` (its base directions ``offset .. offset + d`` of D, its basis (c, K) over the same
    frames), returns ``pt`` (p, T), the plain columns against every term column, and ``tt`` (T, T), the term
    columns against each other on and above the block diagonal (below it zero: :func:`symmetric_from_upper`), T the
    terms' columns in order, each basis function first, direction second.

    Column (kk, a) of a term is ``base_a · basis_kk`` in every frame, so its product with a plain column p is
    ``Σ_f M_f[a, p] basis_f,kk`` and with column (ll, b) of a term u ``Σ_f N_f[a, b] basis_f,kk basis_u,f,ll``:
    c·p·d·K and c·d_t·d_u·K_t·K_u multiplications in place of the rows' (3 per marker) times as many with the
    columns written out. Used for the Schur complement (:meth:`Coupling.schur`) and the constants' normal matrix
    (:func:`identcheck.bundle.normal.normal_equations`).

    Why M directions first: a term's rows of M are then one strided view (no copy) that multiplies its basis at BLAS
    speed; with the plain columns first, each term's slice was copied first (c·p·d values, 7 terms a call on a real
    gait trial's fit). The pairs' products multiply the basis by a contiguous copy of the few (d·d_u) products of
    their directions, not by a strided slice of N: 1.6-1.9 times faster a pair (c 213, K 9-27)."""
    c, _, p = M.shape
    spans = np.cumsum([0] + [d * basis.shape[1] for _, d, basis in parts])
    pt, tt = np.zeros((p, spans[-1])), np.zeros((spans[-1], spans[-1]))
    for i, (off, d, bt) in enumerate(parts):
        K = bt.shape[1]
        part = M[:, off:off + d].reshape(c, d * p).T @ bt                              # (d·p, K)
        pt[:, spans[i]:spans[i + 1]] = part.reshape(d, p, K).transpose(1, 2, 0).reshape(p, K * d)
        for j in range(i, len(parts)):
            off_u, d_u, bu = parts[j]
            nn = N[:, off:off + d, off_u:off_u + d_u].reshape(c, d * d_u)              # (c, d·d_u), a copy
            left = (bt[:, :, None] * nn[:, None, :]).reshape(c, -1)                     # (c, K·d·d_u)
            block = (left.T @ bu).reshape(K, d, d_u, -1)                                # (K, d, d_u, K_u)
            tt[spans[i]:spans[i + 1], spans[j]:spans[j + 1]] = block.transpose(0, 1, 3, 2).reshape(K * d, -1)
    return pt, tt


def term_sums(y: np.ndarray, parts: list, per_frame: bool = False) -> np.ndarray:
    """``Σ_f`` of term columns times vectors, from the base directions' (y (F, D) or (F, D, Q), each frame's products
    of its D base directions with the vectors): column (kk, a) of a term ``(offset, d, basis)`` is ``Σ_f basis_f,kk
    y_f,offset+a`` ((T,) or (T, Q)), or each frame's term ((F, T) or (F, T, Q)) with `per_frame`; the columns as
    :func:`term_products` orders them."""
    out = []
    for off, d, basis in parts:
        yt = y[:, off:off + d]                                                      # (F, d[, Q])
        if per_frame:
            spread = basis.reshape(basis.shape + (1,) * (yt.ndim - 1)) * yt[:, None]   # (F, K, d[, Q])
            out.append(spread.reshape((len(y), basis.shape[1] * d) + yt.shape[2:]))
        else:
            out.append(np.tensordot(basis, yt, axes=(0, 0)).reshape((-1,) + yt.shape[2:]))
    if not out:
        return np.zeros((len(y), 0) + y.shape[2:] if per_frame else (0,) + y.shape[2:])
    return np.concatenate(out, axis=1 if per_frame else 0)


def symmetric_from_upper(upper_blocks: np.ndarray) -> np.ndarray:
    """The symmetric matrix whose part on and above the diagonal is that of `upper_blocks` (a sum built block by block
    on and above the block diagonal; the diagonal blocks are whole and symmetric)."""
    upper = np.triu(upper_blocks)
    return upper + np.triu(upper, 1).T
