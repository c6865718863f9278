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
    ne = len(elim)
    lo, hi = 0, rank                           # rows 0..r_e-1 have their pivot among the eliminated columns
    while lo < hi:
        mid = (lo + hi) // 2
        if any(R[mid, j] != 0 for j in range(ne)):
            lo = mid + 1
        else:
            hi = mid
    out = []
    for r in range(lo, rank):
        row = {}
        for c, key in enumerate(keep):
            v = R[r, ne + c]
            if v != 0:
                row[key] = v
        out.append(row)
    return Eliminated(Summary(keep, out), lo, rank)


def pose_keys(segment: str, frames) -> list:
    """The pose columns of ``segment`` in the frames ``frames`` (indices)."""
    return [(kind, segment, f, a) for f in frames for kind in ("w", "t") for a in range(3)]


def _pools_excluding_each(F, summaries: list, keys: list) -> list:
    """For each summary, the others' rows pooled on ``keys`` (their other columns eliminated), as a list of
    at most two blocks: prefix and suffix pools, so n children cost O(n) eliminations, not O(n²)."""
    n = len(summaries)
    if n == 1:
        return [[]]
    reduced = [eliminate(F, [s], keys).summary for s in summaries]
    if n == 2:
        return [[reduced[1]], [reduced[0]]]
    prefix = [None, reduced[0]]
    for r in reduced[1:-1]:
        prefix.append(eliminate(F, [prefix[-1], r], keys).summary)
    suffix = [None, reduced[-1]]
    for r in reversed(reduced[1:-1]):
        suffix.append(eliminate(F, [suffix[-1], r], keys).summary)
    suffix.reverse()
    return [[b for b in (prefix[i], suffix[i]) if b is not None] for i in range(n)]


class _Memo:
    """Eliminations already done, by what they depend on (bounded: least recently used first out).

    A plan's robustness and motion analyses rank many variants of one skeleton (a marker removed, a joint
    held still); each variant shares most subtrees, and with them most eliminations, with the plan itself.
    A key names everything an elimination's rows depend on — the random stream, the frames, the segments
    and joints involved with their markers, types and frozen flags, and the joints on the path from the
    root (world poses compose along it) — so a hit is the same exact result, not an approximation."""

    MAX_ENTRIES = 400_000             # stored non-zero entries (each a field element) across all results

    def __init__(self):
        self._store: OrderedDict = OrderedDict()
        self._size = 0
        self._ids: dict = {}
        self._lock = threading.Lock()

    def intern(self, sig: tuple) -> int:
        """A small integer for a (nested) signature, so keys stay short however deep the tree."""
        with self._lock:
            return self._ids.setdefault(sig, len(self._ids))

    def get(self, key):
        with self._lock:
            hit = self._store.get(key)
            if hit is not None:
                self._store.move_to_end(key)
            return hit

    def put(self, key, value: Eliminated) -> None:
        size = sum(len(r) for r in value.summary.rows) + 1
        with self._lock:
            if key in self._store:
                return
            self._store[key] = value
            self._size += size
            while self._size > self.MAX_ENTRIES and self._store:
                _, old = self._store.popitem(last=False)
                self._size -= sum(len(r) for r in old.summary.rows) + 1
            if len(self._ids) > 1_000_000:
                self._ids.clear()
                self._store.clear()
                self._size = 0

    def clear(self) -> None:
        with self._lock:
            self._store.clear()
            self._ids.clear()
            self._size = 0


MEMO = _Memo()


class TreeElimination:
    """The staged elimination of one skeleton's equations over the frames ``frames`` (indices).

    ``marker_rows``: segment -> its markers' rows (all frames); ``joint_rows``: joint -> its rows (all
    frames); ``marker_cols``: segment -> its markers' constant keys; ``centre_cols``: joint -> its centre's
    keys; ``joint_cols``: joint -> the keys of its own constants (centre, axis tangents). ``stream``: what
    the random point was drawn from (eliminations are shared, through :data:`MEMO`, only within one
    stream; None shares nothing)."""

    def __init__(self, F, spec, frames, marker_rows, joint_rows, marker_cols, centre_cols, joint_cols,
                 stream: str | None = None):
        self.F, self.spec, self.frames = F, spec, frames
        self.marker_rows, self.joint_rows = marker_rows, joint_rows
        self.marker_cols, self.centre_cols, self.joint_cols = marker_cols, centre_cols, joint_cols
        self._up, self._inner, self._above, self._outer = {}, {}, {}, {}
        self.rank_full = None
        self.downward_done = False
        self.stream = stream
        if stream is not None:
            self._signatures()

    # -- what each elimination depends on ---------------------------------------------------------------
    def _signatures(self) -> None:
        spec = self.spec
        desc = {n: (n, kind, n in spec.frozen) for n, kind, _, _ in spec.joints}
        self._path = {spec.root: MEMO.intern(("root", spec.root))}
        for name, kind, par, chi in spec.joints:
            self._path[chi] = MEMO.intern(("path", self._path[par], desc[name], chi))
        self._sub = {}
        for seg in [j[3] for j in reversed(spec.joints)] + [spec.root]:
            self._sub[seg] = MEMO.intern(("sub", seg, tuple(spec.markers[seg]),
                                          tuple((desc[j[0]], self._sub[j[3]]) for j in spec.children[seg])))
        self._desc = desc
        self._frames_key = tuple(self.frames)

    def _key(self, *parts):
        return None if self.stream is None else (self.stream, self._frames_key) + parts

    def _cached(self, key, blocks, keep, drop_constants: bool = False) -> Eliminated:
        """``eliminate(blocks(), keep)``, or its earlier result under ``key``."""
        hit = MEMO.get(key) if key is not None else None
        if hit is None:
            hit = eliminate(self.F, blocks(), keep, drop_constants)
            if key is not None:
                MEMO.put(key, hit)
        return hit

    # -- upward: subtrees summarised on their parent's poses ------------------------------------------
    def _children_centres(self, seg: str) -> list:
        """Centre keys of seg's child joints, kept when seg carries no markers."""
        if self.spec.markers[seg]:
            return []
        return [key for j in self.spec.children[seg] for key in self.centre_cols[j[0]]]

    def _inner_of(self, seg: str) -> Eliminated:
        key = self._key("inner", self._path[seg], self._sub[seg]) if self.stream else None
        return self._cached(key, lambda: [self.marker_rows[seg]] + [self._up[j[3]] for j in self.spec.children[seg]],
                            pose_keys(seg, self.frames) + self.marker_cols[seg] + self._children_centres(seg))

    def upward(self) -> None:
        """``inner`` and ``up`` of every segment, and rank [V | C] (all rows, every column)."""
        spec = self.spec
        total = 0
        for name, kind, par, chi in reversed(spec.joints):
            inner = self._inner_of(chi)
            self._inner[chi] = inner.summary
            key = self._key("up", self._path[chi], self._sub[chi]) if self.stream else None
            up = self._cached(key, lambda: [inner.summary, self.joint_rows[name]],
                              pose_keys(par, self.frames) + self.centre_cols[name])
            self._up[chi] = up.summary
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
            key = self._key("upV", self._path[chi], self._sub[chi]) if self.stream else None
            e = self._cached(key, lambda: [self.marker_rows[chi], self.joint_rows[name]]
                             + [up[j[3]] for j in spec.children[chi]], pose_keys(par, self.frames), True)
            up[chi] = e.summary
            total += e.rank_eliminated
        root = spec.root
        key = self._key("rootV", self._path[root], self._sub[root]) if self.stream else None
        e = self._cached(key, lambda: [self.marker_rows[root]] + [up[j[3]] for j in spec.children[root]], [], True)
        return total + e.rank_eliminated

    # -- downward: the rest of the tree summarised on each segment's poses -----------------------------
    def downward(self) -> None:
        """``outer`` and ``above`` of every non-root segment (after :meth:`upward`)."""
        spec, F = self.spec, self.F
        self.downward_done = True
        above = {spec.root: []}
        above_sig = {spec.root: ("none",)}
        self._outer_sig = {}
        for seg in [spec.root] + [j[3] for j in spec.joints]:
            kids = spec.children[seg]
            if not kids:
                continue
            base = list(above[seg]) + [self.marker_rows[seg]]
            keep = pose_keys(seg, self.frames) + self.marker_cols[seg]
            if self.stream:
                for j in kids:
                    self._outer_sig[j[3]] = MEMO.intern((
                        "outer", above_sig[seg], self._path[seg], tuple(spec.markers[seg]),
                        tuple((self._desc[o[0]], self._sub[o[3]]) for o in kids if o is not j)))
            keys = {j[3]: self._key("outer", self._outer_sig[j[3]]) if self.stream else None for j in kids}
            hits = {c: MEMO.get(k) for c, k in keys.items() if k is not None}
            if all(hits.get(j[3]) is not None for j in kids):
                outer = hits
            elif not spec.markers[seg]:               # the children's centres are kept: no pooling
                outer = {j[3]: eliminate(F, base + [self._up[o[3]] for o in kids if o is not j],
                                         keep + self._children_centres(seg)) for j in kids}
            else:                                     # pooled on seg's poses, excluding one child at a time
                pools = _pools_excluding_each(F, [self._up[j[3]] for j in kids], pose_keys(seg, self.frames))
                outer = {j[3]: eliminate(F, base + pool, keep) for j, pool in zip(kids, pools)}
            for j in kids:
                if keys[j[3]] is not None:
                    MEMO.put(keys[j[3]], outer[j[3]])
                self._outer[j[3]] = outer[j[3]].summary
                key = self._key("above", self._outer_sig[j[3]], self._desc[j[0]]) if self.stream else None
                above[j[3]] = [self._cached(key, lambda: [self._outer[j[3]], self.joint_rows[j[0]]],
                                            pose_keys(j[3], self.frames)).summary]
                if self.stream:
                    above_sig[j[3]] = ("above", self._outer_sig[j[3]], self._desc[j[0]])

    def joint_subspace(self, joint: tuple) -> Summary:
        """W ∩ span(L_j) for joint (name, kind, parent, child), as echelon rows over L_j."""
        name, kind, par, chi = joint
        keep = (self.marker_cols[par] + self.marker_cols[chi] + self.joint_cols[name]
                + [key for key in self._children_centres(par) if key not in self.centre_cols[name]]
                + self._children_centres(chi))
        key = self._key("joint", self._outer_sig[chi], self._desc[name], self._sub[chi]) if self.stream else None
        return self._cached(key, lambda: [self._outer[chi], self.joint_rows[name], self._inner[chi]], keep).summary
