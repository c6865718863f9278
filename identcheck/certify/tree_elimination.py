"""Eliminating a skeleton's per-frame unknowns leaf to root, so that what the data determine about each
joint's constants is found with small exact matrices instead of one dense matrix per frame.

The equations (:mod:`identcheck.certify.tree_equations`) touch one segment or one joint each. For a set
of rows over columns K = E ∪ L, the combinations the rows fix on L alone are
{λ_L : λ A_E = 0} — read off the reduced row echelon form of [A_E | A_L] as the rows whose pivot lies
in L (:func:`eliminate`); and rank [A_E | A_L] = rank A_E + their number. Eliminating in stages gives
the same subspace (Gaussian elimination in any column order), so a subtree's rows can be summarised by
what they fix on the columns it shares with the rest of the tree — its parent's pose in every frame and
its joint's centre — at most 6F + 3 rows for F frames, however large the subtree:

- ``up(S)``: the subtree of segment S and its parent joint j, on (parent's poses, c_j);
- ``inner(S)``: S's markers and its children's ``up``, on (S's poses, S's markers, and the centres of
  S's child joints when S carries no markers, since those are then what a joint is judged against);
- ``outer(C)``: everything outside the subtree of C and its parent joint j, on (P's poses, P's markers,
  the centres of P's other child joints when P carries no markers);
- ``above(C)``: ``outer(C)`` with j's rows, on C's poses.

What the data determine about joint j's own constants is then W ∩ span(L_j) =
eliminate({outer(C), rows of j, inner(C)}, keep L_j), L_j its two segments' markers, its centre and
axis, and the neighbouring centres it may be judged against; a gradient supported on L_j lies in W
iff it lies there. The whole tree's dim W = rank [V | C] − rank V, both ranks summed stage by stage.
Cost: a few eliminations of O(F)-sized matrices per segment, linear in the number of segments.
"""
from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

from identcheck.certify.tree_equations import CONSTANT_KINDS


@dataclass
class Summary:
    """Echelon rows over the columns ``keys``, each a dict key -> value of its non-zero entries (read out
    of FLINT once, so that a summary used again costs no conversions)."""

    keys: list
    rows: list
    cid: bytes | None = None          # content digest (:func:`digest`), computed once

    @property
    def n(self) -> int:
        return len(self.rows)


@dataclass
class Eliminated:
    summary: Summary
    rank_eliminated: int      # rank of the rows on the eliminated columns
    rank: int                 # rank of all the rows


def eliminate(F, blocks, keep, drop_constants: bool = False) -> Eliminated:
    """The combinations of the rows of ``blocks`` (lists of row dicts, or :class:`Summary`) with no
    component outside the columns ``keep``, as echelon rows over ``keep`` (in its order); every other
    column met is eliminated. ``drop_constants``: ignore the constant columns altogether."""
    keep = list(keep)
    elim, seen = [], set(keep)
    rows = []
    for b in blocks:
        b_rows = b.rows if isinstance(b, Summary) else b
        rows.extend(b_rows)
        for row in b_rows:
            for key in row:
                if key not in seen and not (drop_constants and key[0] in CONSTANT_KINDS):
                    seen.add(key)
                    elim.append(key)
    cols = elim + keep
    if not rows or not cols:
        return Eliminated(Summary(keep, []), 0, 0)
    index = {key: i for i, key in enumerate(cols)}
    M = F.zeros(len(rows), len(cols))
    for i, row in enumerate(rows):
        for key, v in row.items():
            j = index.get(key)
            if j is not None:
                M[i, j] = v
    R, rank = M.rref()
    pivots = _pivot_columns(R, rank)
    ne = len(elim)
    lo = sum(1 for c in pivots if c < ne)      # rows 0..lo-1 have their pivot among the eliminated columns
    kept_pivots = set(pivots[lo:])
    out = []
    for r in range(lo, rank):
        row = {keep[pivots[r] - ne]: R[r, pivots[r]]}
        for c in range(pivots[r] + 1, len(cols)):
            if c not in kept_pivots:           # another row's pivot column is zero in this row
                v = R[r, c]
                if v != 0:
                    row[keep[c - ne]] = v
        out.append(row)
    return Eliminated(Summary(keep, out), lo, rank)


def _pivot_columns(R, rank: int) -> list:
    """The pivot column of each of the first `rank` rows of the reduced row echelon form `R`: one walk to the
    right, since each row's pivot lies right of the one above (at most rank + ncols entries read, where a
    search row by row would read every zero before each pivot)."""
    pivots, c = [], 0
    for r in range(rank):
        while R[r, c] == 0:
            c += 1
        pivots.append(c)
        c += 1
    return pivots


def pose_keys(segment: str, frames) -> list:
    """The pose columns of ``segment`` in the frames ``frames`` (indices)."""
    return [(kind, segment, f, a) for f in frames for kind in ("w", "t") for a in range(3)]


class _Memo:
    """Eliminations already done, by the content of what they eliminated (bounded: least recently used first
    out).

    A plan's robustness and motion analyses rank many variants of one skeleton (a marker removed, a joint
    held still). A variant shares most of its equations with the plan, and often most of its summaries too:
    once a subtree's summary comes out the same, everything that depends on it is the same. So an
    elimination is keyed by its inputs' contents — a block of equations by what determines it (the random
    stream, the frames, the segment or joint with its markers, type and frozen flag, and the joints on its
    path from the root, along which world poses compose), a summary by a 128-bit digest of its rows — and
    the columns it keeps. A hit is the same exact result (up to a digest collision, ~2^-64 over any
    realistic number of summaries). Eviction is a segmented LRU (:meth:`get`)."""

    MAX_ENTRIES = 600_000             # stored non-zero entries (each a field element) across all results
    PROTECTED_SHARE = 0.8             # of which results used again may hold this share

    def __init__(self):
        self._probation: OrderedDict = OrderedDict()     # stored, not used again yet
        self._protected: OrderedDict = OrderedDict()     # used again at least once (a plan's own summaries)
        self._sizes = {"probation": 0, "protected": 0}
        self._ids: dict = {}
        self._lock = threading.Lock()

    @staticmethod
    def _size_of(value: Eliminated) -> int:
        return sum(len(r) for r in value.summary.rows) + 1

    @property
    def _size(self) -> int:
        return self._sizes["probation"] + self._sizes["protected"]

    def intern(self, sig: tuple) -> int:
        """A small integer for a (nested) signature, so keys stay short however deep the tree."""
        with self._lock:
            if len(self._ids) > 1_000_000:
                self._ids.clear()
            return self._ids.setdefault(sig, len(self._ids))

    def get(self, key):
        """The stored result, or None. A result used again moves to the protected part, which is evicted
        last: the variants of a plan keep hitting the plan's own summaries, while most of a variant's new
        summaries are never used again."""
        with self._lock:
            hit = self._protected.get(key)
            if hit is not None:
                self._protected.move_to_end(key)
                return hit
            hit = self._probation.pop(key, None)
            if hit is None:
                return None
            size = self._size_of(hit)
            self._sizes["probation"] -= size
            self._protected[key] = hit
            self._sizes["protected"] += size
            while self._sizes["protected"] > self.PROTECTED_SHARE * self.MAX_ENTRIES and len(self._protected) > 1:
                old_key, old = self._protected.popitem(last=False)
                self._sizes["protected"] -= self._size_of(old)
                self._probation[old_key] = old
                self._sizes["probation"] += self._size_of(old)
            self._evict()
            return hit

    def put(self, key, value: Eliminated) -> None:
        with self._lock:
            if key in self._probation or key in self._protected:
                return
            self._probation[key] = value
            self._sizes["probation"] += self._size_of(value)
            self._evict()

    def _evict(self) -> None:
        while self._size > self.MAX_ENTRIES:
            part = "probation" if self._probation else "protected"
            store = self._probation if self._probation else self._protected
            _, old = store.popitem(last=False)
            self._sizes[part] -= self._size_of(old)

    def clear(self) -> None:
        with self._lock:
            self._probation.clear()
            self._protected.clear()
            self._sizes = {"probation": 0, "protected": 0}
            self._ids.clear()


MEMO = _Memo()


def digest(summary: Summary, exact_text: bool) -> bytes:
    """A 128-bit digest of a summary's columns and rows (``exact_text``: rationals, written as text)."""
    if summary.cid is None:
        index = {key: i for i, key in enumerate(summary.keys)}
        conv = str if exact_text else int
        payload = repr((summary.keys, [[(index[key], conv(v)) for key, v in row.items()] for row in summary.rows]))
        summary.cid = hashlib.blake2b(payload.encode(), digest_size=16).digest()
    return summary.cid


class TreeElimination:
    """The staged elimination of one skeleton's equations over the frames ``frames`` (indices).

    ``marker_rows``: segment -> its markers' rows (all frames); ``joint_rows``: joint -> its rows (all
    frames); ``marker_cols``: segment -> its markers' constant keys; ``centre_cols``: joint -> its centre's
    keys; ``joint_cols``: joint -> the keys of its own constants (centre, axis tangents); the three column maps
    are needed by :meth:`upward`, :meth:`downward` and :meth:`joint_subspace`, not by
    :meth:`rank_per_frame`. ``stream``: what
    the random point was drawn from (eliminations are shared, through :data:`MEMO`, only within one
    stream; None shares nothing)."""

    def __init__(self, F, spec, frames, marker_rows, joint_rows, marker_cols=None, centre_cols=None,
                 joint_cols=None, stream: str | None = None):
        self.F, self.spec, self.frames = F, spec, frames
        self.marker_rows, self.joint_rows = marker_rows, joint_rows
        self.marker_cols, self.centre_cols, self.joint_cols = marker_cols, centre_cols, joint_cols
        self._up, self._inner, self._outer = {}, {}, {}
        self.rank_full = None
        self.downward_done = False
        self.stream = stream
        self._ids: dict = {}               # id(list of equations) -> what determines it
        if stream is not None:
            self._equation_ids()

    # -- what each block of equations depends on --------------------------------------------------------
    def _equation_ids(self) -> None:
        spec, frames = self.spec, tuple(self.frames)
        desc = {n: (n, kind, n in spec.frozen) for n, kind, _, _ in spec.joints}
        path = {spec.root: MEMO.intern(("root", spec.root))}
        for name, kind, par, chi in spec.joints:
            path[chi] = MEMO.intern(("path", path[par], desc[name], chi))
        known = spec.known
        for seg, rows in self.marker_rows.items():
            self._ids[id(rows)] = ("markers", frames, path[seg], seg, tuple(spec.markers[seg]), seg in known)
        for name, kind, par, chi in spec.joints:
            self._ids[id(self.joint_rows[name])] = ("joint", frames, path[par], desc[name], par in known, chi in known)

    def _elim(self, blocks: list, keep: list, drop_constants: bool = False) -> Eliminated:
        """:func:`eliminate`, or its earlier result for the same contents (:class:`_Memo`)."""
        if self.stream is None:
            return eliminate(self.F, blocks, keep, drop_constants)
        exact_text = self.F.p is None
        ids = tuple(("summary", digest(b, exact_text)) if isinstance(b, Summary) else self._ids[id(b)]
                    for b in blocks)
        key = (self.stream, drop_constants, tuple(keep), ids)
        hit = MEMO.get(key)
        if hit is None:
            hit = eliminate(self.F, blocks, keep, drop_constants)
            MEMO.put(key, hit)
        return hit

    # -- upward: subtrees summarised on their parent's poses ------------------------------------------
    def _children_centres(self, seg: str) -> list:
        """Centre keys of seg's child joints, kept when seg carries no markers."""
        if self.spec.markers[seg]:
            return []
        return [key for j in self.spec.children[seg] for key in self.centre_cols[j[0]]]

    def _inner_of(self, seg: str) -> Eliminated:
        return self._elim([self.marker_rows[seg]] + [self._up[j[3]] for j in self.spec.children[seg]],
                          pose_keys(seg, self.frames) + self.marker_cols[seg] + self._children_centres(seg))

    def upward(self) -> None:
        """``inner`` and ``up`` of every segment, and rank [V | C] (all rows, every column)."""
        spec = self.spec
        total = 0
        for name, kind, par, chi in reversed(spec.joints):
            inner = self._inner_of(chi)
            up = self._elim([inner.summary, self.joint_rows[name]], pose_keys(par, self.frames) + self.centre_cols[name])
            self._inner[chi], self._up[chi] = inner.summary, up.summary
            total += inner.rank_eliminated + up.rank_eliminated
        inner = self._inner_of(spec.root)
        self._inner[spec.root] = inner.summary
        self.rank_full = total + inner.rank_eliminated + inner.summary.n

    def rank_per_frame(self) -> int:
        """rank V: the same stages with the constant columns left out (V is block-diagonal over frames, so
        callers sum it frame by frame)."""
        spec = self.spec
        up, total = {}, 0
        for name, kind, par, chi in reversed(spec.joints):
            e = self._elim([self.marker_rows[chi], self.joint_rows[name]] + [up[j[3]] for j in spec.children[chi]],
                           pose_keys(par, self.frames), drop_constants=True)
            up[chi] = e.summary
            total += e.rank_eliminated
        root = spec.root
        e = self._elim([self.marker_rows[root]] + [up[j[3]] for j in spec.children[root]], [], drop_constants=True)
        return total + e.rank_eliminated

    # -- downward: the rest of the tree summarised on each segment's poses -----------------------------
    def _pools_excluding_each(self, summaries: list, keys: list) -> list:
        """For each summary, the others' rows pooled on ``keys`` (their other columns eliminated), as a list
        of at most two blocks: prefix and suffix pools, so n children cost O(n) eliminations, not O(n²)."""
        n = len(summaries)
        if n == 1:
            return [[]]
        reduced = [self._elim([s], keys).summary for s in summaries]
        if n == 2:
            return [[reduced[1]], [reduced[0]]]
        prefix = [None, reduced[0]]
        for r in reduced[1:-1]:
            prefix.append(self._elim([prefix[-1], r], keys).summary)
        suffix = [None, reduced[-1]]
        for r in reversed(reduced[1:-1]):
            suffix.append(self._elim([suffix[-1], r], keys).summary)
        suffix.reverse()
        return [[b for b in (prefix[i], suffix[i]) if b is not None] for i in range(n)]

    def downward(self) -> None:
        """``outer`` and ``above`` of every non-root segment (after :meth:`upward`)."""
        spec = self.spec
        self.downward_done = True
        above = {spec.root: []}
        for seg in [spec.root] + [j[3] for j in spec.joints]:
            kids = spec.children[seg]
            if not kids:
                continue
            base = list(above[seg]) + [self.marker_rows[seg]]
            keep = pose_keys(seg, self.frames) + self.marker_cols[seg]
            if not spec.markers[seg]:                 # the children's centres are kept: no pooling
                for j in kids:
                    self._outer[j[3]] = self._elim(base + [self._up[o[3]] for o in kids if o is not j],
                                                   keep + self._children_centres(seg)).summary
            else:                                     # pooled on seg's poses, excluding one child at a time
                pools = self._pools_excluding_each([self._up[j[3]] for j in kids], pose_keys(seg, self.frames))
                for j, pool in zip(kids, pools):
                    self._outer[j[3]] = self._elim(base + pool, keep).summary
            for j in kids:
                above[j[3]] = [self._elim([self._outer[j[3]], self.joint_rows[j[0]]], pose_keys(j[3], self.frames)).summary]

    def joint_subspace(self, joint: tuple) -> Summary:
        """W ∩ span(L_j) for joint (name, kind, parent, child), as echelon rows over L_j."""
        name, kind, par, chi = joint
        keep = (self.marker_cols[par] + self.marker_cols[chi] + self.joint_cols[name]
                + [key for key in self._children_centres(par) if key not in self.centre_cols[name]]
                + self._children_centres(chi))
        return self._elim([self._outer[chi], self.joint_rows[name], self._inner[chi]], keep).summary
