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
            base = self.bases[..., t.offset:t.offset + t.d]                  # (F, k, d)
            out[..., t.first:t.first + t.size] = (base[:, :, None, :] * t.basis[:, None, :, None]).reshape(
                F, k, t.size)
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
            for t in self.terms:
                yt = y[:, t.offset:t.offset + t.d]
                if per_frame:
                    out[:, t.first:t.first + t.size] = (t.basis[:, :, None] * yt[:, None, :]).reshape(F, t.size)
                else:
                    out[t.first:t.first + t.size] = (t.basis.T @ yt).ravel()
        return out

    def schur(self, Linv: np.ndarray) -> np.ndarray:
        """``Σ_f (L_f⁻¹B_f)ᵀ(L_f⁻¹B_f)`` (P, P) for the per-frame inverse factors `Linv` (F, k, k): the part of the
        Schur complement the frames take away, summed over chunks of frames (:data:`CHUNK_ENTRIES`)."""
        F, k, P0 = self.plain.shape
        D = self.bases.shape[2]
        spans = np.cumsum([0] + [t.size for t in self.terms])
        T = int(spans[-1])
        S_pp, S_pt, S_tt = np.zeros((P0, P0)), np.zeros((P0, T)), np.zeros((T, T))
        step = max(1, CHUNK_ENTRIES // max(k * (P0 + D), P0 * max(D, 1), D * D, 1))
        for f0 in range(0, F, step):
            L = Linv[f0:f0 + step]
            c = len(L)
            Vp = L @ self.plain[f0:f0 + step]                                    # (c, k, P0)
            Vp2 = Vp.reshape(-1, P0)
            S_pp += Vp2.T @ Vp2
            if not self.terms:
                continue
            Vb = L @ self.bases[f0:f0 + step]                                    # (c, k, D)
            M = Vp.transpose(0, 2, 1) @ Vb                                       # (c, P0, D)
            N = Vb.transpose(0, 2, 1) @ Vb                                       # (c, D, D)
            for i, t in enumerate(self.terms):
                bt = t.basis[f0:f0 + step]                                       # (c, K)
                Kt = bt.shape[1]
                part = M[:, :, t.offset:t.offset + t.d].reshape(c, P0 * t.d).T @ bt       # (P0·d, K)
                S_pt[:, spans[i]:spans[i + 1]] += part.reshape(P0, t.d, Kt).transpose(0, 2, 1).reshape(P0, -1)
                for j in range(i, len(self.terms)):
                    u = self.terms[j]
                    nn = N[:, t.offset:t.offset + t.d, u.offset:u.offset + u.d]              # (c, d_t, d_u)
                    left = (bt[:, :, None, None] * nn[:, None]).reshape(c, -1)            # (c, Kt·d_t·d_u)
                    block = (left.T @ u.basis[f0:f0 + step]).reshape(Kt, t.d, u.d, -1)   # (Kt, d_t, d_u, Ku)
                    S_tt[spans[i]:spans[i + 1], spans[j]:spans[j + 1]] += block.transpose(0, 1, 3, 2).reshape(
                        t.size, u.size)
        P = self.P
        if not T and P0 == P:
            return S_pp
        out = np.zeros((P, P))
        term_cols = np.concatenate([t.cols for t in self.terms]) if T else np.zeros(0, dtype=int)
        upper = np.triu(S_tt)                   # the term blocks were summed on and above the block diagonal
        out[np.ix_(self.plain_cols, self.plain_cols)] = S_pp
        out[np.ix_(self.plain_cols, term_cols)] = S_pt
        out[np.ix_(term_cols, self.plain_cols)] = S_pt.T
        out[np.ix_(term_cols, term_cols)] = upper + np.triu(upper, 1).T
        return out
